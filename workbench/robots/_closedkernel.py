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
    out[0], out[1] = ca * x - sa * sd, sa * x + ca * sd
    out[2], out[3] = ca * x + sa * sd, sa * x - ca * sd


@njit(cache=True, inline="always")
def _sub1(k, u, v):
    """(cos, sin, angle) of the rotation taking u onto v about the unit axis k (Paden-Kahan subproblem 1)."""
    ku = k[0] * u[0] + k[1] * u[1] + k[2] * u[2]
    kv = k[0] * v[0] + k[1] * v[1] + k[2] * v[2]
    u0, u1, u2 = u[0] - k[0] * ku, u[1] - k[1] * ku, u[2] - k[2] * ku
    v0, v1, v2 = v[0] - k[0] * kv, v[1] - k[1] * kv, v[2] - k[2] * kv
    y = k[0] * (u1 * v2 - u2 * v1) + k[1] * (u2 * v0 - u0 * v2) + k[2] * (u0 * v1 - u1 * v0)
    x = u0 * v0 + u1 * v1 + u2 * v2
    h = np.sqrt(x * x + y * y)
    if not h > 0.0:  # zero (a singular axis: any angle, 0 chosen) or NaN (no solution upstream)
        return 1.0, y, np.arctan2(y, 1.0)
    return x / h, y / h, np.arctan2(y, x)


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


@njit(cache=True, inline="always")
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
    """`_sub1` without its arctangent: (cos, sin, y, x) with the angle arctan2(y, x), computed only where needed."""
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
                if i3 == 0:
                    c3, s3 = eca[f] * xe - esa[f] * sde, esa[f] * xe + eca[f] * sde
                else:
                    c3, s3 = eca[f] * xe + esa[f] * sde, esa[f] * xe - eca[f] * sde
                d3 = _inside(c3, s3, cm[f, 2], sm[f, 2], thr_in[f, 2])
                if d3:
                    qb[2] = 0.0
                elif _out(c3, s3, cm[f, 2], sm[f, 2], thr[f, 2]):
                    qb[2] = np.nan
                else:
                    qb[2] = _limit(np.arctan2(s3, c3), lower[f, 2], upper[f, 2])
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
                    if i2 == 0:
                        c2, s2 = sca * xs - ssa * sds, ssa * xs + sca * sds
                    else:
                        c2, s2 = sca * xs + ssa * sds, ssa * xs - sca * sds
                    d2 = _inside(c2, s2, cm[f, 1], sm[f, 1], thr_in[f, 1])
                    if d2:
                        qb[1] = 0.0
                    elif _out(c2, s2, cm[f, 1], sm[f, 1], thr[f, 1]):
                        qb[1] = np.nan
                    else:
                        qb[1] = _limit(np.arctan2(s2, c2), lower[f, 1], upper[f, 1])
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
                    d1 = _inside(c1, s1, cm[f, 0], sm[f, 0], thr_in[f, 0])
                    if d1:
                        qb[0] = 0.0
                    elif _out(c1, s1, cm[f, 0], sm[f, 0], thr[f, 0]):
                        qb[0] = np.nan
                    else:
                        qb[0] = _limit(np.arctan2(y1, x1_), lower[f, 0], upper[f, 0])
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
                        if i5 == 0:
                            c5, s5 = ca5 * x5 - sa5 * sd5, sa5 * x5 + ca5 * sd5
                        else:
                            c5, s5 = ca5 * x5 + sa5 * sd5, sa5 * x5 - ca5 * sd5
                        # a joint out of reach or out of its limits voids the branch: the later ones are not solved
                        d5 = _inside(c5, s5, cm[f, 4], sm[f, 4], thr_in[f, 4])
                        if d5:
                            qb[4] = 0.0
                        elif _out(c5, s5, cm[f, 4], sm[f, 4], thr[f, 4]):
                            qb[4] = np.nan
                        else:
                            qb[4] = _limit(np.arctan2(s5, c5), lower[f, 4], upper[f, 4])
                        if np.isnan(qb[4]):
                            if not any_only:
                                _void(out_q, out_valid, i, col, 1, cols, fixed_col, fixed[f], full_rows)
                            continue
                        _rot(wb[f], c5, s5, wc[f], False, u)
                        c4, s4, y4, x4 = _sub1_parts(wa[f], u, yc)
                        d4 = _inside(c4, s4, cm[f, 3], sm[f, 3], thr_in[f, 3])
                        if d4:
                            qb[3] = 0.0
                        elif _out(c4, s4, cm[f, 3], sm[f, 3], thr[f, 3]):
                            qb[3] = np.nan
                        else:
                            qb[3] = _limit(np.arctan2(y4, x4), lower[f, 3], upper[f, 3])
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


@njit(cache=True, nogil=True)
def parallel_rows(poses, pre, tip_inv, rm, tm, ax, n1, kk, c6v, n5, d4, lower, upper, out_q, out_valid):
    """Three-parallel-axes IK (`parallel`'s module docstring, the UR family) of poses (N, 4, 4): 8 branches
    (4 shoulder + 2 wrist + elbow) into out_q (N, 8, 6) and out_valid (N, 8). rm, tm: placements of joints 2..6."""
    n = poses.shape[0]
    a1, a2, a3, a4, a5, a6 = ax[0], ax[1], ax[2], ax[3], ax[4], ax[5]
    r2, r3, r4, r5, r6 = rm[0], rm[1], rm[2], rm[3], rm[4]
    t2, t3, t4, t5, t6 = tm[0], tm[1], tm[2], tm[3], tm[4]
    # constants of the four steps
    par = a1 * (a1[0] * n1[0] + a1[1] * n1[1] + a1[2] * n1[2])
    perp = n1 - par
    cr = np.cross(a1, n1)
    c = r6 @ a6
    cpar = a5 * (a5 @ c)
    m5a, m5b, m5c = n5 @ (c - cpar), n5 @ np.cross(a5, c), n5 @ cpar
    g5 = r5.T @ t5
    gd = r5.T @ d4
    g = r3.T @ t3
    t4par = a3 * (a3 @ t4)
    e3a, e3b, e3c = g @ (t4 - t4par), g @ np.cross(a3, t4), 0.5 * (t3 @ t3 + t4 @ t4) + g @ t4par
    tt = np.empty((4, 4))
    w = np.empty(3)
    nw = np.empty(3)
    n6 = np.empty(3)
    v6 = np.empty(3)
    tmp = np.empty(3)
    u = np.empty(3)
    p4 = np.empty(3)
    x2 = np.empty(3)
    y = np.empty(3)
    s1r = np.empty(4)
    s5r = np.empty(4)
    s3r = np.empty(4)
    qb = np.empty(6)
    pt = np.empty((4, 4))
    for i in range(n):
        for k in range(4):  # joint-6 frame in joint 1's parent frame: pre (P tip^-1)
            for b in range(4):
                acc2 = 0.0
                for l in range(4):
                    acc2 += poses[i, k, l] * tip_inv[l, b]
                pt[k, b] = acc2
        for a in range(4):
            for b in range(4):
                acc = 0.0
                for k in range(4):
                    acc += pre[a, k] * pt[k, b]
                tt[a, b] = acc
        tr = tt[:3, :3]
        _mul(tr, c6v, w)
        for a in range(3):
            w[a] += tt[a, 3]
        # 1. shoulder: n(q1) . W = K
        _acs(_dot(perp, w), _dot(cr, w), kk - _dot(par, w), s1r)
        for i1 in range(2):
            c1, s1 = s1r[2 * i1], s1r[2 * i1 + 1]
            qb[0] = _limit(np.arctan2(s1, c1), lower[0], upper[0])
            for a in range(3):
                nw[a] = par[a] + perp[a] * c1 + cr[a] * s1
            # 2. wrist: n . R5(q5) c = n . z6
            sz = nw[0] * (tr[0, 0] * a6[0] + tr[0, 1] * a6[1] + tr[0, 2] * a6[2]) \
                + nw[1] * (tr[1, 0] * a6[0] + tr[1, 1] * a6[1] + tr[1, 2] * a6[2]) \
                + nw[2] * (tr[2, 0] * a6[0] + tr[2, 1] * a6[1] + tr[2, 2] * a6[2])
            _acs(m5a, m5b, sz - m5c, s5r)
            _mul_t(tr, nw, n6)
            for i5 in range(2):
                c5, s5 = s5r[2 * i5], s5r[2 * i5 + 1]
                qb[4] = _limit(np.arctan2(s5, c5), lower[4], upper[4])
                qb[5] = np.nan
                # 3. q6 turns n seen from the tool onto n seen from joint 5
                _rot(a5, c5, s5, n5, True, tmp)
                _mul_t(r6, tmp, v6)
                c6, s6, q6 = _sub1(a6, n6, v6)
                qb[5] = _limit(q6, lower[5], upper[5])
                # 4. joint 4's origin T_t - T_R G_R^T G_t
                _rot(a5, c5, s5, g5, True, tmp)
                for a in range(3):
                    tmp[a] += t6[a]
                _mul_t(r6, tmp, u)
                _rot(a6, c6, s6, u, True, tmp)
                _mul(tr, tmp, u)
                for a in range(3):
                    p4[a] = tt[a, 3] - u[a]
                _rot(a1, c1, s1, p4, True, tmp)
                for a in range(3):
                    tmp[a] -= t2[a]
                _mul_t(r2, tmp, x2)
                _acs(e3a, e3b, 0.5 * (x2[0] * x2[0] + x2[1] * x2[1] + x2[2] * x2[2]) - e3c, s3r)
                # R4's reference direction through the known frames (shared by both elbows up to q2, q3)
                _rot(a5, c5, s5, gd, True, tmp)
                _mul_t(r6, tmp, u)
                _rot(a6, c6, s6, u, True, tmp)
                _mul(tr, tmp, u)
                _rot(a1, c1, s1, u, True, tmp)
                _mul_t(r2, tmp, y)
                for i3 in range(2):
                    c3, s3 = s3r[2 * i3], s3r[2 * i3 + 1]
                    _rot(a3, c3, s3, t4, False, tmp)
                    _mul(r3, tmp, u)
                    for a in range(3):
                        u[a] += t3[a]
                    c2, s2, q2 = _sub1(a2, u, x2)
                    _rot(a2, c2, s2, y, True, tmp)
                    _mul_t(r3, tmp, u)
                    _rot(a3, c3, s3, u, True, tmp)
                    _mul_t(r4, tmp, u)
                    qb[1] = _limit(q2, lower[1], upper[1])
                    qb[2] = _limit(np.arctan2(s3, c3), lower[2], upper[2])
                    qb[3] = _limit(_sub1(a4, d4, u)[2], lower[3], upper[3])
                    col = 4 * i1 + 2 * i5 + i3
                    ok = True
                    for j in range(6):
                        out_q[i, col, j] = qb[j]
                        ok = ok and not np.isnan(qb[j])
                    out_valid[i, col] = ok


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
        for b in range(nb):  # insertion sort: stable, and few branches per pose are valid
            rank[i, b] = b
        for b in range(1, nb):
            k = rank[i, b]
            v = dist[i, k]
            c = b - 1
            while c >= 0 and dist[i, rank[i, c]] > v:
                rank[i, c + 1] = rank[i, c]
                c -= 1
            rank[i, c + 1] = k
