"""Compiled first-touch kernel of the pad contact model (`pads.first_touches`): one pass per jaw axis over the
triangles near it, every hand rotation, both pads. Numba, cached on disk after the first compile."""

from __future__ import annotations

import numpy as np
from numba import njit

_EPS = 1e-12


@njit(cache=True)
def _cell_key(i, j, k, n1, n2):
    return (i * n1 + j) * n2 + k


@njit(cache=True)
def _axis_triangles(o, y, lo_b, hi_b, cell, dims, start, order, big, centre, reach, radius, out, mark, cmark, stamp):
    """Triangles whose bounding sphere, grown by `radius`, reaches the axis line (o, y): the grid cells the line's
    chord through the box crosses, widened by the largest small-triangle reach, plus the large triangles."""
    n = 0
    for b in big:
        d0, d1, d2 = centre[b, 0] - o[0], centre[b, 1] - o[1], centre[b, 2] - o[2]
        al = d0 * y[0] + d1 * y[1] + d2 * y[2]
        if d0 * d0 + d1 * d1 + d2 * d2 - al * al <= reach[b] ** 2:
            out[n] = b
            n += 1
    # the chord of the line through the grid box
    t0, t1 = -np.inf, np.inf
    for a in range(3):
        if abs(y[a]) < 1e-300:
            if o[a] < lo_b[a] or o[a] > hi_b[a]:
                return n
        else:
            u = (lo_b[a] - o[a]) / y[a]
            v = (hi_b[a] - o[a]) / y[a]
            if u > v:
                u, v = v, u
            t0 = max(t0, u)
            t1 = min(t1, v)
    if t0 > t1 or len(order) == 0:
        return n
    step = 0.5 * cell
    m = int((t1 - t0) / step) + 2
    # cells either side of a sampled line point: a small triangle's centre lies within its size (< cell) plus
    # `radius` of the line, and the nearest sample is within a quarter cell along it
    w = int(np.ceil(radius / cell + 1.25)) + 1
    for s in range(m):
        tt = min(t0 + s * step, t1)
        ci = int((o[0] + tt * y[0] - lo_b[0]) / cell)
        cj = int((o[1] + tt * y[1] - lo_b[1]) / cell)
        ck = int((o[2] + tt * y[2] - lo_b[2]) / cell)
        for i in range(max(ci - w, 0), min(ci + w + 1, dims[0])):
            for j in range(max(cj - w, 0), min(cj + w + 1, dims[1])):
                for k in range(max(ck - w, 0), min(ck + w + 1, dims[2])):
                    c = _cell_key(i, j, k, dims[1], dims[2])
                    if cmark[c] == stamp:
                        continue
                    cmark[c] = stamp
                    for q in range(start[c], start[c + 1]):
                        f = order[q]
                        if mark[f] == stamp:
                            continue
                        mark[f] = stamp
                        d0, d1, d2 = centre[f, 0] - o[0], centre[f, 1] - o[1], centre[f, 2] - o[2]
                        al = d0 * y[0] + d1 * y[1] + d2 * y[2]
                        if d0 * d0 + d1 * d1 + d2 * d2 - al * al <= reach[f] ** 2:
                            out[n] = f
                            n += 1
    # the triangle order of a brute-force scan, so that ties break the same way whatever the grid
    out[:n].sort()
    return n


@njit(cache=True)
def _meets_disc(x, z, r2):
    """Does the 2D triangle (x, z) come within sqrt(r2) of the origin?"""
    c0 = x[0] * z[1] - x[1] * z[0]
    c1 = x[1] * z[2] - x[2] * z[1]
    c2 = x[2] * z[0] - x[0] * z[2]
    if (c0 >= 0 and c1 >= 0 and c2 >= 0) or (c0 <= 0 and c1 <= 0 and c2 <= 0):
        return True
    for e in range(3):
        ax, az, bx, bz = x[e], z[e], x[(e + 1) % 3], z[(e + 1) % 3]
        dx, dz = bx - ax, bz - az
        ll = dx * dx + dz * dz
        t = 0.0 if ll <= 0 else min(max(-(ax * dx + az * dz) / ll, 0.0), 1.0)
        if (ax + t * dx) ** 2 + (az + t * dz) ** 2 <= r2 * (1 + 1e-9) + 1e-18:
            return True
    return False


@njit(cache=True)
def _pick(px, py, pz, valid, side, wlo, whi, tie, cx, cz):
    """The first touch of one triangle for one pad: (score, candidate index, d2) or -inf."""
    top = -np.inf
    for c in range(20):
        if valid[c] and ((side == 1 and py[c] <= whi) or (side == -1 and py[c] >= wlo)):
            sc = side * py[c]
            if sc > top:
                top = sc
    if top == -np.inf:
        return top, -1, np.inf
    best, bd = -1, np.inf
    for c in range(20):
        if valid[c] and ((side == 1 and py[c] <= whi) or (side == -1 and py[c] >= wlo)) and side * py[c] >= top - tie:
            d2 = (px[c] + cx) ** 2 + (pz[c] + cz) ** 2
            if d2 < bd:
                bd, best = d2, c
    return top, best, bd


@njit(cache=True)
def _candidates(x, y, z, hx, hz, ax, az, px, py, pz, valid):
    """The 20 candidate extreme points of one triangle over the pad rectangle (3 vertices, 12 edge-side crossings,
    4 corners and the axis point inside the triangle), as `pads` documents."""
    for v in range(3):
        px[v], pz[v], py[v] = x[v], z[v], y[v]
        valid[v] = abs(x[v]) <= hx + _EPS and abs(z[v]) <= hz + _EPS
    col = 3
    for e in range(3):
        i, j = e, (e + 1) % 3
        xa, xb, za, zb, ya, yb = x[i], x[j], z[i], z[j], y[i], y[j]
        dx, dz = xb - xa, zb - za
        for X in (-hx, hx):
            ok = abs(dx) > _EPS
            s = (X - xa) / dx if ok else 0.0
            zz = za + s * dz
            px[col], pz[col], py[col] = X, zz, ya + s * (yb - ya)
            valid[col] = ok and s >= 0 and s <= 1 and abs(zz) <= hz + _EPS
            col += 1
        for Z in (-hz, hz):
            ok = abs(dz) > _EPS
            s = (Z - za) / dz if ok else 0.0
            xx = xa + s * dx
            px[col], pz[col], py[col] = xx, Z, ya + s * (yb - ya)
            valid[col] = ok and s >= 0 and s <= 1 and abs(xx) <= hx + _EPS
            col += 1
    e1x, e1z = x[1] - x[0], z[1] - z[0]
    e2x, e2z = x[2] - x[0], z[2] - z[0]
    det = e1x * e2z - e2x * e1z
    good = abs(det) > 1e-18
    inv = 1.0 / det if good else 0.0
    for c in range(5):
        if c == 0:
            X, Z = -hx, -hz
        elif c == 1:
            X, Z = hx, -hz
        elif c == 2:
            X, Z = hx, hz
        elif c == 3:
            X, Z = -hx, hz
        else:
            X, Z = ax, az
        qx, qz = X - x[0], Z - z[0]
        u = (qx * e2z - e2x * qz) * inv
        v = (e1x * qz - qx * e1z) * inv
        px[col], pz[col] = X, Z
        py[col] = y[0] + u * (y[1] - y[0]) + v * (y[2] - y[0])
        valid[col] = good and u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12
        col += 1


@njit(cache=True)
def first_touch_kernel(tri, fn, flip, origins, frames0, angles, rect, tie, windows, jaw_max,
                       lo_b, hi_b, cell, dims, start, order, big, centre, reach):
    """Per hand pose (axis-major, rotation-minor) and pad (0: left, +y; 1: right): found, height along y,
    local contact point (TCP frame of that rotation), triangle."""
    cx, cz, hx, hz = rect[0], rect[1], rect[2], rect[3]
    radius = np.hypot(abs(cx) + hx, abs(cz) + hz)
    K, A, T = origins.shape[0], angles.shape[0], tri.shape[0]
    found = np.zeros((K * A, 2), dtype=np.bool_)
    height = np.zeros((K * A, 2))
    local = np.zeros((K * A, 2, 3))
    tri_id = np.full((K * A, 2), -1, dtype=np.int64)
    near = np.empty(T, dtype=np.int64)
    mark = np.full(T, -1, dtype=np.int64)
    cmark = np.full(len(start), -1, dtype=np.int64)
    ly = np.empty((T, 3))
    ca = np.empty((T, 3))
    cb = np.empty((T, 3))
    ny = np.empty(T)
    keep = np.empty(T, dtype=np.int64)
    # the rows of one pose and pad: triangle, top, local point, d2, align
    rt = np.empty(T, dtype=np.int64)
    rs = np.empty(T)
    rp = np.empty((T, 3))
    rd = np.empty(T)
    ra = np.empty(T)
    ymx = np.empty(T)
    ymn = np.empty(T)
    lx3, lz3, ly3 = np.empty(3), np.empty(3), np.empty(3)
    px, py, pz = np.empty(20), np.empty(20), np.empty(20)
    valid = np.empty(20, dtype=np.bool_)
    rad2 = radius * radius
    for k in range(K):
        o = origins[k]
        x0, y, z0 = frames0[k, 0], frames0[k, 1], frames0[k, 2]
        wlo, whi = windows[k, 0], windows[k, 1]
        n = _axis_triangles(o, y, lo_b, hi_b, cell, dims, start, order, big, centre, reach, radius, near, mark, cmark, k)
        m = 0
        a_max, a_min = -np.inf, np.inf
        for q in range(n):
            f = near[q]
            for v in range(3):
                r0, r1, r2 = tri[f, v, 0] - o[0], tri[f, v, 1] - o[1], tri[f, v, 2] - o[2]
                ca[m, v] = r0 * z0[0] + r1 * z0[1] + r2 * z0[2]
                cb[m, v] = r0 * x0[0] + r1 * x0[1] + r2 * x0[2]
            # a projection that misses the disc every rotated pad rectangle lies in is touched at no rotation
            if not _meets_disc(cb[m], ca[m], rad2):
                continue
            mn, mx = np.inf, -np.inf
            for v in range(3):
                r0, r1, r2 = tri[f, v, 0] - o[0], tri[f, v, 1] - o[1], tri[f, v, 2] - o[2]
                ly[m, v] = r0 * y[0] + r1 * y[1] + r2 * y[2]
                mn = min(mn, ly[m, v])
                mx = max(mx, ly[m, v])
            if mx < wlo or mn > whi:
                continue
            ymn[m], ymx[m] = mn, mx
            ny[m] = fn[f, 0] * y[0] + fn[f, 1] * y[1] + fn[f, 2] * y[2]
            keep[m] = f
            # where the axis itself crosses the triangle: surface points inside every rotation's footprint
            e1x, e1z = cb[m, 1] - cb[m, 0], ca[m, 1] - ca[m, 0]
            e2x, e2z = cb[m, 2] - cb[m, 0], ca[m, 2] - ca[m, 0]
            det = e1x * e2z - e2x * e1z
            if abs(det) > 1e-18:
                inv = 1.0 / det
                qx, qz = -cb[m, 0], -ca[m, 0]
                u = (qx * e2z - e2x * qz) * inv
                v = (e1x * qz - qx * e1z) * inv
                if u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12:
                    h = ly[m, 0] + u * (ly[m, 1] - ly[m, 0]) + v * (ly[m, 2] - ly[m, 0])
                    if h <= whi:
                        a_max = max(a_max, h)
                    if h >= wlo:
                        a_min = min(a_min, h)
            m += 1
        # an axis whose own crossings are farther apart than the jaw opens cannot be grasped at any rotation
        if np.isfinite(a_max - a_min) and a_max - a_min > jaw_max + tie:
            continue
        # a triangle wholly between the axis's highest and lowest crossings is first touched by neither pad
        mm = 0
        for q in range(m):
            if not (ymx[q] >= a_max - tie or ymn[q] <= a_min + tie):
                continue
            ly[mm], ca[mm], cb[mm], ny[mm], keep[mm], ymx[mm], ymn[mm] = ly[q], ca[q], cb[q], ny[q], keep[q], ymx[q], ymn[q]
            mm += 1
        # each pad meets the triangles in the order they can first be touched (highest top for the left pad, lowest
        # bottom for the right): once a triangle's bound is `tie` below the best touch so far, none after it counts
        order0 = np.argsort(-ymx[:mm])
        order1 = np.argsort(ymn[:mm])
        for j in range(A):
            c, s = np.cos(angles[j]), np.sin(angles[j])
            hrow = k * A + j
            for si in range(2):
                side = 1 if si == 0 else -1
                seq = order0 if si == 0 else order1
                nr = 0
                g = -np.inf
                for qq in range(mm):
                    q = seq[qq]
                    if (ymx[q] if si == 0 else -ymn[q]) < g - tie:
                        break
                    xmn, xmx, zmn, zmx = np.inf, -np.inf, np.inf, -np.inf
                    for v in range(3):
                        lz3[v] = c * ca[q, v] + s * cb[q, v] - cz
                        lx3[v] = c * cb[q, v] - s * ca[q, v] - cx
                        ly3[v] = ly[q, v]
                        xmn, xmx = min(xmn, lx3[v]), max(xmx, lx3[v])
                        zmn, zmx = min(zmn, lz3[v]), max(zmx, lz3[v])
                    if xmn > hx or xmx < -hx or zmn > hz or zmx < -hz:
                        continue
                    _candidates(lx3, ly3, lz3, hx, hz, -cx, -cz, px, py, pz, valid)
                    top, b, d2 = _pick(px, py, pz, valid, side, wlo, whi, tie, cx, cz)
                    if b < 0:
                        continue
                    rt[nr] = keep[q]
                    rs[nr] = top
                    rp[nr, 0], rp[nr, 1], rp[nr, 2] = px[b] + cx, py[b], pz[b] + cz
                    rd[nr] = d2
                    ra[nr] = abs(ny[q]) if flip else side * ny[q]
                    nr += 1
                    g = max(g, top)
                if nr == 0:
                    continue
                # among the touches within `tie` of the best: nearest the axis, then best facing, then lowest index
                best = -1
                bkey, balign, btri = np.inf, -np.inf, -1
                for r in range(nr):
                    if rs[r] < g - tie:
                        continue
                    key = np.rint(rd[r] / tie ** 2)
                    if key < bkey or (key == bkey and (ra[r] > balign or (ra[r] == balign and rt[r] < btri))):
                        bkey, balign, btri, best = key, ra[r], rt[r], r
                found[hrow, si] = True
                height[hrow, si] = side * rs[best]
                local[hrow, si] = rp[best]
                tri_id[hrow, si] = rt[best]
    return found, height, local, tri_id


def triangle_grid(tri: np.ndarray, radius: float, brute: int = 4096):
    """A uniform grid over triangle centres (cells about the pad's reach), the triangles far larger than a cell kept
    apart: (lo, hi, cell, dims, start, order, big, centre, reach) for `first_touch_kernel`."""
    centre = tri.mean(axis=1)
    size = np.linalg.norm(tri - centre[:, None, :], axis=2).max(axis=1)
    reach = size + radius
    lo = centre.min(axis=0) if len(tri) else np.zeros(3)
    hi = centre.max(axis=0) if len(tri) else np.zeros(3)
    cell = max(2 * radius, float(np.max(hi - lo)) / 64, 1e-6)
    # padded, so that a line passing beside the centres' box still crosses the grid where it nears them
    lo, hi = lo - 2 * radius - cell, hi + 2 * radius + cell
    dims = np.maximum(np.ceil((hi - lo) / cell).astype(np.int64), 1)
    hi = lo + dims * cell
    # reached from more cells than the search widens by, or a mesh small enough to scan: tested one by one
    big_mask = (size > cell) | (len(tri) <= brute)
    idx = np.clip(((centre - lo) / cell).astype(np.int64), 0, dims - 1)
    key = (idx[:, 0] * dims[1] + idx[:, 1]) * dims[2] + idx[:, 2]
    small = np.flatnonzero(~big_mask)
    order = small[np.argsort(key[small], kind="stable")]
    start = np.searchsorted(key[order], np.arange(int(np.prod(dims)) + 1))
    return lo, hi, float(cell), dims, start.astype(np.int64), order.astype(np.int64), \
        np.flatnonzero(big_mask).astype(np.int64), centre, reach
