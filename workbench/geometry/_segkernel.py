"""Compiled region growing and facet boundaries of the segmentation (`facets.segment`): linear in the triangles a
facet holds, so full-resolution scans segment in a fraction of a second. Numba, cached on disk after the first
compile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def grow_facets(normals, nbr, order, conventional, cos_tau, cos_merge):
    """Grow a facet from every seed in `order` (Wan & Harada, Section III, Fig. 2): across shared edges to every
    triangle whose normal is within tau of the seed's. Conventional: each triangle in one facet; over-segmentation: a
    seed is skipped when a facet holding it has a seed normal within the merge angle of its own. `nbr` (n, k)
    neighbours padded with n. Returns (tri_ptr, tri_index, seeds): facet f holds the sorted triangles
    tri_index[tri_ptr[f]:tri_ptr[f + 1]]."""
    n = normals.shape[0]
    k = nbr.shape[1]
    visited = np.zeros(n, dtype=np.bool_)
    assigned = np.zeros(n, dtype=np.bool_)
    covered = np.full(n, -2.0)
    queue = np.empty(n, dtype=np.int64)
    out = np.empty(max(n, 16), dtype=np.int64)
    ptr = [0]
    seeds = []
    size = 0
    for seed in order:
        if conventional:
            if assigned[seed]:
                continue
        elif covered[seed] >= cos_merge:
            continue
        s0, s1, s2 = normals[seed, 0], normals[seed, 1], normals[seed, 2]
        queue[0] = seed
        visited[seed] = True
        head, tail = 0, 1
        while head < tail:
            t = queue[head]
            head += 1
            for j in range(k):
                c = nbr[t, j]
                if c >= n or visited[c] or (conventional and assigned[c]):
                    continue
                if normals[c, 0] * s0 + normals[c, 1] * s1 + normals[c, 2] * s2 >= cos_tau:
                    visited[c] = True
                    queue[tail] = c
                    tail += 1
        region = np.sort(queue[:tail])
        if size + tail > out.shape[0]:
            grown = np.empty(max(2 * out.shape[0], size + tail), dtype=np.int64)
            grown[:size] = out[:size]
            out = grown
        for i in range(tail):
            t = region[i]
            visited[t] = False
            out[size + i] = t
            if conventional:
                assigned[t] = True
            else:
                d = normals[t, 0] * s0 + normals[t, 1] * s1 + normals[t, 2] * s2
                if d > covered[t]:
                    covered[t] = d
        size += tail
        ptr.append(size)
        seeds.append(seed)
    return np.array(ptr, dtype=np.int64), out[:size].copy(), np.array(seeds, dtype=np.int64)


@njit(cache=True)
def facet_boundaries(faces, tri_ptr, tri_index, n_vertices):
    """Boundary edges of every facet: the edges (sorted vertex pairs) its triangles use once, in ascending order of
    the pair per facet. Returns (edge_ptr, edges (E, 2) vertex ids)."""
    m = tri_ptr.shape[0] - 1
    total = 3 * tri_index.shape[0]
    keys = np.empty(total, dtype=np.int64)
    edge_ptr = np.zeros(m + 1, dtype=np.int64)
    out = np.empty((total, 2), dtype=np.int64)
    e = 0
    for f in range(m):
        a, b = tri_ptr[f], tri_ptr[f + 1]
        w = 0
        for q in range(a, b):
            t = tri_index[q]
            for j in range(3):
                u, v = faces[t, j], faces[t, (j + 1) % 3]
                if u > v:
                    u, v = v, u
                keys[w] = u * n_vertices + v
                w += 1
        ks = np.sort(keys[:w])
        i = 0
        while i < w:
            j = i + 1
            while j < w and ks[j] == ks[i]:
                j += 1
            if j - i == 1:
                out[e, 0] = ks[i] // n_vertices
                out[e, 1] = ks[i] % n_vertices
                e += 1
            i = j
        edge_ptr[f + 1] = e
    return edge_ptr, out[:e].copy()
