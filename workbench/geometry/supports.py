"""Support faces of a convex hull, merged when coplanar within a tolerance (issue 10; Wan & Harada, Section IV).

A scanned base is flat only to a tolerance: its convex hull is many small faces whose normals differ by a degree
or so, none of which holds the centre of mass's projection on its own. Hull faces are grouped greedily, largest
first: a face joins a group when its normal is within `angle` of the group's seed and all its vertices lie within
`distance` of the seed's plane. A group is one candidate support; its support polygon is the convex hull of every
hull vertex within `distance` of the table once the object rests on the group's area-weighted normal.
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
        ok = (normals[cand] @ n >= cos_a) & ((tri[cand] @ n).min(axis=1) >= level - distance)
        ok[np.searchsorted(cand, f)] = True
        g = cand[ok]
        free[g] = False
        groups.append(g)
    wn = np.array([(normals[g] * areas[g, None]).sum(axis=0) for g in groups]).reshape(-1, 3)
    wn /= np.linalg.norm(wn, axis=1, keepdims=True).clip(1e-300)
    return groups, wn


def support_stability(verts: np.ndarray, com: np.ndarray, normal: np.ndarray, distance: float) -> tuple[float, np.ndarray]:
    """Stability of resting on the face with outward `normal` (distance from the centre of mass's projection to the
    support polygon's boundary over its height, Section VI) and the support points (hull vertices within `distance`
    of the table)."""
    from scipy.spatial import ConvexHull

    proj = verts @ normal
    level = proj.max()
    pts = verts[proj >= level - distance]
    height = level - float(com @ normal)
    if len(pts) < 3 or height <= 0:
        return 0.0, pts
    u = np.cross(normal, np.eye(3)[np.argmin(np.abs(normal))])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    p2 = np.column_stack([(pts - com) @ u, (pts - com) @ v])
    try:
        h = ConvexHull(p2)
    except Exception:  # collinear support: no area
        return 0.0, pts
    return float(np.min(-h.equations[:, 2])) / height, pts


def stabilities(verts: np.ndarray, com: np.ndarray, normals: np.ndarray, distance: float,
                floor: float = 0.0) -> np.ndarray:
    """`support_stability` of every normal. Supports of fewer than three points score 0, and so do supports whose
    farthest point from the centre of mass's vertical cannot give a stability of `floor` (no hull is built)."""
    rel = verts - com
    proj = rel @ normals.T  # (V, G)
    level = proj.max(axis=0)
    support = proj >= level - distance
    radial2 = np.einsum("vj,vj->v", rel, rel)[:, None] - proj**2
    reach = np.sqrt(np.where(support, radial2, 0.0).max(axis=0).clip(0))
    bound = reach / np.maximum(level, 1e-300)
    out = np.zeros(len(normals))
    for i in np.flatnonzero((support.sum(axis=0) >= 3) & (level > 0) & (bound >= floor)):
        out[i] = support_stability(verts, com, normals[i], distance)[0]
    return out
