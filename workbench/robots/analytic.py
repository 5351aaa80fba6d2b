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

All 2 x 2 x 2 = 8 branches are computed for many poses at once by a compiled kernel (`robots._closedkernel`).
Branches without a real solution or outside the joint limits come back as NaN with `valid` False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.errors import RobotError
from workbench.robots._closedkernel import wrist_rows

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


BLOCK = 4096  # poses per compiled pass (bounds the temporaries of callers that solve millions of poses)


def reachable(ik: AnalyticIK, poses: np.ndarray, block: int = BLOCK) -> np.ndarray:
    """(N,) bool: whether any of the 8 branches of each TCP pose (N, 4, 4) is within the joint limits (Section 5.2:
    the grasp-placement table needs no joint values). Each pose stops at its first valid branch."""
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4))
    valid = np.zeros((len(poses), 8), dtype=bool)
    consts = _constants(ik)
    none = np.empty((1, 1, 1))
    cols = np.arange(6, dtype=np.int64)
    for s in range(0, len(poses), block):
        wrist_rows(poses[s:s + block], *consts, cols, -1, np.zeros(1), none, valid[s:s + block], True)
    return valid.any(axis=1)


def _constants(ik: AnalyticIK) -> tuple[np.ndarray, ...]:
    """`kernel_constants` of one solver, built once (kept on the frozen dataclass)."""
    consts = getattr(ik, "_kernel", None)
    if consts is None:
        consts = kernel_constants([ik])
        object.__setattr__(ik, "_kernel", consts)
    return consts


def solve(ik: AnalyticIK, poses: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """All 8 IK branches of TCP poses (N, 4, 4) in the world: joints (N, 8, 6) and valid (N, 8).

    Branch index bits: 4 = elbow (q3 root), 2 = shoulder (q2 root), 1 = wrist flip (q5 root). Section 5.2."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    q = np.empty((len(poses), 8, 6))
    valid = np.empty((len(poses), 8), dtype=bool)
    solve_into(_constants(ik), poses, q, valid, block=block)
    return q, valid


def kernel_constants(iks: list[AnalyticIK]) -> tuple[np.ndarray, ...]:
    """The compiled kernel's constants of one or more forms, stacked on a leading axis (`_closedkernel.wrist_rows`)."""
    parts: list[list[np.ndarray]] = [[] for _ in range(21)]
    for ik in iks:
        b, t, m1i = ik.base_inv, ik.tip_inv, ik.m1_inv
        (r2, p2), (r3, p3), (r4, _), _, _ = ik.m
        a1, a2, a3 = ik.axes[0], ik.axes[1], ik.axes[2]
        mb = m1i @ b
        g = r3.T @ (p3 - ik.o2)
        wpar = a3 * (a3 @ ik.w3)
        c0 = (p3 - ik.o2) @ (p3 - ik.o2) + ik.w3 @ ik.w3 + 2 * g @ wpar
        wa, wb, wc = ik.wrist_a, ik.wrist_b, ik.wrist_c
        cpar = wb * (wb @ wc)
        consts = np.array([2 * g @ (ik.w3 - wpar), 2 * g @ np.cross(a3, ik.w3), c0, a1 @ p2,
                           wa @ (wc - cpar), wa @ np.cross(wb, wc), wa @ cpar])
        vals = (mb, t[:3, :3] @ ik.c6 + t[:3, 3], m1i[:3, :3] @ b[:3, :3], t[:3, :3] @ ik.wrist_at @ wc,
                t[:3, :3] @ ik.wrist_at @ ik.wrist_d, ik.o, ik.axes, r2, p2, r3, p3, r4, ik.w3, r2.T @ a1, wa, wb, wc,
                ik.wrist_d, consts, ik.lower, ik.upper)
        for part, val in zip(parts, vals):
            part.append(np.asarray(val, dtype=np.float64))
    return tuple(np.ascontiguousarray(np.stack(p)) for p in parts)


def solve_into(consts: tuple[np.ndarray, ...], poses: np.ndarray, q: np.ndarray, valid: np.ndarray,
               cols: tuple[int, ...] = tuple(range(6)), fixed_col: int = -1, fixed: np.ndarray | None = None,
               block: int = BLOCK, use: np.ndarray | None = None) -> None:
    """The 8 branches of each of S forms (`kernel_constants`; form s in branches 8 s .. 8 s + 7) of poses (N, 4, 4),
    written into q (N, 8 S, n) at joint columns `cols` (and `fixed[s]` at `fixed_col`, a 7-joint arm's held joint)
    and valid (N, 8 S), by the compiled kernel; with `use` (N, S), only the forms it marks (the others void)."""
    fixed = np.zeros(len(consts[0])) if fixed is None else np.ascontiguousarray(fixed, dtype=np.float64)
    cols_a = np.asarray(cols, dtype=np.int64)
    poses = np.ascontiguousarray(poses, dtype=np.float64)
    use = np.ones((0, 0), dtype=bool) if use is None else np.ascontiguousarray(use, dtype=bool)
    for s in range(0, len(poses), block):
        wrist_rows(poses[s:s + block], *consts, cols_a, fixed_col, fixed, q[s:s + block], valid[s:s + block], False,
                   use[s:s + block] if len(use) else use)


def whole_turns(joints: np.ndarray, q_ref: np.ndarray, lower: np.ndarray, upper: np.ndarray,
                revolute: np.ndarray | None = None) -> np.ndarray:
    """`joints` (..., n) with each joint that spans more than a turn moved by whole turns toward `q_ref` (broadcast
    to them) where that stays within the limits: the same arm pose, the equivalent angles nearest the reference.
    `revolute` (n,) marks the joints that turn (default all; a prismatic joint's metres are left as they are)."""
    lower, upper = np.asarray(lower, dtype=np.float64), np.asarray(upper, dtype=np.float64)
    turns = upper - lower > 2 * np.pi
    if revolute is not None:
        turns &= np.asarray(revolute, dtype=bool)
    if not turns.any():
        return joints
    with np.errstate(invalid="ignore"):  # NaN rows (no solution) stay NaN
        alt = joints + 2 * np.pi * np.round((q_ref - joints) / (2 * np.pi))
        return np.where(turns & (alt >= lower) & (alt <= upper), alt, joints)


def branch_distances(joints: np.ndarray, valid: np.ndarray, q_ref: np.ndarray, lower: np.ndarray | None = None,
                     upper: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Branches (N, B, n) moved by whole turns toward `q_ref` ((n,) or (N, n)) where that stays within the limits
    (a joint spanning more than a turn), and their L1 distances to it (N, B), inf where not valid."""
    ref = np.asarray(q_ref, dtype=np.float64)
    ref = np.broadcast_to(ref[:, None] if ref.ndim == 2 else ref, joints.shape)
    if lower is not None and upper is not None:
        joints = whole_turns(joints, ref, lower, upper)
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
