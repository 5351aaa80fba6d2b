"""The grasp-placement table Q_ij (Tournassoud, Lozano-Perez & Mazer 1987, Sections 4.1 and 5).

For a grasp class G_i (angle theta) and a placement class P_j (angle phi about the vertical through the table
point H), the object rests at  T_H Rz(phi) P_j  in the world and the TCP is at  T_H Rz(phi) P_j G_i(theta).
Q_ij, the legal (theta, phi) pairs, is sampled on a theta x phi grid and pruned in the paper's order:

1. hand-object collision: theta inside the class's legal intervals (Section 5.1, `classes.py`);
2. hand-table collision: the hand and both fingers at full opening stay `clearance` above the table. It depends
   on theta and P_j only, not on phi (a rotation about the vertical keeps heights);
3. inverse kinematics within the joint limits (Section 5.2): for each remaining theta sample, the phi samples with
   at least one IK branch; stored as a union of phi intervals. Arms with a spherical wrist use the closed form
   (`workbench.analytic`, all 8 branches); other arms the workbench's numerical IK.

The table is a boolean array q[i, j, t, f] over classes, placements, theta samples and phi samples.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field

import numpy as np
from tqdm import tqdm

from workbench.grasping.placements import grips_above_table
from workbench.params import DEG, Params, param
from workbench.planners.tournassoud.classes import GraspClass
from workbench.robots.analytic import analytic_ik, spherical_wrist_reason
from workbench.robots.analytic import reachable as closed_reachable
from workbench.robots.collider import default_scene
from workbench.robots.ik import IKOptions, IKSolver
from workbench.robots.model import Robot


@dataclass(frozen=True)
class TableParams(Params):
    """Resolutions (radians), the table point H = (x, y) on the table top in the world, the hand's clearance above
    the table (m; negative lets the hand go that far below the table plane, i.e. a table that far away), whether
    IK applies the joint limits, and the IK batch size."""

    theta_step: float = param(np.radians(5.0), gt=0, le=np.pi / 2, unit="rad", cli_scale=DEG, cli_unit="deg",
                              help="theta step (grasp angle resolution)")
    phi_step: float = param(np.radians(5.0), gt=0, le=np.pi / 2, unit="rad", cli_scale=DEG, cli_unit="deg",
                            help="phi step (placement angle resolution)")
    table_point: tuple[float, float] = param((0.45, 0.0), ge=-10.0, le=10.0, unit="m",
                                             help="each coordinate of the table point H")
    clearance: float = param(0.002, ge=-10.0, le=1.0, unit="m", help="hand clearance above the table")
    limits: bool = True
    chunk: int = param(20000, ge=1, le=10_000_000, integer=True, help="IK batch size")

    def check(self) -> None:
        self.require(len(self.table_point) == 2, ("table_point",), "the table point is two numbers X,Y in metres")

    def as_dict(self) -> dict:
        d = asdict(self)
        d["table_point"] = [float(x) for x in self.table_point]
        return d


def grid(step: float) -> np.ndarray:
    """Samples k * (2 pi / n) of [0, 2 pi) with n = round(2 pi / step)."""
    n = max(int(round(2 * np.pi / step)), 1)
    return np.arange(n) * (2 * np.pi / n)


def table_frame(point: tuple[float, float]) -> np.ndarray:
    """The 4x4 frame at the table point H = (x, y) on the table top, axes parallel to the world's (Section 4)."""
    out = np.eye(4)
    out[:2, 3] = point
    return out


def rz(phi: np.ndarray) -> np.ndarray:
    """(N, 4, 4) rotations about z."""
    phi = np.asarray(phi, dtype=np.float64).reshape(-1)
    out = np.zeros((len(phi), 4, 4))
    c, s = np.cos(phi), np.sin(phi)
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    out[:, 2, 2] = out[:, 3, 3] = 1.0
    return out


@dataclass
class GraspPlacementTable:
    """Q_ij sampled: q (C, P, T, F) bool, with the stage masks of Section 5 and build timings (s)."""

    theta: np.ndarray
    phi: np.ndarray
    hand_object: np.ndarray   # (C, T)
    hand_table: np.ndarray    # (C, P, T)
    q: np.ndarray             # (C, P, T, F)
    placements: np.ndarray    # (P, 4, 4) object in the table frame (centre of mass above the origin)
    frame: np.ndarray         # (4, 4) table frame at H in the world
    timings: dict = field(default_factory=dict)
    _matrix: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.q.shape)

    def object_pose(self, j: int, phi: float) -> np.ndarray:
        """The object in the world at placement (P_j, phi) (Section 3)."""
        return self.frame @ rz(phi)[0] @ self.placements[j]

    def empty_reason(self) -> str | None:
        """Which pruning stage of Section 5 emptied the table, and what to try (None when some cell is legal)."""
        c, p = self.q.shape[:2]
        if self.q.any():
            return None
        if c == 0:
            return "no grasp class"
        if p == 0:
            return ("no placement class: no convex-hull face holds the centre of mass stably (the part rolls or tips); "
                    "lower --min-stability")
        if not self.hand_object.any():
            return "hand-object: the hand collides with the part at every class and theta; lower --theta-step"
        if not (self.hand_table & self.hand_object[:, None, :]).any():
            return ("hand-table: at every placement the fingers or the hand reach into the table at every legal theta "
                    "(the part is too low for a grasp at the pad's centre, or lies on the faces the classes grasp)")
        return ("inverse kinematics: no (theta, phi) of any cell has an IK solution within the joint limits; move "
                "--table-point into the robot's workspace")

    def phi_intervals(self, i: int, j: int, t: int) -> list[tuple[float, float]]:
        """The phi samples of Q_ij at theta sample t as closed intervals [first, last] of sample values."""
        return runs(self.q[i, j, t], self.phi)

    def matrix(self) -> tuple[np.ndarray, np.ndarray]:
        """Q as a boolean (C T, P F) matrix and its transpose, both row-contiguous, for the chaining's cross-sections:
        rows of grasps select placements, rows of placements select grasps (built once)."""
        if self._matrix is None:
            c, p, t, f = self.q.shape
            m = np.ascontiguousarray(self.q.transpose(0, 2, 1, 3).reshape(c * t, p * f))
            self._matrix = (m, np.ascontiguousarray(m.T))
        return self._matrix

    def placements_of(self, grasps: np.ndarray) -> np.ndarray:
        """(P F) bool: the placements compatible with any grasp of the (C, T) mask (union of phi cross-sections)."""
        m, _ = self.matrix()
        rows = np.flatnonzero(grasps.reshape(-1))
        return m[rows].any(axis=0) if len(rows) else np.zeros(m.shape[1], dtype=bool)

    def grasps_of(self, placements: np.ndarray) -> np.ndarray:
        """(C T) bool: the grasps compatible with any placement of the (P F) mask (union of theta cross-sections)."""
        _, mt = self.matrix()
        rows = np.flatnonzero(placements.reshape(-1))
        return mt[rows].any(axis=0) if len(rows) else np.zeros(mt.shape[1], dtype=bool)


def runs(mask: np.ndarray, values: np.ndarray) -> list[tuple[float, float]]:
    """Maximal runs of True in a 1D mask as (first value, last value); a run may wrap around the end."""
    n = len(mask)
    if n == 0 or not mask.any():
        return []
    if mask.all():
        return [(float(values[0]), float(values[-1]))]
    start = int(np.argmin(mask))
    m = np.roll(mask, -start)
    idx = (np.arange(n) + start) % n
    d = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    a, b = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
    return [(float(values[idx[x]]), float(values[idx[y]])) for x, y in zip(a, b)]


def legal_theta(classes: list[GraspClass], theta: np.ndarray) -> np.ndarray:
    """(C, T): theta samples inside each class's hand-object intervals (Section 5.1)."""
    return np.array([c.legal(theta) for c in classes]).reshape(len(classes), len(theta))


def build_table(classes: list[GraspClass], placements: np.ndarray, robot: Robot, gripper, params: TableParams = TableParams(),
                progress: bool = True) -> GraspPlacementTable:
    """The grasp-placement table of Section 5 (see the module docstring)."""
    t0 = time.perf_counter()
    theta, phi = grid(params.theta_step), grid(params.phi_step)
    c_n, p_n, t_n, f_n = len(classes), len(placements), len(theta), len(phi)
    placements = np.asarray(placements, dtype=np.float64).reshape(-1, 4, 4)
    frame = table_frame(params.table_point)
    ho = legal_theta(classes, theta)
    t1 = time.perf_counter()
    # 2. hand-table: one mask for every (placement, class, theta)
    grasps = np.array([c.pose(theta) for c in classes]).reshape(-1, 4, 4)
    ht = np.zeros((c_n, p_n, t_n), dtype=bool)
    if len(grasps) and p_n:
        above = grips_above_table(placements, grasps, gripper, params.clearance).reshape(p_n, c_n, t_n)
        ht = above.transpose(1, 0, 2) & ho[:, None, :]
    t2 = time.perf_counter()
    # 3. IK per (class, placement, theta) left, for every phi
    q = np.zeros((c_n, p_n, t_n, f_n), dtype=bool)
    ci, pj, tk = np.nonzero(ht)
    if len(ci):
        base = frame[None] @ rz(phi)                                  # (F, 4, 4)
        held = placements[pj] @ grasps.reshape(c_n, t_n, 4, 4)[ci, tk]  # (K, 4, 4) TCP in the table frame
        ok = reachable(robot, base, held, params.chunk, progress, params.limits)
        q[ci, pj, tk] = ok
    t3 = time.perf_counter()
    return GraspPlacementTable(theta=theta, phi=phi, hand_object=ho, hand_table=ht, q=q, placements=placements, frame=frame,
                               timings={"hand_object": t1 - t0, "hand_table": t2 - t1, "ik": t3 - t2, "total": t3 - t0,
                                        "ik_poses": int(len(ci) * f_n)})


def reachable(robot: Robot, base: np.ndarray, held: np.ndarray, chunk: int, progress: bool, limits: bool = True) -> np.ndarray:
    """(K, F): whether TCP pose base[f] @ held[k] has an IK solution within the joint limits (Section 5.2)."""
    k_n, f_n = len(held), len(base)
    out = np.zeros((k_n, f_n), dtype=bool)
    if spherical_wrist_reason(robot):
        return _reachable_numeric(robot, base, held, out, progress)
    ik = analytic_ik(robot, limits=limits)
    rows = max(chunk // f_n, 1)
    for s in tqdm(range(0, k_n, rows), desc="IK (closed form)", unit="chunk", disable=not progress, leave=False):
        h = held[s:s + rows]
        out[s:s + rows] = closed_reachable(ik, compose(base, h).reshape(-1, 4, 4)).reshape(len(h), f_n)
    return out


def compose(base: np.ndarray, held: np.ndarray) -> np.ndarray:
    """(K, F, 4, 4): base[f] @ held[k] for rigid transforms (last rows 0 0 0 1), row by row with broadcasting (the
    table's bases are rotations about z, but any rigid base works)."""
    out = np.empty((len(held), len(base), 4, 4))
    b = base[None, :, :3, :]                                           # (1, F, 3, 4)
    for i in range(3):
        row = out[:, :, i, :]
        np.multiply(b[..., i, 0, None], held[:, None, 0, :], out=row)
        row += b[..., i, 1, None] * held[:, None, 1, :]
        row += b[..., i, 2, None] * held[:, None, 2, :]
        row[..., 3] += b[..., i, 3]
    out[:, :, 3, :] = (0.0, 0.0, 0.0, 1.0)
    return out


def _reachable_numeric(robot: Robot, base: np.ndarray, held: np.ndarray, out: np.ndarray, progress: bool) -> np.ndarray:
    """The workbench's numerical IK (`IKSolver`, Levenberg-Marquardt from the nearest library seed, no collision
    check: Section 5.2 asks for joint angles within their limits) for arms without a closed form."""
    opts = IKOptions(collide=False)
    solver = IKSolver(robot, default_scene(robot.name), opts)
    poses = np.einsum("fij,kjl->kfil", base, held).reshape(-1, 4, 4)
    flat = out.reshape(-1)
    for s in tqdm(range(0, len(poses), 4096), desc="IK (numerical)", unit="chunk", disable=not progress, leave=False):
        target = poses[s:s + 4096]
        seeds = solver.library.q[solver.library.nearest(target, 1)[:, 0]]
        _, ok = solver.solve(target, np.repeat(np.eye(4)[None], len(target), axis=0), seeds, opts.iters_seed)
        flat[s:s + len(target)] = ok
    return out
