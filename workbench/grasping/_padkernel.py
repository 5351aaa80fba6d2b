"""Compiled first-touch kernel of the pad contact model (`pads.first_touches`): a bounding-volume hierarchy over the
triangles, searched per jaw axis and pad by branch and bound for every hand rotation at once (a pad's first touch is
the highest point in its footprint, so a subtree whose bounds lie below a rotation's best touch so far, or outside
its footprint, is skipped for that rotation). Numba, cached on disk after the first compile."""

from __future__ import annotations

import numpy as np
from numba import njit

from workbench.geometry._radix import radix_sort
from workbench.geometry._segkernel import triangle_centres

_EPS = 1e-12
SLAB_MIN = 32_768  # triangles from which the pads' search bounds nodes by their slabs as well as their boxes
# triangles below which the hierarchy's nodes split space (`_split_order`); a full-resolution scan keeps the Morton
# order: at 1M triangles the split's build costs 0.13 s more CPU than the first plan's shorter searches save
SPLIT_MAX = 262_144
_STACK = 256  # deeper than any tree: the implicit tree of 2^62 leaves has 63 levels, a search holds one child per level


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
def _cuts_start(x, y, z, start, hx, hz):
    """Does the triangle (pad coordinates x, z from the pad's centre; heights y) cross the plane y = `start`, the
    pad's starting height, inside the rectangle [-hx, hx] x [-hz, hz]? Then the pad starts inside the part."""
    n = 0
    sx0, sz0, sx1, sz1 = 0.0, 0.0, 0.0, 0.0  # the section's ends (scalars: no array per call in the search)
    for e in range(3):
        i, j = e, (e + 1) % 3
        if (y[i] - start) * (y[j] - start) < 0 and n < 2:
            t = (start - y[i]) / (y[j] - y[i])
            if n == 0:
                sx0, sz0 = x[i] + t * (x[j] - x[i]), z[i] + t * (z[j] - z[i])
            else:
                sx1, sz1 = x[i] + t * (x[j] - x[i]), z[i] + t * (z[j] - z[i])
            n += 1
    if n < 2:
        return False
    # the section's segment against the rectangle (Liang-Barsky clipping)
    t0, t1 = 0.0, 1.0
    dx, dz = sx1 - sx0, sz1 - sz0
    for p, q in ((-dx, sx0 + hx), (dx, hx - sx0), (-dz, sz0 + hz), (dz, hz - sz0)):
        if abs(p) <= _EPS:
            if q < 0:
                return False
        else:
            r = q / p
            if p < 0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
            if t0 > t1:
                return False
    return True


@njit(cache=True)
def _project(shape, node, o, u, slack):
    """The range (min, max) of a node's box along the unit vector `u`, measured from `o`, widened by `slack`."""
    mid = 0.0
    rad = 0.0
    for a in range(3):
        mid += (0.5 * (shape[node, a] + shape[node, 3 + a]) - o[a]) * u[a]
        rad += 0.5 * (shape[node, 3 + a] - shape[node, a]) * abs(u[a])
    return mid - rad - slack, mid + rad + slack


@njit(cache=True)
def _reach(shape, node, o, u, slack):
    """The range (min, max) along the unit vector `u`, from `o`, of a node's points: the box's range, narrowed by the
    node's bounding sphere cut by its slab (centre, radius, normal n, offsets d0..d1 along n; `_build`). For a
    patch nearly facing `u` the slab is far tighter than the box, so the search stays near the touch."""
    lo_b, hi_b = _project(shape, node, o, u, slack)
    c = 0.0
    cn = 0.0
    for a in range(3):
        c += (shape[node, 6 + a] - o[a]) * u[a]
        cn += shape[node, 10 + a] * u[a]
    r, d0, d1 = shape[node, 9], shape[node, 13], shape[node, 14]
    sn = np.sqrt(max(0.0, 1.0 - cn * cn))
    # max over offsets a in [d0, d1] of a cos + sqrt(r^2 - a^2) sin (concave in a, largest at a = r cos), and the min
    a = min(max(r * cn, d0), d1)
    top = a * cn + np.sqrt(max(r * r - a * a, 0.0)) * sn
    a = min(max(-r * cn, d0), d1)
    bottom = a * cn - np.sqrt(max(r * r - a * a, 0.0)) * sn
    return max(lo_b, c + bottom - slack), min(hi_b, c + top + slack)


@njit(cache=True)
def _height_key(shape, node, o, y, slack, si, wlo, whi, slab):
    """How high (the left pad, si 0) or low (the right, as minus the height) a node's points can be first touched;
    -inf for an empty node or one outside the pads' window. The range along y is the box's, narrowed by the node's
    sphere and slab when `slab` (a fine mesh, whose patches are flat beside their size: there the tighter bound saves
    more nodes than it costs)."""
    if shape[node, 0] > shape[node, 3]:
        return -np.inf
    ymn, ymx = _reach(shape, node, o, y, slack) if slab else _project(shape, node, o, y, slack)
    if ymx < wlo or ymn > whi:
        return -np.inf
    # no touch lies past the pad's start: a node reaching beyond it is keyed at the start (a triangle crossing the
    # start, which may block the pad, is then opened first)
    return min(ymx, whi) if si == 0 else -max(ymn, wlo)


@njit(cache=True)
def _footprints(shape, node, o, x0, z0, cs, ua, wa, mask, n_rot, slack, cx, cz, hx, hz):
    """The rotations of `mask` (bit j < n_rot: rotation (cs[j, 0], cs[j, 1]), whose pad axes' absolute components are
    ua[j] and wa[j]) whose pad footprint meets the node's box widened by `slack`."""
    mx0, mz0 = 0.0, 0.0
    h0, h1, h2 = 0.5 * (shape[node, 3] - shape[node, 0]), 0.5 * (shape[node, 4] - shape[node, 1]), \
        0.5 * (shape[node, 5] - shape[node, 2])
    for a in range(3):
        d = 0.5 * (shape[node, a] + shape[node, 3 + a]) - o[a]
        mx0 += d * x0[a]
        mz0 += d * z0[a]
    out = np.int64(0)
    for j in range(n_rot):
        if (mask >> j) & 1:
            c, s = cs[j, 0], cs[j, 1]
            mid = c * mx0 - s * mz0 - cx
            rad = h0 * ua[j, 0] + h1 * ua[j, 1] + h2 * ua[j, 2] + slack
            if mid - rad <= hx and mid + rad >= -hx:
                mid = c * mz0 + s * mx0 - cz
                rad = h0 * wa[j, 0] + h1 * wa[j, 1] + h2 * wa[j, 2] + slack
                if mid - rad <= hz and mid + rad >= -hz:
                    out |= np.int64(1) << j
    return out


@njit(cache=True)
def _heap_push(key, node, mask, n, k, v, m):
    """Push (k, v, m) on the max-heap (by k) of size n; returns its new size."""
    i = n
    while i > 0:
        parent = (i - 1) // 2
        if key[parent] >= k:
            break
        key[i], node[i], mask[i] = key[parent], node[parent], mask[parent]
        i = parent
    key[i], node[i], mask[i] = k, v, m
    return n + 1


@njit(cache=True)
def _heap_pop(key, node, mask, n):
    """Remove the top of the max-heap of size n; returns its new size."""
    n -= 1
    k, v, m = key[n], node[n], mask[n]
    i = 0
    while True:
        c = 2 * i + 1
        if c >= n:
            break
        if c + 1 < n and key[c + 1] > key[c]:
            c += 1
        if key[c] <= k:
            break
        key[i], node[i], mask[i] = key[c], node[c], mask[c]
        i = c
    key[i], node[i], mask[i] = k, v, m
    return n


@njit(cache=True)
def _line_meets_box(shape, node, o, y, slack):
    """Does the line (o, y) pass through the node's box widened by `slack`?"""
    t0, t1 = -np.inf, np.inf
    for a in range(3):
        b0, b1 = shape[node, a] - slack, shape[node, 3 + a] + slack
        if abs(y[a]) < 1e-300:
            if o[a] < b0 or o[a] > b1:
                return False
        else:
            u = (b0 - o[a]) / y[a]
            v = (b1 - o[a]) / y[a]
            if u > v:
                u, v = v, u
            t0 = max(t0, u)
            t1 = min(t1, v)
    return t0 <= t1


@njit(cache=True)
def _local(tri, f, o, x0, y, z0, ca, cb, ly):
    """Triangle (slot) f's vertices relative to the axis origin `o` along z0 (ca), x0 (cb) and y (ly); (min, max) of ly."""
    mn, mx = np.inf, -np.inf
    for v in range(3):
        r0, r1, r2 = tri[f, v, 0] - o[0], tri[f, v, 1] - o[1], tri[f, v, 2] - o[2]
        ca[v] = r0 * z0[0] + r1 * z0[1] + r2 * z0[2]
        cb[v] = r0 * x0[0] + r1 * x0[1] + r2 * x0[2]
        ly[v] = r0 * y[0] + r1 * y[1] + r2 * y[2]
        mn = min(mn, ly[v])
        mx = max(mx, ly[v])
    return mn, mx


@njit(cache=True)
def _pad_touch(cb, ca, ly, c, s, side, start, block, wlo, whi, tie, rect, lx3, lz3, px, py, pz, valid):
    """One triangle (coordinates `cb`, `ca` along the axis frame's x0, z0; heights `ly`) for one pad at the rotation
    (cos, sin) `c, s`: (-1, ...) when it puts the pad's start inside the part (`block`), (0, ...) when it is not
    touched, else (1, height score, candidate index into px/py/pz, squared distance from the axis)."""
    cx, cz, hx, hz = rect[0], rect[1], rect[2], rect[3]
    xmn3, xmx3, zmn3, zmx3 = np.inf, -np.inf, np.inf, -np.inf
    for v in range(3):
        lz3[v] = c * ca[v] + s * cb[v] - cz
        lx3[v] = c * cb[v] - s * ca[v] - cx
        xmn3, xmx3 = min(xmn3, lx3[v]), max(xmx3, lx3[v])
        zmn3, zmx3 = min(zmn3, lz3[v]), max(zmx3, lz3[v])
    if xmn3 > hx or xmx3 < -hx or zmn3 > hz or zmx3 < -hz:
        return 0, 0.0, -1, 0.0
    # a pad starting inside a hole or cavity (a finite window) must start clear of the part: a triangle crossing its
    # starting plane inside its footprint puts the pad into the part there
    if block >= 0 and np.isfinite(start) and _cuts_start(lx3, ly, lz3, start + side * block, hx, hz):
        return -1, 0.0, -1, 0.0
    _candidates(lx3, ly, lz3, hx, hz, -cx, -cz, px, py, pz, valid)
    tp, b, d2 = _pick(px, py, pz, valid, side, wlo, whi, tie, cx, cz)
    if b < 0:
        return 0, 0.0, -1, 0.0
    return 1, tp, b, d2


@njit(cache=True)
def first_touch_kernel(shape, slots, leaf, tri, fn, flip, origins, frames0, angles, rect, tie, windows, jaw_max,
                       block, cone, lift, need):
    """Per hand pose (axis-major, rotation-minor) and pad (0: left, +y; 1: right): found, height along y (the
    contact's), local contact point (TCP frame of that rotation), triangle. `shape, slots, leaf, tri, fn`:
    `triangle_bvh`, the triangles by leaf slot and their unit normals by triangle. `block` (m, negative: off): a pad
    whose finite start's plane, moved `block` beyond it (the intrusion tolerated), cuts a triangle inside its footprint
    touches nothing. `cone`: the cosine of the friction cone's half-angle (below -1: off); a pose whose left touch's
    normal lies outside the cone about +y is not a grasp, so its right pad is not searched (not found), unless `need`
    (K, A) names it or the touch lies less than `lift` below the left pad's start.

    The rotations about one axis share one best-first search per pad: a node is opened for the rotations whose
    footprint meets it and whose best touch so far it may reach within `tie` of, highest first (lowest for the right
    pad), so the nodes near the axis that every rotation needs are bounded and opened once."""
    cx, cz, hx, hz = rect[0], rect[1], rect[2], rect[3]
    radius = np.hypot(abs(cx) + hx, abs(cz) + hz)
    rad2 = radius * radius
    K, A = origins.shape[0], angles.shape[0]
    P = shape.shape[0] // 2  # leaves are the nodes P .. 2P-1 of the implicit tree, the root is node 1
    found = np.zeros((K * A, 2), dtype=np.bool_)
    height = np.zeros((K * A, 2))
    local = np.zeros((K * A, 2, 3))
    tri_id = np.full((K * A, 2), -1, dtype=np.int64)
    if shape[1, 0] > shape[1, 3]:  # no triangle
        return found, height, local, tri_id
    diag = 0.0
    for a in range(3):
        diag += (shape[1, 3 + a] - shape[1, a]) ** 2
    # a box bound is exact up to rounding; the slack keeps every pruning conservative against the per-triangle tests
    slack = 1e-9 * (1.0 + np.sqrt(diag))
    slab = tri.shape[0] >= SLAB_MIN
    stack = np.empty(_STACK, dtype=np.int64)
    leaves = np.empty(P, dtype=np.int64)  # the leaves a line meets (`_axis_crossings`)
    hkey = np.empty(P + 1)  # the open nodes of a best-first search: fewer than the leaves
    hnode = np.empty(P + 1, dtype=np.int64)
    hmask = np.empty(P + 1, dtype=np.int64)
    # the touches of one axis and pad: rotation, triangle, score, local point, d2, align; grown as needed
    cap = 1024
    rj = np.empty(cap, dtype=np.int64)
    rt = np.empty(cap, dtype=np.int64)
    rs = np.empty(cap)
    rp = np.empty((cap, 3))
    rd = np.empty(cap)
    ra = np.empty(cap)
    ca, cb, ly = np.empty(3), np.empty(3), np.empty(3)
    lx3, lz3 = np.empty(3), np.empty(3)
    px, py, pz = np.empty(20), np.empty(20), np.empty(20)
    valid = np.empty(20, dtype=np.bool_)
    # per rotation of a group of at most 64 (one bit each): cos, sin; |ux|, |uz| by world axis; best score; blocked
    cs, ua, wa = np.empty((64, 2)), np.empty((64, 3)), np.empty((64, 3))
    g = np.empty(64)
    blocked = np.empty(64, dtype=np.bool_)
    bkey, balign, btri = np.empty(64), np.empty(64), np.empty(64, dtype=np.int64)
    best = np.empty(64, dtype=np.int64)
    for k in range(K):
        o = origins[k]
        x0, y, z0 = frames0[k, 0], frames0[k, 1], frames0[k, 2]
        wlo, whi = windows[k, 0], windows[k, 1]
        for j0 in range(0, A, 64):
            n_rot = min(A - j0, 64)
            full = np.int64(-1) if n_rot == 64 else (np.int64(1) << n_rot) - 1
            for j in range(n_rot):
                c, s = np.cos(angles[j0 + j]), np.sin(angles[j0 + j])
                cs[j, 0], cs[j, 1] = c, s
                for a in range(3):
                    ua[j, a] = abs(c * x0[a] - s * z0[a])
                    wa[j, a] = abs(c * z0[a] + s * x0[a])
            todo = full  # the rotations still to search: the right pad only where the left one touched
            for si in range(2):
                side = 1 if si == 0 else -1
                start = whi if si == 0 else wlo
                g[:n_rot] = -np.inf
                blocked[:n_rot] = False
                nr = 0
                hn = 0
                kk = _height_key(shape, 1, o, y, slack, si, wlo, whi, slab) if todo else -np.inf
                if kk > -np.inf:
                    m = _footprints(shape, 1, o, x0, z0, cs, ua, wa, todo, n_rot, slack, cx, cz, hx, hz)
                    if m:
                        hn = _heap_push(hkey, hnode, hmask, 0, kk, 1, m)
                while hn > 0:
                    # the rotations the top node may still serve; none: every search is over
                    kt = hkey[0]
                    live = np.int64(0)
                    for j in range(n_rot):
                        if not blocked[j] and kt >= g[j] - tie:
                            live |= np.int64(1) << j
                    if live == 0:
                        break
                    node, m = hnode[0], hmask[0] & live
                    hn = _heap_pop(hkey, hnode, hmask, hn)
                    if m == 0:
                        continue
                    if node < P:
                        for child in (2 * node, 2 * node + 1):
                            kk = _height_key(shape, child, o, y, slack, si, wlo, whi, slab)
                            if kk == -np.inf:
                                continue
                            cm = np.int64(0)
                            for j in range(n_rot):
                                if (m >> j) & 1 and kk >= g[j] - tie:
                                    cm |= np.int64(1) << j
                            if cm:
                                cm = _footprints(shape, child, o, x0, z0, cs, ua, wa, cm, n_rot, slack, cx, cz,
                                                 hx, hz)
                            if cm:
                                hn = _heap_push(hkey, hnode, hmask, hn, kk, child, cm)
                        continue
                    for qs in range((node - P) * leaf, (node - P + 1) * leaf):
                        f = slots[qs]
                        if f < 0:
                            continue
                        mn, mx = _local(tri, qs, o, x0, y, z0, ca, cb, ly)
                        if not _meets_disc(cb, ca, rad2) or mx < wlo or mn > whi:
                            continue
                        sc = min(mx, whi) if si == 0 else -max(mn, wlo)
                        for j in range(n_rot):
                            if not (m >> j) & 1 or blocked[j] or sc < g[j] - tie:
                                continue
                            st, tp, b, d2 = _pad_touch(cb, ca, ly, cs[j, 0], cs[j, 1], side, start, block, wlo, whi,
                                                       tie, rect, lx3, lz3, px, py, pz, valid)
                            if st < 0:
                                blocked[j] = True
                                continue
                            if st == 0:
                                continue
                            if nr == cap:
                                cap *= 2
                                rj2, rt2 = np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64)
                                rs2, rp2, rd2, ra2 = np.empty(cap), np.empty((cap, 3)), np.empty(cap), np.empty(cap)
                                rj2[:nr], rt2[:nr], rs2[:nr], rp2[:nr], rd2[:nr], ra2[:nr] = rj, rt, rs, rp, rd, ra
                                rj, rt, rs, rp, rd, ra = rj2, rt2, rs2, rp2, rd2, ra2
                            ny = fn[f, 0] * y[0] + fn[f, 1] * y[1] + fn[f, 2] * y[2]
                            rj[nr], rt[nr], rs[nr] = j, f, tp
                            rp[nr, 0], rp[nr, 1], rp[nr, 2] = px[b] + cx, py[b], pz[b] + cz
                            rd[nr] = d2
                            ra[nr] = abs(ny) if flip else side * ny
                            nr += 1
                            g[j] = max(g[j], tp)
                # per rotation, among the touches within `tie` of its best: nearest the axis, then best facing, then
                # lowest index
                bkey[:n_rot], balign[:n_rot], btri[:n_rot], best[:n_rot] = np.inf, -np.inf, -1, -1
                for r in range(nr):
                    j = rj[r]
                    if blocked[j] or rs[r] < g[j] - tie:
                        continue
                    key = np.rint(rd[r] / tie ** 2)
                    if key < bkey[j] or (key == bkey[j] and (ra[r] > balign[j] or (ra[r] == balign[j]
                                                                                   and rt[r] < btri[j]))):
                        bkey[j], balign[j], btri[j], best[j] = key, ra[r], rt[r], r
                todo = np.int64(0)
                for j in range(n_rot):
                    r = best[j]
                    if r < 0:
                        continue
                    if ra[r] >= cone or need[k, j0 + j] or rs[r] + lift > whi:
                        todo |= np.int64(1) << j
                    hrow = k * A + j0 + j
                    found[hrow, si] = True
                    # the pad stops at its contact, the touch nearest the axis within `tie` of the first: the
                    # opening is then the contacts' distance along the axis
                    height[hrow, si] = rp[r, 1]
                    local[hrow, si] = rp[r]
                    tri_id[hrow, si] = rt[r]
        # an axis whose own crossings are farther apart than the jaw opens cannot be grasped at any rotation: none
        # of its rotations is a hit (both pads found). The axis point lies in every rotation's footprint, so a
        # rotation's touches lie at least as far apart as the crossings: the line is searched only where some
        # rotation's do not fit
        wide = False
        for j in range(A):
            hrow = k * A + j
            if found[hrow, 0] and found[hrow, 1] and height[hrow, 0] - height[hrow, 1] > jaw_max + tie:
                wide = True
                break
        if wide:
            a_max, a_min = _axis_crossings(shape, slots, leaf, tri, o, x0, y, z0, wlo, whi, slack, rad2, stack,
                                           leaves, ca, cb, ly)
            if np.isfinite(a_max - a_min) and a_max - a_min > jaw_max + tie:
                for j in range(A):  # the right pad's touch dropped: the left one stays, for what it faces
                    hrow = k * A + j
                    found[hrow, 1] = False
                    height[hrow, 1] = 0.0
                    local[hrow, 1, :] = 0.0
                    tri_id[hrow, 1] = -1
    return found, height, local, tri_id


@njit(cache=True)
def _line_leaves(shape, o, d, slack, stack, leaves):
    """The leaves of the hierarchy whose boxes (widened by `slack`) the line through `o` along `d` passes through,
    into `leaves` (at least as long as the leaves are many), depth first; returns how many."""
    P = shape.shape[0] // 2
    n = 0
    stack[0] = 1
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        if shape[node, 0] > shape[node, 3] or not _line_meets_box(shape, node, o, d, slack):
            continue
        if node < P:
            stack[top] = 2 * node
            stack[top + 1] = 2 * node + 1
            top += 2
            continue
        leaves[n] = node
        n += 1
    return n


@njit(cache=True)
def _axis_crossings(shape, slots, leaf, tri, o, x0, y, z0, wlo, whi, slack, rad2, stack, leaves, ca, cb, ly):
    """The highest and lowest heights (a_max, a_min) at which the axis (o, y) crosses a triangle within the window
    [wlo, whi] (-inf, inf: none)."""
    a_max, a_min = -np.inf, np.inf
    P = shape.shape[0] // 2
    for i in range(_line_leaves(shape, o, y, slack, stack, leaves)):
        node = leaves[i]
        for q in range((node - P) * leaf, (node - P + 1) * leaf):
            if slots[q] < 0:
                continue
            mn, mx = _local(tri, q, o, x0, y, z0, ca, cb, ly)
            if mx < wlo or mn > whi or not _meets_disc(cb, ca, rad2):
                continue
            e1x, e1z = cb[1] - cb[0], ca[1] - ca[0]
            e2x, e2z = cb[2] - cb[0], ca[2] - ca[0]
            det = e1x * e2z - e2x * e1z
            if abs(det) > 1e-18:
                inv = 1.0 / det
                qx, qz = -cb[0], -ca[0]
                u = (qx * e2z - e2x * qz) * inv
                v = (e1x * qz - qx * e1z) * inv
                if u >= -1e-12 and v >= -1e-12 and u + v <= 1 + 1e-12:
                    h = ly[0] + u * (ly[1] - ly[0]) + v * (ly[2] - ly[0])
                    if h <= whi:
                        a_max = max(a_max, h)
                    if h >= wlo:
                        a_min = min(a_min, h)
    return a_max, a_min


@njit(cache=True)
def _spread(v):
    """The bits of a 10-bit integer spread three apart (one axis of a Morton code)."""
    v = (v | (v << 16)) & 0x030000FF
    v = (v | (v << 8)) & 0x0300F00F
    v = (v | (v << 4)) & 0x030C30C3
    return (v | (v << 2)) & 0x09249249


@njit(cache=True)
def _morton_order(points):
    """The indices (n,) of `points` (n, 3), the triangles' centres, in Morton order on a 1024^3 grid over their
    bounds, ties by index: the codes above the indices in one word, sorted by their 30 bits ten at a time (a stable
    radix sort)."""
    n = points.shape[0]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for i in range(n):
        for a in range(3):
            lo[a] = min(lo[a], points[i, a])
            hi[a] = max(hi[a], points[i, a])
    width = np.empty(3)
    for a in range(3):
        width[a] = max(hi[a] - lo[a], 1e-300)
    word = np.empty(n, dtype=np.int64)
    for i in range(n):
        code = 0
        for a in range(3):
            code |= _spread(min(max(np.int64((points[i, a] - lo[a]) / width[a] * 1023), 0), 1023)) << a
        word[i] = (code << 32) | i
    return radix_sort(word, np.empty(n, dtype=np.int64), 32, 62, 10) & 0xFFFFFFFF


@njit(cache=True, inline="always")
def _before(pc, order, ax, i, j):
    """Does the triangle at position i come before the one at j along axis `ax` (centres `pc` by position, ties by
    triangle index: a strict order)?"""
    return pc[i, ax] < pc[j, ax] or (pc[i, ax] == pc[j, ax] and order[i] < order[j])


@njit(cache=True, inline="always")
def _swap(pc, order, i, j):
    order[i], order[j] = order[j], order[i]
    for a in range(3):
        pc[i, a], pc[j, a] = pc[j, a], pc[i, a]


@njit(cache=True)
def _select(pc, order, ax, a, b, k):
    """Rearrange positions a..b-1 (`order` and the centres `pc` with it) so that a..k-1 hold their k - a first along
    axis `ax` (`_before`), in linear expected time (quickselect, median-of-three pivots)."""
    lo, hi = a, b - 1
    while lo < hi:
        if hi - lo < 3:  # three or fewer: in order by insertion
            for i in range(lo + 1, hi + 1):
                j = i
                while j > lo and _before(pc, order, ax, j, j - 1):
                    _swap(pc, order, j, j - 1)
                    j -= 1
            return
        mid = (lo + hi) >> 1
        if _before(pc, order, ax, mid, lo):
            _swap(pc, order, mid, lo)
        if _before(pc, order, ax, hi, lo):
            _swap(pc, order, hi, lo)
        if _before(pc, order, ax, hi, mid):
            _swap(pc, order, hi, mid)
        _swap(pc, order, mid, hi - 1)  # the pivot, out of the way at hi - 1
        p = hi - 1
        i, j = lo, hi - 1
        while True:
            i += 1
            while _before(pc, order, ax, i, p):
                i += 1
            j -= 1
            while j > lo and _before(pc, order, ax, p, j):
                j -= 1
            if i >= j:
                break
            _swap(pc, order, i, j)
        _swap(pc, order, i, hi - 1)  # the pivot to its place, i
        if k == i:
            return
        if k < i:
            hi = i - 1
        else:
            lo = i + 1


@njit(cache=True)
def _split_order(centres, leaf, P):
    """The triangles' indices (T,) in the order of a top-down spatial split matching the implicit tree of P leaves of
    `leaf` slots, filled from the left: a node's triangles, split along the longest side of their centres' bounds
    (ties by index), give its left child the first as many as it holds and its right child the rest. Each node then
    holds the triangles of one box of space, where the Morton order's nodes may straddle a jump of its curve.
    Started from the Morton order, whose nodes' triangles already lie near each other in memory; a large node is
    split by `_partition`, which keeps that order on either side. `centres` (T, 3): the triangles' centres."""
    n = centres.shape[0]
    order = _morton_order(centres)
    pc = np.empty((n, 3))
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for i in range(n):
        for a in range(3):
            c = centres[order[i], a]
            pc[i, a] = c
            lo[a], hi[a] = min(lo[a], c), max(hi[a], c)
    buf_o, buf_c, bins = np.empty(n, dtype=np.int64), np.empty((n, 3)), np.empty(n, dtype=np.int64)
    count = np.empty(_BINS, dtype=np.int64)
    # (first, end, capacity in slots, are its bounds known) of the nodes still to split, and their centres' bounds
    todo = np.empty((128, 4), dtype=np.int64)
    todo_box = np.empty((128, 6))
    todo[0, 0], todo[0, 1], todo[0, 2], todo[0, 3] = 0, n, P * leaf, 1
    todo_box[0, :3], todo_box[0, 3:] = lo, hi
    box = np.empty(6)
    left, right = np.empty(6), np.empty(6)
    top = 1
    while top > 0:
        top -= 1
        a, b, cap, known = todo[top, 0], todo[top, 1], todo[top, 2], todo[top, 3]
        if cap <= leaf or b - a <= 1:
            continue
        half = cap // 2
        m = min(b, a + half)
        lk = rk = 0
        if b - a > half:
            if known:
                box[:] = todo_box[top]
            else:
                _bounds(pc, a, b, box)
            ax = 0
            if box[4] - box[1] > box[3] - box[0]:
                ax = 1
            if box[5] - box[2] > max(box[3] - box[0], box[4] - box[1]):
                ax = 2
            if b - a > _PARTITION_MIN:
                _partition(pc, order, ax, a, b, m, box[ax], box[3 + ax], buf_o, buf_c, bins, count, left, right)
                lk = rk = 1
            else:
                _select(pc, order, ax, a, b, m)
        elif known:
            left[:] = todo_box[top]  # all of it to the left child
            lk = 1
        todo[top, 0], todo[top, 1], todo[top, 2], todo[top, 3] = m, b, half, rk
        todo_box[top, :] = right
        todo[top + 1, 0], todo[top + 1, 1], todo[top + 1, 2], todo[top + 1, 3] = a, m, half, lk
        todo_box[top + 1, :] = left
        top += 2
    return order


_BINS = 1024  # the bins of `_partition`'s histogram
_PARTITION_MIN = 16  # triangles above which a node is split by `_partition`, at or below by `_select` alone


@njit(cache=True)
def _bounds(pc, a, b, box):
    """The bounds of the centres at positions a..b-1 into box (lo, hi)."""
    box[:3], box[3:] = np.inf, -np.inf
    for i in range(a, b):
        for k in range(3):
            box[k], box[3 + k] = min(box[k], pc[i, k]), max(box[3 + k], pc[i, k])


@njit(cache=True)
def _partition(pc, order, ax, a, b, m, lo, hi, buf_o, buf_c, bins, count, left, right):
    """Rearrange positions a..b-1 as `_select(pc, order, ax, a, b, m)` does, and the bounds of the centres at a..m-1
    into `left` and at m..b-1 into `right`, in two passes: a histogram of the centres along `ax` over lo..hi finds the
    bin holding the (m - a)-th, then the triangles are moved in a stable partition (those below that bin, that bin's,
    those above), so that each side keeps its order, and `_select` orders only that bin's few."""
    nb = min(count.shape[0], max((b - a) >> 2, 1))  # about four to a bin
    count[:nb] = 0
    scale = (nb / (hi - lo)) if hi > lo else 0.0
    for i in range(a, b):
        q = min(max(np.int64((pc[i, ax] - lo) * scale), 0), nb - 1)  # monotone in the centre: bins keep the order
        bins[i] = q
        count[q] += 1
    k = m - a
    below, cut = 0, 0
    while below + count[cut] < k:
        below += count[cut]
        cut += 1
    p0, p1, p2 = 0, below, below + count[cut]  # where the three runs start in the buffer
    l0, l1, l2, r0, r1, r2 = np.inf, np.inf, np.inf, np.inf, np.inf, np.inf
    L0, L1, L2, R0, R1, R2 = -np.inf, -np.inf, -np.inf, -np.inf, -np.inf, -np.inf
    for i in range(a, b):
        q = bins[i]
        x, y, z = pc[i, 0], pc[i, 1], pc[i, 2]
        if q < cut:
            j = p0
            p0 += 1
            l0, l1, l2, L0, L1, L2 = min(l0, x), min(l1, y), min(l2, z), max(L0, x), max(L1, y), max(L2, z)
        elif q == cut:
            j = p1
            p1 += 1
        else:
            j = p2
            p2 += 1
            r0, r1, r2, R0, R1, R2 = min(r0, x), min(r1, y), min(r2, z), max(R0, x), max(R1, y), max(R2, z)
        buf_o[j] = order[i]
        buf_c[j, 0], buf_c[j, 1], buf_c[j, 2] = x, y, z
    left[0], left[1], left[2], left[3], left[4], left[5] = l0, l1, l2, L0, L1, L2
    right[0], right[1], right[2], right[3], right[4], right[5] = r0, r1, r2, R0, R1, R2
    for j in range(b - a):
        order[a + j] = buf_o[j]
        pc[a + j, 0], pc[a + j, 1], pc[a + j, 2] = buf_c[j, 0], buf_c[j, 1], buf_c[j, 2]
    s, e = a + below, a + below + count[cut]
    _select(pc, order, ax, s, e, m)
    for i in range(s, e):
        side = left if i < m else right
        for t in range(3):
            side[t], side[3 + t] = min(side[t], pc[i, t]), max(side[3 + t], pc[i, t])


@njit(cache=True, inline="always")
def _centre_normal(shape, nsum, node, c, nn):
    """A built node's box centre into c and unit mean normal into nn (`_unit_normal`); False, with its sphere and
    offsets zeroed, for an empty node."""
    if shape[node, 0] > shape[node, 3]:
        shape[node, 6:] = 0.0
        return False
    _unit_normal(nsum, node, nn)
    for a in range(3):
        c[a] = 0.5 * (shape[node, a] + shape[node, 3 + a])
    return True


@njit(cache=True, nogil=True)  # a large part's first plan builds it beside segmentation (grasps._prebuild)
def _build(vertices, faces, leaf, slots, tri_s, shape):
    """Fill the hierarchy in one pass over the triangles (`faces` into `vertices`) in the order of `_split_order` (the
    Morton order from `SPLIT_MAX` triangles): `slots` (the triangle of every leaf slot, -1 for none), `tri_s` (the
    triangles' corners by slot, gathered here) and `shape`: per node its box (lo, hi; empty: lo > hi), the box centre c,
    the radius of a sphere about c holding the node's points, the unit mean normal n of its triangles (area-weighted;
    any unit vector where they cancel) and the least and largest offsets of its points along n. Exact at the leaves; a
    parent's sphere and offsets hold its children's (their reach along n by `_reach`)."""
    n = faces.shape[0]
    N = shape.shape[0]
    P = N // 2
    centres = triangle_centres(vertices, faces)
    order = _split_order(centres, leaf, P) if n < SPLIT_MAX else _morton_order(centres)
    nsum = np.empty((N, 3))
    c, nn = np.empty(3), np.empty(3)
    for node in range(P, N):
        q0 = (node - P) * leaf
        s0, s1, s2 = 0.0, 0.0, 0.0
        for a in range(3):
            shape[node, a] = np.inf
            shape[node, 3 + a] = -np.inf
        for q in range(q0, q0 + leaf):
            if q >= n:
                slots[q] = -1
                continue
            f = order[q]
            slots[q] = f
            for v in range(3):
                u = faces[f, v]
                for a in range(3):
                    x = vertices[u, a]
                    tri_s[q, v, a] = x
                    shape[node, a] = min(shape[node, a], x)
                    shape[node, 3 + a] = max(shape[node, 3 + a], x)
            e10, e11, e12 = (tri_s[q, 1, 0] - tri_s[q, 0, 0], tri_s[q, 1, 1] - tri_s[q, 0, 1],
                             tri_s[q, 1, 2] - tri_s[q, 0, 2])
            e20, e21, e22 = (tri_s[q, 2, 0] - tri_s[q, 0, 0], tri_s[q, 2, 1] - tri_s[q, 0, 1],
                             tri_s[q, 2, 2] - tri_s[q, 0, 2])
            s0 += e11 * e22 - e12 * e21
            s1 += e12 * e20 - e10 * e22
            s2 += e10 * e21 - e11 * e20
        nsum[node, 0], nsum[node, 1], nsum[node, 2] = s0, s1, s2
        if not _centre_normal(shape, nsum, node, c, nn):
            continue
        r2, d0, d1 = 0.0, np.inf, -np.inf
        for q in range(q0, min(q0 + leaf, n)):
            for v in range(3):
                w0, w1, w2 = tri_s[q, v, 0] - c[0], tri_s[q, v, 1] - c[1], tri_s[q, v, 2] - c[2]
                r2 = max(r2, w0 * w0 + w1 * w1 + w2 * w2)
                d = w0 * nn[0] + w1 * nn[1] + w2 * nn[2]
                d0 = min(d0, d)
                d1 = max(d1, d)
        _set_shape(shape, node, c, np.sqrt(r2), nn, d0, d1)
    for node in range(P - 1, 0, -1):
        for a in range(3):
            nsum[node, a] = nsum[2 * node, a] + nsum[2 * node + 1, a]
            shape[node, a] = min(shape[2 * node, a], shape[2 * node + 1, a])
            shape[node, 3 + a] = max(shape[2 * node, 3 + a], shape[2 * node + 1, 3 + a])
        if not _centre_normal(shape, nsum, node, c, nn):
            continue
        r, d0, d1 = 0.0, np.inf, -np.inf
        for child in (2 * node, 2 * node + 1):
            if shape[child, 0] > shape[child, 3]:
                continue
            gap = np.sqrt((shape[child, 6] - c[0]) ** 2 + (shape[child, 7] - c[1]) ** 2 + (shape[child, 8] - c[2]) ** 2)
            r = max(r, gap + shape[child, 9])
            a, b = _reach(shape, child, c, nn, 0.0)
            d0 = min(d0, a)
            d1 = max(d1, b)
        box = np.sqrt((shape[node, 3] - shape[node, 0]) ** 2 + (shape[node, 4] - shape[node, 1]) ** 2
                      + (shape[node, 5] - shape[node, 2]) ** 2) / 2
        _set_shape(shape, node, c, min(r, box), nn, d0, d1)  # no larger than the box's own sphere


@njit(cache=True)
def _unit_normal(nsum, node, out):
    """`nsum[node]` made a unit vector into `out` (z where it vanishes)."""
    ln = np.sqrt(nsum[node, 0] ** 2 + nsum[node, 1] ** 2 + nsum[node, 2] ** 2)
    if ln > 0:
        for a in range(3):
            out[a] = nsum[node, a] / ln
    else:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0


@njit(cache=True)
def _set_shape(shape, node, c, r, n, d0, d1):
    """Write a node's sphere (centre c, radius r) and slab (normal n, offsets d0..d1) into `shape`."""
    for a in range(3):
        shape[node, 6 + a] = c[a]
        shape[node, 10 + a] = n[a]
    shape[node, 9] = r
    shape[node, 13], shape[node, 14] = d0, d1


def triangle_bvh(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, leaf: int | None = None) -> tuple:
    """A bounding-volume hierarchy over the triangles `faces` (T, 3) into `vertices` (V, 3) for `first_touch_kernel`:
    the triangles split in space node by node (`_split_order`; in Morton order from `SPLIT_MAX`), `leaf` to a leaf
    (None: by the count, 4 to 16), and a complete binary tree over the leaves (node 1 the root, node i's children 2i and
    2i + 1, the leaves P .. 2P - 1). Returns the node shapes (2P, 15): box lo, hi (empty: lo > hi), and the sphere and
    slab of `_build`; the triangle of every leaf slot (P * leaf, -1 for none); `leaf`; the triangles by slot (T, 3, 3),
    so that a leaf's triangles lie together in memory; and the triangles' `normals` (T, 3). `leaf` >= T gives one leaf:
    a scan of every triangle."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    n = len(faces)
    if leaf is None:
        # wide leaves halve the build and shorten the pads' searches at full resolution; on a coarse mesh, whose
        # triangles are large beside the hand, narrow ones spare the hand's separating-axis tests
        leaf = 4 if n < 8_192 else 8 if n < 131_072 else 16
    leaf = max(int(leaf), 1)
    P = 1 << int(np.ceil(np.log2(max(-(-n // leaf), 1))))
    slots = np.empty(P * leaf, dtype=np.int64)
    tri_s = np.empty((n, 3, 3))
    shape = np.empty((2 * P, 15))
    shape[0] = 0.0  # node 0 is not in the tree
    _build(vertices, faces, leaf, slots, tri_s, shape)
    return shape, slots, leaf, tri_s, np.ascontiguousarray(normals, dtype=np.float64)


@njit(cache=True)
def line_crossings(shape, slots, leaf, tri, starts, dirs):
    """Every crossing of the rays (starts (K, 3), unit dirs (K, 3)) with the triangles of the hierarchy
    (`triangle_bvh`), edges and corners included (a ray through a shared edge crosses both triangles there): (ray,
    triangle, distance along the ray), ray-major."""
    K = starts.shape[0]
    P = shape.shape[0] // 2
    cap = max(16, 4 * K)
    ray = np.empty(cap, dtype=np.int64)
    tid = np.empty(cap, dtype=np.int64)
    dist = np.empty(cap)
    m = 0
    if shape[1, 0] > shape[1, 3]:
        return ray[:0], tid[:0], dist[:0]
    diag = 0.0
    for a in range(3):
        diag += (shape[1, 3 + a] - shape[1, a]) ** 2
    slack = 1e-9 * (1.0 + np.sqrt(diag))
    stack = np.empty(_STACK, dtype=np.int64)
    leaves = np.empty(P, dtype=np.int64)
    for k in range(K):
        o, d = starts[k], dirs[k]
        for i in range(_line_leaves(shape, o, d, slack, stack, leaves)):
            node = leaves[i]
            for q in range((node - P) * leaf, (node - P + 1) * leaf):
                if slots[q] < 0:
                    continue
                # scalars, not array slices: an array temporary per triangle costs more than the test
                a0, a1, a2 = tri[q, 0, 0], tri[q, 0, 1], tri[q, 0, 2]
                e10, e11, e12 = tri[q, 1, 0] - a0, tri[q, 1, 1] - a1, tri[q, 1, 2] - a2
                e20, e21, e22 = tri[q, 2, 0] - a0, tri[q, 2, 1] - a1, tri[q, 2, 2] - a2
                px = d[1] * e22 - d[2] * e21
                py = d[2] * e20 - d[0] * e22
                pz = d[0] * e21 - d[1] * e20
                det = e10 * px + e11 * py + e12 * pz
                if det == 0.0:
                    continue
                inv = 1.0 / det
                sx, sy, sz = o[0] - a0, o[1] - a1, o[2] - a2
                u = (sx * px + sy * py + sz * pz) * inv
                if u < 0.0 or u > 1.0:
                    continue
                qx = sy * e12 - sz * e11
                qy = sz * e10 - sx * e12
                qz = sx * e11 - sy * e10
                v = (d[0] * qx + d[1] * qy + d[2] * qz) * inv
                if v < 0.0 or u + v > 1.0:
                    continue
                if m == cap:
                    cap *= 2
                    ray2, tid2, dist2 = np.empty(cap, dtype=np.int64), np.empty(cap, dtype=np.int64), np.empty(cap)
                    ray2[:m], tid2[:m], dist2[:m] = ray[:m], tid[:m], dist[:m]
                    ray, tid, dist = ray2, tid2, dist2
                ray[m], tid[m] = k, slots[q]
                dist[m] = (e20 * qx + e21 * qy + e22 * qz) * inv
                m += 1
    return ray[:m].copy(), tid[:m].copy(), dist[:m].copy()


@njit(cache=True)
def point_distance(tri, p):
    """The least distance from the point `p` (3,) to the triangles `tri` (T, 3, 3): each triangle's closest point by
    its Voronoi regions (Ericson, Real-Time Collision Detection, 5.1.5), a triangle whose box lies farther than the
    best so far skipped."""
    best2 = np.inf
    for t in range(tri.shape[0]):
        gap2 = 0.0
        for a in range(3):
            lo = min(tri[t, 0, a], tri[t, 1, a], tri[t, 2, a])
            hi = max(tri[t, 0, a], tri[t, 1, a], tri[t, 2, a])
            g = lo - p[a] if p[a] < lo else (p[a] - hi if p[a] > hi else 0.0)
            gap2 += g * g
        if gap2 >= best2:
            continue
        ax, ay, az = tri[t, 0, 0], tri[t, 0, 1], tri[t, 0, 2]
        abx, aby, abz = tri[t, 1, 0] - ax, tri[t, 1, 1] - ay, tri[t, 1, 2] - az
        acx, acy, acz = tri[t, 2, 0] - ax, tri[t, 2, 1] - ay, tri[t, 2, 2] - az
        apx, apy, apz = p[0] - ax, p[1] - ay, p[2] - az
        d1 = abx * apx + aby * apy + abz * apz
        d2 = acx * apx + acy * apy + acz * apz
        bpx, bpy, bpz = p[0] - tri[t, 1, 0], p[1] - tri[t, 1, 1], p[2] - tri[t, 1, 2]
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        cpx, cpy, cpz = p[0] - tri[t, 2, 0], p[1] - tri[t, 2, 1], p[2] - tri[t, 2, 2]
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
        if d1 <= 0.0 and d2 <= 0.0:  # vertex a
            qx, qy, qz = ax, ay, az
        elif d3 >= 0.0 and d4 <= d3:  # vertex b
            qx, qy, qz = tri[t, 1, 0], tri[t, 1, 1], tri[t, 1, 2]
        elif vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:  # edge ab
            v = d1 / (d1 - d3)
            qx, qy, qz = ax + v * abx, ay + v * aby, az + v * abz
        elif d6 >= 0.0 and d5 <= d6:  # vertex c
            qx, qy, qz = tri[t, 2, 0], tri[t, 2, 1], tri[t, 2, 2]
        elif vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:  # edge ac
            w = d2 / (d2 - d6)
            qx, qy, qz = ax + w * acx, ay + w * acy, az + w * acz
        elif va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:  # edge bc
            w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
            bx, by, bz = tri[t, 1, 0], tri[t, 1, 1], tri[t, 1, 2]
            qx, qy, qz = bx + w * (tri[t, 2, 0] - bx), by + w * (tri[t, 2, 1] - by), bz + w * (tri[t, 2, 2] - bz)
        else:  # inside the face
            den = va + vb + vc
            if den == 0.0:  # degenerate: its vertices stand for it
                qx, qy, qz = ax, ay, az
            else:
                v, w = vb / den, vc / den
                qx, qy, qz = ax + abx * v + acx * w, ay + aby * v + acy * w, az + abz * v + acz * w
        d = (p[0] - qx) ** 2 + (p[1] - qy) ** 2 + (p[2] - qz) ** 2
        if d < best2:
            best2 = d
    return np.sqrt(best2)
