"""Contact-point sampling on facets (Wan & Harada, Section III, "Mesh sampling").

One sampling of the whole surface serves every facet: each sample is distributed to all facets containing
its triangle. The near-neighbour filter (fixed radius) thins the shared samples once, before distribution,
so overlapping facets keep the same contact points; two samples only suppress each other when their surface
normals are within `tau`, so points on the two sides of an edge both survive. The distance filter then
keeps (facet, sample) pairs whose distance to the facet's boundary lies in [dist_min, dist_max].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from numba import njit
from scipy.spatial import cKDTree

from workbench.geometry._segkernel import vertex_rows
from workbench.geometry.facets import Facets, distance_to_boundary


@dataclass(frozen=True)
class Samples:
    """Surface samples and their distribution to facets.

    `points`, `faces`: every sample and its triangle; `kept`: survivors of the near-neighbour filter;
    `pair_facet`, `pair_sample`: (facet, sample) pairs of kept samples; `pair_dist`: distance to that facet's
    boundary; `pair_ok`: the distance filter's verdict.
    """

    points: np.ndarray
    faces: np.ndarray
    kept: np.ndarray
    pair_facet: np.ndarray
    pair_sample: np.ndarray
    pair_dist: np.ndarray
    pair_ok: np.ndarray


def sample_count(mesh: trimesh.Trimesh, density: float | None, radius: float) -> int:
    """Number of surface samples: `density` per square metre, or by default 8 per radius^2 of the neighbour filter
    (the paper derives the density from the surface size)."""
    per_m2 = density if density is not None else 8.0 / radius**2
    return int(np.clip(np.ceil(mesh.area * per_m2), 1, 2_000_000))


def sample_surface(mesh: trimesh.Trimesh, count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """`count` area-uniform random points on the surface and their triangles (seeded)."""
    rng = np.random.default_rng(seed)
    areas = mesh.area_faces
    faces = np.searchsorted(np.cumsum(areas) / areas.sum(), rng.random(count), side="right").clip(0, len(areas) - 1)
    tri = vertex_rows(np.ascontiguousarray(mesh.vertices, dtype=np.float64), mesh.faces.view(np.ndarray)[faces])
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return pts, faces


def neighbour_filter(points: np.ndarray, normals: np.ndarray, radius: float, tau: float) -> np.ndarray:
    """Greedy fixed-radius thinning in sample order: a sample is dropped when a kept one lies within `radius`
    with a normal within `tau` (Section III, near-neighbour filter). Returns the kept mask."""
    n = len(points)
    if n == 0 or radius <= 0:
        return np.ones(n, dtype=bool)
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    pairs = pairs[np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]) >= np.cos(tau)]
    if len(pairs) == 0:
        return np.ones(n, dtype=bool)
    # neighbour lists of lower-indexed samples, for the greedy pass in index order
    lo, hi = pairs[:, 0], pairs[:, 1]  # query_pairs gives i < j
    order = np.argsort(hi, kind="stable")
    return _greedy_keep(np.ascontiguousarray(lo[order], dtype=np.int64),
                        np.searchsorted(hi[order], np.arange(n + 1)).astype(np.int64), n)


@njit(cache=True)
def _greedy_keep(lower, ptr, n):
    """Samples kept in index order: sample k is dropped when one of its lower-indexed neighbours
    lower[ptr[k]:ptr[k + 1]] is kept."""
    kept = np.ones(n, dtype=np.bool_)
    for k in range(n):
        for q in range(ptr[k], ptr[k + 1]):
            if kept[lower[q]]:
                kept[k] = False
                break
    return kept


def distribute(mesh: trimesh.Trimesh, facets: Facets, count: int, radius: float, dist_min: float, dist_max: float,
               seed: int) -> Samples:
    """Sample the surface once, thin it, give every kept sample to every facet holding its triangle, and apply the
    distance filter."""
    points, faces = sample_surface(mesh, count, seed)
    kept = neighbour_filter(points, mesh.face_normals[faces], radius, facets.tau)
    ks = np.flatnonzero(kept)
    counts, pair_facet = facets.holding(faces[ks])  # all facets of each kept sample's triangle
    pair_sample = np.repeat(ks, counts)
    pair_dist = distance_to_boundary(facets, pair_facet, points[pair_sample])
    pair_ok = (pair_dist >= dist_min) & (pair_dist <= dist_max)
    return Samples(points=points, faces=faces, kept=kept, pair_facet=pair_facet, pair_sample=pair_sample,
                   pair_dist=pair_dist, pair_ok=pair_ok)
