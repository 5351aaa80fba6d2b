"""Closed-form inverse kinematics of 6R arms with three parallel axes (the UR family: UR3, UR5, UR10 and their
e-series; the standard analytic solution with its 8 branches), read off the robot model like the spherical-wrist
solver of `workbench.robots.analytic` (no DH table, no list of names). It applies when

- the arm has six revolute joints;
- axes 2, 3 and 4 are parallel (direction n);
- axes 5 and 6 meet in one point W;
- axis 1 is not parallel to n, nor axis 5 to n.

Then, with T the last joint's frame in joint 1's parent frame (Paden-Kahan subproblems):

1. rotations about n keep W's component along n, so n(q1) . W = K, a constant: A cos q1 + B sin q1 = C, two q1
   (shoulder left or right);
2. axis 6's component along n is the same in the tool and in joint 4's frame: n . R5(q5) c = n . z6, two q5 (wrist
   up or down);
3. q6 rotates n, seen from the tool, onto n seen from joint 5 (one solution; any q6 where axis 6 is along n, the
   wrist singularity);
4. joint 4's frame is then known: its distance from joint 2's origin gives two q3 (elbow), then q2 and q4 are single
   rotations about n.

All 2 x 2 x 2 = 8 branches are computed for many poses at once (struct of arrays, no per-pose loop); branches
without a real solution or outside the joint limits come back as NaN with `valid` False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.errors import RobotError
from workbench.robots.analytic import BLOCK, TOL_AXES, _acs, _closest, _dot, _lin, _limit, _rot, _sub1

TOL_PARALLEL = 1e-9


@dataclass(frozen=True)
class ParallelIK:
    """Constants of the closed form for one robot (see the module docstring); build with `parallel_ik(robot)`."""

    pre: np.ndarray          # world -> joint-1 parent frame: M1^-1 base^-1
    tip_inv: np.ndarray      # TCP -> joint-6 frame
    m: tuple                 # (R, t) placements of joints 2..6 in their parent joint's frame
    axes: np.ndarray         # (6, 3) joint axes in their own frames
    n1: np.ndarray           # the parallel axes' direction in joint 1's frame
    k: float                 # n . W in joint 1's frame (step 1)
    c6: np.ndarray           # W in joint 6's frame
    n5: np.ndarray           # n in joint 5's parent frame (joint 4's), seen through M5's rotation: R5^T n4
    d4: np.ndarray           # a unit vector orthogonal to axis 4 (step 4)
    lower: np.ndarray
    upper: np.ndarray


def _parallel(u: np.ndarray, v: np.ndarray) -> bool:
    return float(np.linalg.norm(np.cross(u, v))) < TOL_PARALLEL


def parallel_axes_reason(robot) -> str:
    """Why this closed form does not apply to `robot` ('' when it does)."""
    if robot.nq != 6:
        return f"it has {robot.nq} joints, not 6"
    if robot.chain_prismatic.any():
        return "it has prismatic joints"
    pl, ax = robot.chain_placement, robot.chain_axis
    if not (_parallel(pl[2][:3, :3] @ ax[2], ax[1]) and _parallel(pl[3][:3, :3] @ ax[3], ax[2])):
        return "its axes 2, 3 and 4 are not parallel"
    _, d56 = _closest(np.zeros(3), ax[4], pl[5][:3, 3], pl[5][:3, :3] @ ax[5])
    if d56 > TOL_AXES:
        return "its axes 5 and 6 do not intersect"
    n1 = pl[1][:3, :3] @ ax[1]
    if _parallel(ax[0], n1):
        return "its axis 1 is parallel to axes 2-4"
    n4 = pl[3][:3, :3].T @ pl[2][:3, :3].T @ ax[1]
    if _parallel(pl[4][:3, :3].T @ n4, ax[4]):
        return "its axis 5 is parallel to axes 2-4"
    return ""


def parallel_ik(robot, limits: bool = True) -> ParallelIK:
    """The closed-form solver of `robot` (module docstring), or a RobotError saying why it has none.

    `limits=False` keeps every branch regardless of the joint limits (angles then in (-pi, pi])."""
    why = parallel_axes_reason(robot)
    if why:
        raise RobotError(f"robot {robot.name!r} has no three-parallel-axes closed form: {why}")
    pl, ax = robot.chain_placement, robot.chain_axis
    inv = np.linalg.inv
    w5, _ = _closest(np.zeros(3), ax[4], pl[5][:3, 3], pl[5][:3, :3] @ ax[5])
    c6 = (inv(pl[5]) @ np.append(w5, 1))[:3]
    w1 = (pl[1] @ pl[2] @ pl[3] @ pl[4] @ np.append(w5, 1))[:3]   # W at q2 = q3 = q4 = 0, joint 1's frame
    n1 = pl[1][:3, :3] @ ax[1]
    n4 = pl[3][:3, :3].T @ pl[2][:3, :3].T @ ax[1]
    d = np.cross(ax[3], [1.0, 0, 0]) if abs(ax[3][0]) < 0.9 else np.cross(ax[3], [0, 1.0, 0])
    big = np.full(6, np.inf)
    return ParallelIK(pre=inv(pl[0]) @ inv(robot.base), tip_inv=inv(robot.tip_in_joint),
                      m=tuple((pl[k][:3, :3].copy(), pl[k][:3, 3].copy()) for k in range(1, 6)), axes=ax.copy(),
                      n1=n1, k=float(n1 @ w1), c6=c6, n5=pl[4][:3, :3].T @ n4, d4=d / np.linalg.norm(d),
                      lower=robot.lower.copy() if limits else -big, upper=robot.upper.copy() if limits else big)


def solve(ik: ParallelIK, poses: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """All 8 IK branches of TCP poses (N, 4, 4) in the world: joints (N, 8, 6) and valid (N, 8).

    Branch index bits: 4 = q1 root (shoulder), 2 = q5 root (wrist), 1 = q3 root (elbow)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    n = len(poses)
    q = np.empty((n, 8, 6))
    valid = np.empty((n, 8), dtype=bool)
    for s in range(0, n, block):
        q[s:s + block], valid[s:s + block] = _solve_block(ik, poses[s:s + block])
    return q, valid


def _solve_block(ik: ParallelIK, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(poses)
    t = ik.pre @ poses @ ik.tip_inv                       # joint-6 frame in joint 1's parent frame
    tr = t[:, :3, :3].transpose(1, 2, 0)                   # (3, 3, N)
    tt = t[:, :3, 3].T                                     # (3, N)
    ax = ik.axes
    a1, a2, a3, a4, a5, a6 = ax
    (r2, t2), (r3, t3), (r4, t4), (r5, t5), (r6, t6) = ik.m

    def apply(v: np.ndarray) -> np.ndarray:
        """T_R v for a constant vector v (3,) -> (3, N)."""
        return tr[:, 0] * v[0] + tr[:, 1] * v[1] + tr[:, 2] * v[2]

    def apply_t(v: np.ndarray) -> np.ndarray:
        """T_R^T v for vectors v (3, ..., N)."""
        return np.stack([sum(tr[i, j] * v[i] for i in range(3)) for j in range(3)])

    # 1. shoulder: n(q1) . W = K
    w = apply(ik.c6) + tt
    n1 = ik.n1
    par = a1 * (a1 @ n1)
    perp, cr = n1 - par, np.cross(a1, n1)
    c1, s1 = _acs(_dot(perp, w), _dot(cr, w), ik.k - _dot(par, w))                        # (2, N)
    c1, s1 = c1[:, None, None], s1[:, None, None]                                          # (2, 1, 1, N)
    nw = par[:, None, None, None, None] + perp[:, None, None, None, None] * c1 + cr[:, None, None, None, None] * s1
    # 2. wrist: n . R5(q5) c = n . z6
    zt = apply(a6)
    sz = (nw * zt[:, None, None, None]).sum(0)                                              # (2, 1, 1, N)
    m, c = ik.n5, r6 @ a6
    cpar = a5 * (a5 @ c)
    c5, s5 = _acs(m @ (c - cpar), m @ np.cross(a5, c), sz[:, 0, 0] - m @ cpar)              # (2, 2, N): q5 root, q1 root
    c5, s5 = c5.swapaxes(0, 1)[:, :, None], s5.swapaxes(0, 1)[:, :, None]                   # (2, 2, 1, N)
    # 3. q6 turns n seen from the tool onto n seen from joint 5
    n6 = apply_t(nw)                                                                        # (3, 2, 1, 1, N)
    v6 = _lin(r6.T, _rot(a5, c5, s5, m.reshape(3, 1, 1, 1, 1), inverse=True))              # (3, 2, 2, 1, N)
    c6, s6 = _sub1(a6, np.broadcast_to(n6, v6.shape), v6)
    # 4. joint 4's frame: T G^-1 with G = M5 R5(q5) M6 R6(q6); only its origin T_t - T_R G_R^T G_t and its rotation
    # applied to d4 are needed, with G_R^T G_t = R6^T(q6) R6^T (R5^T(q5) R5^T t5 + t6)
    def g_inv(v: np.ndarray, extra: np.ndarray | None = None) -> np.ndarray:
        """R6(q6)^T R6^T (R5(q5)^T v + extra) for constant vectors v and extra: (3, 2, 2, 1, N)."""
        x = _rot(a5, c5, s5, v.reshape(3, 1, 1, 1, 1), inverse=True)
        if extra is not None:
            x = x + extra.reshape(3, 1, 1, 1, 1)
        return _rot(a6, c6, s6, _lin(r6.T, x), inverse=True)

    def t_apply(u: np.ndarray) -> np.ndarray:
        return tr[:, 0][:, None, None, None] * u[0] + tr[:, 1][:, None, None, None] * u[1] + tr[:, 2][:, None, None, None] * u[2]

    p4 = tt[:, None, None, None] - t_apply(g_inv(r5.T @ t5, t6))                        # frame-4 origin
    x1 = _rot(a1, c1, s1, p4, inverse=True)
    x2 = _lin(r2.T, x1 - t2.reshape(3, 1, 1, 1, 1))
    g = r3.T @ t3
    t4par = a3 * (a3 @ t4)
    rhs = 0.5 * ((x2 * x2).sum(0) - t3 @ t3 - t4 @ t4) - g @ t4par
    c3, s3 = _acs(g @ (t4 - t4par), g @ np.cross(a3, t4), rhs)                             # (2, 2, 2, 1, N)
    c3, s3 = np.moveaxis(c3[..., 0, :], 0, 2), np.moveaxis(s3[..., 0, :], 0, 2)            # (2, 2, 2, N)
    u = _lin(r3, _rot(a3, c3, s3, t4.reshape(3, 1, 1, 1, 1))) + t3.reshape(3, 1, 1, 1, 1)
    c2, s2 = _sub1(a2, u, np.broadcast_to(x2, u.shape))
    # q4: R4(q4) d = R4^T R3(q3)^T R3^T R2(q2)^T R2^T R1(q1)^T T4_R d
    d = ik.d4
    y = _lin(r2.T, _rot(a1, c1, s1, t_apply(g_inv(r5.T @ d)), inverse=True))
    y = _lin(r3.T, _rot(a2, c2, s2, y, inverse=True))
    y = _lin(r4.T, _rot(a3, c3, s3, y, inverse=True))
    c4, s4 = _sub1(a4, np.broadcast_to(d.reshape(3, 1, 1, 1, 1), y.shape), y)
    q = np.empty((n, 2, 2, 2, 6))
    view = q.transpose(1, 2, 3, 0, 4)                                                       # (2, 2, 2, N, 6)
    full = (2, 2, 2, n)
    for j, (sj, cj) in enumerate(((s1, c1), (s2, c2), (s3, c3), (s4, c4), (s5, c5), (s6, c6))):
        view[..., j] = np.broadcast_to(_limit(np.arctan2(sj, cj), ik.lower[j], ik.upper[j]), full)
    q = q.reshape(n, 8, 6)
    return q, ~np.isnan(q).any(axis=2)
