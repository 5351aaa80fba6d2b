"""Compiled closed forms, one pose at a time in scalar code (Numba, cached on disk after the first compile): the
spherical-wrist solution of `robots.analytic` for one or more 6R forms at once (a 7-joint arm's swept samples), and
the three-parallel-axes solution of `robots.parallel`. The constants come from those modules' solvers; the steps
are theirs, written per pose."""

from __future__ import annotations

import numpy as np
from numba import njit

TWO_PI = 2.0 * np.pi


@njit(cache=True, inline="always")
def _rot(k, c, s, v, inverse, out):
    """Rotate v (3,) about the unit axis k by the angle (c, s) (Rodrigues); `inverse` by minus it."""
    if inverse:
        s = -s
    kv = (k[0] * v[0] + k[1] * v[1] + k[2] * v[2]) * (1.0 - c)
    x = v[0] * c + (k[1] * v[2] - k[2] * v[1]) * s + k[0] * kv
    y = v[1] * c + (k[2] * v[0] - k[0] * v[2]) * s + k[1] * kv
    z = v[2] * c + (k[0] * v[1] - k[1] * v[0]) * s + k[2] * kv
    out[0], out[1], out[2] = x, y, z


@njit(cache=True, inline="always")
def _dot(u, v):
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit(cache=True, inline="always")
def _mul(r, v, out):
    """r (3, 3) times v (3,)."""
    x = r[0, 0] * v[0] + r[0, 1] * v[1] + r[0, 2] * v[2]
    y = r[1, 0] * v[0] + r[1, 1] * v[1] + r[1, 2] * v[2]
    z = r[2, 0] * v[0] + r[2, 1] * v[1] + r[2, 2] * v[2]
    out[0], out[1], out[2] = x, y, z


@njit(cache=True, inline="always")
def _mul_t(r, v, out):
    """r^T (3, 3) times v (3,)."""
    x = r[0, 0] * v[0] + r[1, 0] * v[1] + r[2, 0] * v[2]
    y = r[0, 1] * v[0] + r[1, 1] * v[1] + r[2, 1] * v[2]
    z = r[0, 2] * v[0] + r[1, 2] * v[1] + r[2, 2] * v[2]
    out[0], out[1], out[2] = x, y, z


@njit(cache=True, inline="always")
def _into_wrist(a1, c1, s1, a2, c2, s2, a3, c3, s3, r2, r3, r4, v, tmp, u, out):
    """R4^T R3^T ... of `v` through joints 1-3 and the fixed frames r2, r3, r4 into `out` (3,)."""
    _rot(a1, c1, s1, v, True, tmp)
    _mul_t(r2, tmp, u)
    _rot(a2, c2, s2, u, True, tmp)
    _mul_t(r3, tmp, u)
    _rot(a3, c3, s3, u, True, tmp)
    _mul_t(r4, tmp, out)


@njit(cache=True, inline="always")
def _acs(a, b, c, out):
    """Both x of a cos x + b sin x = c as out[0:2] = (cos, sin), out[2:4] = (cos, sin); NaN where there is none."""
    r = np.sqrt(a * a + b * b)
    x = c / r
    if abs(x) <= 1.0 + 1e-10:
        x = min(1.0, max(-1.0, x))
    else:
        x = np.nan
    sd = np.sqrt(1.0 - x * x)
    ca, sa = a / r, b / r
    out[0], out[1] = _root(ca, sa, x, sd, 0)
    out[2], out[3] = _root(ca, sa, x, sd, 1)


@njit(cache=True, inline="always")
def _limit(q, lo, hi):
    """q in (-pi, pi] moved by a whole turn into [lo, hi] (the representative nearest to 0), NaN if none."""
    if q >= lo and q <= hi:
        return q
    if q - TWO_PI >= lo and q - TWO_PI <= hi:
        return q - TWO_PI
    if q + TWO_PI >= lo and q + TWO_PI <= hi:
        return q + TWO_PI
    return np.nan


@njit(cache=True, inline="never")  # a call, not ten inlined copies: a smaller kernel runs faster
def _void(out_q, out_valid, i, col0, count, cols, fixed_col, fixed_val, full_rows):
    """Branches col0 .. col0 + count - 1 of pose i without a solution: NaN joints (the held joint still written);
    with `full_rows` (cols and fixed_col cover every column), whole rows at once."""
    for col in range(col0, col0 + count):
        if full_rows:
            for j in range(out_q.shape[2]):
                out_q[i, col, j] = np.nan
        else:
            for j in range(cols.shape[0]):
                out_q[i, col, cols[j]] = np.nan
        if fixed_col >= 0:
            out_q[i, col, fixed_col] = fixed_val
        out_valid[i, col] = False


@njit(cache=True, inline="always")
def _mul_row(r, m, row, out):
    """out[row] = r (3, 3) times m[row] (3,)."""
    x = r[0, 0] * m[row, 0] + r[0, 1] * m[row, 1] + r[0, 2] * m[row, 2]
    y = r[1, 0] * m[row, 0] + r[1, 1] * m[row, 1] + r[1, 2] * m[row, 2]
    z = r[2, 0] * m[row, 0] + r[2, 1] * m[row, 1] + r[2, 2] * m[row, 2]
    out[row, 0], out[row, 1], out[row, 2] = x, y, z


@njit(cache=True, inline="always")
def _sub1_parts(k, u, v):
    """The rotation taking u onto v about the unit axis k (Paden-Kahan subproblem 1) as (cos, sin, y, x): its angle
    is arctan2(y, x), taken only where needed."""
    ku = k[0] * u[0] + k[1] * u[1] + k[2] * u[2]
    kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2]
    u0, u1, u2 = u[0] - k[0] * ku, u[1] - k[1] * ku, u[2] - k[2] * ku
    v0, v1, v2 = v[0] - k[0] * kv, v[1] - k[1] * kv, v[2] - k[2] * kv
    y = k[0] * (u1 * v2 - u2 * v1) + k[1] * (u2 * v0 - u0 * v2) + k[2] * (u0 * v1 - u1 * v0)
    x = u0 * v0 + u1 * v1 + u2 * v2
    h = np.sqrt(x * x + y * y)
    if not h > 0.0:  # zero (a singular axis: any angle, 0 chosen) or NaN (no solution upstream)
        return 1.0, y, y, 1.0
    return x / h, y / h, y, x


@njit(cache=True, inline="always")
def _inside(c, s, cm, sm, thr_in):
    """Whether the angle (c, s) is surely within a joint's limits, with a representative `_limit` finds: thr_in is
    cos((hi - lo) / 2) + 1e-9 for limits narrower than a turn within [-2 pi, 2 pi] (`_out`), -inf without limits,
    inf otherwise (never sure). Its arctangent can then wait until a branch below it is output."""
    return c * cm + s * sm >= thr_in


@njit(cache=True, inline="always")
def _root(ca, sa, x, sd, which):
    """(cos, sin) of root `which` (0 or 1) of a cos q + b sin q = c, given (ca, sa) = (a, b) / r, x = c / r and
    sd = sqrt(1 - x^2)."""
    if which == 0:
        return ca * x - sa * sd, sa * x + ca * sd
    return ca * x + sa * sd, sa * x - ca * sd


@njit(cache=True, inline="always")
def _joint(c, s, y, x, cm, sm, thr_in, thr, lo, hi):
    """A joint's value for the angle (c, s) = arctan2(y, x) and whether its arctangent was put off: (0, True) when
    surely within the limits (`_inside`), (NaN, False) when surely outside them (`_out`), else (`_limit` of it,
    False)."""
    if _inside(c, s, cm, sm, thr_in):
        return 0.0, True
    if _out(c, s, cm, sm, thr):
        return np.nan, False
    return _limit(np.arctan2(y, x), lo, hi), False


@njit(cache=True, inline="always")
def _out(c, s, cm, sm, thr):
    """Whether the angle (c, s) is surely outside a joint's limits [lo, hi] narrower than a turn: (cm, sm) is the
    direction of their middle, thr = cos((hi - lo) / 2) - 1e-9 (-inf for wider limits), so that no representative
    of the angle (`_limit`) can lie within them when c cm + s sm < thr (NaN: outside)."""
    return not (c * cm + s * sm >= thr)


@njit(cache=True, nogil=True)
def wrist_rows(poses, mb, kw, rb, kc, kd, o, ax, r2, p2, r3, p3, r4, w3, a1p, wa, wb, wc, wd, consts, lower, upper,
               cols, fixed_col, fixed, out_q, out_valid, any_only=False, use=np.ones((0, 0), dtype=np.bool_)):
    """Spherical-wrist IK (`analytic._solve_block`, Section 5.2) of poses (N, 4, 4) for S forms (constants stacked
    on a leading axis S): the 8 branches of form s go to out_q[:, 8 s + b, cols] (branch b = 4 elbow + 2 shoulder +
    wrist flip), with out_q[:, 8 s + b, fixed_col] = fixed[s] when fixed_col >= 0; out_valid (N, 8 S). With
    `any_only`, out_q is not touched and each pose stops at its first valid branch (out_valid must start False).
    A non-empty `use` (N, S) solves form s of pose i only where use[i, s] (the others void).

    What does not change from form to form (a 7-joint arm's swept samples share all but the first placement) is
    computed once per pose; a joint's limits are tested on its (cos, sin) first (`_out`, `_inside`), and its
    arctangent is taken only where that test is not sure, or for the output once a branch below it is valid: the same
    values, bit for bit, as solving each form on its own."""
    n, nf = poses.shape[0], mb.shape[0]
    w = np.empty(3)
    pw = np.empty(3)
    tmp = np.empty(3)
    v = np.empty(3)
    x = np.empty(3)
    yc0 = np.empty(3)
    yd0 = np.empty(3)
    yc = np.empty(3)
    yd = np.empty(3)
    u = np.empty(3)
    t2 = np.empty(3)
    qb = np.empty(6)
    pkw = np.empty((nf, 3))  # the pose's rotation times kw, kc, kd, in the slot of the first form with the same ones
    pkc = np.empty((nf, 3))
    pkd = np.empty((nf, 3))
    # per form: the elbow equation's constant amplitude and phase, the first form with the same kw / kc and kd
    er, eca, esa = np.empty(nf), np.empty(nf), np.empty(nf)
    done_w = np.empty(nf, dtype=np.bool_)
    done_c = np.empty(nf, dtype=np.bool_)
    same_w = np.empty(nf, dtype=np.int64)
    same_c = np.empty(nf, dtype=np.int64)
    cm, sm, thr, thr_in = np.empty((nf, 6)), np.empty((nf, 6)), np.empty((nf, 6)), np.empty((nf, 6))
    for f in range(nf):
        a, b = consts[f, 0], consts[f, 1]
        er[f] = np.sqrt(a * a + b * b)
        eca[f], esa[f] = a / er[f], b / er[f]
        same_w[f], same_c[f] = f, f
        for g in range(f):
            if kw[g, 0] == kw[f, 0] and kw[g, 1] == kw[f, 1] and kw[g, 2] == kw[f, 2]:
                same_w[f] = g
                break
        for g in range(f):
            if (kc[g, 0] == kc[f, 0] and kc[g, 1] == kc[f, 1] and kc[g, 2] == kc[f, 2] and kd[g, 0] == kd[f, 0]
                    and kd[g, 1] == kd[f, 1] and kd[g, 2] == kd[f, 2]):
                same_c[f] = g
                break
        for j in range(6):
            lo, hi = lower[f, j], upper[f, j]
            cm[f, j], sm[f, j], thr[f, j], thr_in[f, j] = 1.0, 0.0, -np.inf, np.inf
            if np.isfinite(lo) and np.isfinite(hi) and hi - lo < TWO_PI:
                mid, half = (lo + hi) / 2, (hi - lo) / 2
                cm[f, j], sm[f, j], thr[f, j] = np.cos(mid), np.sin(mid), np.cos(half) - 1e-9
                if lo >= -TWO_PI and hi <= TWO_PI:  # a representative within a turn of (-pi, pi], as `_limit` tries
                    thr_in[f, j] = np.cos(half) + 1e-9
            elif lo == -np.inf and hi == np.inf:
                thr_in[f, j] = -np.inf
    full_rows = cols.shape[0] + (1 if fixed_col >= 0 else 0) == out_q.shape[2]
    for i in range(n):
        pr = poses[i, :3, :3]
        found = False
        done_w[:] = False
        done_c[:] = False
        for f in range(nf):
            if found:  # any_only: this pose has a valid branch
                break
            if use.shape[0] and not use[i, f]:
                if not any_only:
                    _void(out_q, out_valid, i, 8 * f, 8, cols, fixed_col, fixed[f], full_rows)
                continue
            # the wrist centre in the joint-1 parent frame, and R6 (c, d) through the pose's rotation
            g = same_w[f]
            if not done_w[g]:
                _mul_row(pr, kw, g, pkw)
                done_w[g] = True
            for a in range(3):
                w[a] = pkw[g, a] + poses[i, a, 3]
            _mul(mb[f, :3, :3], w, pw)
            for a in range(3):
                pw[a] += mb[f, a, 3]
            a1, a2, a3 = ax[f, 0], ax[f, 1], ax[f, 2]
            d0, d1, d2 = pw[0] - o[f, 0], pw[1] - o[f, 1], pw[2] - o[f, 2]
            # 1. elbow: two q3 (`_acs` with the form's constant amplitude)
            xe = (d0 * d0 + d1 * d1 + d2 * d2 - consts[f, 2]) / er[f]
            if not abs(xe) <= 1.0 + 1e-10:  # out of reach (or NaN): the form's 8 branches are void
                if not any_only:
                    _void(out_q, out_valid, i, 8 * f, 8, cols, fixed_col, fixed[f], full_rows)
                continue
            xe = min(1.0, max(-1.0, xe))
            sde = np.sqrt(1.0 - xe * xe)
            have_y0 = False  # R6 c and d: only once an elbow is within its limits
            h = a1[0] * pw[0] + a1[1] * pw[1] + a1[2] * pw[2] - consts[f, 3]
            for i3 in range(2):
                c3, s3 = _root(eca[f], esa[f], xe, sde, i3)
                qb[2], d3 = _joint(c3, s3, s3, c3, cm[f, 2], sm[f, 2], thr_in[f, 2], thr[f, 2],
                                   lower[f, 2], upper[f, 2])
                if np.isnan(qb[2]):  # no elbow (or out of its limits): its 4 branches are void
                    if not any_only:
                        _void(out_q, out_valid, i, 8 * f + 4 * i3, 4, cols, fixed_col, fixed[f], full_rows)
                    continue
                if not have_y0:
                    g = same_c[f]
                    if not done_c[g]:
                        _mul_row(pr, kc, g, pkc)
                        _mul_row(pr, kd, g, pkd)
                        done_c[g] = True
                    for a in range(3):
                        tmp[a] = pkc[g, a]
                    _mul(rb[f], tmp, yc0)
                    for a in range(3):
                        tmp[a] = pkd[g, a]
                    _mul(rb[f], tmp, yd0)
                    have_y0 = True
                _rot(a3, c3, s3, w3[f], False, tmp)
                _mul(r3[f], tmp, v)
                for a in range(3):
                    v[a] += p3[f, a]
                # 2. shoulder: two q2 from W's height along axis 1
                av2 = a2[0] * v[0] + a2[1] * v[1] + a2[2] * v[2]
                vp0, vp1, vp2 = v[0] - a2[0] * av2, v[1] - a2[1] * av2, v[2] - a2[2] * av2
                x0 = a2[1] * v[2] - a2[2] * v[1]
                x1 = a2[2] * v[0] - a2[0] * v[2]
                x2 = a2[0] * v[1] - a2[1] * v[0]
                ap = a1p[f]
                sa_ = ap[0] * vp0 + ap[1] * vp1 + ap[2] * vp2
                sb_ = ap[0] * x0 + ap[1] * x1 + ap[2] * x2
                sr = np.sqrt(sa_ * sa_ + sb_ * sb_)
                xs = (h - av2 * (ap[0] * a2[0] + ap[1] * a2[1] + ap[2] * a2[2])) / sr
                if not abs(xs) <= 1.0 + 1e-10:
                    if not any_only:
                        _void(out_q, out_valid, i, 8 * f + 4 * i3, 4, cols, fixed_col, fixed[f], full_rows)
                    continue
                xs = min(1.0, max(-1.0, xs))
                sds = np.sqrt(1.0 - xs * xs)
                sca, ssa = sa_ / sr, sb_ / sr
                for i2 in range(2):
                    c2, s2 = _root(sca, ssa, xs, sds, i2)
                    qb[1], d2 = _joint(c2, s2, s2, c2, cm[f, 1], sm[f, 1], thr_in[f, 1], thr[f, 1],
                                       lower[f, 1], upper[f, 1])
                    if np.isnan(qb[1]):
                        if not any_only:
                            _void(out_q, out_valid, i, 8 * f + 4 * i3 + 2 * i2, 2, cols, fixed_col, fixed[f], full_rows)
                        continue
                    t2[0] = a2[0] * av2 + vp0 * c2 + x0 * s2
                    t2[1] = a2[1] * av2 + vp1 * c2 + x1 * s2
                    t2[2] = a2[2] * av2 + vp2 * c2 + x2 * s2
                    _mul(r2[f], t2, x)
                    for a in range(3):
                        x[a] += p2[f, a]
                    # 3. base: x onto W about axis 1
                    c1, s1, y1, x1_ = _sub1_parts(a1, x, pw)
                    qb[0], d1 = _joint(c1, s1, y1, x1_, cm[f, 0], sm[f, 0], thr_in[f, 0], thr[f, 0],
                                       lower[f, 0], upper[f, 0])
                    if np.isnan(qb[0]):
                        if not any_only:
                            _void(out_q, out_valid, i, 8 * f + 4 * i3 + 2 * i2, 2, cols, fixed_col, fixed[f], full_rows)
                        continue
                    # 4. wrist: Y c and Y d with Y = R4^T R03^T R6 (R5 R6)^T
                    free6 = any_only and upper[f, 5] - lower[f, 5] >= TWO_PI  # validity alone: any q6 is in range
                    # Y c first: q5 needs it alone; Y d only once a branch has q4 and q5 within their limits
                    _into_wrist(a1, c1, s1, a2, c2, s2, a3, c3, s3, r2[f], r3[f], r4[f], yc0, tmp, u, yc)
                    have_yd = False
                    wa0, wa1, wa2 = wa[f, 0], wa[f, 1], wa[f, 2]
                    qa, qbb = consts[f, 4], consts[f, 5]
                    qr = np.sqrt(qa * qa + qbb * qbb)
                    x5 = (wa0 * yc[0] + wa1 * yc[1] + wa2 * yc[2] - consts[f, 6]) / qr
                    if not abs(x5) <= 1.0 + 1e-10:
                        if not any_only:
                            _void(out_q, out_valid, i, 8 * f + 4 * i3 + 2 * i2, 2, cols, fixed_col, fixed[f], full_rows)
                        continue
                    x5 = min(1.0, max(-1.0, x5))
                    sd5 = np.sqrt(1.0 - x5 * x5)
                    ca5, sa5 = qa / qr, qbb / qr
                    for i5 in range(2):
                        col = 8 * f + 4 * i3 + 2 * i2 + i5
                        c5, s5 = _root(ca5, sa5, x5, sd5, i5)
                        # a joint out of reach or out of its limits voids the branch: the later ones are not solved
                        qb[4], d5 = _joint(c5, s5, s5, c5, cm[f, 4], sm[f, 4], thr_in[f, 4], thr[f, 4],
                                           lower[f, 4], upper[f, 4])
                        if np.isnan(qb[4]):
                            if not any_only:
                                _void(out_q, out_valid, i, col, 1, cols, fixed_col, fixed[f], full_rows)
                            continue
                        _rot(wb[f], c5, s5, wc[f], False, u)
                        c4, s4, y4, x4 = _sub1_parts(wa[f], u, yc)
                        qb[3], d4 = _joint(c4, s4, y4, x4, cm[f, 3], sm[f, 3], thr_in[f, 3], thr[f, 3],
                                           lower[f, 3], upper[f, 3])
                        if np.isnan(qb[3]):
                            if not any_only:
                                _void(out_q, out_valid, i, col, 1, cols, fixed_col, fixed[f], full_rows)
                            continue
                        if free6:
                            qb[5] = 0.0
                        else:
                            if not have_yd:
                                _into_wrist(a1, c1, s1, a2, c2, s2, a3, c3, s3, r2[f], r3[f], r4[f], yd0, tmp, u,
                                            yd)
                                have_yd = True
                            _rot(wa[f], c4, s4, yd, True, tmp)
                            _rot(wb[f], c5, s5, tmp, True, u)
                            c6, s6, y6, x6 = _sub1_parts(wc[f], wd[f], u)
                            if _out(c6, s6, cm[f, 5], sm[f, 5], thr[f, 5]):
                                qb[5] = np.nan
                            else:
                                qb[5] = _limit(np.arctan2(y6, x6), lower[f, 5], upper[f, 5])
                        ok = not np.isnan(qb[5])
                        out_valid[i, col] = ok
                        if any_only:
                            found = found or ok
                            continue
                        if not ok:
                            _void(out_q, out_valid, i, col, 1, cols, fixed_col, fixed[f], full_rows)
                            continue
                        # the arctangents put off above, once per joint value this branch is the first to output
                        if d3:
                            qb[2], d3 = _limit(np.arctan2(s3, c3), lower[f, 2], upper[f, 2]), False
                        if d2:
                            qb[1], d2 = _limit(np.arctan2(s2, c2), lower[f, 1], upper[f, 1]), False
                        if d1:
                            qb[0], d1 = _limit(np.arctan2(y1, x1_), lower[f, 0], upper[f, 0]), False
                        if d5:
                            qb[4] = _limit(np.arctan2(s5, c5), lower[f, 4], upper[f, 4])
                        if d4:
                            qb[3] = _limit(np.arctan2(y4, x4), lower[f, 3], upper[f, 3])
                        for j in range(6):
                            out_q[i, col, cols[j]] = qb[j]
                        if fixed_col >= 0:
                            out_q[i, col, fixed_col] = fixed[f]


@njit(cache=True, inline="always")
def _turn(q):
    """q moved by a whole turn into (-pi, pi] (a sum of two angles each in [-pi, pi])."""
    if q > np.pi:
        return q - TWO_PI
    if q <= -np.pi:
        return q + TWO_PI
    return q


@njit(cache=True, inline="always")
def _half(c, r):
    """(cos, sin) of the angle d in [0, pi] with cos d = c / r (NaN when |c / r| > 1)."""
    x = c / r
    if abs(x) <= 1.0 + 1e-10:
        x = min(1.0, max(-1.0, x))
    else:
        x = np.nan
    return x, np.sqrt(1.0 - x * x)


@njit(cache=True)
def _unrot(k, v):
    """(A, B, C) with R_k(x)^T v = A cos x + B sin x + C for every angle x (Rodrigues, split by its terms)."""
    kv = k * (k @ v)
    return v - kv, -np.cross(k, v), kv


@njit(cache=True)
def _plane(k):
    """Two unit vectors completing the unit axis k to a right-handed frame (e1, e2 = k x e1)."""
    e = np.cross(k, np.array([1.0, 0.0, 0.0])) if abs(k[0]) < 0.9 else np.cross(k, np.array([0.0, 1.0, 0.0]))
    e = e / np.sqrt(e @ e)
    return e, np.cross(k, e)


@njit(cache=True, inline="always")
def _angle(y, x):
    """atan2 as subproblem 1 reports it: 0 where the projections vanish (a singular axis)."""
    if x == 0.0 and y == 0.0:
        return 0.0
    return np.arctan2(y, x)


@njit(cache=True, nogil=True)
def parallel_rows(poses, pre, tip_inv, rm, tm, ax, n1, kk, c6v, n5, d4, lower, upper, out_q, out_valid):
    """Three-parallel-axes IK (`parallel`'s module docstring, the UR family) of poses (N, 4, 4): 8 branches
    (4 shoulder + 2 wrist + elbow) into out_q (N, 8, 6) and out_valid (N, 8). rm, tm: placements of joints 2..6.

    The work is shared down the tree q1 pair -> q5 pair -> q6 -> q3 pair, and a branch stops (NaN joints) at the
    first joint with no real solution or outside its limits. Every rotation by a joint that is not yet known is
    folded into constants (A cos q + B sin q + C), and angles about an axis are read in a fixed basis of the plane
    across it (one atan2 each). Steps 2 and 4 have constant coefficients, so each root pair is one phase plus and
    minus a half-angle (one atan2 per pair); q4 is the angle of joint 4's reference direction at q2 = q3 = 0 less
    the turn q2 and q3 give it about the parallel axes, one atan2 per wrist branch."""
    n = poses.shape[0]
    a1, a2, a3, a4, a5, a6 = ax[0], ax[1], ax[2], ax[3], ax[4], ax[5]
    r2, r3, r4, r5, r6 = rm[0], rm[1], rm[2], rm[3], rm[4]
    t2, t3, t4, t5, t6 = tm[0], tm[1], tm[2], tm[3], tm[4]
    # 1. shoulder: n(q1) = par + perp cos q1 + cr sin q1
    par = a1 * (a1 @ n1)
    perp = n1 - par
    cr = np.cross(a1, n1)
    # r2^T R1(q1)^T = q1a cos q1 + q1b sin q1 + q1c
    ka = np.array([[0.0, -a1[2], a1[1]], [a1[2], 0.0, -a1[0]], [-a1[1], a1[0], 0.0]])
    q1c = np.ascontiguousarray(r2.T) @ np.outer(a1, a1)
    q1a = np.ascontiguousarray(r2.T) - q1c
    q1b = -(np.ascontiguousarray(r2.T) @ ka)
    r2t2 = r2.T @ t2
    # 2. wrist: n . R5(q5) c = n . z6, m5a cos q5 + m5b sin q5 = n . z6 - m5c
    c = r6 @ a6
    cpar = a5 * (a5 @ c)
    m5a, m5b, m5c = n5 @ (c - cpar), n5 @ np.cross(a5, c), n5 @ cpar
    m5r, p5 = np.sqrt(m5a * m5a + m5b * m5b), np.arctan2(m5b, m5a)
    c5p, s5p = m5a / m5r, m5b / m5r
    # 3. n seen from joint 5 in the tool frame, r6^T R5(q5)^T n5, on the plane across axis 6 (basis f1, f2)
    f1, f2 = _plane(a6)
    va, vb, vc = _unrot(a5, n5)
    v6 = np.empty((3, 2))
    for k, vec in enumerate((va, vb, vc)):
        w6 = r6.T @ vec
        v6[k, 0], v6[k, 1] = f1 @ w6, f2 @ w6
    # 4. joint 4's origin (g5 through joint 5 and the tool) and reference direction (gd), r6^T (R5(q5)^T g + t)
    g5 = r5.T @ t5
    gd = r5.T @ d4
    vg = np.empty((3, 3))
    vd = np.empty((3, 3))
    ga, gb, gc = _unrot(a5, g5)
    da, db, dc = _unrot(a5, gd)
    vg[0], vg[1], vg[2] = r6.T @ ga, r6.T @ gb, r6.T @ (gc + t6)
    vd[0], vd[1], vd[2] = r6.T @ da, r6.T @ db, r6.T @ dc
    #    elbow: |x2|^2 / 2 = e3a cos q3 + e3b sin q3 + e3c
    g = r3.T @ t3
    t4par = a3 * (a3 @ t4)
    e3a, e3b, e3c = g @ (t4 - t4par), g @ np.cross(a3, t4), 0.5 * (t3 @ t3 + t4 @ t4) + g @ t4par
    e3r, p3 = np.sqrt(e3a * e3a + e3b * e3b), np.arctan2(e3b, e3a)
    c3p, s3p = e3a / e3r, e3b / e3r
    #    joint 4's origin from joint 2 at q2 = 0, r3 R3(q3) t4 + t3, on the plane across axis 2 (basis e1, e2)
    e1, e2 = _plane(a2)
    u3 = np.empty((3, 2))
    for k, w3 in enumerate((r3 @ (t4 - t4par), r3 @ np.cross(a3, t4), r3 @ t4par + t3)):
        u3[k, 0], u3[k, 1] = e1 @ w3, e2 @ w3
    #    joint 4's reference direction d4 and a4 x d4 seen in joint 2's frame at q3 = 0
    r34 = r3 @ r4
    ex, ey = r34 @ d4, r34 @ np.cross(a4, d4)
    sg = 1.0 if a3 @ (r3.T @ a2) > 0 else -1.0   # axis 2 seen from joint 3: +- axis 3
    tau = 1.0 if a4 @ (r4.T @ a3) > 0 else -1.0  # axis 3 seen from joint 4: +- axis 4
    tt = np.empty((3, 4))
    pt = np.empty((4, 4))
    m1 = np.empty((3, 3))
    nn = np.empty((3, 3))
    w = np.empty(3)
    trf1 = np.empty(3)
    trf2 = np.empty(3)
    z6 = np.empty(3)
    b1 = np.empty(3)
    nex = np.empty(3)
    ney = np.empty(3)
    ug = np.empty(3)
    ud = np.empty(3)
    tmp = np.empty(3)
    x2 = np.empty(3)
    for i in range(n):
        for col in range(8):
            out_valid[i, col] = False
            for j in range(6):
                out_q[i, col, j] = np.nan
        for k in range(4):  # joint-6 frame in joint 1's parent frame: pre (P tip^-1)
            for b in range(4):
                acc2 = 0.0
                for l in range(4):
                    acc2 += poses[i, k, l] * tip_inv[l, b]
                pt[k, b] = acc2
        for a in range(3):
            for b in range(4):
                acc = 0.0
                for k in range(4):
                    acc += pre[a, k] * pt[k, b]
                tt[a, b] = acc
        tr = tt[:, :3]
        _mul(tr, c6v, w)
        for a in range(3):
            w[a] += tt[a, 3]
        pa, pb = _dot(perp, w), _dot(cr, w)
        r1 = np.sqrt(pa * pa + pb * pb)
        x1, sd = _half(kk - _dot(par, w), r1)
        if np.isnan(sd):
            continue
        ca, sa = pa / r1, pb / r1
        _mul(tr, f1, trf1)
        _mul(tr, f2, trf2)
        _mul(tr, a6, z6)
        for i1 in range(2):
            sd1 = sd if i1 == 0 else -sd
            c1, s1 = ca * x1 - sa * sd1, sa * x1 + ca * sd1
            q1 = _limit(np.arctan2(s1, c1), lower[0], upper[0])
            if np.isnan(q1):
                continue
            nw0, nw1, nw2 = par[0] + perp[0] * c1 + cr[0] * s1, par[1] + perp[1] * c1 + cr[1] * s1, \
                par[2] + perp[2] * c1 + cr[2] * s1
            x5, sd5 = _half(nw0 * z6[0] + nw1 * z6[1] + nw2 * z6[2] - m5c, m5r)
            if np.isnan(sd5):
                continue
            d5 = np.arctan2(sd5, x5)
            n6x = nw0 * trf1[0] + nw1 * trf1[1] + nw2 * trf1[2]  # n seen from the tool, on the plane across axis 6
            n6y = nw0 * trf2[0] + nw1 * trf2[1] + nw2 * trf2[2]
            for a in range(3):  # r2^T R1(q1)^T, then through the tool's rotation
                for b in range(3):
                    m1[a, b] = q1a[a, b] * c1 + q1b[a, b] * s1 + q1c[a, b]
            for a in range(3):
                for b in range(3):
                    nn[a, b] = m1[a, 0] * tr[0, b] + m1[a, 1] * tr[1, b] + m1[a, 2] * tr[2, b]
                b1[a] = m1[a, 0] * tt[0, 3] + m1[a, 1] * tt[1, 3] + m1[a, 2] * tt[2, 3] - r2t2[a]
            _mul_t(nn, ex, nex)
            _mul_t(nn, ey, ney)
            for i5 in range(2):
                sgn5 = 1.0 if i5 == 0 else -1.0
                c5, s5 = _root(c5p, s5p, x5, sd5, i5)
                q5 = _limit(_turn(p5 + sgn5 * d5), lower[4], upper[4])
                if np.isnan(q5):
                    continue
                # 3. q6 turns n seen from the tool onto n seen from joint 5
                vx = v6[0, 0] * c5 + v6[1, 0] * s5 + v6[2, 0]
                vy = v6[0, 1] * c5 + v6[1, 1] * s5 + v6[2, 1]
                yy, xx = n6x * vy - n6y * vx, n6x * vx + n6y * vy
                hh = np.sqrt(xx * xx + yy * yy)
                if not hh > 0.0:  # zero (a singular axis: any angle, 0 chosen) or NaN (no solution upstream)
                    c6, s6, q6 = 1.0, yy, np.arctan2(yy, 1.0)
                else:
                    c6, s6, q6 = xx / hh, yy / hh, np.arctan2(yy, xx)
                q6 = _limit(q6, lower[5], upper[5])
                if np.isnan(q6):
                    continue
                # 4. joint 4's origin x2 in joint 2's frame, and its reference direction's angle at q2 = q3 = 0
                for a in range(3):
                    tmp[a] = vg[0, a] * c5 + vg[1, a] * s5 + vg[2, a]
                _rot(a6, c6, s6, tmp, True, ug)
                for a in range(3):
                    tmp[a] = vd[0, a] * c5 + vd[1, a] * s5 + vd[2, a]
                _rot(a6, c6, s6, tmp, True, ud)
                for a in range(3):
                    x2[a] = b1[a] - (nn[a, 0] * ug[0] + nn[a, 1] * ug[1] + nn[a, 2] * ug[2])
                x3, sd3 = _half(0.5 * (x2[0] * x2[0] + x2[1] * x2[1] + x2[2] * x2[2]) - e3c, e3r)
                if np.isnan(sd3):
                    continue
                d3 = np.arctan2(sd3, x3)
                q40 = _angle(_dot(ney, ud), _dot(nex, ud))
                xe1, xe2 = _dot(e1, x2), _dot(e2, x2)
                for i3 in range(2):
                    sgn3 = 1.0 if i3 == 0 else -1.0
                    c3, s3 = _root(c3p, s3p, x3, sd3, i3)
                    q3 = _limit(_turn(p3 + sgn3 * d3), lower[2], upper[2])
                    if np.isnan(q3):
                        continue
                    ux = u3[0, 0] * c3 + u3[1, 0] * s3 + u3[2, 0]
                    uy = u3[0, 1] * c3 + u3[1, 1] * s3 + u3[2, 1]
                    q2 = _limit(_angle(ux * xe2 - uy * xe1, ux * xe1 + uy * xe2), lower[1], upper[1])
                    if np.isnan(q2):
                        continue
                    q4 = q40 - tau * (q3 + sg * q2)
                    q4 = _limit(q4 - TWO_PI * np.rint(q4 / TWO_PI), lower[3], upper[3])
                    if np.isnan(q4):
                        continue
                    col = 4 * i1 + 2 * i5 + i3
                    out_q[i, col, 0], out_q[i, col, 1], out_q[i, col, 2] = q1, q2, q3
                    out_q[i, col, 3], out_q[i, col, 4], out_q[i, col, 5] = q4, q5, q6
                    out_valid[i, col] = True


@njit(cache=True, nogil=True)
def branch_order(joints, valid, ref, lower, upper, wrap, dist, rank):
    """`analytic.branch_distances` and a stable argsort of its distances in one pass: with `wrap`, joints (M, B, n)
    moved in place by whole turns toward ref (M, n) where that stays within the limits; dist (M, B) their L1
    distances to ref (inf where not valid), rank (M, B) the branches nearest first (ties in branch order)."""
    m, nb, n = joints.shape
    for i in range(m):
        for b in range(nb):
            if not valid[i, b]:
                dist[i, b] = np.inf
                continue
            d = 0.0
            for j in range(n):
                x = joints[i, b, j]
                if wrap:
                    alt = x + TWO_PI * np.rint((ref[i, j] - x) / TWO_PI)
                    if alt >= lower[j] and alt <= upper[j]:
                        x = alt
                        joints[i, b, j] = x
                d += abs(x - ref[i, j])
            dist[i, b] = d
        # stable: the valid branches by distance (insertion sort among the few), then the others in branch order
        m_ = 0
        for b in range(nb):
            v = dist[i, b]
            if not v < np.inf:
                continue
            c = m_ - 1
            while c >= 0 and dist[i, rank[i, c]] > v:
                rank[i, c + 1] = rank[i, c]
                c -= 1
            rank[i, c + 1] = b
            m_ += 1
        for b in range(nb):
            if not dist[i, b] < np.inf:
                rank[i, m_] = b
                m_ += 1
