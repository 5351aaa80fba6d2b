"""Stable placements on a table and the grasps that survive them (Wan & Harada, Sections IV and VI).

Candidate supports are the faces of the object's convex hull, coplanar hull triangles merged. The object
rests on a face; it is stable when the centre of mass projects inside the support polygon, and its stability
is the distance from that projection to the polygon's boundary divided by the height of the centre of mass
(Section VI, "Experiences"), i.e. the tangent of the tilt it can take before tipping. Free-air grasps are
transformed into each placement (not re-planned) and kept when the hand and both fingers at full opening stay
above the table.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from .errors import WorkbenchError
from .gripper import Gripper
from .objects import ObjectModel


@dataclass(frozen=True)
class PlacementParams:
    """min_stability: smallest accepted stability (distance to the support boundary over centre-of-mass height;
    0.1 is a tilt of 5.7 degrees). clearance: how far above the table (m) the hand must stay."""

    min_stability: float = 0.1
    clearance: float = 0.002

    def __post_init__(self) -> None:
        if not self.min_stability >= 0 or not self.clearance >= 0:
            raise WorkbenchError(f"placement parameters must be non-negative, got {self}")

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class Placements:
    """Stable placements: object poses in the table frame (P, 4, 4) with the centre of mass above the origin and
    the lowest point on z = 0; stability values; support polygons (in the table frame, z = 0); the outward normal
    of the supporting hull face in the object frame. `rejected_*` keep the unstable candidates for inspection."""

    poses: np.ndarray
    stability: np.ndarray
    supports: list[np.ndarray]
    normals: np.ndarray
    rejected_poses: np.ndarray
    rejected_stability: np.ndarray

    def __len__(self) -> int:
        return len(self.stability)


def rest_pose(normal: np.ndarray, com: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """The pose putting the face with outward `normal` down (rotation about a horizontal axis only), the centre of
    mass above the origin and the lowest vertex on z = 0."""
    n = normal / np.linalg.norm(normal)
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(n, down)
    s, c = np.linalg.norm(axis), float(n @ down)
    if s < 1e-12:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = axis / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rot = np.eye(3) + s * kx + (1 - c) * kx @ kx
    pose = np.eye(4)
    pose[:3, :3] = rot
    rc = rot @ com
    pose[:3, 3] = (-rc[0], -rc[1], -float((vertices @ rot.T)[:, 2].min()))
    return pose


def stable_placements(obj: ObjectModel, params: PlacementParams = PlacementParams()) -> Placements:
    """Stable placements of `obj` on its convex-hull faces (Section IV, freetabletopplacement)."""
    hull = obj.mesh.convex_hull
    verts = np.asarray(hull.vertices)
    tol = 1e-6 + 1e-4 * float(obj.mesh.scale)
    # merged coplanar faces: trimesh's facets plus lone triangles
    groups = [np.asarray(f) for f in hull.facets]
    in_facet = np.zeros(len(hull.faces), dtype=bool)
    for f in groups:
        in_facet[f] = True
    groups += [np.array([i]) for i in np.flatnonzero(~in_facet)]
    poses, stab, supports, normals = [], [], [], []
    for faces in groups:
        a = hull.area_faces[faces]
        n = (hull.face_normals[faces] * a[:, None]).sum(0)
        n /= np.linalg.norm(n)
        pose = rest_pose(n, obj.com, verts)
        placed = verts @ pose[:3, :3].T + pose[:3, 3]
        contact = placed[placed[:, 2] <= tol][:, :2]
        height = float((pose[:3, :3] @ obj.com + pose[:3, 3])[2])
        margin = _inside_margin(contact)
        poses.append(pose)
        stab.append(margin / height if height > 0 else 0.0)
        supports.append(_polygon(contact))
        normals.append(n)
    poses, stab = np.array(poses), np.array(stab)
    ok = stab >= max(params.min_stability, 1e-9)
    order = np.argsort(-stab[ok], kind="stable")
    idx = np.flatnonzero(ok)[order]
    return Placements(poses=poses[idx], stability=stab[idx], supports=[supports[i] for i in idx],
                      normals=np.array(normals)[idx].reshape(-1, 3), rejected_poses=poses[~ok], rejected_stability=stab[~ok])


def _polygon(points2d: np.ndarray) -> np.ndarray:
    """Convex support polygon (counter-clockwise, z = 0) of the contact points."""
    if len(points2d) >= 3:
        try:
            h = ConvexHull(points2d)
            ring = points2d[h.vertices]
            return np.column_stack([ring, np.zeros(len(ring))])
        except Exception:  # collinear contacts: a segment, no area
            pass
    return np.column_stack([points2d, np.zeros(len(points2d))])


def _inside_margin(points2d: np.ndarray) -> float:
    """Distance from the origin (the centre of mass's projection) to the boundary of the contacts' convex hull;
    negative or zero when the origin is outside or the support has no area."""
    if len(points2d) < 3:
        return 0.0
    try:
        h = ConvexHull(points2d)
    except Exception:
        return 0.0
    # equations: n.x + d <= 0 inside, n unit; margin = min(-d) over facets
    return float(np.min(-h.equations[:, 2]))


def grips_above_table(placement_poses: np.ndarray, grasp_poses: np.ndarray, gripper: Gripper,
                      clearance: float) -> np.ndarray:
    """(P, G) mask: the hand and both fingers at full opening stay `clearance` above the table (z = 0) for grasp g in
    placement p (Section IV, freetabletopgrip)."""
    pts = np.asarray(gripper.collision_mesh().convex_hull.vertices)  # lowest point of a mesh is a hull vertex
    # z of every hull point for every (placement, grasp): row 2 of P @ G applied to the points
    row = np.einsum("pj,gjk->pgk", placement_poses[:, 2, :], grasp_poses)  # (P, G, 4)
    z = np.einsum("pgk,vk->pgv", row[..., :3], pts) + row[..., 3:4]
    return z.min(axis=2) >= clearance


def free_tabletop_grips(placements: Placements, grasp_poses: np.ndarray, gripper: Gripper,
                        params: PlacementParams = PlacementParams()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grasps kept at each placement: (placement index, grasp index, TCP pose in the table frame)."""
    ok = grips_above_table(placements.poses, grasp_poses, gripper, params.clearance)
    p, g = np.nonzero(ok)
    return p, g, placements.poses[p] @ grasp_poses[g]
