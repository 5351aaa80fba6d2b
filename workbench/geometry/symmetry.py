"""A part's rotational symmetry, found from its mesh: the turns about its centre of mass that map the mesh onto
itself, so that two poses that differ by such a turn look the same (a judge of where a part ended up, such as the
simulation's goal check, counts them as one pose).

Candidates come from the principal axes of inertia (any symmetry turn maps them onto each other): a half turn about
each axis whose moment is distinct, and, about the distinct axis of a body with two equal moments, every angle (a
body of revolution) or else turns of 360/k degrees (k = 2..12). A candidate is kept when the mesh turned by it
coincides with the mesh: every vertex and face centre of the turned mesh lies within `tol` of the mesh's surface.
A body of revolution is checked at several angles (7, 31, 97 and 151 degrees) and, when it is, half turns about an
axis across it (an end-for-end flip) are checked as well. A body with three equal moments (a cube, a sphere) is
given no symmetry: its principal axes are not determined by its inertia.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import trimesh

DEFAULT_TOL = 5e-4  # m: how far the turned mesh may lie from the mesh (a tessellated cylinder's facets are well within it)
EQUAL_MOMENTS = 1e-3  # relative difference under which two principal moments count as equal
REVOLUTION_ANGLES = np.radians([7.0, 31.0, 97.0, 151.0])
ORDERS = range(12, 1, -1)


@dataclass(frozen=True)
class Symmetry:
    """Rotational symmetry of a part about its centre of mass `centre` (part frame): `turns` (K, 3, 3), the
    discrete turns that map it onto itself (the identity first), and `axis`, the unit axis of a body of revolution
    (None otherwise), about which every angle is a symmetry as well; `tol` (m) is the coincidence tolerance."""

    centre: np.ndarray
    turns: np.ndarray
    axis: np.ndarray | None
    tol: float

    def angle(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """The smallest rotation angle (rad) between rotations a and b (..., 3, 3) of the part, b taken up to the
        part's symmetry: min over turns g (and, for a body of revolution, every angle about its axis) of the angle
        between a and b g."""
        e = np.einsum("...ji,...jk->...ik", b, a)  # b^T a: a in b's frame
        if self.axis is None:
            c = (np.einsum("...ij,gij->...g", e, self.turns) - 1.0) / 2.0  # trace(g^T e)
            return np.arccos(np.clip(c.max(axis=-1), -1.0, 1.0))
        # about the axis every angle is free: what is left is how far e g^T tilts the axis (swing-twist decomposition)
        ga = np.einsum("gji,j->gi", self.turns, self.axis)  # g^T axis
        c = np.einsum("i,...ij,gj->...g", self.axis, e, ga)
        return np.arccos(np.clip(c.max(axis=-1), -1.0, 1.0))


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """The 3x3 rotation by `angle` (rad) about the unit `axis` (Rodrigues)."""
    k = np.asarray(axis, dtype=np.float64)
    x = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * x + (1.0 - np.cos(angle)) * (x @ x)


def part_symmetry(mesh: trimesh.Trimesh, tol: float = DEFAULT_TOL, centre: np.ndarray | None = None,
                  admits: Callable[[np.ndarray], bool] | None = None) -> Symmetry:
    """The rotational symmetry of a watertight `mesh` (part frame, metres), within `tol` (see the module
    docstring; under a second for the bundled parts), about its centre of mass or about `centre` (3,) when given:
    the turns about that point that map the mesh onto itself (a part's convex hull about the part's centre of
    mass, for what depends on just those two, such as where a dropped part comes to rest). `admits(turn)` (3, 3),
    when given, is a cheap necessary condition checked before the mesh is: a candidate it refuses is not a
    symmetry (the result is then the symmetry among the turns it admits)."""
    inertia = np.asarray(mesh.moment_inertia, dtype=np.float64)
    if centre is None:
        centre = np.asarray(mesh.center_mass, dtype=np.float64)
    else:  # the inertia about `centre` (parallel axes): the turns about it keep it
        centre = np.asarray(centre, dtype=np.float64)
        d = centre - np.asarray(mesh.center_mass, dtype=np.float64)
        inertia = inertia + float(mesh.mass) * (float(d @ d) * np.eye(3) - np.outer(d, d))
    moments, axes = np.linalg.eigh(inertia)
    scale = max(float(np.abs(moments).max()), 1e-30)
    equal = [abs(moments[i] - moments[j]) <= EQUAL_MOMENTS * scale for i, j in ((0, 1), (1, 2), (0, 2))]
    coincide = _Coincidence(mesh, centre, tol)

    def test(r: np.ndarray) -> bool:
        return (admits is None or bool(admits(r))) and coincide(r)

    turns = [np.eye(3)]
    axis = None
    if sum(equal) == 0:
        turns += [r for r in (rotation(axes[:, i], np.pi) for i in range(3)) if test(r)]
    elif sum(equal) == 1:
        lone = [2, 0, 1][equal.index(True)]  # the axis whose moment differs from the other two
        a, across = axes[:, lone], axes[:, (lone + 1) % 3]
        if all(test(rotation(a, t)) for t in REVOLUTION_ANGLES):
            axis = a
            flip = rotation(across, np.pi)
            if test(flip):
                turns.append(flip)
        else:
            k = next((k for k in ORDERS if test(rotation(a, 2 * np.pi / k))), 1)
            turns += [rotation(a, 2 * np.pi * j / k) for j in range(1, k)]
    return Symmetry(centre=centre, turns=np.array(turns), axis=axis, tol=float(tol))


class _Coincidence:
    """Whether the mesh turned by R about `centre` lies within `tol` of the mesh: its vertices and face centres
    (at most about 4,000, taken at a fixed stride), about 64 of them first so that most candidates fail fast."""

    def __init__(self, mesh: trimesh.Trimesh, centre: np.ndarray, tol: float):
        pts = np.vstack([mesh.vertices, mesh.triangles_center]) - centre
        self.points = pts[::max(1, len(pts) // 4000)]
        self.query = trimesh.proximity.ProximityQuery(mesh)
        self.centre, self.tol = centre, tol

    def __call__(self, r: np.ndarray) -> bool:
        moved = self.points @ r.T + self.centre
        for part in (moved[::max(1, len(moved) // 64)], moved):
            _, dist, _ = self.query.on_surface(part)
            if dist.max() > self.tol:
                return False
        return True
