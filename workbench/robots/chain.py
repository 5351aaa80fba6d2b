"""Batched kinematics of a serial chain (Wan & Harada Section IV needs IK for 10,000s of grips): forward
kinematics and Jacobians of many configurations at once in numpy (entry-major arrays), and a damped
Levenberg-Marquardt IK solve within the joint limits (`solve_ik`), with stall detection per row.
"""

from __future__ import annotations

import numpy as np

from workbench.robots._lmkernel import lm_rows, tcp_rows
from workbench.robots.model import Robot

STALL_WINDOW = 6  # LM iterations between progress checks


STALL_RATIO = 0.8  # a row whose error did not drop below this fraction over the window is given up


def _joint_terms(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per joint, constant matrices with placement_R @ Rot(axis, q) = M0 + sin(q) Ms + cos(q) Mc (Rodrigues)."""
    cached = getattr(robot, "_joint_terms", None)
    if cached is None:
        m0, ms, mc = [], [], []
        for pl, (x, y, z), pr in zip(robot.chain_placement, robot.chain_axis, robot.chain_prismatic):
            r = pl[:3, :3]
            if pr:
                m0.append(r)
                ms.append(np.zeros((3, 3)))
                mc.append(np.zeros((3, 3)))
                continue
            k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
            m0.append(r @ (np.eye(3) + k @ k))
            ms.append(r @ k)
            mc.append(-r @ k @ k)
        cached = (np.array(m0), np.array(ms), np.array(mc))
        robot._joint_terms = cached
    return cached


# The products below are written as elementwise sums in a fixed order, not einsum: einsum picks its inner loop from
# the strides, which change with the batch size (a batch of one is contiguous along the summed axis), and the last
# bits of a row's result would then depend on the rows solved with it.


def _mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched 3x3 products in entry-major layout: (3, 3, B) x (3, 3, B) -> (3, 3, B)."""
    return a[:, 0, None] * b[0][None] + a[:, 1, None] * b[1][None] + a[:, 2, None] * b[2][None]


def _mv(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(3, 3, B) rotations times a constant vector (3,) -> (3, B)."""
    return r[:, 0] * v[0] + r[:, 1] * v[1] + r[:, 2] * v[2]


def _mc(r: np.ndarray, m: np.ndarray) -> np.ndarray:
    """(3, 3, B) rotations times a constant matrix (3, 3) -> (3, 3, B)."""
    return np.stack([r[:, 0] * m[0, j] + r[:, 1] * m[1, j] + r[:, 2] * m[2, j] for j in range(3)], axis=1)


def _aligned(robot: Robot) -> list[tuple[int, float, bool]]:
    """Per joint: (axis index, sign) when its axis is a coordinate axis (else index -1), and whether its placement
    rotation is the identity."""
    cached = getattr(robot, "_aligned", None)
    if cached is None:
        cached = []
        for pl, ax in zip(robot.chain_placement, robot.chain_axis):
            k = int(np.argmax(np.abs(ax)))
            aligned = abs(abs(ax[k]) - 1.0) < 1e-12
            cached.append((k if aligned else -1, float(np.sign(ax[k])), bool(np.abs(pl[:3, :3] - np.eye(3)).max() < 1e-15)))
        robot._aligned = cached
    return cached


def _fk(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`forward_soa` plus the joints' world axes (n, 3, B). Joints about a coordinate axis rotate two columns of the
    running rotation (no 3x3 product); others use Rodrigues' constant terms."""
    n, b = q.shape
    m0, ms, mc = _joint_terms(robot)
    info = _aligned(robot)
    sq, cq = np.sin(q), np.cos(q)
    rot = np.empty((n, 3, 3, b))
    pos = np.empty((n, 3, b))
    axes = np.empty((n, 3, b))
    r = np.repeat(robot.base[:3, :3, None], b, axis=2)
    t = np.repeat(robot.base[:3, 3, None], b, axis=1)
    for i in range(n):
        pl = robot.chain_placement[i]
        t = t + _mv(r, pl[:3, 3])
        k, sign, identity = info[i]
        if robot.chain_prismatic[i]:
            r = _mc(r, m0[i])
            axes[i] = _mv(r, robot.chain_axis[i])
            t = t + axes[i] * q[i]
            rot[i] = r
        elif k >= 0:
            if not identity:
                r = _mc(r, pl[:3, :3])
            u, v = (k + 1) % 3, (k + 2) % 3
            c, s_ = cq[i], sq[i] * sign
            out = rot[i]
            out[:, u] = c * r[:, u] + s_ * r[:, v]
            out[:, v] = c * r[:, v] - s_ * r[:, u]
            out[:, k] = r[:, k]
            r = out
            axes[i] = r[:, k] * sign
        else:
            local = m0[i][:, :, None] + ms[i][:, :, None] * sq[i] + mc[i][:, :, None] * cq[i]
            r = _mm(r, local)
            rot[i] = r
            axes[i] = _mv(r, robot.chain_axis[i])
        pos[i] = t
    tip = robot.tip_in_joint
    tcp_t = t + _mv(r, tip[:3, 3])
    tcp_r = _mc(r, tip[:3, :3])
    return rot, pos, axes, tcp_r, tcp_t


def forward_soa(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched forward kinematics in entry-major layout (the batch is the last, contiguous axis): joint rotations
    (n, 3, 3, B), joint origins (n, 3, B), TCP rotation (3, 3, B) and position (3, B) for joint vectors q (n, B)."""
    rot, pos, _, tcp_r, tcp_t = _fk(robot, q)
    return rot, pos, tcp_r, tcp_t


def forward(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched forward kinematics in the world: joint rotations (B, n, 3, 3), joint origins (B, n, 3), TCP rotation
    (B, 3, 3) and TCP position (B, 3) for joint vectors q (B, n)."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    rot, pos, tcp_r, tcp_t = forward_soa(robot, np.ascontiguousarray(q.T))
    return rot.transpose(3, 0, 1, 2), pos.transpose(2, 0, 1), tcp_r.transpose(2, 0, 1), tcp_t.T


def _jacobian_soa(robot: Robot, axes: np.ndarray, pos: np.ndarray, tcp_t: np.ndarray) -> np.ndarray:
    """World-frame geometric Jacobian of the TCP, (6, n, B), linear rows first, from the joints' world axes."""
    d = tcp_t[None] - pos
    lin = np.stack([axes[:, 1] * d[:, 2] - axes[:, 2] * d[:, 1],
                    axes[:, 2] * d[:, 0] - axes[:, 0] * d[:, 2],
                    axes[:, 0] * d[:, 1] - axes[:, 1] * d[:, 0]], axis=0)  # (3, n, B)
    ang = axes.transpose(1, 0, 2)
    pr = robot.chain_prismatic
    if pr.any():
        lin[:, pr] = ang[:, pr]
        ang = ang.copy()
        ang[:, pr] = 0.0
    return np.concatenate([lin, ang], axis=0)


def jacobian(robot: Robot, q: np.ndarray) -> np.ndarray:
    """World-frame geometric Jacobian (B, 6, n) of the TCP at joint vectors q (B, n), linear rows first."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    _, pos, axes, _, tcp_t = _fk(robot, np.ascontiguousarray(q.T))
    return _jacobian_soa(robot, axes, pos, tcp_t).transpose(2, 0, 1)


def solve_ik(robot: Robot, targets: np.ndarray, q0: np.ndarray, iters: int, tol_pos: float = 1e-4,
             tol_rot: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Batched Levenberg-Marquardt IK (Sugihara's damping E + 1e-3) with joint-limit clamping.

    The step is J^T (J J^T + lambda I)^-1 e, solved per pose by a 6x6 Cholesky in a compiled kernel, one pose at a
    time (a row's answer never depends on the rows solved with it). A pose stops when converged, or when its error
    stalls for STALL_WINDOW iterations. Returns the joint vectors (M, n) and which converged (M,)."""
    targets = np.ascontiguousarray(np.asarray(targets, dtype=np.float64).reshape(-1, 4, 4))
    q0 = np.ascontiguousarray(np.asarray(q0, dtype=np.float64).reshape(len(targets), -1))
    return lm_rows(*_kernel_chain(robot), robot.lower, robot.upper, targets, q0, int(iters), float(tol_pos),
                   float(tol_rot), STALL_WINDOW, STALL_RATIO)


def tcp_positions(robot: Robot, q: np.ndarray) -> np.ndarray:
    """TCP positions (M, 3) in the world of joint vectors q (M, n), compiled (cheap for a few rows)."""
    q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, dtype=np.float64)))
    return tcp_rows(*_kernel_chain(robot), q)


def _kernel_chain(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The chain as the compiled kernels take it: base, placements (n, 4, 4), axes, prismatic flags, tip; cached."""
    cached = getattr(robot, "_kernel_chain", None)
    if cached is None:
        f64 = lambda a: np.ascontiguousarray(np.asarray(a, dtype=np.float64))  # noqa: E731
        cached = (f64(robot.base), f64(np.array(robot.chain_placement)), f64(robot.chain_axis),
                  np.ascontiguousarray(np.asarray(robot.chain_prismatic, dtype=np.bool_)), f64(robot.tip_in_joint))
        robot._kernel_chain = cached
    return cached
