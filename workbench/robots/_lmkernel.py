"""Compiled Levenberg-Marquardt IK kernel of `chain.solve_ik`: one pose at a time in scalar loops (the sums in a
fixed order, so a row's answer never depends on the rows solved with it). Numba, cached on disk after the first
compile."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def _fk_row(q, base, pl, axis, prism, tip, rot, pos, waxis):
    """FK of one joint vector: joint world axes `waxis` (n, 3) and origins `pos` (n, 3); TCP rotation into `rot`
    (3, 3), TCP position returned as (x, y, z)."""
    n = q.shape[0]
    r = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            r[a, b] = base[a, b]
    t0, t1, t2 = base[0, 3], base[1, 3], base[2, 3]
    for i in range(n):
        p0, p1, p2 = pl[i, 0, 3], pl[i, 1, 3], pl[i, 2, 3]
        t0, t1, t2 = (t0 + r[0, 0] * p0 + r[0, 1] * p1 + r[0, 2] * p2,
                      t1 + r[1, 0] * p0 + r[1, 1] * p1 + r[1, 2] * p2,
                      t2 + r[2, 0] * p0 + r[2, 1] * p1 + r[2, 2] * p2)
        for a in range(3):
            for b in range(3):
                tmp[a, b] = r[a, 0] * pl[i, 0, b] + r[a, 1] * pl[i, 1, b] + r[a, 2] * pl[i, 2, b]
        x, y, z = axis[i, 0], axis[i, 1], axis[i, 2]
        if prism[i]:
            for a in range(3):
                for b in range(3):
                    r[a, b] = tmp[a, b]
            w0 = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z
            w1 = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z
            w2 = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z
            t0, t1, t2 = t0 + w0 * q[i], t1 + w1 * q[i], t2 + w2 * q[i]
        else:
            s, c = np.sin(q[i]), np.cos(q[i])
            v = 1.0 - c
            # Rodrigues: I + s K + (1 - c) K^2 for the unit axis (x, y, z)
            m00, m01, m02 = c + v * x * x, v * x * y - s * z, v * x * z + s * y
            m10, m11, m12 = v * x * y + s * z, c + v * y * y, v * y * z - s * x
            m20, m21, m22 = v * x * z - s * y, v * y * z + s * x, c + v * z * z
            for a in range(3):
                u0, u1, u2 = tmp[a, 0], tmp[a, 1], tmp[a, 2]
                r[a, 0] = u0 * m00 + u1 * m10 + u2 * m20
                r[a, 1] = u0 * m01 + u1 * m11 + u2 * m21
                r[a, 2] = u0 * m02 + u1 * m12 + u2 * m22
            w0 = r[0, 0] * x + r[0, 1] * y + r[0, 2] * z
            w1 = r[1, 0] * x + r[1, 1] * y + r[1, 2] * z
            w2 = r[2, 0] * x + r[2, 1] * y + r[2, 2] * z
        waxis[i, 0], waxis[i, 1], waxis[i, 2] = w0, w1, w2
        pos[i, 0], pos[i, 1], pos[i, 2] = t0, t1, t2
    p0, p1, p2 = tip[0, 3], tip[1, 3], tip[2, 3]
    e0 = t0 + r[0, 0] * p0 + r[0, 1] * p1 + r[0, 2] * p2
    e1 = t1 + r[1, 0] * p0 + r[1, 1] * p1 + r[1, 2] * p2
    e2 = t2 + r[2, 0] * p0 + r[2, 1] * p1 + r[2, 2] * p2
    for a in range(3):
        for b in range(3):
            rot[a, b] = r[a, 0] * tip[0, b] + r[a, 1] * tip[1, b] + r[a, 2] * tip[2, b]
    return e0, e1, e2


@njit(cache=True, nogil=True)
def _log(m, out):
    """Rotation vector of the rotation `m` (3, 3) into `out` (3,) (the SO(3) log map; near pi from the symmetric
    part, the sign from the antisymmetric one)."""
    v0, v1, v2 = 0.5 * (m[2, 1] - m[1, 2]), 0.5 * (m[0, 2] - m[2, 0]), 0.5 * (m[1, 0] - m[0, 1])
    c = 0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0)
    c = min(1.0, max(-1.0, c))
    s = np.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    theta = np.arctan2(s, c)
    if c >= -0.95:
        f = theta / s if s > 1e-9 else 1.0
        out[0], out[1], out[2] = v0 * f, v1 * f, v2 * f
        return
    # R + R^T = 2 I + 2 (1 - c) (k k^T - I): the axis from the largest diagonal entry of k k^T
    w = 1.0 - c
    k = np.empty(3)
    j = 0
    best = -1.0
    for a in range(3):
        d = (m[a, a] - c) / w
        if d > best:
            best, j = d, a
    kj = np.sqrt(max(best, 0.0))
    for a in range(3):
        k[a] = kj if a == j else 0.5 * (m[a, j] + m[j, a]) / (w * kj)
    nrm = np.sqrt(k[0] * k[0] + k[1] * k[1] + k[2] * k[2])
    sign = 1.0 if k[0] * v0 + k[1] * v1 + k[2] * v2 >= 0.0 else -1.0
    for a in range(3):
        out[a] = sign * theta * k[a] / nrm


@njit(cache=True, nogil=True)
def lm_rows(base, pl, axis, prism, tip, lower, upper, targets, q0, iters, tol_pos, tol_rot, window, ratio):
    """Damped LM (Sugihara's damping E + 1e-3) per pose: the step J^T (J J^T + lambda I)^-1 e by a 6x6 Cholesky,
    at most 0.6 rad per joint, clamped to the limits. A pose stops when converged, when its error did not drop below
    `ratio` of itself over `window` iterations, or after `iters` steps. Returns q (M, n) and converged (M,)."""
    m, n = q0.shape
    out = np.empty((m, n))
    ok = np.zeros(m, dtype=np.bool_)
    rot = np.empty((3, 3))
    pos = np.empty((n, 3))
    wax = np.empty((n, 3))
    rel = np.empty((3, 3))
    er = np.empty(3)
    e = np.empty(6)
    jac = np.empty((6, n))
    a = np.empty((6, 6))
    low = np.empty((6, 6))
    y = np.empty(6)
    x = np.empty(6)
    dq = np.empty(n)
    q = np.empty(n)
    for row in range(m):
        for j in range(n):
            q[j] = min(upper[j], max(lower[j], q0[row, j]))
        last = np.inf
        for it in range(iters + 1):
            e0, e1, e2 = _fk_row(q, base, pl, axis, prism, tip, rot, pos, wax)
            e[0], e[1], e[2] = targets[row, 0, 3] - e0, targets[row, 1, 3] - e1, targets[row, 2, 3] - e2
            for u in range(3):  # target rotation times the TCP's transposed
                for v in range(3):
                    rel[u, v] = targets[row, u, 0] * rot[v, 0] + targets[row, u, 1] * rot[v, 1] + targets[row, u, 2] * rot[v, 2]
            _log(rel, er)
            e[3], e[4], e[5] = er[0], er[1], er[2]
            np_ = np.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
            nr = np.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
            if np_ < tol_pos and nr < tol_rot:
                ok[row] = True
                break
            err = np_ + 0.2 * nr
            if it == 0:
                last = err
            elif it % window == 0:
                if not err <= ratio * last:
                    break
                last = err
            if it == iters:
                break
            for k in range(n):
                w0, w1, w2 = wax[k, 0], wax[k, 1], wax[k, 2]
                if prism[k]:
                    jac[0, k], jac[1, k], jac[2, k] = w0, w1, w2
                    jac[3, k], jac[4, k], jac[5, k] = 0.0, 0.0, 0.0
                else:
                    d0, d1, d2 = e0 - pos[k, 0], e1 - pos[k, 1], e2 - pos[k, 2]
                    jac[0, k] = w1 * d2 - w2 * d1
                    jac[1, k] = w2 * d0 - w0 * d2
                    jac[2, k] = w0 * d1 - w1 * d0
                    jac[3, k], jac[4, k], jac[5, k] = w0, w1, w2
            energy = 0.0
            for u in range(6):
                energy += e[u] * e[u]
            damp = 0.5 * energy + 1e-3
            for u in range(6):
                for v in range(6):
                    acc = damp if u == v else 0.0
                    for k in range(n):
                        acc += jac[u, k] * jac[v, k]
                    a[u, v] = acc
            for j in range(6):  # Cholesky a = L L^T, then two triangular solves
                d = a[j, j]
                for k in range(j):
                    d -= low[j, k] * low[j, k]
                low[j, j] = np.sqrt(max(d, 1e-300))
                for i in range(j + 1, 6):
                    acc = a[i, j]
                    for k in range(j):
                        acc -= low[i, k] * low[j, k]
                    low[i, j] = acc / low[j, j]
            for i in range(6):
                acc = e[i]
                for k in range(i):
                    acc -= low[i, k] * y[k]
                y[i] = acc / low[i, i]
            for i in range(5, -1, -1):
                acc = y[i]
                for k in range(i + 1, 6):
                    acc -= low[k, i] * x[k]
                x[i] = acc / low[i, i]
            step = 0.0
            for k in range(n):
                acc = 0.0
                for u in range(6):
                    acc += jac[u, k] * x[u]
                dq[k] = acc
                step = max(step, abs(acc))
            scale = min(1.0, 0.6 / max(step, 1e-12))
            for k in range(n):
                q[k] = min(upper[k], max(lower[k], q[k] + dq[k] * scale))
        for j in range(n):
            out[row, j] = q[j]
    return out, ok


@njit(cache=True, nogil=True)
def tcp_rows(base, pl, axis, prism, tip, q):
    """TCP positions (M, 3) of joint vectors q (M, n)."""
    m, n = q.shape
    out = np.empty((m, 3))
    rot = np.empty((3, 3))
    pos = np.empty((n, 3))
    wax = np.empty((n, 3))
    for row in range(m):
        out[row, 0], out[row, 1], out[row, 2] = _fk_row(q[row], base, pl, axis, prism, tip, rot, pos, wax)
    return out
