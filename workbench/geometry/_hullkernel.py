"""Compiled greedy grouping of a convex hull's faces (`supports.coplanar_groups`): each seed's candidates are found by
walking the hull's edges from the seed through the vertices within the distance of its plane, so the cost follows
each group's size, not the hull's. Numba, cached on disk after the first compile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def group_facets(vertices, faces, facet_of, m_ptr, members, normals, order, v_ptr, v_adj, f_ptr, f_idx, distance,
                 flat, cos_a, areas, flat_share, cos_flat):
    """The group of every facet (T,), groups numbered in seed order. A facet is a set of hull faces (`facet_of` (F,),
    its members `m_ptr, members` in CSR) with unit outward normal `normals[t]` and area `areas[t]`; seeds are taken
    in `order`. A seed's plane is its normal through its highest vertex; it takes every free facet all of whose
    vertices lie within `distance` below that plane and that faces it within the angle (cos_a), or lie within `flat`,
    do not face away and either have at most `flat_share` of the seed's area (a sliver, whatever its tilt) or face
    it within `cos_flat`. On a convex polytope the vertices above any plane form a connected part of its edge graph,
    so a walk from the seed's vertices finds all of them. `v_ptr, v_adj`: vertex neighbours (CSR); `f_ptr, f_idx`: faces of
    each vertex (CSR)."""
    T, V = m_ptr.shape[0] - 1, vertices.shape[0]
    label = np.full(T, -1, dtype=np.int64)
    vmark = np.full(V, -1, dtype=np.int64)
    tmark = np.full(T, -1, dtype=np.int64)
    height = np.zeros(V)
    queue = np.empty(V, dtype=np.int64)
    reach = max(distance, flat)
    group = 0
    for seed in order:
        if label[seed] >= 0:
            continue
        n0, n1, n2 = normals[seed, 0], normals[seed, 1], normals[seed, 2]
        d = -np.inf
        for q in range(m_ptr[seed], m_ptr[seed + 1]):
            for j in range(3):
                p = faces[members[q], j]
                d = max(d, vertices[p, 0] * n0 + vertices[p, 1] * n1 + vertices[p, 2] * n2)
        tail = 0
        for q in range(m_ptr[seed], m_ptr[seed + 1]):
            for j in range(3):
                v = faces[members[q], j]
                if vmark[v] != seed:
                    vmark[v] = seed
                    height[v] = (vertices[v, 0] * n0 + vertices[v, 1] * n1 + vertices[v, 2] * n2) - d
                    queue[tail] = v
                    tail += 1
        head = 0
        while head < tail:
            v = queue[head]
            head += 1
            for q in range(v_ptr[v], v_ptr[v + 1]):
                w = v_adj[q]
                if vmark[w] == seed:
                    continue
                h = (vertices[w, 0] * n0 + vertices[w, 1] * n1 + vertices[w, 2] * n2) - d
                if h >= -reach:
                    vmark[w] = seed
                    height[w] = h
                    queue[tail] = w
                    tail += 1
        label[seed] = group
        for i in range(tail):
            v = queue[i]
            for q in range(f_ptr[v], f_ptr[v + 1]):
                t = facet_of[f_idx[q]]
                if tmark[t] == seed or label[t] >= 0:
                    continue
                tmark[t] = seed
                low = np.inf
                for r in range(m_ptr[t], m_ptr[t + 1]):
                    for j in range(3):
                        a = faces[members[r], j]
                        low = min(low, height[a] if vmark[a] == seed else -np.inf)
                facing = n0 * normals[t, 0] + n1 * normals[t, 1] + n2 * normals[t, 2]
                if (low >= -distance and facing >= cos_a) or (low >= -flat and facing > 0 and (
                        areas[t] <= flat_share * areas[seed] or facing >= cos_flat)):
                    label[t] = group
        group += 1
    return label


@njit(cache=True, nogil=True)
def inner_vertices(faces, normals, n_vertices, sin2):
    """(V,) whether the faces at a vertex have at most two unit normals, each to within an angle whose sine squared
    is `sin2` (cross products: a dot product cannot resolve angles below 1e-8 rad), two that are not parallel. On a
    closed mesh such a vertex lies inside the flat fan of its faces or on the straight crease where two planes meet,
    between the crease's ends, so it is not a vertex of the convex hull. A vertex no face uses is not inner."""
    ref = np.full(n_vertices, -1, dtype=np.int64)
    ref2 = np.full(n_vertices, -1, dtype=np.int64)
    inner = np.ones(n_vertices, dtype=np.bool_)
    for t in range(faces.shape[0]):
        for k in range(3):
            v = faces[t, k]
            r = ref[v]
            if r < 0:
                ref[v] = t
                continue
            if not inner[v] or _parallel(normals, t, r, sin2):
                continue
            q = ref2[v]
            if q < 0:
                c0, c1, c2 = _cross(normals, t, r)
                if c0 * c0 + c1 * c1 + c2 * c2 > sin2:  # not opposite either: the planes meet in a line
                    ref2[v] = t
                else:
                    inner[v] = False
            elif not _parallel(normals, t, q, sin2):
                inner[v] = False
    for v in range(n_vertices):
        if ref[v] < 0:
            inner[v] = False
    return inner


@njit(cache=True, inline="always")
def _cross(normals, a, b):
    return (normals[a, 1] * normals[b, 2] - normals[a, 2] * normals[b, 1],
            normals[a, 2] * normals[b, 0] - normals[a, 0] * normals[b, 2],
            normals[a, 0] * normals[b, 1] - normals[a, 1] * normals[b, 0])


@njit(cache=True, inline="always")
def _parallel(normals, a, b, sin2):
    """Do the unit normals of faces a and b agree to within the angle whose sine squared is `sin2`?"""
    c0, c1, c2 = _cross(normals, a, b)
    dot = normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1] + normals[a, 2] * normals[b, 2]
    return dot > 0.0 and c0 * c0 + c1 * c1 + c2 * c2 <= sin2
