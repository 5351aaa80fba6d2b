"""The convex hull of a part, with the facets that rounding splits merged back (qhull's pre-merge).

A finely triangulated part saved in single precision (an STL of a subdivided or tessellated part) has vertices along
its hull's edges and on its flat sides rounded up to 6e-8 of their coordinates out of plane. A plain hull keeps
each of them as a vertex and splits every flat side into slivers whose normals point anywhere. Merging facets that
lie in one plane to within `merge_tolerance` (well above that rounding, far below anything a gripper or a table
feels) gives back the part's own hull: its flat sides as coplanar triangles and its corners as vertices.
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from workbench.geometry._hullkernel import inner_vertices

MERGE = 1e-7  # of the part's size: facets this close to one plane are one
ROUNDING = 5e-7  # of the largest coordinate: several times single precision's rounding (6e-8)


def merge_tolerance(points: np.ndarray) -> float:
    """The distance (m) within which hull facets of `points` (N, 3) are merged into one plane."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return 0.0
    return max(MERGE * float(np.ptp(points, axis=0).max()), ROUNDING * float(np.abs(points).max()))


def convex_hull(points: np.ndarray) -> trimesh.Trimesh:
    """The convex hull of `points` (N, 3), triangulated (qhull Qt), outward-facing, with facets within
    `merge_tolerance` of one plane merged. Qhull runs once as usual; only when two neighbouring facets of its hull
    lie in one plane to that tolerance (rounding split a flat side) does it run again with its pre-merge (C-n,
    measured in the unit box that QbB scales the points to), on the first hull's vertices."""
    points = np.asarray(points, dtype=np.float64)
    hull = ConvexHull(points, qhull_options="QbB Pp Qt")
    planes = _planes(hull)
    tol = merge_tolerance(points)
    if _split(hull, planes, tol):
        corners = points[hull.vertices]
        extent = float(np.ptp(corners, axis=0).max())
        hull = ConvexHull(corners, qhull_options=f"QbB Pp Qt C-{2.0 * tol / extent:.3g}")
        planes = _planes(hull)
    return _mesh(hull, planes)


def _planes(hull: ConvexHull) -> tuple[np.ndarray, np.ndarray]:
    """Each simplex's unit normal (F, 3) (either way round) and its first vertex (F, 3), in the points' own frame
    (qhull's equations are in the unit box QbB scaled them to)."""
    tri = hull.points[hull.simplices]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0, length, 1.0), tri[:, 0]


def _split(hull: ConvexHull, planes: tuple[np.ndarray, np.ndarray], tol: float) -> bool:
    """Whether two neighbouring facets of `hull` that qhull kept apart lie in one plane within `tol`: the vertex of
    each simplex across an edge from a simplex of another facet lies within `tol` of that simplex's plane. `planes`:
    `_planes(hull)`."""
    n, p0 = planes
    i = np.repeat(np.arange(len(hull.simplices)), 3)
    j = hull.neighbors.reshape(-1)  # simplex j lies across from vertex k of simplex i
    across = np.flatnonzero(np.any(hull.equations[i] != hull.equations[j], axis=1))  # not one of qhull's facets
    k = np.argmax(hull.neighbors[j[across]] == i[across, None], axis=1)  # the vertex of j opposite to i
    far = hull.points[hull.simplices[j[across], k]]
    return bool(np.any(np.abs(np.einsum("ij,ij->i", far - p0[i[across]], n[i[across]])) <= tol))


def _mesh(hull: ConvexHull, planes: tuple[np.ndarray, np.ndarray]) -> trimesh.Trimesh:
    """The hull as an outward-facing mesh of its vertices, zero-area simplices dropped. `planes`: `_planes(hull)`."""
    n, p0 = planes
    keep = np.linalg.norm(n, axis=1) > 0
    centre = hull.points[hull.vertices].mean(axis=0)  # strictly inside a hull with volume
    faces = hull.simplices[keep]
    out = np.einsum("ij,ij->i", n[keep], p0[keep] - centre) < 0
    faces[out] = faces[out][:, ::-1]
    vid = np.sort(hull.vertices)
    index = np.zeros(len(hull.points), dtype=np.int64)
    index[vid] = np.arange(len(vid))
    return trimesh.Trimesh(vertices=hull.points[vid], faces=index[faces], process=True, validate=False)


FLAT_ANGLE = 1e-9  # rad: faces whose normals agree to this lie in one plane, for `hull_points`


def hull_points(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, closed: bool) -> np.ndarray:
    """The vertices (N, 3) of a mesh that may be vertices of its convex hull: on a closed mesh, all but those inside
    a flat fan of faces or on a straight crease between two flat sides (`_hullkernel.inner_vertices`: a part
    subdivided in place, or a CAD part meshed with points inside its flat sides and along its edges, has most of its
    vertices there), so qhull partitions only the rest and gives the same hull sooner. `faces` (F, 3), `normals`
    (F, 3) their unit normals."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if not closed or len(faces) == 0:
        return vertices
    inner = inner_vertices(np.ascontiguousarray(faces, dtype=np.int64), np.ascontiguousarray(normals, dtype=np.float64),
                           len(vertices), np.sin(FLAT_ANGLE) ** 2)
    return vertices[~inner] if inner.any() and not inner.all() else vertices


def mesh_hull(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, closed: bool) -> trimesh.Trimesh:
    """`convex_hull` of a mesh's vertices (those `hull_points` keeps), from its arrays (a thread can build it)."""
    return convex_hull(hull_points(vertices, faces, normals, closed))


def part_hull(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """`mesh_hull` of a part, built once per mesh (kept in its cache, dropped when the mesh changes)."""
    hull = mesh._cache["workbench_hull"]
    if hull is None:
        hull = mesh._cache["workbench_hull"] = mesh_hull(mesh.vertices.view(np.ndarray), mesh.faces, mesh.face_normals,
                                                         mesh.is_watertight)
    return hull
