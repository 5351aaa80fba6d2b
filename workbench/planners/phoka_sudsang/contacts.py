"""Discrete contact points of a triangle mesh (Phoka & Sudsang, Section III).

Every facet's centroid is a candidate contact point and its inward unit normal the direction a fingertip
pushes. The paper's objects have about 500 triangles; larger meshes are decimated first by quadric edge
collapse (fast-simplification, through trimesh), a parameter of the stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from trimesh.ray.ray_util import contains_points

from workbench.errors import MeshError
from workbench.geometry.objects import ObjectModel
from workbench.params import Params, param


@dataclass(frozen=True)
class ContactParams(Params):
    """Parameters of the contact stage: `faces` is the triangle budget (None or 0 keeps the mesh as it is);
    `resolution` the grid cells along the longest side when a mesh must be remeshed before decimation."""

    faces: int | None = param(500, ge=0, le=200_000, integer=True, optional=True,
                              help="triangles kept for contact points (0: keep the mesh)")
    resolution: int = param(100, ge=8, le=2000, integer=True, help="remesh grid cells along the longest side")

    def check(self) -> None:
        self.require(not self.faces or self.faces >= 4, ("faces",),
                     "too few triangles for contact points; use at least 4 (or 0 to keep the mesh)")

    def validate(self) -> "ContactParams":
        """Ranges are checked at construction; kept for callers that validate explicitly."""
        return self


@dataclass(frozen=True)
class ContactSet:
    """Contact points T_O of an object: facet centroids, inward unit normals, the facet each comes from.

    `mesh` is the (decimated) mesh whose faces the contacts are the centroids of; `com` the object's centre
    of mass (the reference point of torques in force-closure tests); `radius` the largest distance of a contact
    from `com`, the length that makes torques comparable to forces.
    """

    points: np.ndarray      # (N, 3) metres
    normals: np.ndarray     # (N, 3) inward unit normals
    face: np.ndarray        # (N,) face index in `mesh`
    mesh: trimesh.Trimesh
    com: np.ndarray
    radius: float

    def __len__(self) -> int:
        return int(len(self.points))


def decimate(mesh: trimesh.Trimesh, faces: int | None, resolution: int = 100) -> trimesh.Trimesh:
    """The mesh reduced to about `faces` triangles by quadric decimation, or subdivided (each triangle split in four)
    until it has at least half of them.

    Quadric decimation (fast-simplification) refuses edge collapses that would leave a near-degenerate triangle,
    so on meshes full of slivers (typical CSG output) it stalls far above the target. A closed mesh is then
    remeshed first: inside/outside on a grid of `resolution` cells along its longest side, the surface-nets
    surface of that grid, Taubin smoothing, and the decimation of that well-shaped surface.
    """
    if len(mesh.faces) == 0:
        raise MeshError("mesh has no faces: give a triangle mesh with at least 4 faces")
    if not faces or len(mesh.faces) <= faces:
        out = mesh.copy()
        # a coarse CAD mesh (a box is 12 triangles) would give too few contact points: split every triangle in
        # four until the mesh has at least half the budget
        while faces and len(out.faces) < faces / 2:
            out = out.subdivide()
    else:
        out = mesh.simplify_quadric_decimation(face_count=int(faces))
        if len(out.faces) > 1.1 * faces and mesh.is_watertight:
            out = remesh(mesh, resolution).simplify_quadric_decimation(face_count=int(faces))
        if len(out.faces) > 2 * faces:
            raise MeshError(f"decimation stopped at {len(out.faces)} triangles (asked {faces}) and the mesh is not closed, "
                            f"so it cannot be remeshed; repair the mesh or raise faces")
    area = out.area_faces
    keep = area > 1e-12 * max(float(area.max(initial=0.0)), 1e-300)
    if not keep.all():
        out.update_faces(keep)
        out.remove_unreferenced_vertices()
    if len(out.faces) < 4:
        raise MeshError(f"mesh decimated to {len(out.faces)} faces, too few for a 4-contact grasp; raise faces")
    if out.is_watertight and out.volume < 0:
        out.invert()
    return out


def contact_points(obj: ObjectModel | trimesh.Trimesh, params: ContactParams = ContactParams()) -> ContactSet:
    """Contact points T_O: centroids of the (decimated) faces with inward unit normals (Section III)."""
    params.validate()
    mesh = obj.mesh if isinstance(obj, ObjectModel) else obj
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError("mesh is empty: give a triangle mesh with faces")
    reduced = decimate(mesh, params.faces, params.resolution)
    points = np.asarray(reduced.triangles_center, dtype=np.float64)
    normals = -np.asarray(reduced.face_normals, dtype=np.float64)
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norm > 0, norm, 1.0)
    if isinstance(obj, ObjectModel):
        com = np.asarray(obj.com, dtype=np.float64)
    else:
        com = np.asarray(reduced.center_mass if reduced.is_watertight else points.mean(0), dtype=np.float64)
    radius = float(np.linalg.norm(points - com, axis=1).max())
    return ContactSet(points=points, normals=normals, face=np.arange(len(points), dtype=np.int64), mesh=reduced,
                      com=com, radius=radius)


def remesh(mesh: trimesh.Trimesh, resolution: int = 100) -> trimesh.Trimesh:
    """A well-shaped closed surface of a closed mesh: surface nets of its inside/outside grid, Taubin-smoothed."""
    pitch = float(mesh.extents.max()) / resolution
    lo = mesh.bounds[0] - pitch
    n = np.ceil((mesh.extents + 2 * pitch) / pitch).astype(int) + 1
    axes = [lo[i] + pitch * np.arange(n[i]) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    occupied = _contains(mesh, grid).reshape(n)
    if not occupied.any():
        raise MeshError(f"remeshing at {resolution} cells found no inside; raise the resolution")
    vertices, faces = surface_nets(occupied, lo, pitch)
    out = trimesh.Trimesh(vertices, faces, process=True)
    trimesh.smoothing.filter_taubin(out, iterations=10)
    return out


def _contains(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Inside test by ray parity, the majority over three fixed directions (trimesh's own retry direction is
    random, which made remeshing non-deterministic)."""

    dirs = np.array([[0.4395064455, 0.617598629942, 0.652231566745], [-0.7071, 0.1, 0.7], [0.3, -0.8, 0.52]])
    votes = sum(contains_points(mesh.ray, points, check_direction=d / np.linalg.norm(d)).astype(np.int8) for d in dirs)
    return votes >= 2


def surface_nets(occupied: np.ndarray, origin: np.ndarray, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Triangles of the surface-nets surface of a boolean grid (voxel centres at origin + pitch * index).

    One vertex per cell whose eight corners differ (the mean of its sign-changing edges' midpoints), one quad
    (two triangles) per grid edge whose ends differ, facing from the inside to the outside.
    """
    o = np.pad(occupied, 1)
    nx, ny, nz = o.shape
    corners = [(a, b, c) for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    corner = [o[a:nx - 1 + a, b:ny - 1 + b, c:nz - 1 + c] for a, b, c in corners]
    inside = sum(x.astype(np.int8) for x in corner)
    active = (inside > 0) & (inside < 8)
    cell_id = np.full(active.shape, -1, dtype=np.int64)
    cell_id[active] = np.arange(int(active.sum()))
    acc = np.zeros(active.shape + (3,))
    count = np.zeros(active.shape)
    for p in range(8):
        for q in range(p + 1, 8):
            if sum(abs(x - y) for x, y in zip(corners[p], corners[q])) != 1:
                continue
            change = corner[p] != corner[q]
            acc[change] += (np.array(corners[p]) + np.array(corners[q])) / 2.0
            count[change] += 1
    vertices = origin + (np.argwhere(active) + acc[active] / count[active][:, None] - 1.0) * pitch
    faces = []
    for axis in range(3):
        first = [slice(None)] * 3
        second = [slice(None)] * 3
        first[axis], second[axis] = slice(0, -1), slice(1, None)
        a, b = o[tuple(first)], o[tuple(second)]
        edge = np.argwhere(a != b)
        u, v = [x for x in range(3) if x != axis]
        quad = []
        for du, dv in ((-1, -1), (0, -1), (0, 0), (-1, 0)):
            cell = edge.copy()
            cell[:, u] += du
            cell[:, v] += dv
            quad.append(cell_id[cell[:, 0], cell[:, 1], cell[:, 2]])
        quad = np.stack(quad, axis=1)
        flip = ~a[a != b]                          # outside first: face the other way
        if axis == 1:                              # (u, v) = (x, z) and x cross z = -y
            flip = ~flip
        quad[flip] = quad[flip][:, ::-1]
        faces.append(np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]]))
    return vertices, np.concatenate(faces)
