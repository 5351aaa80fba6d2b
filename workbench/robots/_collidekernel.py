"""Compiled broad phase of `robots.collider.Collider`: forward kinematics of one joint vector at a time, every
collision part's bounding box in the world, and, where a box meets the table or the object's box, the part's
convex-hull vertices, which settle most such pairs exactly (a vertex inside the table slab is a contact; hull
vertices clear of a box by a margin mean no contact). Pairs left open go to the python-fcl narrow phase (Numba,
cached on disk)."""

from __future__ import annotations

import numpy as np
from numba import njit

FREE, HIT, OPEN = 0, 1, 2  # a configuration's status: clear, in contact, some pairs left to the narrow phase


@njit(cache=True, nogil=True)
def _frames(q, base, pl, axis, prism, rot, pos):
    """World rotation (n, 3, 3) and origin (n, 3) of every joint frame after its motion (as `chain.forward`)."""
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
            t0 += (r[0, 0] * x + r[0, 1] * y + r[0, 2] * z) * q[i]
            t1 += (r[1, 0] * x + r[1, 1] * y + r[1, 2] * z) * q[i]
            t2 += (r[2, 0] * x + r[2, 1] * y + r[2, 2] * z) * q[i]
        else:
            s, c = np.sin(q[i]), np.cos(q[i])
            v = 1.0 - c
            m00, m01, m02 = c + v * x * x, v * x * y - s * z, v * x * z + s * y
            m10, m11, m12 = v * x * y + s * z, c + v * y * y, v * y * z - s * x
            m20, m21, m22 = v * x * z - s * y, v * y * z + s * x, c + v * z * z
            for a in range(3):
                u0, u1, u2 = tmp[a, 0], tmp[a, 1], tmp[a, 2]
                r[a, 0] = u0 * m00 + u1 * m10 + u2 * m20
                r[a, 1] = u0 * m01 + u1 * m11 + u2 * m21
                r[a, 2] = u0 * m02 + u1 * m12 + u2 * m22
        for a in range(3):
            for b in range(3):
                rot[i, a, b] = r[a, b]
        pos[i, 0], pos[i, 1], pos[i, 2] = t0, t1, t2


@njit(cache=True, inline="always")
def _overlap(lo, hi, bmin, bmax):
    return (lo[0] <= bmax[0] and lo[1] <= bmax[1] and lo[2] <= bmax[2]
            and hi[0] >= bmin[0] and hi[1] >= bmin[1] and hi[2] >= bmin[2])


@njit(cache=True, nogil=True)
def classify_rows(q, base, pl, axis, prism, joint, obb_r, obb_c, obb_h, vstart, verts, exact, vs_object, tmin, tmax,
                  places, orr, oc, oh, margin, status, open_table, open_obj):
    """Per joint vector q[b]: status[b] FREE, HIT or OPEN, and for OPEN the (part) pairs with the table
    (open_table[b]) and with the object placed at places[b] (open_obj[b]; places of shape (0, 4, 4): no object)
    that the narrow phase must test. Part p rides on joint joint[p]; its box (obb_r, obb_c, obb_h) and hull vertices
    verts[vstart[p]:vstart[p + 1]] are in that joint's frame; only parts with exact[p] (meshes, boxes) use their
    vertices. A part box meeting the table or the object box is a candidate pair (as the fcl broad phase); its hull
    vertices then decide it: one inside the slab by `margin` is a contact, all clear of the box by `margin` none."""
    nb, nq, nparts = q.shape[0], q.shape[1], joint.shape[0]
    rot = np.empty((nq, 3, 3))
    pos = np.empty((nq, 3))
    lo = np.empty(3)
    hi = np.empty(3)
    vlo = np.empty(3)
    vhi = np.empty(3)
    omin = np.empty(3)
    omax = np.empty(3)
    am = np.empty((3, 3))
    ac = np.empty(3)
    has_obj = places.shape[0] > 0
    cw = np.empty(3)
    rad = np.empty(nparts)  # a part's box lies in the ball of its half-diagonal: a cheap first test of each pair
    for p in range(nparts):
        rad[p] = np.sqrt(obb_h[p, 0] ** 2 + obb_h[p, 1] ** 2 + obb_h[p, 2] ** 2) * (1.0 + 1e-12) + 1e-12
    for b in range(nb):
        _frames(q[b], base, pl, axis, prism, rot, pos)
        if has_obj:
            pr = places[b]
            for a in range(3):
                c = pr[a, 3]
                h = 0.0
                for k in range(3):
                    c += pr[a, k] * oc[k]
                    w = pr[a, 0] * orr[0, k] + pr[a, 1] * orr[1, k] + pr[a, 2] * orr[2, k]
                    h += abs(w) * oh[k]
                omin[a], omax[a] = c - h, c + h
        hit = False
        undecided = False
        for p in range(nparts):
            open_table[b, p] = False
            open_obj[b, p] = False
        for p in range(nparts):
            j = joint[p]
            rj = rot[j]
            for a in range(3):
                c = pos[j, a]
                for k in range(3):
                    c += rj[a, k] * obb_c[p, k]
                cw[a] = c
            r = rad[p]  # the box's world extent along each axis is at most the ball's: no box, no pair
            if not (cw[0] - r <= tmax[0] and cw[1] - r <= tmax[1] and cw[2] - r <= tmax[2]
                    and cw[0] + r >= tmin[0] and cw[1] + r >= tmin[1] and cw[2] + r >= tmin[2]):
                if not (has_obj and vs_object[p] and cw[0] - r <= omax[0] and cw[1] - r <= omax[1]
                        and cw[2] - r <= omax[2] and cw[0] + r >= omin[0] and cw[1] + r >= omin[1]
                        and cw[2] + r >= omin[2]):
                    continue
            for a in range(3):
                h = 0.0
                for k in range(3):
                    w = rj[a, 0] * obb_r[p, 0, k] + rj[a, 1] * obb_r[p, 1, k] + rj[a, 2] * obb_r[p, 2, k]
                    h += abs(w) * obb_h[p, k]
                lo[a], hi[a] = cw[a] - h, cw[a] + h
            ct = _overlap(lo, hi, tmin, tmax)
            co = has_obj and vs_object[p] and _overlap(lo, hi, omin, omax)
            if not ct and not co:
                continue
            if exact[p] and ct:  # heights first: most parts over the table are clear above it or dip into it
                zlo, zhi = np.inf, -np.inf
                for v in range(vstart[p], vstart[p + 1]):
                    x2 = pos[j, 2] + rj[2, 0] * verts[v, 0] + rj[2, 1] * verts[v, 1] + rj[2, 2] * verts[v, 2]
                    zlo, zhi = min(zlo, x2), max(zhi, x2)
                    if tmin[2] + margin < x2 < tmax[2] - margin:
                        x0 = pos[j, 0] + rj[0, 0] * verts[v, 0] + rj[0, 1] * verts[v, 1] + rj[0, 2] * verts[v, 2]
                        x1 = pos[j, 1] + rj[1, 0] * verts[v, 0] + rj[1, 1] * verts[v, 1] + rj[1, 2] * verts[v, 2]
                        if tmin[0] + margin < x0 < tmax[0] - margin and tmin[1] + margin < x1 < tmax[1] - margin:
                            hit = True
                            break
                if hit:
                    break
                ct = zlo - margin <= tmax[2] and zhi + margin >= tmin[2]
            if exact[p] and co:  # the hull in the object's frame against the object's own box (oc +- oh)
                pr = places[b]
                for a in range(3):
                    c = 0.0
                    for k in range(3):
                        am[a, k] = pr[0, a] * rj[0, k] + pr[1, a] * rj[1, k] + pr[2, a] * rj[2, k]
                        c += pr[k, a] * (pos[j, k] - pr[k, 3])
                    ac[a] = c
                    vlo[a], vhi[a] = np.inf, -np.inf
                for v in range(vstart[p], vstart[p + 1]):
                    for a in range(3):
                        x = ac[a] + am[a, 0] * verts[v, 0] + am[a, 1] * verts[v, 1] + am[a, 2] * verts[v, 2]
                        vlo[a], vhi[a] = min(vlo[a], x), max(vhi[a], x)
                co = True
                for a in range(3):
                    co = co and vlo[a] - margin <= oc[a] + oh[a] and vhi[a] + margin >= oc[a] - oh[a]
            open_table[b, p] = ct
            open_obj[b, p] = co
            undecided = undecided or ct or co
        status[b] = HIT if hit else (OPEN if undecided else FREE)
