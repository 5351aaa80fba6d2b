"""Features of a polyhedron for grasp classes (Tournassoud, Lozano-Perez & Mazer 1987, Section 2.1).

- Faces: the mesh's coplanar facets (trimesh's facets, lone triangles as their own face), each with its outward
  normal, plane offset, triangles and area.
- Edges: feature edges, i.e. mesh edges whose dihedral angle exceeds a parameter; collinear feature edges that
  share a vertex are merged into one segment.
- Vertices: the convex ones: at least three distinct adjacent face normals, and every neighbouring vertex strictly
  on the inner side of the plane through the vertex normal to the mean adjacent face normal.

2D helpers serve the projections of Section 2.1: faces and their overlaps rasterised on a grid (cell centres inside a triangle),
segments sampled against a raster.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh


@dataclass(frozen=True)
class Face:
    """A planar face: outward unit normal, plane offset (normal . x = offset), triangles (T, 3, 3) and area."""

    normal: np.ndarray
    offset: float
    triangles: np.ndarray
    area: float


@dataclass(frozen=True)
class Edge:
    """A feature edge segment p0-p1 with the outward normals of its two adjacent faces."""

    p0: np.ndarray
    p1: np.ndarray
    normals: np.ndarray  # (2, 3)

    @property
    def direction(self) -> np.ndarray:
        d = self.p1 - self.p0
        return d / np.linalg.norm(d)


@dataclass(frozen=True)
class Vertex:
    """A convex vertex with the outward normals of its adjacent faces."""

    point: np.ndarray
    normals: np.ndarray  # (K, 3)


@dataclass(frozen=True)
class Features:
    """The features of a polyhedral part (Section 2.1): its faces, feature edges and vertices."""

    faces: list[Face]
    edges: list[Edge]
    vertices: list[Vertex]


def faces_of(mesh: trimesh.Trimesh, min_area: float) -> list[Face]:
    """The coplanar facets of `mesh` with area >= `min_area`, largest first (Section 2.1)."""
    groups = [np.asarray(f) for f in mesh.facets]
    used = np.zeros(len(mesh.faces), dtype=bool)
    for g in groups:
        used[g] = True
    groups += [np.array([t]) for t in np.flatnonzero(~used)]
    tris = np.asarray(mesh.triangles)
    areas = np.asarray(mesh.area_faces)
    out = []
    for g in groups:
        area = float(areas[g].sum())
        if area < min_area:
            continue
        n = (np.asarray(mesh.face_normals)[g] * areas[g, None]).sum(axis=0)
        n /= np.linalg.norm(n)
        out.append(Face(normal=n, offset=float(np.mean(tris[g].reshape(-1, 3) @ n)), triangles=tris[g], area=area))
    out.sort(key=lambda f: -f.area)
    return out


def feature_edges(mesh: trimesh.Trimesh, min_angle: float, min_length: float = 0.0) -> list[Edge]:
    """Mesh edges with a dihedral angle above `min_angle` (radians), collinear neighbours merged (Section 2.1)."""
    adj = np.asarray(mesh.face_adjacency)
    if len(adj) == 0:
        return []
    angles = np.asarray(mesh.face_adjacency_angles)
    convex = np.asarray(mesh.face_adjacency_convex)
    keep = (angles > min_angle) & convex
    pairs = np.asarray(mesh.face_adjacency_edges)[keep]
    fn = np.asarray(mesh.face_normals)[adj[keep]]
    v = np.asarray(mesh.vertices)
    segs = [[int(a), int(b), n] for (a, b), n in zip(pairs, fn)]
    # merge collinear segments that share a vertex and the same pair of face normals
    merged = True
    while merged:
        merged = False
        by_vertex: dict[int, list[int]] = {}
        for k, (a, b, _) in enumerate(segs):
            by_vertex.setdefault(a, []).append(k)
            by_vertex.setdefault(b, []).append(k)
        for vid, ks in by_vertex.items():
            if len(ks) != 2:
                continue
            s, t = segs[ks[0]], segs[ks[1]]
            if s is None or t is None:
                continue
            da = v[s[1]] - v[s[0]]
            db = v[t[1]] - v[t[0]]
            if abs(abs(da @ db) - np.linalg.norm(da) * np.linalg.norm(db)) > 1e-9 * (np.linalg.norm(da) * np.linalg.norm(db)):
                continue
            if np.abs(np.abs(s[2] @ t[2].T) - np.eye(2)).max() > 1e-6 and np.abs(np.abs(s[2] @ t[2][::-1].T) - np.eye(2)).max() > 1e-6:
                continue
            ends = [x for x in (s[0], s[1], t[0], t[1]) if x != vid]
            segs[ks[0]] = [ends[0], ends[1], s[2]]
            segs[ks[1]] = None
            merged = True
        segs = [s for s in segs if s is not None]
    out = [Edge(v[a].copy(), v[b].copy(), n) for a, b, n in segs if np.linalg.norm(v[b] - v[a]) >= min_length]
    out.sort(key=lambda e: -float(np.linalg.norm(e.p1 - e.p0)))
    return out


def convex_vertices(mesh: trimesh.Trimesh) -> list[Vertex]:
    """Convex vertices: corners (>= 3 distinct adjacent normals) with all neighbours strictly inside (Section 2.1)."""
    v = np.asarray(mesh.vertices)
    fn = np.asarray(mesh.face_normals)
    out = []
    nbrs = mesh.vertex_neighbors
    vf = mesh.vertex_faces
    for i in range(len(v)):
        faces = vf[i][vf[i] >= 0]
        if len(faces) < 3:
            continue
        normals = fn[faces]
        distinct = [normals[0]]
        for n in normals[1:]:
            if all(n @ d < 1 - 1e-6 for d in distinct):
                distinct.append(n)
        if len(distinct) < 3:
            continue
        m = np.mean(distinct, axis=0)
        if np.linalg.norm(m) < 1e-9:
            continue
        m /= np.linalg.norm(m)
        d = (v[nbrs[i]] - v[i]) @ m
        if len(d) and (d < -1e-9).all():
            out.append(Vertex(v[i].copy(), np.array(distinct)))
    return out


def features(mesh: trimesh.Trimesh, min_face_area: float, edge_angle: float) -> Features:
    """Faces, feature edges and convex vertices of `mesh` (Section 2.1)."""
    return Features(faces_of(mesh, min_face_area), feature_edges(mesh, edge_angle), convex_vertices(mesh))


# -- 2D geometry in a plane --------------------------------------------------------------------------------------


def plane_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A right-handed orthonormal basis (u, v) of the plane normal to n (u x v = n), fixed by n alone."""
    ref = np.eye(3)[int(np.argmin(np.abs(n)))]
    u = np.cross(ref, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


@dataclass(frozen=True)
class Raster:
    """A 2D region sampled on a grid: cell (i, j) is the square of side `cell` at origin + (j, i) * cell."""

    origin: np.ndarray
    cell: float
    mask: np.ndarray

    @property
    def area(self) -> float:
        return float(self.mask.sum()) * self.cell ** 2

    def points(self) -> np.ndarray:
        """Centres of the cells inside (K, 2)."""
        i, j = np.nonzero(self.mask)
        return self.origin + (np.stack([j, i], axis=1) + 0.5) * self.cell

    def lookup(self, pts: np.ndarray) -> np.ndarray:
        """Whether 2D points fall in a cell inside."""
        ij = np.floor((np.asarray(pts) - self.origin) / self.cell).astype(np.int64)
        h, w = self.mask.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < w) & (ij[:, 1] >= 0) & (ij[:, 1] < h)
        out = np.zeros(len(ij), dtype=bool)
        out[ok] = self.mask[ij[ok, 1], ij[ok, 0]]
        return out


def grid_for(lo: np.ndarray, hi: np.ndarray, cells: int = 200, min_cell: float = 2e-4) -> tuple[np.ndarray, float, tuple[int, int]]:
    """Origin, cell size and (height, width) of a grid covering the box [lo, hi] with about `cells` along its longest side."""
    cell = max(float(np.max(hi - lo)) / cells, min_cell)
    shape = (int(np.ceil((hi[1] - lo[1]) / cell)) + 1, int(np.ceil((hi[0] - lo[0]) / cell)) + 1)
    return np.asarray(lo, dtype=np.float64), cell, shape


def rasterise(tris: np.ndarray, origin: np.ndarray, cell: float, shape: tuple[int, int]) -> Raster:
    """The cells of a grid whose centre lies in (or on the edge of) one of the 2D triangles (T, 3, 2), all at once by
    scan lines: for every triangle and every cell row its span crosses, the span's first and last cell, filled
    through a difference array (cost per row, not per cell of each triangle's bounding box)."""
    h, w = shape
    mask = np.zeros((h, w), dtype=bool)
    p = (np.asarray(tris, dtype=np.float64).reshape(-1, 3, 2) - origin) / cell - 0.5  # cell (i, j) centre at (j, i)
    if len(p) == 0:
        return Raster(np.asarray(origin, dtype=np.float64), cell, mask)
    eps = 1e-9
    y_lo = np.clip(np.ceil(p[:, :, 1].min(axis=1) - eps), 0, h).astype(np.int64)
    y_hi = np.clip(np.floor(p[:, :, 1].max(axis=1) + eps), -1, h - 1).astype(np.int64)
    counts = np.maximum(y_hi - y_lo + 1, 0)
    tri = np.repeat(np.arange(len(p)), counts)
    iy = y_lo[tri] + np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    y = iy.astype(np.float64)
    x_min = np.full(len(iy), np.inf)
    x_max = np.full(len(iy), -np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        x0, y0, x1, y1 = p[tri, a, 0], p[tri, a, 1], p[tri, b, 0], p[tri, b, 1]
        dy = y1 - y0
        flat = np.abs(dy) <= eps
        t = np.clip((y - y0) / np.where(flat, 1.0, dy), 0.0, 1.0)
        cross = ~flat & (y >= np.minimum(y0, y1) - eps) & (y <= np.maximum(y0, y1) + eps)
        x = x0 + t * (x1 - x0)
        on = flat & (np.abs(y - y0) <= eps)             # a horizontal edge on the row: both its ends
        x_min = np.where(cross, np.minimum(x_min, x), np.where(on, np.minimum(x_min, np.minimum(x0, x1)), x_min))
        x_max = np.where(cross, np.maximum(x_max, x), np.where(on, np.maximum(x_max, np.maximum(x0, x1)), x_max))
    c0 = np.clip(np.ceil(x_min - eps), 0, w).astype(np.int64)
    c1 = np.clip(np.floor(x_max + eps), -1, w - 1).astype(np.int64)
    keep = np.isfinite(x_min) & (c1 >= c0)
    diff = np.zeros((h, w + 1), dtype=np.int32)
    np.add.at(diff, (iy[keep], c0[keep]), 1)
    np.add.at(diff, (iy[keep], c1[keep] + 1), -1)
    mask = np.cumsum(diff[:, :w], axis=1) > 0
    return Raster(np.asarray(origin, dtype=np.float64), cell, mask)


def face_overlap(tri_a: np.ndarray, tri_b: np.ndarray, cells: int = 200) -> Raster | None:
    """The overlap of two triangle sets in 2D as a raster (None when their bounding boxes miss)."""
    lo = np.maximum(tri_a.reshape(-1, 2).min(0), tri_b.reshape(-1, 2).min(0))
    hi = np.minimum(tri_a.reshape(-1, 2).max(0), tri_b.reshape(-1, 2).max(0))
    if (hi <= lo).any():
        return None
    origin, cell, shape = grid_for(lo, hi, cells)
    a = rasterise(tri_a, origin, cell, shape)
    b = rasterise(tri_b, origin, cell, shape)
    return Raster(origin, cell, a.mask & b.mask)


def segment_spans(p0: np.ndarray, p1: np.ndarray, region: Raster) -> list[tuple[float, float]]:
    """Parameter intervals [s0, s1] of the 2D segment p0 + s (p1 - p0) inside a raster region (sampled at half cells)."""
    n = max(int(np.ceil(np.linalg.norm(p1 - p0) / (region.cell / 2))), 2)
    s = np.linspace(0.0, 1.0, n + 1)
    inside = region.lookup(p0 + s[:, None] * (p1 - p0))
    d = np.diff(np.concatenate([[0], inside.astype(np.int8), [0]]))
    a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [(float(s[x]), float(s[y])) for x, y in zip(a, b) if y > x]
