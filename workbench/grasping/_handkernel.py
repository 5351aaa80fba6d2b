"""Compiled collision of the hand's convex volumes with the part's triangles (level 2 of `grasps`): each convex piece
(the swept body, a finger box's sweep, a finger box) placed at each hand pose is tested against the triangle
hierarchy the pad model already built (`_padkernel.triangle_bvh`), by the separating axis theorem. So a
full-resolution part needs no second hierarchy, and the cost follows the triangles near the hand. Numba, cached on
disk after the first compile."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import trimesh
from numba import njit

_STACK = 256  # deeper than any tree (`_padkernel._STACK`)


def convex_piece(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A convex volume for `hull_hits`: its hull's vertices (V, 3), face planes (unit normals (F, 3) and offsets (F,),
    inside where n . x <= offset) and edge directions (E, 3, unit, up to sign), coplanar faces and parallel edges
    given once. The same points give the same piece, computed once (a hand's volumes recur on every part)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    return _piece(v.tobytes(), v.shape)


@lru_cache(maxsize=256)
def _piece(data: bytes, shape: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    hull = trimesh.Trimesh(np.frombuffer(data, dtype=np.float64).reshape(shape)).convex_hull
    v = np.asarray(hull.vertices, dtype=np.float64)
    n = np.asarray(hull.face_normals, dtype=np.float64)
    d = np.einsum("ij,ij->i", n, v[hull.faces[:, 0]])
    _, first, plane = np.unique(np.round(np.column_stack([n, d]), 12), axis=0, return_index=True,
                                return_inverse=True)
    # the largest faces first: a hand's flat sides set most of the part apart, so the search stops at them early
    area = np.bincount(plane.reshape(-1), weights=hull.area_faces, minlength=len(first))
    first = first[np.lexsort((first, -np.round(area, 15)))]
    e = v[hull.edges_unique[:, 1]] - v[hull.edges_unique[:, 0]]
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    sign = np.sign(e[np.arange(len(e)), np.argmax(np.abs(e), axis=1)])
    _, keep = np.unique(np.round(e * sign[:, None], 12), axis=0, return_index=True)
    keep.sort()
    out = (v, n[first], d[first], e[keep])
    for a in out:
        a.flags.writeable = False
    return out


def pack(pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> tuple:
    """Convex pieces (`convex_piece`) as one set of arrays for `hull_hits`: vertices, normals, offsets, edges and the
    start of each piece's rows in them."""
    arrays = [np.concatenate([p[k] for p in pieces]) for k in range(4)]
    ptrs = [np.concatenate([[0], np.cumsum([len(p[k]) for p in pieces])]).astype(np.int64) for k in (0, 1, 3)]
    return (*[np.ascontiguousarray(a, dtype=np.float64) for a in arrays], *ptrs)


@njit(cache=True)
def _by_faces(tri, q, wn, wd, faces, nf, eps):
    """Triangle (slot) q against the placed piece's face planes `faces[:nf]` (it lies inside the others'): 1 when
    one separates them, 0 when a corner of it lies in the piece (they meet), -1 when the faces do not decide."""
    in0, in1, in2 = True, True, True  # which of the triangle's corners lie in the piece
    for i in range(nf):
        f = faces[i]
        p0 = tri[q, 0, 0] * wn[f, 0] + tri[q, 0, 1] * wn[f, 1] + tri[q, 0, 2] * wn[f, 2]
        p1 = tri[q, 1, 0] * wn[f, 0] + tri[q, 1, 1] * wn[f, 1] + tri[q, 1, 2] * wn[f, 2]
        p2 = tri[q, 2, 0] * wn[f, 0] + tri[q, 2, 1] * wn[f, 1] + tri[q, 2, 2] * wn[f, 2]
        if min(p0, p1, p2) > wd[f] + eps:
            return 1
        in0 = in0 and p0 <= wd[f] + eps
        in1 = in1 and p1 <= wd[f] + eps
        in2 = in2 and p2 <= wd[f] + eps
    return 0 if in0 or in1 or in2 else -1


@njit(cache=True)
def _by_other_axes(tri, q, wv, v0, v1, we, e0, e1, eps):
    """Is triangle (slot) q, which no face plane of the placed piece separates and none of whose corners lies in
    it, separated from it by the triangle's plane, or by an axis across a triangle edge and a piece edge (the
    separating axis theorem)?"""
    ux, uy, uz = tri[q, 1, 0] - tri[q, 0, 0], tri[q, 1, 1] - tri[q, 0, 1], tri[q, 1, 2] - tri[q, 0, 2]
    vx, vy, vz = tri[q, 2, 0] - tri[q, 0, 0], tri[q, 2, 1] - tri[q, 0, 1], tri[q, 2, 2] - tri[q, 0, 2]
    mx, my, mz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    ln = np.sqrt(mx * mx + my * my + mz * mz)
    if ln > 0:
        mx, my, mz = mx / ln, my / ln, mz / ln
        c = tri[q, 0, 0] * mx + tri[q, 0, 1] * my + tri[q, 0, 2] * mz
        lo, hi = np.inf, -np.inf
        for i in range(v0, v1):
            p = wv[i, 0] * mx + wv[i, 1] * my + wv[i, 2] * mz
            lo, hi = min(lo, p), max(hi, p)
        if lo > c + eps or hi < c - eps:
            return True
    for j in range(3):
        k = (j + 1) % 3
        tx, ty, tz = tri[q, k, 0] - tri[q, j, 0], tri[q, k, 1] - tri[q, j, 1], tri[q, k, 2] - tri[q, j, 2]
        tl = np.sqrt(tx * tx + ty * ty + tz * tz)
        if tl == 0:
            continue
        for g in range(e0, e1):
            ax = ty * we[g, 2] - tz * we[g, 1]
            ay = tz * we[g, 0] - tx * we[g, 2]
            az = tx * we[g, 1] - ty * we[g, 0]
            al = np.sqrt(ax * ax + ay * ay + az * az)
            if al <= 1e-9 * tl:  # parallel edges: the face axes cover them
                continue
            ax, ay, az = ax / al, ay / al, az / al
            tlo, thi = np.inf, -np.inf
            for a in range(3):
                p = tri[q, a, 0] * ax + tri[q, a, 1] * ay + tri[q, a, 2] * az
                tlo, thi = min(tlo, p), max(thi, p)
            lo, hi = np.inf, -np.inf
            for i in range(v0, v1):
                p = wv[i, 0] * ax + wv[i, 1] * ay + wv[i, 2] * az
                lo, hi = min(lo, p), max(hi, p)
            if lo > thi + eps or hi < tlo - eps:
                return True
    return False


@njit(cache=True)
def _outside_box(tri, q, R, cw, h, eps):
    """Is triangle (slot) q wholly outside the box (centre cw, axes the columns of R, half extents h)?"""
    for a in range(3):
        lo, hi = np.inf, -np.inf
        for v in range(3):
            p = ((tri[q, v, 0] - cw[0]) * R[0, a] + (tri[q, v, 1] - cw[1]) * R[1, a]
                 + (tri[q, v, 2] - cw[2]) * R[2, a])
            lo, hi = min(lo, p), max(hi, p)
        if lo > h[a] + eps or hi < -h[a] - eps:
            return True
    return False


@njit(cache=True)
def hull_hits(shape, slots, leaf, tri, verts, normals, offsets, edges, vptr, fptr, eptr, poses, eps):
    """(N,) whether any convex piece p, placed at poses[n, p] (N, P, 4, 4, in the part's frame), meets a triangle of
    the hierarchy (`_padkernel.triangle_bvh`: node shapes, slots, leaf size, triangles by slot), within `eps`. A piece
    is solid: a triangle inside it meets it.

    Each placed piece is first bounded by its box in its own frame: a node or triangle outside that box is apart
    after three axes. The piece's face planes are placed only once a node meets the box, its vertices and edges once
    a triangle needs them (a swept hand has hundreds of faces and edges; most poses meet few nodes, and most
    triangles are decided by the faces)."""
    N, P = poses.shape[0], poses.shape[1]
    M = shape.shape[0] // 2
    out = np.zeros(N, dtype=np.bool_)
    if shape[1, 0] > shape[1, 3]:
        return out
    wv = np.empty((verts.shape[0], 3))
    wn = np.empty((normals.shape[0], 3))
    wd = np.empty(normals.shape[0])
    we = np.empty((edges.shape[0], 3))
    stack = np.empty(_STACK, dtype=np.int64)
    # per stack entry, the faces whose planes its node's box straddles: a box wholly inside a face's plane holds its
    # children's, so below it that face separates nothing and is not tested again
    width = 1
    for p in range(P):
        width = max(width, fptr[p + 1] - fptr[p])
    act = np.empty((_STACK, width), dtype=np.int64)
    nact = np.empty(_STACK, dtype=np.int64)
    diag = 0.0
    for a in range(3):
        diag += (shape[1, 3 + a] - shape[1, a]) ** 2
    slack = 1e-9 * (1.0 + np.sqrt(diag))  # a face is dropped only with room to spare against rounding
    # each piece's box in its own frame: centre and half extents
    bc, bh = np.empty((P, 3)), np.empty((P, 3))
    for p in range(P):
        for a in range(3):
            lo_a, hi_a = np.inf, -np.inf
            for i in range(vptr[p], vptr[p + 1]):
                lo_a, hi_a = min(lo_a, verts[i, a]), max(hi_a, verts[i, a])
            bc[p, a], bh[p, a] = 0.5 * (lo_a + hi_a), 0.5 * (hi_a - lo_a)
    cw, ext = np.empty(3), np.empty(3)
    for n in range(N):
        for p in range(P):
            R = poses[n, p, :3, :3]
            t = poses[n, p, :3, 3]
            v0, v1 = vptr[p], vptr[p + 1]
            f0, f1 = fptr[p], fptr[p + 1]
            e0, e1 = eptr[p], eptr[p + 1]
            h = bh[p]
            for a in range(3):
                cw[a] = R[a, 0] * bc[p, 0] + R[a, 1] * bc[p, 1] + R[a, 2] * bc[p, 2] + t[a]
                ext[a] = abs(R[a, 0]) * h[0] + abs(R[a, 1]) * h[1] + abs(R[a, 2]) * h[2]  # the box's world extents
            placed = edged = False
            hit = False
            stack[0] = 1
            nact[0] = f1 - f0
            for i in range(f1 - f0):
                act[0, i] = f0 + i
            top = 1
            while top > 0 and not hit:
                top -= 1
                node = stack[top]
                if shape[node, 0] > shape[node, 3]:
                    continue
                apart = False
                for a in range(3):  # the world axes
                    mid = 0.5 * (shape[node, a] + shape[node, 3 + a]) - cw[a]
                    if abs(mid) > ext[a] + 0.5 * (shape[node, 3 + a] - shape[node, a]) + eps:
                        apart = True
                        break
                if not apart:  # the box's own axes
                    for a in range(3):
                        mid, r = 0.0, h[a]
                        for b in range(3):
                            mid += (0.5 * (shape[node, b] + shape[node, 3 + b]) - cw[b]) * R[b, a]
                            r += 0.5 * (shape[node, 3 + b] - shape[node, b]) * abs(R[b, a])
                        if abs(mid) > r + eps:
                            apart = True
                            break
                if apart:
                    continue
                if not placed:  # the piece's face planes, placed once a node meets its box
                    for f in range(f0, f1):
                        for a in range(3):
                            wn[f, a] = R[a, 0] * normals[f, 0] + R[a, 1] * normals[f, 1] + R[a, 2] * normals[f, 2]
                        wd[f] = offsets[f] + wn[f, 0] * t[0] + wn[f, 1] * t[1] + wn[f, 2] * t[2]
                    placed = True
                kept = 0  # the node's box wholly outside one face plane, or wholly inside some
                for i in range(nact[top]):
                    f = act[top, i]
                    c, r = 0.0, 0.0
                    for a in range(3):
                        c += 0.5 * (shape[node, a] + shape[node, 3 + a]) * wn[f, a]
                        r += 0.5 * (shape[node, 3 + a] - shape[node, a]) * abs(wn[f, a])
                    if c - r > wd[f] + eps:
                        apart = True
                        break
                    if c + r > wd[f] - slack:
                        act[top, kept] = f
                        kept += 1
                if apart:
                    continue
                if kept == 0:  # the node's box inside every face plane: its triangles lie in the piece
                    hit = True
                    break
                if node < M:
                    stack[top] = 2 * node
                    stack[top + 1] = 2 * node + 1
                    nact[top] = nact[top + 1] = kept
                    for i in range(kept):
                        act[top + 1, i] = act[top, i]
                    top += 2
                    continue
                for q in range((node - M) * leaf, (node - M + 1) * leaf):
                    if slots[q] < 0 or _outside_box(tri, q, R, cw, h, eps):
                        continue
                    faces = _by_faces(tri, q, wn, wd, act[top], kept, eps)
                    if faces == 1:
                        continue
                    if faces == -1:
                        if not edged:  # the piece's vertices and edges, placed once some triangle needs them
                            for i in range(v0, v1):
                                for a in range(3):
                                    wv[i, a] = (R[a, 0] * verts[i, 0] + R[a, 1] * verts[i, 1]
                                                + R[a, 2] * verts[i, 2] + t[a])
                            for g in range(e0, e1):
                                for a in range(3):
                                    we[g, a] = R[a, 0] * edges[g, 0] + R[a, 1] * edges[g, 1] + R[a, 2] * edges[g, 2]
                            edged = True
                        if _by_other_axes(tri, q, wv, v0, v1, we, e0, e1, eps):
                            continue
                    hit = True
                    break
            if hit:
                out[n] = True
                break
    return out
