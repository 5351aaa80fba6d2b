"""Batched kinematics of a serial chain (Wan & Harada Section IV needs IK for 10,000s of grips): forward
kinematics and Jacobians of many configurations at once in numpy (entry-major arrays), and a damped
Levenberg-Marquardt IK solve within the joint limits (`solve_ik`), with stall detection per row.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

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


def _rotvec_soa(m: np.ndarray) -> np.ndarray:
    """Rotation vectors (3, B) of rotations (3, 3, B) (SO(3) log; near pi through scipy)."""
    v = 0.5 * np.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    c = np.clip(0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0), -1.0, 1.0)
    s = np.sqrt((v * v).sum(0))
    theta = np.arctan2(s, c)
    out = v * np.where(s > 1e-9, theta / np.maximum(s, 1e-300), 1.0)
    far = c < -0.95
    if far.any():
        out[:, far] = Rotation.from_matrix(m[:, :, far].transpose(2, 0, 1)).as_rotvec().T
    return out


def rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation vectors (B, 3) of rotation matrices (B, 3, 3) (the SO(3) log map)."""
    return _rotvec_soa(np.ascontiguousarray(np.asarray(m, dtype=np.float64).transpose(1, 2, 0))).T


def _spd_solve(a: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a x = rhs for symmetric positive definite a (m, m, B), rhs (m, B), by Cholesky in entry-major layout."""
    m = a.shape[0]
    low = np.zeros_like(a)
    for j in range(m):
        d = a[j, j] - (low[j, :j] ** 2).sum(0)
        low[j, j] = np.sqrt(np.maximum(d, 1e-300))
        if j + 1 < m:
            low[j + 1:, j] = (a[j + 1:, j] - (low[j + 1:, :j] * low[j, :j][None]).sum(1)) / low[j, j]
    y = np.empty_like(rhs)
    for i in range(m):
        y[i] = (rhs[i] - (low[i, :i] * y[:i]).sum(0)) / low[i, i]
    x = np.empty_like(rhs)
    for i in range(m - 1, -1, -1):
        x[i] = (y[i] - (low[i + 1:, i] * x[i + 1:]).sum(0)) / low[i, i]
    return x


def solve_ik(robot: Robot, targets: np.ndarray, q0: np.ndarray, iters: int, tol_pos: float = 1e-4,
             tol_rot: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Batched Levenberg-Marquardt IK (Sugihara's damping E + 1e-3) with joint-limit clamping.

    The step is J^T (J J^T + lambda I)^-1 e, solved per pose by a 6x6 Cholesky vectorised across poses.
    Converged rows leave the active set; rows whose error stalls for STALL_WINDOW iterations are given up.
    Returns the joint vectors (M, n) and which converged (M,)."""
    targets = np.asarray(targets, dtype=np.float64)
    q = np.ascontiguousarray(np.clip(np.array(q0, dtype=np.float64), robot.lower, robot.upper).T)  # (n, M)
    n, m = q.shape
    lo, hi = robot.lower[:, None], robot.upper[:, None]
    t_rot = np.ascontiguousarray(targets[:, :3, :3].transpose(1, 2, 0))
    t_pos = np.ascontiguousarray(targets[:, :3, 3].T)
    ok = np.zeros(m, dtype=bool)
    active = np.arange(m)
    last = np.full(m, np.inf)
    eye6 = np.eye(6)[:, :, None]
    qa, tr, tp = q, t_rot, t_pos
    for it in range(iters + 1):
        _, pos, axes, tcp_r, tcp_t = _fk(robot, qa)
        ep = tp - tcp_t
        er = _rotvec_soa(_mm(tr, tcp_r.transpose(1, 0, 2)))
        np_, nr = np.sqrt((ep * ep).sum(0)), np.sqrt((er * er).sum(0))
        conv = (np_ < tol_pos) & (nr < tol_rot)
        q[:, active] = qa
        ok[active[conv]] = True
        keep = ~conv
        err = np_ + 0.2 * nr
        if it > 0 and it % STALL_WINDOW == 0:
            keep &= err <= STALL_RATIO * last[active]
            last[active] = err
        elif it == 0:
            last[active] = err
        if it == iters or not keep.any():
            break
        if not keep.all():
            active, qa, tr, tp = active[keep], qa[:, keep], tr[..., keep], tp[:, keep]
            axes, pos, tcp_t, ep, er = axes[..., keep], pos[..., keep], tcp_t[:, keep], ep[:, keep], er[:, keep]
        e = np.concatenate([ep, er], axis=0)  # (6, B)
        jac = _jacobian_soa(robot, axes, pos, tcp_t)  # (6, n, B)
        energy = 0.5 * (e * e).sum(0)
        a = eye6 * (energy + 1e-3)
        for k in range(n):
            a = a + jac[:, None, k] * jac[None, :, k]
        x = _spd_solve(a, e)
        dq = jac[0] * x[0]
        for i in range(1, 6):
            dq = dq + jac[i] * x[i]
        step = np.abs(dq).max(axis=0)
        dq *= np.minimum(1.0, 0.6 / np.maximum(step, 1e-12))
        qa = np.clip(qa + dq, lo, hi)
    return np.ascontiguousarray(q.T), ok
