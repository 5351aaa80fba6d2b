"""Support faces of a convex hull, merged when coplanar within a tolerance (issue 10; Wan & Harada, Section IV).

A scanned base is flat only to a tolerance: its convex hull is many small faces whose normals differ by a degree
or so, none of which holds the centre of mass's projection on its own. Hull faces are grouped greedily, largest
first: a face joins a group when its normal is within `angle` of the group's seed and all its vertices lie within
`distance` of the seed's plane, or when its vertices lie within a quarter of `distance` whatever its tilt (thin
slivers along the rim of a noisy base). A group is one candidate support resting on its area-weighted normal; its support polygon is the convex hull
of the group's vertices (all within `distance` of the table). Only the group's own vertices count: on a curved side
(a cylinder's flat strips) vertices of neighbouring strips also lie within half a millimetre of the table, but the
object would roll, not rest on them.
"""

from __future__ import annotations

import numpy as np
import trimesh


def coplanar_groups(hull: trimesh.Trimesh, distance: float, angle: float) -> tuple[list[np.ndarray], np.ndarray]:
    """Groups of hull faces (lists of face ids, largest seed first) and their area-weighted outward unit normals."""
    normals = np.asarray(hull.face_normals)
    areas = np.asarray(hull.area_faces)
    tri = np.asarray(hull.triangles)
    order = np.lexsort((np.arange(len(areas)), -areas))
    free = np.ones(len(areas), dtype=bool)
    cos_a = np.cos(angle)
    groups = []
    for f in order:
        if not free[f]:
            continue
        n = normals[f]
        level = float(tri[f, 0] @ n)
        cand = np.flatnonzero(free)
        low = (tri[cand] @ n).min(axis=1) - level
        # within the angle and the distance; or, whatever its tilt, flat against the plane to a quarter of the
        # distance (the slivers a noisy scan's hull puts along the rim of its base)
        ok = (low >= -distance) & ((normals[cand] @ n >= cos_a) | (low >= -0.25 * distance))
        ok[np.searchsorted(cand, f)] = True
        g = cand[ok]
        free[g] = False
        groups.append(g)
    wn = np.array([(normals[g] * areas[g, None]).sum(axis=0) for g in groups]).reshape(-1, 3)
    wn /= np.linalg.norm(wn, axis=1, keepdims=True).clip(1e-300)
    return groups, wn


def support_stability(points: np.ndarray, com: np.ndarray, normal: np.ndarray) -> float:
    """Stability of resting on the support `points` (vertices of one coplanar group) with outward `normal` down:
    the distance from the centre of mass's projection to the support polygon's boundary over the centre of mass's
    height (Section VI); negative when the projection falls outside, 0 when the support has no area."""
    from scipy.spatial import ConvexHull

    height = float(((points - com) @ normal).max())
    if len(points) < 3 or height <= 0:
        return 0.0
    u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    p2 = np.column_stack([(points - com) @ u, (points - com) @ v])
    try:
        h = ConvexHull(p2)
    except Exception:  # collinear support: no area
        return 0.0
    return float(np.min(-h.equations[:, 2])) / height  # equations: unit n.x + d <= 0 inside; negative outside


def stabilities(hull: trimesh.Trimesh, com: np.ndarray, groups: list[np.ndarray], normals: np.ndarray,
                floor: float = 0.0) -> np.ndarray:
    """`support_stability` of every group, its support the vertices of its faces. Groups whose farthest support point
    from the centre of mass's vertical cannot give a stability of `floor` score 0 (no hull is built)."""
    faces = np.asarray(hull.faces)
    verts = np.asarray(hull.vertices)
    out = np.zeros(len(groups))
    for i, g in enumerate(groups):
        pts = verts[np.unique(faces[g])]
        rel = pts - com
        n = normals[i]
        h = rel @ n
        height = float(h.max())
        if height <= 0:
            continue
        reach = np.sqrt(max(float((np.einsum("vj,vj->v", rel, rel) - h**2).max()), 0.0))
        if reach / height < floor:
            continue
        out[i] = support_stability(pts, com, n)
    return out
