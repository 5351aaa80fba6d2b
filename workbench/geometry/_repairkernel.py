"""Compiled per-face measures for the repair's checks (`repair.repair`): face areas and the sign of the enclosed
volume, read straight from the vertices and faces, so that loading a full-resolution scan gathers no (n, 3, 3)
corner array for them. Numba, cached on disk after the first compile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _edge_cross(vertices, a, b, c):
    """The cross product (x, y, z) of the edges (corner 1 - corner 0) x (corner 2 - corner 1) of the face (a, b, c),
    in numpy's order of operations (trimesh's `triangles.cross`)."""
    u0, u1, u2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
    w0, w1, w2 = vertices[c, 0] - vertices[b, 0], vertices[c, 1] - vertices[b, 1], vertices[c, 2] - vertices[b, 2]
    return u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0


@njit(cache=True)
def face_areas(vertices, faces):
    """(n,) each face's area as trimesh's `area_faces` computes it, to the bit: half the norm of the cross product of
    its edges (`_edge_cross`)."""
    out = np.empty(faces.shape[0])
    for t in range(faces.shape[0]):
        x, y, z = _edge_cross(vertices, faces[t, 0], faces[t, 1], faces[t, 2])
        out[t] = np.sqrt((x * x + y * y) + z * z) / 2.0
    return out


@njit(cache=True)
def unit_normals(vertices, faces):
    """(n, 3) each face's unit normal as trimesh's `face_normals` computes it, to the bit: its edges' cross product
    (`_edge_cross`) times the reciprocal of its norm, zero where that norm is at most trimesh's zero tolerance."""
    out = np.zeros((faces.shape[0], 3))
    for t in range(faces.shape[0]):
        x, y, z = _edge_cross(vertices, faces[t, 0], faces[t, 1], faces[t, 2])
        norm = np.sqrt((x * x + y * y) + z * z)
        if norm > _TOL_ZERO:
            r = 1.0 / norm
            out[t, 0], out[t, 1], out[t, 2] = x * r, y * r, z * r
    return out


_TOL_ZERO = 1e-13  # trimesh.constants.tol.zero, below which `util.unitize` leaves a vector zero


@njit(cache=True)
def volume_terms(vertices, faces):
    """The sum over the faces of the signed-volume terms trimesh's integration adds (cross x times the corners' x
    sum, six times the volume), and a bound on how far any order of adding those terms can move the sum (twice the
    face count times the float64 epsilon times the sum of their magnitudes)."""
    s, m = 0.0, 0.0
    for t in range(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        u1, u2 = vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        w1, w2 = vertices[c, 1] - vertices[b, 1], vertices[c, 2] - vertices[b, 2]
        term = (u1 * w2 - u2 * w1) * ((vertices[a, 0] + vertices[b, 0]) + vertices[c, 0])
        s += term
        m += abs(term)
    return s, 2.0 * (faces.shape[0] + 1) * 2.220446049250313e-16 * m * 1.01


@njit(cache=True)
def centre_terms(vertices, faces):
    """Trimesh's mass-property integrands of each face without the inertia's (`repair.volume_centre`), in numpy's
    order of operations, so the same bits: the cross products (n, 3) of the edges (corner 1 - corner 0) x (corner 2
    - corner 1), and the terms (4, n) whose sums over the faces are six times the volume and 24 times its first
    moments; read straight from the vertices and faces, with no (n, 3, 3) or (n, 3) temporaries."""
    n = faces.shape[0]
    cross = np.empty((n, 3))
    terms = np.empty((4, n))
    for t in range(n):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        cx, cy, cz = _edge_cross(vertices, a, b, c)
        cross[t, 0], cross[t, 1], cross[t, 2] = cx, cy, cz
        for k in range(3):
            p, q, r = vertices[a, k], vertices[b, k], vertices[c, k]
            f1 = (p + q) + r
            f2 = ((p * p + q * q) + p * q) + r * f1
            if k == 0:
                terms[0, t] = cx * f1
            terms[1 + k, t] = (cx if k == 0 else cy if k == 1 else cz) * f2
    return cross, terms


@njit(cache=True)
def rotated_faces(rank, faces, n):
    """The faces (m, 3) relabelled by `rank` (old vertex -> new) and each rotated to start at its lowest label (the
    first where two are equal, as argmin takes; the winding kept), and one sort key per face, (f0 * n + f1) * n + f2,
    whose order is the rows' lexicographic one while n < 2^21 (`repair.canonical`)."""
    m = faces.shape[0]
    out = np.empty((m, 3), dtype=np.int64)
    key = np.empty(m, dtype=np.int64)
    for t in range(m):
        a, b, c = rank[faces[t, 0]], rank[faces[t, 1]], rank[faces[t, 2]]
        if a <= b and a <= c:
            f0, f1, f2 = a, b, c
        elif b <= c:
            f0, f1, f2 = b, c, a
        else:
            f0, f1, f2 = c, a, b
        out[t, 0], out[t, 1], out[t, 2] = f0, f1, f2
        key[t] = (f0 * n + f1) * n + f2
    return out, key


@njit(cache=True)
def winding_flags(order, starts, faces):
    """(watertight, winding consistent) from the faces' edge groups (`_segkernel.edge_groups`): every edge is two
    faces'; each edge of two faces is used by them in opposite directions (edge q = 3 t + j runs from corner j to
    corner j + 1 of face t)."""
    pairs = 0
    consistent = True
    for g in range(starts.shape[0] - 1):
        if starts[g + 1] - starts[g] != 2:
            continue
        pairs += 1
        a, b = order[starts[g]], order[starts[g] + 1]
        if faces[a // 3, (a % 3 + 1) % 3] != faces[b // 3, b % 3]:
            consistent = False
    return 2 * pairs == 3 * faces.shape[0], consistent


@njit(cache=True)
def triple_codes(faces, n):
    """One int64 code per face (m,) naming its three vertices in any order: (lo * n + mid) * n + hi (n < 2^21)."""
    out = np.empty(faces.shape[0], dtype=np.int64)
    for t in range(faces.shape[0]):
        a, b, c = faces[t, 0], faces[t, 1], faces[t, 2]
        if a > b:
            a, b = b, a
        if b > c:
            b, c = c, b
        if a > b:
            a, b = b, a
        out[t] = (a * n + b) * n + c
    return out
