"""Mesh segmentation into planar facets (Wan & Harada, Section III, Fig. 2).

Two algorithms: the conventional one puts each triangle in exactly one facet; over-segmentation examines
every triangle as a seed and lets facets overlap. A facet grows from its seed across shared edges to every
triangle whose normal is within `tau` of the seed's normal. Seeds are taken in a fixed order (larger
triangles first, then by index), so results are deterministic.

The paper leaves open how near-identical facets are avoided when every triangle is a seed; here a seed is
skipped when it already lies in a facet whose seed normal is within `merge_angle` of its own (0 examines
literally every triangle; the default, tau/2, keeps facets overlapping while bounding their number).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import trimesh

from workbench.errors import WorkbenchError
from workbench.geometry._segkernel import (
    by_triangle,
    edge_groups,
    facet_boundaries,
    facet_sums,
    grow_facets,
    neighbour_table,
)


@dataclass(frozen=True)
class Facets:
    """Facets of a mesh in CSR form: facet f holds triangles `tri_index[tri_ptr[f]:tri_ptr[f+1]]`.

    `normals` are area-weighted unit normals (outward), `centers` area-weighted centroids, `areas` the facet
    areas, `seeds` the seed triangle of each facet; boundary edges of facet f are
    `edges[edge_ptr[f]:edge_ptr[f+1]]` as (E, 2, 3) segment end points.
    """

    method: str
    tau: float
    tri_ptr: np.ndarray
    tri_index: np.ndarray
    normals: np.ndarray
    centers: np.ndarray
    areas: np.ndarray
    seeds: np.ndarray
    edge_ptr: np.ndarray
    edges: np.ndarray

    def __len__(self) -> int:
        return len(self.seeds)

    def triangles_of(self, f: int) -> np.ndarray:
        return self.tri_index[self.tri_ptr[f]:self.tri_ptr[f + 1]]

    def membership(self) -> tuple[np.ndarray, np.ndarray]:
        """(facet id, triangle id) for every membership, sorted by triangle (then facet); computed once (read-only)."""
        return self._membership

    @cached_property
    def _membership(self) -> tuple[np.ndarray, np.ndarray]:
        fid, tid = by_triangle(self.tri_ptr, self.tri_index)
        fid.flags.writeable = tid.flags.writeable = False
        return fid, tid


def segment(mesh: trimesh.Trimesh, tau: float = np.radians(18.0), method: str = "over",
            merge_angle: float | None = None) -> Facets:
    """Segment `mesh` into facets: `method` "over" (over-segmentation) or "conventional" (Fig. 2)."""
    if method not in ("over", "conventional"):
        raise WorkbenchError(f"segmentation method must be 'over' or 'conventional', got {method!r}")
    if not 0 < tau < np.pi / 2:
        raise WorkbenchError(f"segmentation threshold tau must be between 0 and 90 degrees, got {np.degrees(tau):.3g} degrees")
    merge = tau / 2 if merge_angle is None else float(merge_angle)
    normals = np.asarray(mesh.face_normals)
    areas = np.asarray(mesh.area_faces)
    n_tri = len(normals)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    order, starts = edge_groups(faces, len(mesh.vertices))
    nbr = neighbour_table(order, starts, n_tri)
    seed_order = np.lexsort((np.arange(n_tri), -np.round(areas, 12)))
    tri_ptr, tri_index, seeds = grow_facets(np.ascontiguousarray(normals, dtype=np.float64), nbr, seed_order,
                                            method == "conventional", float(np.cos(tau)), float(np.cos(merge)))
    wn, wc, area = facet_sums(tri_ptr, tri_index, np.ascontiguousarray(normals, dtype=np.float64),
                              np.ascontiguousarray(mesh.triangles_center, dtype=np.float64),
                              np.ascontiguousarray(areas, dtype=np.float64))
    edge_ptr, be = facet_boundaries(faces, tri_ptr, tri_index, len(mesh.vertices), order, starts, nbr)
    return Facets(method=method, tau=tau, tri_ptr=tri_ptr, tri_index=tri_index,
                  normals=wn / np.linalg.norm(wn, axis=1, keepdims=True).clip(1e-300),
                  centers=wc / area[:, None].clip(1e-300), areas=area, seeds=seeds, edge_ptr=edge_ptr,
                  edges=mesh.vertices[be])


def distance_to_boundary(facets: Facets, facet_ids: np.ndarray, points: np.ndarray, budget: int = 2_000_000) -> np.ndarray:
    """Distance from each point to the boundary of its facet, measured in the facet's plane (Section III, distance
    filter). Points go in chunks of at most `budget` (point, boundary edge) rows, so memory stays bounded when facets
    overlap heavily (the literal over-segmentation)."""
    facet_ids = np.asarray(facet_ids, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.full(len(facet_ids), np.inf)
    counts = facets.edge_ptr[facet_ids + 1] - facets.edge_ptr[facet_ids]
    cum = np.cumsum(counts)
    start = 0
    while start < len(facet_ids):
        base = cum[start - 1] if start else 0
        stop = max(int(np.searchsorted(cum, base + budget, side="right")), start + 1)
        out[start:stop] = _distance_chunk(facets, facet_ids[start:stop], points[start:stop], counts[start:stop])
        start = stop
    return out


def _distance_chunk(facets: Facets, facet_ids: np.ndarray, points: np.ndarray, counts: np.ndarray) -> np.ndarray:
    out = np.full(len(facet_ids), np.inf)
    has = counts > 0
    if not has.any():
        return out
    rows = np.repeat(np.arange(len(facet_ids)), counts)
    starts = np.repeat(facets.edge_ptr[facet_ids] - np.cumsum(counts) + counts, counts)
    seg = facets.edges[starts + np.arange(counts.sum())]
    n = facets.normals[facet_ids][rows]
    # project the segment and the point onto the facet plane, then point-to-segment distance
    p = points[rows]
    a = seg[:, 0] - (np.einsum("ij,ij->i", seg[:, 0] - p, n))[:, None] * n
    b = seg[:, 1] - (np.einsum("ij,ij->i", seg[:, 1] - p, n))[:, None] * n
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab).clip(1e-300), 0.0, 1.0)
    d = np.linalg.norm(p - (a + t[:, None] * ab), axis=1)
    first = np.concatenate([[0], np.cumsum(counts[has])[:-1]])
    out[has] = np.minimum.reduceat(d, first)
    return out
