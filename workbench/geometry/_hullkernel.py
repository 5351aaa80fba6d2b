"""Compiled greedy grouping of a large convex hull's faces (`supports.coplanar_groups`): each seed's candidates are
found by walking the hull's edges from the seed through the vertices within the distance of its plane, so the cost
follows each group's size, not the hull's. Numba, cached on disk after the first compile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def group_faces(vertices, faces, normals, order, v_ptr, v_adj, f_ptr, f_idx, distance, cos_a):
    """The group of every hull face (F,), groups numbered in seed order. A seed takes every free face whose vertices
    lie within `distance` below its plane and that faces it within the angle (cos_a), or lies within a quarter of the
    distance and does not face away. On a convex polytope the vertices above any plane form a connected part of its
    edge graph, so a walk from the seed's vertices finds all of them. `v_ptr, v_adj`: vertex neighbours (CSR);
    `f_ptr, f_idx`: faces of each vertex (CSR)."""
    F, V = faces.shape[0], vertices.shape[0]
    label = np.full(F, -1, dtype=np.int64)
    vmark = np.full(V, -1, dtype=np.int64)
    fmark = np.full(F, -1, dtype=np.int64)
    height = np.zeros(V)
    queue = np.empty(V, dtype=np.int64)
    group = 0
    for seed in order:
        if label[seed] >= 0:
            continue
        n0, n1, n2 = normals[seed, 0], normals[seed, 1], normals[seed, 2]
        p = faces[seed, 0]
        d = vertices[p, 0] * n0 + vertices[p, 1] * n1 + vertices[p, 2] * n2
        tail = 0
        for j in range(3):
            v = faces[seed, j]
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
                if h >= -distance:
                    vmark[w] = seed
                    height[w] = h
                    queue[tail] = w
                    tail += 1
        label[seed] = group
        for i in range(tail):
            v = queue[i]
            for q in range(f_ptr[v], f_ptr[v + 1]):
                f = f_idx[q]
                if fmark[f] == seed or label[f] >= 0:
                    continue
                fmark[f] = seed
                a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
                if vmark[a] != seed or vmark[b] != seed or vmark[c] != seed:
                    continue
                low = min(min(height[a], height[b]), height[c])
                facing = n0 * normals[f, 0] + n1 * normals[f, 1] + n2 * normals[f, 2]
                if low >= -distance and (facing >= cos_a or (low >= -0.25 * distance and facing > 0)):
                    label[f] = group
        group += 1
    return label
