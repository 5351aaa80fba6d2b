"""Stable placements on a table and the grasps that survive them (Wan & Harada, Sections IV and VI).

Candidate supports are the faces of the object's convex hull, coplanar hull triangles merged. The object
rests on a face; it is stable when the centre of mass projects inside the support polygon, and its stability
is the distance from that projection to the polygon's boundary divided by the height of the centre of mass
(Section VI, "Experiences"), i.e. the tangent of the tilt it can take before tipping. Free-air grasps are
transformed into each placement (not re-planned) and kept when the hand and both fingers at full opening stay
above the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from workbench.errors import MeshError
from workbench.geometry.objects import ObjectModel
from workbench.params import Params, param
from workbench.robots.gripper import Gripper


@dataclass(frozen=True)
class PlacementParams(Params):
    """min_stability: smallest accepted stability (distance to the support boundary over centre-of-mass height;
    0.1 is a tilt of 5.7 degrees). clearance: how far above the table (m) the hand must stay."""

    min_stability: float = param(0.1, ge=0, help="smallest stability (support margin over centre-of-mass height)")
    clearance: float = param(0.002, ge=0, le=0.5, unit="m", help="hand clearance above the table")


@dataclass(frozen=True)
class Placements:
    """Stable placements: object poses in the table frame (P, 4, 4) with the centre of mass above the origin and
    the lowest point on z = 0; stability values; support polygons (in the table frame, z = 0); the outward normal
    of the supporting hull face in the object frame. `rejected_stability` keeps every unstable candidate's value and `rejected_poses` the first 64 poses."""

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
    """Stable placements of `obj` on its convex-hull faces (Section IV, freetabletopplacement).

    Every candidate is first scored against its own (merged) face polygon, all at once; the candidates that can
    reach the threshold are then settled exactly: the object rests with that face's area-weighted normal down, the
    support polygon is the hull of all vertices touching the table, and stability = margin / height.
    """
    pts = np.asarray(obj.mesh.vertices)
    centred = pts - pts.mean(axis=0)
    thickness = float(np.linalg.svd(centred, compute_uv=False)[-1]) / np.sqrt(max(len(pts), 1)) if len(pts) >= 4 else 0.0
    if thickness <= 1e-9 * max(float(obj.mesh.scale), 1e-12):
        raise MeshError(f"{obj.source or obj.name} is flat (every vertex lies in one plane): it has no volume to rest on the "
                        f"table; give a mesh of a solid part (a closed surface, or a sheet with thickness)")
    hull = obj.mesh.convex_hull
    verts = np.asarray(hull.vertices)
    faces = np.asarray(hull.faces)
    in_facet = np.zeros(len(faces), dtype=bool)
    groups = [np.asarray(f) for f in hull.facets]
    for f in groups:
        in_facet[f] = True
    lone = np.flatnonzero(~in_facet)
    groups += [np.array([f]) for f in lone]
    group_of = np.concatenate(groups)
    owner_face = np.repeat(np.arange(len(groups)), [len(g) for g in groups])
    normals = np.zeros((len(groups), 3))
    np.add.at(normals, owner_face, hull.face_normals[group_of] * hull.area_faces[group_of, None])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    # quick score of every candidate: the centre of mass's projection against the face's own boundary edges
    edges = [np.asarray(b) for b in hull.facets_boundary] + [faces[f][[[0, 1], [1, 2], [2, 0]]] for f in lone]
    owner = np.repeat(np.arange(len(edges)), [len(e) for e in edges])
    e = np.vstack(edges)
    a, b = verts[e[:, 0]], verts[e[:, 1]]
    inward = np.cross(normals[owner], b - a)
    inward /= np.linalg.norm(inward, axis=1, keepdims=True).clip(1e-300)
    centre = np.array([verts[x].reshape(-1, 3).mean(axis=0) for x in edges])
    inward *= np.sign(np.einsum("ij,ij->i", centre[owner] - a, inward))[:, None]
    margin = np.minimum.reduceat(np.einsum("ij,ij->i", obj.com - a, inward),
                                 np.concatenate([[0], np.cumsum([len(x) for x in edges])[:-1]]))
    height = np.einsum("ij,ij->i", centre - obj.com, normals)
    quick = np.where(height > 0, margin / np.maximum(height, 1e-300), 0.0)
    threshold = max(params.min_stability, 1e-9)
    stability = quick.copy()
    tol = 1e-6 + 1e-4 * float(obj.mesh.scale)
    poses, supports = {}, {}
    for i in np.flatnonzero(quick >= 0.8 * threshold):
        pose = rest_pose(normals[i], obj.com, verts)
        placed = verts @ pose[:3, :3].T + pose[:3, 3]
        contact = placed[placed[:, 2] <= tol][:, :2]
        poses[i], supports[i] = pose, _polygon(contact)
        stability[i] = _inside_margin(contact) / float((pose[:3, :3] @ obj.com + pose[:3, 3])[2])
    ok = (stability >= threshold) & np.isin(np.arange(len(groups)), list(poses))
    idx = np.flatnonzero(ok)[np.argsort(-stability[ok], kind="stable")]
    rejected = np.flatnonzero(~ok)
    rejected_poses = np.array([rest_pose(normals[i], obj.com, verts) for i in rejected[:64]]).reshape(-1, 4, 4)
    return Placements(poses=np.array([poses[i] for i in idx]).reshape(-1, 4, 4), stability=stability[idx],
                      supports=[supports[i] for i in idx], normals=normals[idx].reshape(-1, 3),
                      rejected_poses=rejected_poses, rejected_stability=stability[rejected])


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
    negative when the origin is outside, zero when the support has no area."""
    if len(points2d) < 3:
        return 0.0
    try:
        h = ConvexHull(points2d)
    except Exception:  # collinear contacts
        return 0.0
    return float(np.min(-h.equations[:, 2]))  # equations: unit n.x + d <= 0 inside


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
