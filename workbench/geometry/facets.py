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
from workbench.geometry._radix import descending_order
from workbench.geometry._segkernel import (
    boundary_distances,
    boundary_lengths,
    by_triangle,
    edge_groups,
    facets_holding,
    grow_facets,
    neighbour_table,
    triangle_centres,
    vertex_rows,
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

    def holding(self, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The facets holding each of `triangles` (Q,): (how many (Q,), their ids, ascending per triangle, concatenated
        in query order); the rows `membership` gives for those triangles, without sorting every membership."""
        tri = np.ascontiguousarray(triangles, dtype=np.int64).reshape(-1)
        return facets_holding(self.tri_ptr, self.tri_index, self._n_tri, tri)

    @cached_property
    def perimeters(self) -> np.ndarray:
        """(F,) each facet's boundary length (read-only)."""
        out = boundary_lengths(self.edge_ptr, np.ascontiguousarray(self.edges, dtype=np.float64))
        out.flags.writeable = False
        return out

    @cached_property
    def _n_tri(self) -> int:
        return int(self.tri_index.max(initial=-1)) + 1

    @cached_property
    def _membership(self) -> tuple[np.ndarray, np.ndarray]:
        fid, tid = by_triangle(self.tri_ptr, self.tri_index)
        fid.flags.writeable = tid.flags.writeable = False
        return fid, tid


FACETS_KEY = "workbench_facets"  # the mesh cache entry holding its last segmentation (`segment`)
# the mesh cache entry holding its edge tables, (`edge_groups`' two arrays, `neighbour_table`), as loading builds them
EDGES_KEY = "workbench_edges"


def segment(mesh: trimesh.Trimesh, tau: float = np.radians(18.0), method: str = "over",
            merge_angle: float | None = None) -> Facets:
    """Segment `mesh` into facets: `method` "over" (over-segmentation) or "conventional" (Fig. 2)."""
    if method not in ("over", "conventional"):
        raise WorkbenchError(f"segmentation method must be 'over' or 'conventional', got {method!r}")
    if not 0 < tau < np.pi / 2:
        raise WorkbenchError(f"segmentation threshold tau must be between 0 and 90 degrees, got {np.degrees(tau):.3g} degrees")
    merge = tau / 2 if merge_angle is None else float(merge_angle)
    # the last segmentation of this mesh, kept in trimesh's cache (dropped when the mesh changes): planning again with
    # other sampling, filters or gripper (a widget's slider) segments once
    key = (method, float(tau), merge)
    kept = mesh._cache[FACETS_KEY]
    if kept is not None and kept[0] == key:
        return kept[1]
    normals = np.asarray(mesh.face_normals)
    areas = np.asarray(mesh.area_faces)
    n_tri = len(normals)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    tables = mesh._cache[EDGES_KEY]
    if tables is None:
        order, starts = edge_groups(faces, len(mesh.vertices))
        tables = mesh._cache[EDGES_KEY] = (order, starts, neighbour_table(order, starts, n_tri))
    order, starts, nbr = tables
    seed_order = descending_order(np.round(areas, 12).view(np.int64))  # largest first, ties by index
    tri_ptr, tri_index, seeds, wn, wc, area, edge_ptr, be = grow_facets(
        np.ascontiguousarray(normals, dtype=np.float64), nbr, seed_order, method == "conventional",
        float(np.cos(tau)), float(np.cos(merge)),
        triangle_centres(np.ascontiguousarray(mesh.vertices, dtype=np.float64), faces),
        np.ascontiguousarray(areas, dtype=np.float64), faces, len(mesh.vertices), order, starts)
    out = Facets(method=method, tau=tau, tri_ptr=tri_ptr, tri_index=tri_index,
                 normals=wn / np.linalg.norm(wn, axis=1, keepdims=True).clip(1e-300),
                 centers=wc / area[:, None].clip(1e-300), areas=area, seeds=seeds, edge_ptr=edge_ptr,
                 edges=vertex_rows(np.ascontiguousarray(mesh.vertices, dtype=np.float64), be))
    for a in (out.tri_ptr, out.tri_index, out.normals, out.centers, out.areas, out.seeds, out.edge_ptr, out.edges):
        a.flags.writeable = False  # shared by every plan of the mesh
    mesh._cache[FACETS_KEY] = (key, out)
    return out


def distance_to_boundary(facets: Facets, facet_ids: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each point to the boundary of its facet, measured in the facet's plane (Section III, distance
    filter); compiled, so memory stays bounded however many boundary edges the facets share (the literal
    over-segmentation)."""
    facet_ids = np.ascontiguousarray(facet_ids, dtype=np.int64)
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return boundary_distances(facets.edge_ptr, np.ascontiguousarray(facets.edges, dtype=np.float64),
                              np.ascontiguousarray(facets.normals, dtype=np.float64), facet_ids, points)
