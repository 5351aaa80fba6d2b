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

All 2 x 2 x 2 = 8 branches are computed for many poses at once by a compiled kernel (`robots._closedkernel`); branches
without a real solution or outside the joint limits come back as NaN with `valid` False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.errors import RobotError
from workbench.robots._closedkernel import parallel_rows
from workbench.robots.analytic import BLOCK, TOL_AXES, _closest

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
    kernel: tuple = ()       # the constants above as the compiled kernel takes them (contiguous, built once)


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
    lower, upper = (robot.lower.copy(), robot.upper.copy()) if limits else (-big, big)
    m = tuple((pl[k][:3, :3].copy(), pl[k][:3, 3].copy()) for k in range(1, 6))
    pre, tip_inv, n5, d4 = inv(pl[0]) @ inv(robot.base), inv(robot.tip_in_joint), pl[4][:3, :3].T @ n4, d / np.linalg.norm(d)
    k = float(n1 @ w1)
    f64 = np.ascontiguousarray
    kernel = (f64(pre), f64(tip_inv), f64(np.stack([r for r, _ in m])), f64(np.stack([t for _, t in m])), f64(ax),
              f64(n1), k, f64(c6), f64(n5), f64(d4), f64(lower), f64(upper))
    return ParallelIK(pre=pre, tip_inv=tip_inv, m=m, axes=ax.copy(), n1=n1, k=k, c6=c6, n5=n5, d4=d4, lower=lower,
                      upper=upper, kernel=kernel)


def solve(ik: ParallelIK, poses: np.ndarray, block: int = BLOCK) -> tuple[np.ndarray, np.ndarray]:
    """All 8 IK branches of TCP poses (N, 4, 4) in the world: joints (N, 8, 6) and valid (N, 8), by the compiled
    kernel (`_closedkernel.parallel_rows`).

    Branch index bits: 4 = q1 root (shoulder), 2 = q5 root (wrist), 1 = q3 root (elbow)."""
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4))
    n = len(poses)
    q = np.empty((n, 8, 6))
    valid = np.empty((n, 8), dtype=bool)
    for s in range(0, n, block):
        parallel_rows(poses[s:s + block], *ik.kernel, q[s:s + block], valid[s:s + block])
    return q, valid
