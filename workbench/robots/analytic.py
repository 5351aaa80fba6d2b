"""Closed-form inverse kinematics of 6R arms with a spherical wrist (Tournassoud, Lozano-Perez & Mazer 1987,
Section 5.2: the last three axes intersect, so joints 1-3 follow from the wrist point, joints 4-6 from the
orientation).

The solver is read off the pinocchio model of any `Robot` (no DH table needed). It applies when

- the arm has six revolute joints;
- axes 4, 5 and 6 meet in one point, the wrist centre W (a spherical wrist);
- axes 1 and 2 meet in one point O (a PUMA-like shoulder, as in the PUMA 560, KUKA, ABB and Staubli arms).

Then (Pieper's decoupling, solved with Paden-Kahan subproblems):

1. |W - O| does not depend on q1, q2: one equation A cos q3 + B sin q3 = C, two solutions (elbow);
2. W's height along axis 1 does not depend on q1: A cos q2 + B sin q2 = C, two solutions (shoulder);
3. q1 rotates the resulting point onto W about axis 1 (one solution);
4. with c the wrist's last axis: a4 . R5(q5) c = a4 . Y c gives two q5 (wrist flip); q4 and q6 are single rotations.

All 2 x 2 x 2 = 8 branches are computed for many poses at once with numpy (struct-of-arrays, no per-pose loop).
Branches without a real solution or outside the joint limits come back as NaN with `valid` False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.errors import RobotError

TOL_AXES = 1e-9  # metres: how close lines must pass to count as intersecting


@dataclass(frozen=True)
class Chain:
    """A 6R (or 6-joint) serial chain as the closed forms read it, with a `Robot`'s attribute names: joint k's
    placement in its parent joint's frame (`chain_placement`, (n, 4, 4)), its axis in its own frame, the root's pose
    in the world (`base`) and the TCP in the last joint's frame (`tip_in_joint`). `reversed_chain` turns it around;
    `sub_chain` fixes trailing joints."""

    name: str
    chain_placement: np.ndarray
    chain_axis: np.ndarray
    base: np.ndarray
    tip_in_joint: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    joint_names: tuple[str, ...]

    @property
    def nq(self) -> int:
        return len(self.chain_axis)

    @property
    def chain_prismatic(self) -> np.ndarray:
        return np.zeros(self.nq, dtype=bool)


def chain_of(robot) -> Chain:
    """The chain of a revolute-only `Robot` (RobotError when a joint is prismatic)."""
    if robot.chain_prismatic.any():
        raise RobotError(f"robot {robot.name!r} has prismatic joints; the closed forms are for revolute arms")
    return Chain(robot.name, robot.chain_placement.copy(), robot.chain_axis.copy(), robot.base.copy(),
                 robot.tip_in_joint.copy(), robot.lower.copy(), robot.upper.copy(), tuple(robot.joint_names))


def sub_chain(chain: Chain, fixed: dict[int, float]) -> Chain:
    """`chain` with the joints of `fixed` (0-based index -> angle) held: a held joint's rotation folds into the next
    joint's placement (into the base for the first joint, into the tip for the last)."""
    pl, keep = list(chain.chain_placement), [k for k in range(chain.nq) if k not in fixed]
    base, tip, placements, pending = chain.base, chain.tip_in_joint, [], np.eye(4)
    for k in range(chain.nq):
        if k in fixed:
            rot = np.eye(4)
            rot[:3, :3] = _rotation(chain.chain_axis[k], fixed[k])
            pending = pending @ pl[k] @ rot
            continue
        if not placements:  # the first kept joint: what came before belongs to the base
            base, pending = base @ pending, np.eye(4)
        placements.append(pending @ pl[k])
        pending = np.eye(4)
    return Chain(chain.name, np.stack(placements), chain.chain_axis[keep].copy(), base, pending @ tip,
                 chain.lower[keep].copy(), chain.upper[keep].copy(), tuple(chain.joint_names[k] for k in keep))


def reversed_chain(chain: Chain) -> Chain:
    """The chain run from the TCP to the root: for the pose P of the TCP, the root's pose in the TCP frame is
    T^-1 M6^-1 R6(q6)^-1 ... M1^-1 with base^-1 P = M1 R1(q1) ... M6 R6(q6) T; joint k of the result is joint
    n + 1 - k about the negated axis (the same angle and limits). Its TCP pose is `reverse_poses` of the original's."""
    inv = np.linalg.inv
    pl = chain.chain_placement
    n = len(pl)
    placements = [inv(chain.tip_in_joint)] + [inv(pl[k]) for k in range(n - 1, 0, -1)]
    return Chain(chain.name + " (reversed)", np.stack(placements), -chain.chain_axis[::-1].copy(), np.eye(4),
                 inv(pl[0]), chain.lower[::-1].copy(), chain.upper[::-1].copy(), chain.joint_names[::-1])


def reverse_poses(chain: Chain, poses: np.ndarray) -> np.ndarray:
    """The TCP poses of `reversed_chain(chain)` for TCP poses (N, 4, 4) of `chain`: (base^-1 P)^-1."""
    rel = np.linalg.inv(chain.base) @ poses
    out = np.empty_like(rel)
    rt = rel[:, :3, :3].transpose(0, 2, 1)
    out[:, :3, :3] = rt
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rt, rel[:, :3, 3])
    out[:, 3] = (0.0, 0.0, 0.0, 1.0)
    return out


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=np.float64)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@dataclass(frozen=True)
class AnalyticIK:
    """Constants of the closed form for one robot (see the module docstring); build with `analytic_ik(robot)`."""

    base_inv: np.ndarray      # world -> robot root
    tip_inv: np.ndarray       # TCP -> joint-6 frame
    m1_inv: np.ndarray        # root -> joint-1 parent placement removed
    m: tuple                  # (R, t) placements of joints 2..6 in their parent joint's frame
    axes: np.ndarray          # (6, 3) joint axes in their own frames
    o: np.ndarray             # intersection of axes 1 and 2, joint-1 frame
    o2: np.ndarray            # the same point in joint-2 frame
    w3: np.ndarray            # wrist centre in joint-3 frame
    c6: np.ndarray            # wrist centre in joint-6 frame
    wrist_a: np.ndarray       # axes 4, 5, 6 expressed in joint-4 frame at q = 0
    wrist_b: np.ndarray
    wrist_c: np.ndarray
    wrist_d: np.ndarray       # a unit vector orthogonal to wrist_c
    wrist_at: np.ndarray      # (R5 R6)^T: maps joint-6 frame vectors to joint-4 frame at q5 = q6 = 0
    lower: np.ndarray
    upper: np.ndarray
    joint_names: tuple[str, ...]


def _closest(p: np.ndarray, u: np.ndarray, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float]:
    """Midpoint of the closest points of lines p + s u and q + t v, and their distance (inf if parallel)."""
    w = p - q
    a, b, c, d, e = u @ u, u @ v, v @ v, u @ w, v @ w
    den = a * c - b * b
    if den < 1e-12:
        return p, float("inf")
    s, t = (b * e - c * d) / den, (a * e - b * d) / den
    x, y = p + s * u, q + t * v
    return (x + y) / 2, float(np.linalg.norm(x - y))


def _dist_line(x: np.ndarray, p: np.ndarray, u: np.ndarray) -> float:
    r = x - p
    return float(np.linalg.norm(r - (r @ u) * u))


def spherical_wrist_reason(robot) -> str:
    """Why the closed form does not apply to `robot` ('' when it does)."""
    if robot.nq != 6:
        return f"it has {robot.nq} joints, not 6"
    if robot.chain_prismatic.any():
        return "it has prismatic joints"
    pl, ax = robot.chain_placement, robot.chain_axis
    # axes 4, 5, 6 in joint-4 frame
    m5, m6 = pl[4], pl[5]
    a4, p4 = ax[3], np.zeros(3)
    a5, p5 = m5[:3, :3] @ ax[4], m5[:3, 3]
    m56 = m5 @ m6
    a6, p6 = m56[:3, :3] @ ax[5], m56[:3, 3]
    w, d45 = _closest(p4, a4, p5, a5)
    if d45 > TOL_AXES or _dist_line(w, p6, a6) > TOL_AXES:
        return "its last three axes do not meet in one point (no spherical wrist)"
    m2 = pl[1]
    _, d12 = _closest(np.zeros(3), ax[0], m2[:3, 3], m2[:3, :3] @ ax[1])
    if d12 > TOL_AXES:
        return "its first two axes do not intersect"
    return ""


def analytic_ik(robot, limits: bool = True) -> AnalyticIK:
    """The closed-form solver of `robot` (Section 5.2), or a RobotError saying why it has none.

    `limits=False` keeps every branch regardless of the joint limits (angles then in (-pi, pi])."""
    why = spherical_wrist_reason(robot)
    if why:
        raise RobotError(f"robot {robot.name!r} has no closed-form IK: {why}; use the numerical IK (ik_feasibility)")
    pl, ax = robot.chain_placement, robot.chain_axis
    m2 = pl[1]
    o, _ = _closest(np.zeros(3), ax[0], m2[:3, 3], m2[:3, :3] @ ax[1])
    inv = np.linalg.inv
    o2 = (inv(m2) @ np.append(o, 1))[:3]
    m5, m6 = pl[4], pl[5]
    w4, _ = _closest(np.zeros(3), ax[3], m5[:3, 3], m5[:3, :3] @ ax[4])
    w3 = (pl[3] @ np.append(w4, 1))[:3]
    c6 = (inv(m5 @ m6) @ np.append(w4, 1))[:3]
    r56 = m5[:3, :3] @ m6[:3, :3]
    a, b, c = ax[3], m5[:3, :3] @ ax[4], r56 @ ax[5]
    d = np.cross(c, [1.0, 0, 0]) if abs(c[0]) < 0.9 else np.cross(c, [0, 1.0, 0])
    d /= np.linalg.norm(d)
    big = np.full(6, np.inf)
    return AnalyticIK(base_inv=inv(robot.base), tip_inv=inv(robot.tip_in_joint), m1_inv=inv(pl[0]),
                      m=tuple((pl[k][:3, :3].copy(), pl[k][:3, 3].copy()) for k in range(1, 6)), axes=ax.copy(),
                      o=o, o2=o2, w3=w3, c6=c6, wrist_a=a, wrist_b=b, wrist_c=c, wrist_d=d, wrist_at=r56.T,
                      lower=robot.lower.copy() if limits else -big, upper=robot.upper.copy() if limits else big,
                      joint_names=tuple(robot.joint_names))


# -- vector helpers, struct of arrays: vectors (3, N) ---------------------------------------------------------------


def _axis(k: np.ndarray) -> tuple[int, float] | None:
    """(index, sign) when the unit vector k is a coordinate axis, else None (the fast paths below)."""
    m = int(np.argmax(np.abs(k)))
    return (m, float(np.sign(k[m]))) if abs(abs(k[m]) - 1.0) < 1e-15 else None


_NEXT = ((1, 2), (2, 0), (0, 1))  # the two other coordinates, cyclic


def _rot(k: np.ndarray, c: np.ndarray, s: np.ndarray, v: np.ndarray, inverse: bool = False) -> np.ndarray:
    """Rotate vectors v (3, N) about the constant unit axis k by angles with cosines c and sines s (Rodrigues);
    `inverse` rotates by minus those angles (no negated copy of s)."""
    ax = _axis(k)
    if ax is not None:
        m, sg = ax
        i, j = _NEXT[m]
        out = np.empty(np.broadcast_shapes(v.shape, (3,) + np.shape(c)))
        np.multiply(v[i], c, out=out[i])
        np.multiply(v[j], c, out=out[j])
        if (sg > 0) != inverse:
            out[i] -= v[j] * s
            out[j] += v[i] * s
        else:
            out[i] += v[j] * s
            out[j] -= v[i] * s
        out[m] = v[m]
        return out
    if inverse:
        s = -s
    kv = (k[0] * v[0] + k[1] * v[1] + k[2] * v[2]) * (1 - c)
    return np.stack((v[0] * c + (k[1] * v[2] - k[2] * v[1]) * s + k[0] * kv,
                     v[1] * c + (k[2] * v[0] - k[0] * v[2]) * s + k[1] * kv,
                     v[2] * c + (k[0] * v[1] - k[1] * v[0]) * s + k[2] * kv))


def _lin(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Constant 3x3 matrix times vectors (3, N); zero entries skipped, unit entries not multiplied (DH-like frames)."""
    rows = []
    for i in range(3):
        acc = None
        for j in range(3):
            c = float(r[i, j])
            if abs(c) < 1e-15:
                continue
            term = v[j] if abs(c - 1) < 1e-15 else (-v[j] if abs(c + 1) < 1e-15 else c * v[j])
            acc = term if acc is None else acc + term
        rows.append(np.zeros_like(v[0]) if acc is None else acc)
    return np.stack(rows)


def _dot(k: np.ndarray, v: np.ndarray) -> np.ndarray:
    ax = _axis(k)
    if ax is not None:
        return v[ax[0]] * ax[1]
    return k[0] * v[0] + k[1] * v[1] + k[2] * v[2]


def _acs(a, b, c) -> tuple[np.ndarray, np.ndarray]:
    """Both solutions x of a cos x + b sin x = c as (cos x, sin x), each (2, N) (NaN where there is none)."""
    r2 = a * a + b * b
    x = c / np.sqrt(r2)
    x = np.where(np.abs(x) <= 1 + 1e-10, np.clip(x, -1, 1), np.nan)
    sd = np.sqrt(1 - x * x)
    ca, sa = a / np.sqrt(r2), b / np.sqrt(r2)
    # x = phi +/- delta with cos phi = ca, sin phi = sa, cos delta = x, sin delta = sd
    cs = np.stack((ca * x - sa * sd, ca * x + sa * sd))
    sn = np.stack((sa * x + ca * sd, sa * x - ca * sd))
    return cs, sn


def _sub1(k: np.ndarray, u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(cos, sin) of the angle rotating u onto v about the constant unit axis k (Paden-Kahan subproblem 1)."""
    ax = _axis(k)
    if ax is not None:
        m, sg = ax
        i, j = _NEXT[m]
        x = u[i] * v[i] + u[j] * v[j]
        y = (u[i] * v[j] - u[j] * v[i]) * sg
    else:
        ku, kv = _dot(k, u), _dot(k, v)
        up = u - np.multiply.outer(k, ku)
        vp = v - np.multiply.outer(k, kv)
        y = (k[0] * (up[1] * vp[2] - up[2] * vp[1]) + k[1] * (up[2] * vp[0] - up[0] * vp[2])
             + k[2] * (up[0] * vp[1] - up[1] * vp[0]))
        x = up[0] * vp[0] + up[1] * vp[1] + up[2] * vp[2]
    h = np.hypot(x, y)
    ok = h > 0
    h = np.where(ok, h, 1.0)
    return np.where(ok, x / h, 1.0), y / h


def _limit(q: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """q in (-pi, pi] moved by a multiple of 2 pi into [lo, hi] (the representative nearest to 0), NaN if none."""
    ok = (q >= lo) & (q <= hi)
    if ok.all() or not np.isfinite(lo) and not np.isfinite(hi):
        return q
    out = np.where(ok, q, np.nan)
    for shift in (-2 * np.pi, 2 * np.pi):
        alt = q + shift
        out = np.where(np.isnan(out) & (alt >= lo) & (alt <= hi), alt, out)
    return out


BLOCK = 4096  # poses per vectorised pass: its ~50 temporaries of 8 x BLOCK doubles stay in the CPU caches


def reachable(ik: AnalyticIK, poses: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """(N,) bool: whether any of the 8 branches of each TCP pose (N, 4, 4) is within the joint limits (Section 5.2:
    the grasp-placement table needs no joint values). Skips writing the joints and, when the last joint's range
    spans a full turn, its angle altogether."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    out = np.empty(len(poses), dtype=bool)
    for s in range(0, len(poses), block):
        out[s:s + block] = _solve_block(ik, poses[s:s + block], joints=False)[1].any(axis=1)
    return out


def solve(ik: AnalyticIK, poses: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """All 8 IK branches of TCP poses (N, 4, 4) in the world: joints (N, 8, 6) and valid (N, 8).

    Branch index bits: 4 = elbow (q3 root), 2 = shoulder (q2 root), 1 = wrist flip (q5 root). Section 5.2.
    Poses are solved `block` at a time into preallocated outputs (larger blocks spill the temporaries out of the
    caches and run slower)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    n = len(poses)
    if n <= block:
        return _solve_block(ik, poses)
    q = np.empty((n, 8, 6))
    valid = np.empty((n, 8), dtype=bool)
    for s in range(0, n, block):
        q[s:s + block], valid[s:s + block] = _solve_block(ik, poses[s:s + block])
    return q, valid


def _solve_block(ik: AnalyticIK, poses: np.ndarray, joints: bool = True) -> tuple[np.ndarray | None, np.ndarray]:
    """`solve` on one block of poses (N, 4, 4); without `joints`, only the validity (None, (N, 8))."""
    n = len(poses)
    # the joint-6 frame in the robot root is B P T (B = base^-1, P = pose, T = TCP -> joint 6); only its products
    # with constant vectors are needed: B P T u = B (P_R (T_R u) + P_t + P_R T_t) ...
    pr = poses[:, :3, :3].transpose(1, 2, 0)                 # (3, 3, N)
    b, t, m1i = ik.base_inv, ik.tip_inv, ik.m1_inv

    def rot6(u: np.ndarray) -> np.ndarray:
        """R6 u in the joint-1 parent frame with M1's rotation removed: M1_R^T B_R P_R T_R u."""
        k = t[:3, :3] @ u
        return _lin(m1i[:3, :3] @ b[:3, :3], pr[:, 0] * k[0] + pr[:, 1] * k[1] + pr[:, 2] * k[2])

    k = t[:3, :3] @ ik.c6 + t[:3, 3]
    w = pr[:, 0] * k[0] + pr[:, 1] * k[1] + pr[:, 2] * k[2] + poses[:, :3, 3].T
    mb = m1i @ b
    pw = _lin(mb[:3, :3], w) + mb[:3, 3][:, None]             # wrist centre before q1
    ax = ik.axes
    (r2, p2), (r3, p3), (r4, _), _, _ = ik.m
    a1, a2, a3 = ax[0], ax[1], ax[2]

    def col(x: np.ndarray) -> np.ndarray:
        """A constant vector (3,) or per-pose vectors (3, N) as (3, A, B, C, N|1) for broadcasting over the branch axes
        A (q3 root), B (q2 root), C (q5 root): scalars per branch are (A, B, C, N), vectors get a leading 3."""
        return x.reshape(3, 1, 1, 1, -1)

    # 1. elbow: |v(q3) - o2|^2 = |pw - o|^2 -> two q3
    rad2 = ((pw - ik.o[:, None]) ** 2).sum(0)
    g = r3.T @ (p3 - ik.o2)
    w3 = ik.w3
    wpar = a3 * (a3 @ w3)
    c0 = (p3 - ik.o2) @ (p3 - ik.o2) + w3 @ w3 + 2 * g @ wpar
    c3, s3 = _acs(2 * g @ (w3 - wpar), 2 * g @ np.cross(a3, w3), rad2 - c0)
    c3, s3 = c3[:, None, None, :], s3[:, None, None, :]                      # (2, 1, 1, N)
    v = _lin(r3, _rot(a3, c3, s3, col(w3))) + col(p3)
    # 2. shoulder: height of W along axis 1 -> two q2 per q3
    a1p = r2.T @ a1
    vpar = np.multiply.outer(a2, _dot(a2, v))
    vperp = v - vpar
    av = np.stack((a2[1] * v[2] - a2[2] * v[1], a2[2] * v[0] - a2[0] * v[2], a2[0] * v[1] - a2[1] * v[0]))
    h = _dot(a1, pw) - a1 @ p2
    c2, s2 = _acs(_dot(a1p, vperp), _dot(a1p, av), h - _dot(a1p, vpar))
    c2, s2 = c2[:, :, 0].swapaxes(0, 1), s2[:, :, 0].swapaxes(0, 1)          # (2, 2, 1, N)
    x = _lin(r2, vpar + vperp * c2 + av * s2) + col(p2)
    # 3. base: rotate x onto W about axis 1
    c1, s1 = _sub1(a1, x, col(pw))
    # 4. wrist: Y = R4^T R03^T R6 (R5 R6)^T; only Y c and Y d are needed
    wa, wb, wc, wd = ik.wrist_a, ik.wrist_b, ik.wrist_c, ik.wrist_d
    free6 = not joints and ik.upper[5] - ik.lower[5] >= 2 * np.pi
    ys = []
    for vec in ((wc,) if free6 else (wc, wd)):
        y = _rot(a1, c1, s1, col(rot6(ik.wrist_at @ vec)), inverse=True)
        y = _rot(a2, c2, s2, _lin(r2.T, y), inverse=True)
        ys.append(_lin(r4.T, _rot(a3, c3, s3, _lin(r3.T, y), inverse=True)))
    yc, yd = ys[0], (ys[1] if len(ys) > 1 else None)
    cpar = wb * (wb @ wc)
    c5, s5 = _acs(wa @ (wc - cpar), wa @ np.cross(wb, wc), _dot(wa, yc) - wa @ cpar)
    c5, s5 = np.moveaxis(c5[..., 0, :], 0, 2), np.moveaxis(s5[..., 0, :], 0, 2)  # (2, 2, 2, N)
    u = _rot(wb, c5, s5, col(wc))
    c4, s4 = _sub1(wa, u, yc)
    angles = [(s1, c1), (s2, c2), (s3, c3), (s4, c4), (s5, c5)]
    if not free6:
        tt = _rot(wb, c5, s5, _rot(wa, c4, s4, yd, inverse=True), inverse=True)
        c6, s6 = _sub1(wc, col(wd), tt)
        angles.append((s6, c6))
    if not joints:  # validity only: every computed joint within its limits (by whole turns), NaN fails
        ok = np.ones((2, 2, 2, n), dtype=bool)
        for j, (sj, cj) in enumerate(angles):
            a = np.arctan2(sj, cj)
            lo, hi = ik.lower[j], ik.upper[j]
            inside = (a >= lo) & (a <= hi)
            if lo < -np.pi or hi > np.pi:
                inside |= ((a + 2 * np.pi >= lo) & (a + 2 * np.pi <= hi)) | ((a - 2 * np.pi >= lo) & (a - 2 * np.pi <= hi))
            ok &= inside
        return None, ok.transpose(3, 0, 1, 2).reshape(n, 8)
    # each joint's angle on its own branch shape (q1, q2: 4 per pose, q3: 2, wrist: 8), written into the output's
    # (N, q3 root, q2 root, q5 root, joint) layout through a transposed view (no stacked or broadcast copies)
    q = np.empty((n, 2, 2, 2, 6))
    view = q.transpose(1, 2, 3, 0, 4)                                         # (2, 2, 2, N, 6)
    for j, (sj, cj) in enumerate(angles):
        view[..., j] = _limit(np.arctan2(sj, cj), ik.lower[j], ik.upper[j])
    q = q.reshape(n, 8, 6)
    valid = ~np.isnan(q).any(axis=2)
    return q, valid


def branch_distances(joints: np.ndarray, valid: np.ndarray, q_ref: np.ndarray, lower: np.ndarray | None = None,
                     upper: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Branches (N, B, n) moved by whole turns toward `q_ref` ((n,) or (N, n)) where that stays within the limits
    (a joint spanning more than a turn), and their L1 distances to it (N, B), inf where not valid."""
    ref = np.asarray(q_ref, dtype=np.float64)
    ref = np.broadcast_to(ref[:, None] if ref.ndim == 2 else ref, joints.shape)
    if lower is not None and upper is not None and (np.asarray(upper) - np.asarray(lower) > 2 * np.pi).any():
        alt = joints + 2 * np.pi * np.round((ref - joints) / (2 * np.pi))
        joints = np.where((alt >= lower) & (alt <= upper), alt, joints)
    with np.errstate(invalid="ignore"):  # NaN joints of invalid branches
        return joints, np.where(valid, np.abs(joints - ref).sum(axis=2), np.inf)


def nearest_branch(joints: np.ndarray, valid: np.ndarray, q_ref: np.ndarray, lower: np.ndarray | None = None,
                   upper: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per pose, the valid branch nearest to `q_ref` ((6,) or (N, 6)): joints (N, 6) and whether one exists (N,)
    (`branch_distances`)."""
    joints, dist = branch_distances(joints, valid, q_ref, lower, upper)
    k = np.argmin(dist, axis=1)
    rows = np.arange(len(joints))
    return joints[rows, k], np.isfinite(dist[rows, k])
