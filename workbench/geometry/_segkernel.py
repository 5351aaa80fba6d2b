"""Compiled region growing and facet boundaries of the segmentation (`facets.segment`): linear in the triangles a
facet holds, so full-resolution scans segment in a fraction of a second. Numba, cached on disk after the first
compile; the segmentation's kernels release the GIL, so a large part's hull and triangle hierarchy build beside them
(`grasps.plan_grasps`)."""

from __future__ import annotations

import numpy as np
from numba import njit

from workbench.geometry._radix import radix_sort


@njit(cache=True)
def _sort(values, m, bits, tmp):
    """values[:m] (non-negative, below 2^bits, or any with `bits` 0) sorted in place: by insertion up to 32 values
    (a scan's facets are mostly a triangle or a few), numpy's sort up to 256 or where `bits` is 0, else a radix sort
    in 11-bit digits through `tmp`, linear in m."""
    if m <= 32:
        for i in range(1, m):
            x = values[i]
            j = i - 1
            while j >= 0 and values[j] > x:
                values[j + 1] = values[j]
                j -= 1
            values[j + 1] = x
    elif m <= 256 or bits == 0:
        values[:m] = np.sort(values[:m])
    elif (bits + 10) // 11 % 2 == 1:  # an odd number of passes leaves the result in tmp
        values[:m] = radix_sort(values[:m], tmp[:m], 0, bits, 11)
    else:
        radix_sort(values[:m], tmp[:m], 0, bits, 11)


@njit(cache=True, nogil=True)
def grow_facets(normals, nbr, order, conventional, cos_tau, cos_merge, centres, areas, faces, n_vertices, edges,
                starts):
    """Grow a facet from every seed in `order` (Wan & Harada, Section III, Fig. 2): across shared edges to every
    triangle whose normal is within tau of the seed's. Conventional: each triangle in one facet; over-segmentation: a
    seed is skipped when a facet holding it has a seed normal within the merge angle of its own. `nbr` (n, k)
    neighbours padded with n (`neighbour_table`; `edges`, `starts`: `edge_groups`, for the edges of one or of three
    or more triangles). Returns (tri_ptr, tri_index, seeds, wn, wc, ar, edge_ptr, boundary): facet f holds the sorted
    triangles tri_index[tri_ptr[f]:tri_ptr[f + 1]]; per facet the sums over them, in that order, of normal * area,
    centre * area (`centres` (n, 3)) and area (`areas` (n,)), taken while they are written; and its boundary, the
    edges its triangles use once, boundary[edge_ptr[f]:edge_ptr[f + 1]] (vertex ids (E, 2)) in ascending order of
    their sorted vertex pair. The growth finds the boundary as it goes: an edge to a triangle it does not take is
    one."""
    n = normals.shape[0]
    k = nbr.shape[1]
    visited = np.zeros(n, dtype=np.bool_)
    assigned = np.zeros(n, dtype=np.bool_)
    covered = np.full(n, -2.0)
    queue = np.empty(n, dtype=np.int64)
    # the memberships and boundary edges, written once in place: room for a scan's over-segmentation (about five
    # facets to a triangle, two boundary edges to a membership), of which only the pages written are ever mapped; a
    # buffer grown by doubling and copied out at the end would map each page several times over
    out = np.empty(max(8 * n, 16), dtype=np.int64)
    keys = np.empty(max(k * n, 16), dtype=np.int64)  # the boundary edges of the facet being grown
    pending = np.empty(max(k * n, 16), dtype=np.int64)  # its edges that are not two triangles', counted at its end
    group = np.empty(0, dtype=np.int64)  # each edge's group, filled at the first such edge
    bound = np.empty((max(8 * n, 16), 2), dtype=np.int64)
    # per facet (at most one per triangle, each its seed's): where its triangles and boundary edges start, its seed
    # and its sums
    ptr, eptr = np.zeros(n + 1, dtype=np.int64), np.zeros(n + 1, dtype=np.int64)
    seeds = np.empty(n, dtype=np.int64)
    sums = np.empty((n, 7))
    m = 0
    size = 0
    e = 0
    tmp = np.empty(n, dtype=np.int64)
    bits = 1
    while (1 << bits) < n:
        bits += 1
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
        w, p = 0, 0
        while head < tail:
            t = queue[head]
            head += 1
            for j in range(k):
                c = nbr[t, j]
                if c >= n:
                    pending[p] = 3 * t + j
                    p += 1
                    continue
                if visited[c]:
                    continue
                if (not (conventional and assigned[c])
                        and normals[c, 0] * s0 + normals[c, 1] * s1 + normals[c, 2] * s2 >= cos_tau):
                    visited[c] = True
                    queue[tail] = c
                    tail += 1
                else:
                    u, v = faces[t, j], faces[t, (j + 1) % 3]
                    keys[w] = min(u, v) * n_vertices + max(u, v)
                    w += 1
        if p > 0 and group.shape[0] == 0:
            group = np.empty(3 * n, dtype=np.int64)
            for g in range(starts.shape[0] - 1):
                for r in range(starts[g], starts[g + 1]):
                    group[edges[r]] = g
        for i in range(p):
            q = pending[i]
            g = group[q]
            uses = 0
            for r in range(starts[g], starts[g + 1]):
                if visited[edges[r] // 3]:
                    uses += 1
            if uses == 1:
                u, v = faces[q // 3, q % 3], faces[q // 3, (q % 3 + 1) % 3]
                keys[w] = min(u, v) * n_vertices + max(u, v)
                w += 1
        _sort(queue, tail, bits, tmp)
        if size + tail > out.shape[0]:
            grown = np.empty(max(2 * out.shape[0], size + tail), dtype=np.int64)
            grown[:size] = out[:size]
            out = grown
        sn0, sn1, sn2, sc0, sc1, sc2, sa = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        for i in range(tail):
            t = queue[i]
            visited[t] = False
            out[size + i] = t
            a = areas[t]
            sn0 += normals[t, 0] * a
            sn1 += normals[t, 1] * a
            sn2 += normals[t, 2] * a
            sc0 += centres[t, 0] * a
            sc1 += centres[t, 1] * a
            sc2 += centres[t, 2] * a
            sa += a
            if conventional:
                assigned[t] = True
            else:
                d = normals[t, 0] * s0 + normals[t, 1] * s1 + normals[t, 2] * s2
                if d > covered[t]:
                    covered[t] = d
        size += tail
        seeds[m] = seed
        sums[m, 0], sums[m, 1], sums[m, 2], sums[m, 3], sums[m, 4], sums[m, 5], sums[m, 6] = \
            sn0, sn1, sn2, sc0, sc1, sc2, sa
        _sort(keys, w, 0, tmp)
        if e + w > bound.shape[0]:
            wider = np.empty((max(2 * bound.shape[0], e + w), 2), dtype=np.int64)
            wider[:e] = bound[:e]
            bound = wider
        for i in range(w):
            bound[e + i, 0] = keys[i] // n_vertices
            bound[e + i, 1] = keys[i] % n_vertices
        e += w
        m += 1
        ptr[m], eptr[m] = size, e
    return (ptr[:m + 1].copy(), out[:size], seeds[:m].copy(), sums[:m, 0:3].copy(), sums[:m, 3:6].copy(),
            sums[:m, 6].copy(), eptr[:m + 1].copy(), bound[:e])


@njit(cache=True, nogil=True)
def _pair_order(lo, hi, n_vertices):
    """The stable argsort of the vertex pairs (lo, hi) by lo, then hi, and where each distinct pair's run starts (then
    the total): a counting sort by lo (each vertex starts a handful of edges), then each vertex's run by hi, in place
    where it is short. Linear in the edges."""
    m = lo.shape[0]
    start = np.zeros(n_vertices + 1, dtype=np.int64)
    for i in range(m):
        start[lo[i] + 1] += 1
    for b in range(n_vertices):
        start[b + 1] += start[b]
    pos = start[:-1].copy()
    order = np.empty(m, dtype=np.int64)
    for i in range(m):
        order[pos[lo[i]]] = i
        pos[lo[i]] += 1
    for b in range(n_vertices):
        s, e = start[b], start[b + 1]
        if e - s > 32:  # a fan's apex: a merge sort, stable too
            run = order[s:e].copy()
            order[s:e] = run[np.argsort(hi[run], kind="mergesort")]
            continue
        for i in range(s + 1, e):
            x = order[i]
            j = i - 1
            while j >= s and hi[order[j]] > hi[x]:
                order[j + 1] = order[j]
                j -= 1
            order[j + 1] = x
    runs = np.empty(m + 1, dtype=np.int64)
    r = 0
    for i in range(m):
        if i == 0 or lo[order[i]] != lo[order[i - 1]] or hi[order[i]] != hi[order[i - 1]]:
            runs[r] = i
            r += 1
    runs[r] = m
    return order, runs[:r + 1].copy()


def edge_groups(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's edges: every triangle edge (3 t + j: from corner j to j + 1) sorted by its vertex pair, and where
    each pair's run starts in that order (one run per distinct edge, then the total). A linear sort of the 3n edges."""
    lo, hi = _edge_pairs(np.ascontiguousarray(faces, dtype=np.int64))
    return _pair_order(lo, hi, max(int(n_vertices), int(lo.max(initial=-1)) + 1))


@njit(cache=True, nogil=True)
def _edge_pairs(faces):
    """(lo, hi) (3n,): the lower and higher vertex of every triangle edge, edge 3 t + j from corner j to j + 1."""
    n = faces.shape[0]
    lo, hi = np.empty(3 * n, dtype=np.int64), np.empty(3 * n, dtype=np.int64)
    for t in range(n):
        for j in range(3):
            u, v = faces[t, j], faces[t, (j + 1) % 3]
            lo[3 * t + j], hi[3 * t + j] = min(u, v), max(u, v)
    return lo, hi


@njit(cache=True, nogil=True)
def neighbour_table(order, starts, n):
    """(n, 3) int32 the triangle across each edge of every triangle, n where none: edges shared by exactly two
    triangles (as trimesh's face adjacency; an edge of three or more triangles joins none). Half the bytes of int64,
    for the region growing's random reads."""
    table = np.full((n, 3), n, dtype=np.int32)
    for g in range(starts.shape[0] - 1):
        if starts[g + 1] - starts[g] != 2:
            continue
        a, b = order[starts[g]], order[starts[g] + 1]
        if a // 3 != b // 3:
            table[a // 3, a % 3] = b // 3
            table[b // 3, b % 3] = a // 3
    return table


@njit(cache=True, nogil=True)
def vertex_rows(vertices, ids):
    """(E, k, 3) the points of the vertex ids (E, k): numpy's `vertices[ids]`, several times faster on a scan's
    millions of triangles or facet boundary edges."""
    out = np.empty((ids.shape[0], ids.shape[1], 3))
    for i in range(ids.shape[0]):
        for j in range(ids.shape[1]):
            v = ids[i, j]
            out[i, j, 0], out[i, j, 1], out[i, j, 2] = vertices[v, 0], vertices[v, 1], vertices[v, 2]
    return out


@njit(cache=True)
def boundary_lengths(edge_ptr, edges):
    """(F,) the length of each facet's boundary edges (E, 2, 3), summed in their order."""
    out = np.zeros(edge_ptr.shape[0] - 1)
    for f in range(out.shape[0]):
        for i in range(edge_ptr[f], edge_ptr[f + 1]):
            d0, d1, d2 = edges[i, 1, 0] - edges[i, 0, 0], edges[i, 1, 1] - edges[i, 0, 1], edges[i, 1, 2] - edges[i, 0, 2]
            out[f] += np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
    return out


@njit(cache=True, nogil=True)
def triangle_centres(vertices, faces):
    """(n, 3) each triangle's centre, as numpy's mean of its three corners (the same operations, so the same bits as
    trimesh's `triangles_center`), without gathering the corners first."""
    out = np.empty((faces.shape[0], 3))
    for t in range(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        for k in range(3):
            out[t, k] = ((vertices[a, k] + vertices[b, k]) + vertices[c, k]) / 3.0
    return out


@njit(cache=True)
def by_triangle(tri_ptr, tri_index):
    """Every (facet, triangle) membership sorted by triangle, then facet: a counting sort, linear in the memberships.
    Returns (facet ids, triangle ids)."""
    n = 0
    for q in range(tri_index.shape[0]):
        n = max(n, tri_index[q] + 1)
    start = np.zeros(n + 1, dtype=np.int64)
    for q in range(tri_index.shape[0]):
        start[tri_index[q] + 1] += 1
    for t in range(n):
        start[t + 1] += start[t]
    fid = np.empty(tri_index.shape[0], dtype=np.int64)
    tid = np.empty(tri_index.shape[0], dtype=np.int64)
    for f in range(tri_ptr.shape[0] - 1):
        for q in range(tri_ptr[f], tri_ptr[f + 1]):
            t = tri_index[q]
            fid[start[t]] = f
            tid[start[t]] = t
            start[t] += 1
    return fid, tid


@njit(cache=True)
def boundary_distances(edge_ptr, edges, normals, facet_ids, points):
    """Distance from each point to the boundary edges (E, 2, 3) of its facet, both projected onto the facet's plane
    (normal `normals[f]`): the least point-to-segment distance, inf for a facet without boundary. The sums of three
    products go in numpy einsum's order (first and last, then the middle), so the distances are numpy's to the bit."""
    k = facet_ids.shape[0]
    out = np.full(k, np.inf)
    for i in range(k):
        f = facet_ids[i]
        n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
        p0, p1, p2 = points[i, 0], points[i, 1], points[i, 2]
        best = np.inf
        for e in range(edge_ptr[f], edge_ptr[f + 1]):
            s = edges[e, 0]
            h = ((s[0] - p0) * n0 + (s[2] - p2) * n2) + (s[1] - p1) * n1
            a0, a1, a2 = s[0] - h * n0, s[1] - h * n1, s[2] - h * n2
            s = edges[e, 1]
            h = ((s[0] - p0) * n0 + (s[2] - p2) * n2) + (s[1] - p1) * n1
            b0, b1, b2 = s[0] - h * n0 - a0, s[1] - h * n1 - a1, s[2] - h * n2 - a2
            t = (((p0 - a0) * b0 + (p2 - a2) * b2) + (p1 - a1) * b1) / max((b0 * b0 + b2 * b2) + b1 * b1, 1e-300)
            t = min(max(t, 0.0), 1.0)
            q0, q1, q2 = p0 - (a0 + t * b0), p1 - (a1 + t * b1), p2 - (a2 + t * b2)
            best = min(best, np.sqrt(q0 * q0 + q1 * q1 + q2 * q2))
        out[i] = best
    return out


@njit(cache=True)
def facets_holding(tri_ptr, tri_index, n_tri, queries):
    """For each triangle of `queries` (Q,), the facets holding it in ascending order: (counts (Q,), facet ids
    concatenated in query order), as `by_triangle` would give them for those triangles (none for a query outside
    [0, n_tri), such as -1 for no triangle). Two passes over the memberships reading only their triangle ids against
    a byte per triangle, with no scatter of every membership."""
    slot = np.full(n_tri, -1, dtype=np.int64)
    asked = np.zeros(n_tri, dtype=np.bool_)  # a byte per triangle stays in cache as the memberships stream past
    distinct = 0
    for i in range(queries.shape[0]):
        t = queries[i]
        if 0 <= t < n_tri and not asked[t]:
            slot[t] = distinct
            asked[t] = True
            distinct += 1
    per = np.zeros(distinct + 2, dtype=np.int64)  # the last slot: a query outside the mesh (-1), held by none
    for q in range(tri_index.shape[0]):
        if asked[tri_index[q]]:
            per[slot[tri_index[q]] + 1] += 1
    for u in range(distinct + 1):
        per[u + 1] += per[u]
    grouped = np.empty(per[distinct], dtype=np.int64)
    pos = per[:-1].copy()
    for f in range(tri_ptr.shape[0] - 1):  # facets in order: the facets of each triangle stay ascending
        for q in range(tri_ptr[f], tri_ptr[f + 1]):
            if asked[tri_index[q]]:
                u = slot[tri_index[q]]
                grouped[pos[u]] = f
                pos[u] += 1
    which = np.empty(queries.shape[0], dtype=np.int64)
    counts = np.empty(queries.shape[0], dtype=np.int64)
    total = 0
    for i in range(queries.shape[0]):
        t = queries[i]
        u = slot[t] if 0 <= t < n_tri else distinct
        which[i] = u
        counts[i] = per[u + 1] - per[u]
        total += counts[i]
    out = np.empty(total, dtype=np.int64)
    k = 0
    for i in range(queries.shape[0]):
        u = which[i]
        for q in range(per[u], per[u + 1]):
            out[k] = grouped[q]
            k += 1
    return counts, out


@njit(cache=True)
def connected(table):
    """Whether the faces form one body across the edges of `table` (`neighbour_table`: n where none)."""
    n = table.shape[0]
    if n == 0:
        return True
    seen = np.zeros(n, dtype=np.bool_)
    queue = np.empty(n, dtype=np.int64)
    queue[0] = 0
    seen[0] = True
    head, tail = 0, 1
    while head < tail:
        t = queue[head]
        head += 1
        for j in range(table.shape[1]):
            c = table[t, j]
            if c < n and not seen[c]:
                seen[c] = True
                queue[tail] = c
                tail += 1
    return tail == n
