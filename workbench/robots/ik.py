"""IK feasibility of tabletop grips (Wan & Harada Section IV: the `ik` and `ikret` tables).

For every tabletop grip (a TCP pose in the world) five poses are solved, as the paper's reference implementation
does (the `ik` table's feasibility columns): the grasp; `handx`, the grasp retracted by `handx` along the TCP's -z
(the paper's hand x axis is our approach axis) and `handxworldz`, that pose raised by `worldz` along world +z (the
empty hand leaving or approaching the resting object); `worlda`, the grasp lifted by `worlda` along world +z with
the object held (the object lifted straight off the table), and `worldaworldz`, that pose raised by `worldz`.
A pose is feasible when IK converges (position within `tol_pos`, orientation within `tol_rot`) inside the joint
limits and the arm and the gripper at that configuration do not collide with the table, nor the arm with the
object, which rests on its placement for the first three poses and moves with the hand for the lifts (python-fcl
on the URDF's collision geometry; the gripper's contact with the object is the grasp planner's business); nor the arm and gripper
with themselves when `self_collide` (`robots.selfcollision`, pinocchio + coal, allowed pairs from the
SRDF or sampled).

Speed (Section VI, Table I's t-tpgik): a reachability pre-filter (`ReachFilter`: distance from the
shoulder, also over a humanoid's waist, and the workspace box); a closed form where the arm has one
(`robots.solvers`: all branches at once, the one nearest the robot's home configuration kept); otherwise one
batched Levenberg-Marquardt iteration (numpy forward kinematics and Jacobians of the serial chain, entry-major
arrays) serves thousands of poses, each from its own seeds: the neighbouring pose of the same grip, the library of
table-clear sampled configurations nearest to the target, random restarts hashed from the pose. Chunks run on all
cores (an `IKPool` of forkserver worker processes, each building the solver once) with a tqdm progress bar. A grip's
row depends on the grip, the robot, the scene and the options alone, never on the chunk, the worker, the order or
the command that solved it.
"""

from __future__ import annotations

import copy
import hashlib
import multiprocessing as mp
import os
import signal
import sys
import threading
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from multiprocessing import forkserver
from typing import Callable, Iterator

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from tqdm.auto import tqdm

from workbench.errors import ParameterError, RobotError
from workbench.params import Params, param
from workbench.robots._closedkernel import branch_order
from workbench.robots.analytic import branch_distances, whole_turns
from workbench.robots.chain import forward, solve_ik
from workbench.robots.collider import Collider, Scene
from workbench.robots.model import Robot, RobotSpec, robot_from_spec
from workbench.robots.selfcollision import SelfCollision
from workbench.robots.solvers import closed_form, describe, nearby_form, wrist_shell

KINDS = ("grasp", "handx", "handxworldz", "worlda", "worldaworldz")
# each pose after the grasp (index into KINDS) and its neighbour on the way, from which it is solved or referenced
ON_THE_WAY = ((1, 0), (2, 1), (3, 0), (4, 3))
HELD = np.array([False, False, False, True, True])  # kinds at which the object moves with the hand
SOLVERS = ("auto", "numerical")
BETWEEN_TRIES = 8  # branches of a swept closed form tried as seeds where its samples miss a pose
WORLDA = 0.05  # default lift of the held object straight up (m), the paper's ikret worlda


@dataclass(frozen=True)
class IKOptions(Params):
    """Solver settings (they change the rows, so they are stored with the scene).

    tol_pos (m) and tol_rot (rad): convergence; iters_warm/iters_seed: LM iterations from a warm start and
    from a library seed; seeds: library seeds tried after the warm start, picked among the seed_pool nearest
    library poses at least seed_spread rad apart; library: size of the seed
    library; restarts: random configurations tried last, drawn from a hash of the pose; chunk: grips per parallel
    task (scheduling only, not in the rows); seed: RNG seed of the library and the restarts;
    collide: reject arm/gripper-table and arm-object collisions; self_collide (with collide): reject self-colliding
    solutions (the arm and the planning gripper, `robots.selfcollision`, allowed pairs from the SRDF or sampled; the
    roadmap planner's IK stage turns it on);
    solver: "auto" solves with the arm's closed form where it has one (`robots.solvers.closed_form`: all branches,
    the collision-free one nearest the home configuration kept), "numerical" always with Levenberg-Marquardt."""

    tol_pos: float = param(1e-4, gt=0, le=0.01, unit="m", help="position tolerance")
    tol_rot: float = param(1e-3, gt=0, le=0.1, unit="rad", help="rotation tolerance")
    iters_warm: int = param(60, ge=1, le=10_000, integer=True, help="LM iterations from a warm start")
    iters_seed: int = param(300, ge=0, le=100_000, integer=True, help="LM iterations from a library seed")
    seeds: int = param(5, ge=0, le=1000, integer=True, help="library seeds tried after the warm start")
    seed_pool: int = param(24, ge=1, le=100_000, integer=True, help="nearest library poses the seeds are picked from")
    seed_spread: float = param(1.0, ge=0, le=np.pi, unit="rad", help="smallest angle between picked seeds")
    library: int = param(32768, ge=1, le=10_000_000, integer=True, help="seed library size")
    restarts: int = param(4, ge=0, le=1000, integer=True, help="random restarts (seeded by the pose) after the library seeds")
    chunk: int = param(4096, ge=1, le=10_000_000, integer=True, help="grips per parallel task (resume unit; not in the rows)")
    seed: int = param(0, ge=0, le=2**32 - 1, integer=True, help="RNG seed")
    collide: bool = True
    self_collide: bool = False
    solver: str = "auto"

    def check(self) -> None:
        if self.solver not in SOLVERS:
            raise ParameterError(f"IK solver {self.solver!r} is not one of {', '.join(SOLVERS)}")

    def as_dict(self) -> dict:
        d = asdict(self)
        d.pop("chunk")  # scheduling only: the rows do not depend on it
        return d


def solver_kind(robot: Robot, opts: IKOptions) -> str:
    """The IK `opts` give `robot`, in words (stored with the scene: the rows depend on it)."""
    return describe(robot, numerical=opts.solver == "numerical")


@dataclass
class IKResult:
    """Per grip (in input order): feasibility (N, 5) for the KINDS (grasp, handx, handxworldz, worlda,
    worldaworldz); joints (N, 5, nq), NaN where infeasible."""

    feasible: np.ndarray
    joints: np.ndarray
    order: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


class SeedLibrary:
    """Deterministic sampled configurations and their TCP poses; `nearest` picks the seeds whose TCP pose is
    closest to each target (k-d tree over position and `rho`-weighted rotation matrix entries)."""

    def __init__(self, robot: Robot, size: int, seed: int, rho: float = 0.1, collider: "Collider | None" = None):

        rng = np.random.default_rng(seed)
        q = rng.uniform(robot.lower, robot.upper, size=(size, robot.nq))
        q[0] = robot.neutral()
        if collider is not None:  # keep seeds whose arm is clear of the table
            free = ~collider.collides_q(q, None, table_only=True)
            if free.sum() >= min(size, 64):
                q = q[free]
        self.q = q
        size = len(q)
        _, _, r, t = forward(robot, self.q)
        self.rho = rho
        self.tree = cKDTree(np.concatenate([t, rho * r.reshape(size, 9)], axis=1))

    def nearest(self, targets: np.ndarray, k: int, pool: int = 1, spread: float = 1.0) -> np.ndarray:
        """(M, k) library indices, nearest first. With pool > k, the k are picked greedily among the `pool` nearest
        so that each differs from those already picked by more than `spread` rad (Euclidean in joint space),
        filling up with the nearest remaining ones: diverse seeds reach different IK branches."""
        k = max(1, min(k, len(self.q)))
        pool = max(k, min(pool, len(self.q)))
        emb = np.concatenate([targets[:, :3, 3], self.rho * targets[:, :3, :3].reshape(len(targets), 9)], axis=1)
        _, ix = self.tree.query(emb, k=pool)
        ix = np.asarray(ix, dtype=np.int64).reshape(len(targets), pool)
        if pool == k:
            return ix
        m = len(ix)
        cand = self.q[ix]  # (M, pool, n)
        chosen = np.zeros((m, pool), dtype=bool)
        chosen[:, 0] = True
        count = np.ones(m, dtype=np.int64)
        for c in range(1, pool):
            d = np.linalg.norm(cand[:, :c] - cand[:, c:c + 1], axis=2)
            d = np.where(chosen[:, :c], d, np.inf).min(axis=1)
            take = (d > spread) & (count < k)
            chosen[:, c] = take
            count += take
        # fill rows that found fewer than k diverse seeds with the nearest unchosen ones
        for c in range(1, pool):
            take = ~chosen[:, c] & (count < k)
            chosen[:, c] |= take
            count += take
        order = np.argsort(~chosen, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(ix, order, axis=1)


def retract(poses: np.ndarray, handx: float, worldz: float, worlda: float = WORLDA) -> np.ndarray:
    """(N, 5, 4, 4) TCP poses of the KINDS (Section IV, ikret): the grasp; moved back by `handx` along the TCP's -z;
    that pose raised by `worldz` along world +z; the grasp raised by `worlda` along world +z (the held object lifted
    straight up); and that pose raised by `worldz`. The orientation is the grasp's throughout."""
    poses = np.asarray(poses, dtype=np.float64)
    out = np.repeat(poses[:, None], len(KINDS), axis=1)
    out[:, 1, :3, 3] -= handx * poses[:, :3, 2]
    out[:, 2, :3, 3] = out[:, 1, :3, 3]
    out[:, 2, 2, 3] += worldz
    out[:, 3, 2, 3] += worlda
    out[:, 4, 2, 3] += worlda + worldz
    return out


def held_placements(targets: np.ndarray, placements: np.ndarray) -> np.ndarray:
    """(N, K, 4, 4) object poses at each pose kind of `targets` (N, K, 4, 4): the resting placement, or for the
    lifts (HELD) the placement carried along by the hand (T_k T_grasp^-1 placement)."""
    out = np.repeat(np.asarray(placements, dtype=np.float64)[:, None], targets.shape[1], axis=1)
    held = np.flatnonzero(HELD[:targets.shape[1]])
    for k in held:
        if np.array_equal(targets[:, k, :3, :3], targets[:, 0, :3, :3]):  # `retract`'s lifts: a translation
            out[:, k, :3, 3] += targets[:, k, :3, 3] - targets[:, 0, :3, 3]
        else:
            out[:, k] = targets[:, k] @ np.linalg.inv(targets[:, 0]) @ out[:, k]
    return out


def check_poses(poses: np.ndarray, label: str = "TCP pose") -> np.ndarray:
    """(N, 4, 4) finite rigid transforms, or a RobotError naming the first bad one."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise RobotError(f"{label}s must be an (N, 4, 4) array, got shape {poses.shape}")
    bad = ~np.isfinite(poses).all(axis=(1, 2))
    if bad.any():
        raise RobotError(f"{label} {int(np.argmax(bad))} (of {len(poses)}) has NaN or infinite entries; rebuild the tabletop grips")
    r = poses[:, :3, :3]
    dev = np.zeros(len(poses))
    for i in range(3):  # |R R^T - I| entry by entry: columns of the (N,) batch, no batched 3x3 products
        for j in range(i, 3):
            dot = r[:, i, 0] * r[:, j, 0] + r[:, i, 1] * r[:, j, 1] + r[:, i, 2] * r[:, j, 2]
            dev = np.maximum(dev, np.abs(dot - (i == j)))
    if (dev > 1e-5).any():
        raise RobotError(f"{label} {int(np.argmax(dev > 1e-5))} (of {len(poses)}) is not a rigid transform; rebuild the tabletop grips")
    return poses


def neighbour_order(grips: dict[str, np.ndarray]) -> np.ndarray:
    """Indices sorting grips so consecutive ones are close: by free-air grasp, then placement orientation (which
    includes the rotation angle), then position in a serpentine over the grid (x rows, y alternating)."""
    n = len(grips["rotmat"])
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    rot = np.asarray(grips["placement_rotmat"])
    if "idtabletopplacements" in grips:  # one rotation per tabletop placement: sort the few distinct ones
        _, first, inverse = np.unique(np.asarray(grips["idtabletopplacements"]), return_index=True, return_inverse=True)
        _, orient = np.unique(np.round(rot[first, :3, :3].reshape(len(first), 9), 6), axis=0, return_inverse=True)
        orient = orient.ravel()[inverse.ravel()]
    else:
        _, orient = np.unique(np.round(rot[:, :3, :3].reshape(n, 9), 6), axis=0, return_inverse=True)
    pos = np.asarray(grips["tabletopposition"], dtype=np.float64)
    ix = np.unique(np.round(pos[:, 0], 4), return_inverse=True)[1].ravel()
    iy = np.unique(np.round(pos[:, 1], 4), return_inverse=True)[1].ravel()
    iy_s = np.where(ix % 2 == 0, iy, -iy)
    return np.lexsort((np.asarray(grips["idtabletopgrips"]), iy_s, ix, orient.ravel(), np.asarray(grips["idfreeairgrip"])))


def chunk_bounds(n: int, chunk: int) -> list[tuple[int, int]]:
    """Fixed chunk boundaries over the sorted grips (they depend only on n, so resumed runs match)."""
    return [(s, min(s + chunk, n)) for s in range(0, n, chunk)]


class ReachFilter:
    """Reachability pre-filter: necessary conditions on the TCP position only (never rejects a reachable pose).

    For a split joint s, the TCP is within L_s (the summed link lengths from joint s's origin to the TCP) of
    joint s's origin, which itself lies on the set swept by the joints before s. For the deepest joint whose
    origin no earlier joint moves (the shoulder) that set is a point; for up to `grid_joints` joints further
    (a humanoid's waist, a UR's shoulder offset) it is sampled on a grid of those joints within their limits,
    and the slack is the largest distance between neighbouring samples. A pose passes when every split's
    condition and the workspace box hold."""

    def __init__(self, robot: Robot, scene: Scene, grid_joints: int = 2, grid: int = 48):

        j0, _ = robot.shoulder()  # 1-based joint index
        n = robot.nq
        self.tests = []
        for s in range(j0, min(j0 + grid_joints, n) + 1):
            length = float(np.linalg.norm(robot.tip_in_joint[:3, 3]))
            for j in range(s + 1, n + 1):
                length += float(np.linalg.norm(robot.chain_placement[j - 1][:3, 3]))
            for j in range(s, n + 1):
                if robot.chain_prismatic[j - 1]:
                    length += float(max(abs(robot.lower[j - 1]), abs(robot.upper[j - 1])))
            gridded = [j for j in range(1, s) if j > 0] if s > j0 else []
            if len(gridded) > grid_joints:
                continue
            axes = [np.linspace(robot.lower[j - 1], robot.upper[j - 1], grid) for j in gridded]
            q = np.tile(robot.neutral(), (grid ** len(gridded), 1))
            if gridded:
                mesh = np.meshgrid(*axes, indexing="ij")
                for j, m in zip(gridded, mesh):
                    q[:, j - 1] = m.ravel()
            _, pos, _, _ = forward(robot, q)
            pts = pos[:, s - 1]
            slack = 0.0
            if gridded:
                g = pts.reshape(*([grid] * len(gridded)), 3)
                for ax in range(len(gridded)):
                    slack += float(np.linalg.norm(np.diff(g, axis=ax), axis=-1).max())
            self.tests.append((cKDTree(pts), length + slack))
        self.wmin = np.asarray(scene.workspace_min)
        self.wmax = np.asarray(scene.workspace_max)

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        """(...) bool for TCP poses (..., 4, 4): True where the pose may be reachable."""
        p = np.asarray(poses)[..., :3, 3]
        flat = p.reshape(-1, 3)
        ok = (flat >= self.wmin).all(-1) & (flat <= self.wmax).all(-1)
        for tree, bound in self.tests:
            if ok.any():
                d, _ = tree.query(flat[ok], k=1)
                sub = ok[ok]
                sub &= d <= bound
                ok[ok] = sub
        return ok.reshape(p.shape[:-1])


def converge(robot: Robot, targets: np.ndarray, q0: np.ndarray, iters: int, opts: IKOptions = IKOptions()) -> tuple[np.ndarray, np.ndarray]:
    """The solver's numeric core without collision checks, for callers that check their own (straight TCP lines
    checked against the table, the object and the arm itself): joint vectors (M, n) from seeds `q0` for TCP poses
    (M, 4, 4) and whether each converged within `opts`' tolerances and the joint limits."""
    return solve_ik(robot, targets, q0, iters, opts.tol_pos, opts.tol_rot)


CLOSED_BLOCK = 1024  # targets per closed-form pass: all their branches stay in the CPU caches


class IKSolver:
    """One robot's IK engine for a scene and an object (Section IV): the robot, its seed library, its collider
    (arm and gripper against the table, arm against the object) and the reachability pre-filter, built once.

    `solve` is the one batched solve-and-check step; `chunk` walks sorted grips in warm-started lanes (the
    precomputation); the roadmap planner's query-time IK (`planners.wan_harada.query.GripIK`) calls `solve`
    with its own seeds (the nearest stored solutions) and `library_seeds` for the fall-back."""

    def __init__(self, robot: Robot, scene: Scene, opts: IKOptions = IKOptions(), obj_mesh: trimesh.Trimesh | None = None):
        self.robot, self.scene, self.opts = robot, scene, opts
        self.collider = Collider(robot, scene, obj_mesh) if opts.collide else None
        self.self_collision = SelfCollision(robot) if opts.collide and opts.self_collide else None
        self.analytic = closed_form(robot) if opts.solver == "auto" else None
        self.nearby = nearby_form(robot) if opts.solver == "auto" and self.analytic is None else None
        # a swept joint misses poses that need it between samples: its branches without the limits seed LM there
        self.unlimited = closed_form(robot, limits=False) if self.analytic is not None and robot.nq > 6 else None
        # and skips the poses its wrist cannot reach at any joint 7 (no numerical solve could accept them)
        self.shell = wrist_shell(robot, opts.tol_pos, opts.tol_rot) if self.unlimited is not None else None
        self.library = SeedLibrary(robot, opts.library if self.analytic is None else 64, opts.seed, collider=self.collider)
        self.prefilter = ReachFilter(robot, scene)
        self._wrap = bool((robot.upper - robot.lower > 2 * np.pi).any())  # a joint spanning more than a turn

    def for_object(self, obj_mesh: trimesh.Trimesh | None) -> IKSolver:
        """This solver for another object: its own collider, the same robot, seed library (the library keeps the seeds
        clear of the table, which no object changes), self-collision model and reachability filter."""
        other = copy.copy(self)
        other.collider = Collider(self.robot, self.scene, obj_mesh) if self.opts.collide else None
        return other

    def solve(self, targets: np.ndarray, placements: np.ndarray, q0: np.ndarray, iters: int) -> tuple[np.ndarray, np.ndarray]:
        """Joint vectors (M, n) from seeds `q0` for TCP poses (M, 4, 4) of grips of the object at `placements`
        (M, 4, 4), and whether each converged within the limits and is collision-free. With the closed form: the
        collision-free branch nearest to the seed."""
        if self.analytic is not None:
            return self._closed(targets, placements, q0)
        return self._numeric(targets, placements, q0, iters)

    def _numeric(self, targets: np.ndarray, placements: np.ndarray, q0: np.ndarray, iters: int) -> tuple[np.ndarray, np.ndarray]:
        """Levenberg-Marquardt from `q0`, then the collision checks (`solve` without the closed form)."""
        o = self.opts
        q, ok = solve_ik(self.robot, targets, q0, iters, o.tol_pos, o.tol_rot)
        if self.collider is not None and ok.any():
            sel = np.flatnonzero(ok)
            ok[sel[self.collider.collides_q(q[sel], placements[sel])]] = False
        if self.self_collision is not None and ok.any():
            sel = np.flatnonzero(ok)
            ok[sel[self.self_collision.collides(q[sel])]] = False
        return q, ok

    def _closed(self, targets: np.ndarray, placements: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The collision-free closed-form branch of every target nearest to `q0` (rows of NaN: none), CLOSED_BLOCK
        targets at a time (a 7-joint arm's 128 branches of a whole chunk would fill hundreds of MB; each row depends
        on its own target alone)."""
        if len(targets) <= CLOSED_BLOCK:
            return self._closed_block(targets, placements, q0)
        parts = [self._closed_block(targets[s:s + CLOSED_BLOCK], placements[s:s + CLOSED_BLOCK],
                                    None if q0 is None else q0[s:s + CLOSED_BLOCK])
                 for s in range(0, len(targets), CLOSED_BLOCK)]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def _closed_block(self, targets: np.ndarray, placements: np.ndarray, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`_closed` of one block. Branches are checked nearest first, each row only until one is free: the same
        answer as checking them all."""
        m, n = len(targets), self.robot.nq
        joints, valid = self.analytic.solve(targets)
        ref = np.where(np.isfinite(q0), q0, 0.0) if q0 is not None else np.zeros((m, n))
        q, ok = self._nearest_free(joints, valid, ref, placements)
        if self.unlimited is not None:  # the fall-backs add solutions where there were none, never replace one
            q, ok = self._between_samples(targets, placements, valid, ref, q, ok)
            q, ok = self._refined(targets, placements, valid, ref, q, ok)
        return q, ok

    def _nearest_free(self, joints: np.ndarray, valid: np.ndarray, ref: np.ndarray,
                      placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per row of branches (M, B, n), the collision-free valid one nearest `ref` (M, n) (rows of NaN: none)."""
        m, n = len(joints), self.robot.nq
        dist = np.empty(valid.shape)
        rank = np.empty(valid.shape, dtype=np.int64)
        branch_order(joints, valid, np.ascontiguousarray(ref, dtype=np.float64), self.robot.lower, self.robot.upper,
                     self._wrap, dist, rank)
        q = np.full((m, n), np.nan)
        ok = np.zeros(m, dtype=bool)
        left = np.flatnonzero(np.isfinite(dist).any(axis=1))
        for r in range(joints.shape[1]):
            b = rank[left, r]
            left = left[np.isfinite(dist[left, b])]
            if not len(left):
                break
            b = rank[left, r]
            cand = joints[left, b]
            free = np.ones(len(left), dtype=bool)
            if self.collider is not None:
                free &= ~self.collider.collides_q(cand, placements[left])
            if self.self_collision is not None and free.any():
                sel = np.flatnonzero(free)
                free[sel[self.self_collision.collides(cand[sel])]] = False
            q[left[free]], ok[left[free]] = cand[free], True
            left = left[~free]
        return q, ok

    def _reachable_rows(self, targets: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """The `rows` of targets that pass the reach filter and a 7-joint arm's wrist shell."""
        rows = rows[self.prefilter(targets[rows])] if len(rows) else rows
        if self.shell is not None and len(rows):
            rows = rows[self.shell(targets[rows])]
        return rows

    def _refined(self, targets: np.ndarray, placements: np.ndarray, valid: np.ndarray, ref: np.ndarray,
                 q: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses still without a collision-free branch: the swept joint's angles between its samples (a window of
        free branches narrower than the sweep's spacing, `ClosedForm.refine`), nearest `ref` first."""
        rows = self._reachable_rows(targets, np.flatnonzero(~ok)) if self.analytic.refine is not None else []
        if not len(rows):
            return q, ok
        joints, fine = self.analytic.refine(targets[rows], valid[rows])
        dist = np.empty(fine.shape)
        rank = np.empty(fine.shape, dtype=np.int64)
        branch_order(joints, fine, np.ascontiguousarray(ref[rows], dtype=np.float64), self.robot.lower,
                     self.robot.upper, self._wrap, dist, rank)
        r, b = np.nonzero(fine)  # every valid branch in one check (few rows; most of them collide everywhere)
        free = np.ones(len(r), dtype=bool)
        if self.collider is not None and len(r):
            free &= ~self.collider.collides_q(joints[r, b], placements[rows[r]])
        if self.self_collision is not None and free.any():
            sel = np.flatnonzero(free)
            free[sel[self.self_collision.collides(joints[r[sel], b[sel]])]] = False
        d = np.full(fine.shape, np.inf)
        d[r[free], b[free]] = dist[r[free], b[free]]
        best = np.argmin(d, axis=1)  # the nearest free one (ties: the first in branch order, as nearest-first does)
        hit = np.isfinite(d[np.arange(len(rows)), best])
        q[rows[hit]], ok[rows[hit]] = joints[np.flatnonzero(hit), best[hit]], True
        return q, ok

    def _between_samples(self, targets: np.ndarray, placements: np.ndarray, valid: np.ndarray, ref: np.ndarray,
                         q: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Poses a swept closed form misses within the limits although the arm reaches them: Levenberg-Marquardt from
        their branch nearest `ref` without the limits (clipped into them by the solver), which the free joint then
        moves off its sample, up to BETWEEN_TRIES branches nearest `ref` first; then `solve_from_seeds`. Poses the
        wrist cannot reach at any angle of the swept joint (`solvers.wrist_shell`) are not tried: none would converge."""
        rows = self._reachable_rows(targets, np.flatnonzero(~valid.any(axis=1)))
        if not len(rows):
            return q, ok
        qu, vu = self.unlimited.solve(targets[rows])
        qu, dist = branch_distances(qu, vu, ref[rows])
        rank = np.argsort(dist, axis=1, kind="stable")[:, :BETWEEN_TRIES]
        for r in range(rank.shape[1]):  # nearest first, each row until one converges
            b = rank[:, r]
            sel = np.flatnonzero(np.isfinite(dist[np.arange(len(rows)), b]) & ~ok[rows])
            if not len(sel):
                break
            qn, okn = self._numeric(targets[rows[sel]], placements[rows[sel]], qu[sel, b[sel]], self.opts.iters_seed)
            q[rows[sel[okn]]], ok[rows[sel[okn]]] = qn[okn], True
        rest = rows[~ok[rows]]
        if len(rest):  # then the numerical solver's own seeds: the library's and the pose-hashed restarts
            qn, okn = self.solve_from_seeds(targets[rest], placements[rest], np.full((len(rest), self.robot.nq), np.nan),
                                            numeric=True)
            q[rest[okn]], ok[rest[okn]] = qn[okn], True
        return q, ok

    def _chunk_closed(self, targets: np.ndarray, placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """`chunk` with the closed form: the grasp takes the collision-free branch nearest the robot's home
        configuration (`Robot.home`; the others stay available to the query-time IK), every other pose the branch
        nearest to its neighbour's on the way (handx from the grasp, handxworldz from handx, worlda from the grasp,
        worldaworldz from worlda; from the grasp's when the neighbour has none). The object is held at the lifts."""
        c, nk, n = len(targets), targets.shape[1], self.robot.nq
        place = held_placements(targets, placements)  # (C, K, 4, 4)
        feas = np.zeros((c, nk), dtype=bool)
        joints = np.full((c, nk, n), np.nan)
        q, ok = self._closed(targets[:, 0], place[:, 0], np.broadcast_to(self.robot.home(), (c, n)))
        feas[:, 0], joints[:, 0] = ok, q
        grasp_ref = np.where(ok[:, None], q, 0.0)
        for k, prev in ON_THE_WAY[: nk - 1]:
            ref = np.where(feas[:, prev, None], np.nan_to_num(joints[:, prev]), grasp_ref)
            q, ok = self._closed(targets[:, k], place[:, k], ref)
            feas[:, k], joints[:, k] = ok, q
        return feas, joints

    def library_seeds(self, targets: np.ndarray) -> np.ndarray:
        """(M, seeds) library indices tried after the warm start, diverse among the nearest (IKOptions)."""
        o = self.opts
        return self.library.nearest(targets, o.seeds, pool=o.seed_pool, spread=o.seed_spread)

    def chunk(self, targets: np.ndarray, placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One chunk of sorted grips: targets (C, K, 4, 4) -> feasible (C, K), joints (C, K, n) for the K = 5 KINDS.

        Each grip is solved on its own, so its row depends on the grip alone, never on the chunk, the worker or its
        neighbours: the grasp from the library seed nearest to its pose, every other pose first from its neighbour's
        solution on the way (handx from the grasp, handxworldz from handx, worlda from the grasp, worldaworldz from
        worlda); then the failures from up to `seeds` diverse library seeds and `restarts` random configurations
        drawn from a hash of the pose, one seed rank at a time for the poses still unsolved."""
        if self.analytic is not None:
            return self._chunk_closed(targets, placements)
        c, n, nk = len(targets), self.robot.nq, targets.shape[1]
        place = held_placements(targets, placements)
        feas = np.zeros((c, nk), dtype=bool)
        joints = np.full((c, nk, n), np.nan)
        for k, prev in ((0, -1), *ON_THE_WAY)[:nk]:
            warm = joints[:, prev] if prev >= 0 else np.full((c, n), np.nan)
            joints[:, k], feas[:, k] = self.solve_from_seeds(targets[:, k], place[:, k], warm)
        return feas, chain_turns(self.robot, joints)

    def solve_from_seeds(self, targets: np.ndarray, placements: np.ndarray, warm: np.ndarray,
                         numeric: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Joints (M, n) (NaN where none) and feasibility (M,) of poses that pass the reach filter, each from its own
        seeds in a fixed order (`chunk`): `warm` (rows of NaN: none) or the nearest library seed; the branches of the
        nearest decomposable model (`solvers.nearby_form`, an arm with more than 7 joints), nearest the home first;
        the other library seeds; the restarts. With `numeric`, Levenberg-Marquardt from every seed even where the robot
        has a closed form (the poses its swept samples miss)."""
        o = self.opts
        m, n = len(targets), self.robot.nq
        q_out = np.full((m, n), np.nan)
        good = np.zeros(m, dtype=bool)
        live = np.flatnonzero(self.prefilter(targets))
        if len(live) == 0:
            return q_out, good
        near = self.library.nearest(targets[live], max(1, o.seeds), pool=o.seed_pool, spread=o.seed_spread)
        q0 = warm[live].copy()
        cold = np.isnan(q0).any(axis=1)
        q0[cold] = self.library.q[near[cold, 0]]
        tries = [(q0, o.iters_warm, np.ones(len(live), dtype=bool))]
        if self.nearby is not None:  # the nearest decomposable model's exact branches, nearest the home first
            qb, vb = self.nearby.solve(targets[live])
            qb, dist = branch_distances(qb, vb, self.robot.home(), self.robot.lower, self.robot.upper)
            rank = np.argsort(dist, axis=1, kind="stable")[:, :max(1, o.seeds)]
            for r in range(rank.shape[1]):
                b = rank[:, r]
                rows = np.arange(len(live))
                tries.append((np.nan_to_num(qb[rows, b]), o.iters_warm, np.isfinite(dist[rows, b])))
        for r in range(o.seeds):  # the nearest seed was tried first where there was no warm start
            tries.append((self.library.q[near[:, r]], o.iters_seed, ~cold if r == 0 else np.ones(len(live), dtype=bool)))
        if o.restarts:
            keys = pose_keys(targets[live], o.seed)
        for r in range(o.restarts):
            tries.append((random_configurations(self.robot, keys, r), o.iters_seed, np.ones(len(live), dtype=bool)))
        left = np.ones(len(live), dtype=bool)
        for seeds, iters, use in tries:
            sel = np.flatnonzero(left & use)
            if len(sel) == 0:
                continue
            rows = live[sel]
            q, ok = (self._numeric if numeric else self.solve)(targets[rows], placements[rows], seeds[sel], iters)
            q_out[rows[ok]] = q[ok]
            good[rows[ok]] = True
            left[sel[ok]] = False
            if not left.any():
                break
        return q_out, good


def chain_turns(robot: Robot, joints: np.ndarray) -> np.ndarray:
    """Joints (M, K, n) of grips at the KINDS' poses with every joint spanning more than a turn moved by whole turns
    (`analytic.whole_turns`, the same arm poses): the grasp's toward the robot's home configuration, each other pose's
    toward its neighbour's on the way (handx toward the grasp, handxworldz toward handx, worlda toward the grasp,
    worldaworldz toward worlda; toward the grasp's where the neighbour has none), as the closed form's branch choice
    does. A numerical solution from a far seed may lie turns away from home, and the arm would swing them round."""
    if joints.shape[1] == 0 or not (robot.upper - robot.lower > 2 * np.pi).any():
        return joints
    revolute = ~np.asarray(robot.chain_prismatic, dtype=bool)
    out = joints.copy()
    home = robot.home()
    out[:, 0] = whole_turns(out[:, 0], home, robot.lower, robot.upper, revolute)
    grasp = np.where(np.isfinite(out[:, 0]), out[:, 0], home)
    for k, prev in ON_THE_WAY[: joints.shape[1] - 1]:
        ref = np.where(np.isfinite(out[:, prev]).all(axis=1, keepdims=True), out[:, prev], grasp)
        out[:, k] = whole_turns(out[:, k], ref, robot.lower, robot.upper, revolute)
    return out


_MASK64 = np.uint64(0xFFFFFFFFFFFFFFFF)


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 arrays (a bijective bit mixer)."""
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return x ^ (x >> np.uint64(31))


def pose_keys(poses: np.ndarray, seed: int = 0) -> np.ndarray:
    """(M,) uint64 keys hashed from the bytes of poses (M, 4, 4) and `seed`: a grip's random seeds follow from its
    pose alone, whatever chunk or process solves it."""
    words = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(len(poses), 16)).view(np.uint64)
    h = np.full(len(poses), np.uint64(seed) ^ np.uint64(0x9E3779B97F4A7C15), dtype=np.uint64)
    for j in range(16):
        h = _mix(h ^ words[:, j])
    return h


def random_configurations(robot: Robot, keys: np.ndarray, rank: int) -> np.ndarray:
    """(M, n) joint vectors uniform within the limits, the `rank`-th random restart of each key (`pose_keys`)."""
    n = robot.nq
    with np.errstate(over="ignore"):
        ctr = keys[:, None] + np.uint64(rank * n + 1) * np.uint64(0x9E3779B97F4A7C15) + np.arange(n, dtype=np.uint64)
    u = (_mix(ctr) >> np.uint64(11)).astype(np.float64) * 2.0 ** -53
    return robot.lower + u * (robot.upper - robot.lower)


@contextmanager
def children_without_sigint(other_threads: bool = False) -> Iterator[None]:
    """Worker processes started inside never see a terminal's Ctrl-C, which reaches the whole process group: the
    driver stops the run and says so once. SIGINT is blocked in this thread while they start (a signal mask is
    inherited by the processes and threads started meanwhile), and a Ctrl-C in that time is delivered here at the
    end. With `other_threads` (processes started by another thread, as Dask's nannies do), SIGINT is ignored instead,
    which processes inherit too; a Ctrl-C while they start is then lost."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if other_threads:
        old_handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, old_handler)
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


_WORKER_SOLVER: IKSolver | None = None  # the solver of an IKPool worker process, built by its initializer


def _init_worker(spec: RobotSpec, scene: Scene, opts: IKOptions, obj_mesh: trimesh.Trimesh | None) -> None:
    global _WORKER_SOLVER
    _WORKER_SOLVER = IKSolver(robot_from_spec(spec), scene, opts, obj_mesh)


def _work_chunk(poses: np.ndarray, placements: np.ndarray, handx: float, worldz: float,
                worlda: float) -> tuple[np.ndarray, np.ndarray]:
    return _WORKER_SOLVER.chunk(retract(poses, handx, worldz, worlda), placements)


class IKPool:
    """Worker processes that each build the solver once (from the picklable robot spec, which covers the gripper)
    and then solve chunks. Started with `forkserver` (or `spawn`), never `fork`: forking a process that runs
    threads (a Jupyter kernel, BLAS) can deadlock. Make one per run, or keep one for several runs of the same
    robot, scene, options and object; close it (or use it as a context manager) when done."""

    def __init__(self, robot: Robot, scene: Scene, opts: IKOptions, obj_mesh: trimesh.Trimesh | None, workers: int):
        methods = mp.get_all_start_methods()
        ctx = mp.get_context("forkserver" if "forkserver" in methods else "spawn")
        if ctx.get_start_method() == "forkserver":
            ctx.set_forkserver_preload(["workbench.robots.ik"])  # the server imports the library, not the caller
            with children_without_sigint():  # the server, and every worker it forks, inherit the mask
                forkserver.ensure_running()
        self.key = (robot.spec.digest, scene, opts, _mesh_key(obj_mesh))
        self.workers = int(workers)
        self.executor = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx, initializer=_init_worker,
                                            initargs=(robot.spec, scene, opts, obj_mesh))

    def submit(self, poses: np.ndarray, placements: np.ndarray, handx: float, worldz: float, worlda: float):
        """Solve the grips of TCP poses (C, 4, 4) at the five KINDS (`retract`, in the worker: a fifth of the data
        to send) of the object at `placements` (C, 4, 4); a future of `IKSolver.chunk`'s result."""
        return self.executor.submit(_work_chunk, poses, placements, handx, worldz, worlda)

    def close(self) -> None:
        WORKER_CPU_SECONDS[0] += sum(_cpu_seconds(pid) for pid in list(getattr(self.executor, "_processes", None) or {}))
        self.executor.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> "IKPool":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


WORKER_CPU_SECONDS = [0.0]  # processor time of the IKPool workers closed in this process (benchmarks read it)


def _cpu_seconds(pid: int) -> float:
    """User and system time of process `pid` so far (Linux /proc; 0 where it cannot be read)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


def _mesh_key(mesh: trimesh.Trimesh | None) -> str:
    if mesh is None:
        return ""
    return hashlib.sha256(np.asarray(mesh.vertices, dtype=np.float64).tobytes()
                          + np.asarray(mesh.faces, dtype=np.int64).tobytes()).hexdigest()[:16]


def _result(future):
    try:
        return future.result()
    except BrokenProcessPool:
        raise RobotError("the IK worker processes stopped before finishing (a script that starts workers must guard its "
                         "code with `if __name__ == '__main__':`, or use --workers 1)") from None


def diagnose_unreachable(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, obj_mesh: trimesh.Trimesh | None,
                         opts: IKOptions = IKOptions(), samples: int = 24) -> str:
    """Why no grip's grasp pose is feasible, from `samples` of them solved again without collision checks: out of
    reach; the arm's links in the part (the usual sign of a missing gripper mount on a URDF's flange); the table;
    or self-collision. One line with what to try (zero is a result that names its cause)."""
    poses = check_poses(grips["rotmat"])
    places = check_poses(grips["placement_rotmat"], "object placement")
    pick = np.unique(np.linspace(0, len(poses) - 1, min(samples, len(poses))).astype(np.int64))
    free = IKSolver(robot, scene, replace(opts, collide=False))
    targets, placements = poses[pick], places[pick]
    q = np.full((len(pick), robot.nq), np.nan)
    ok = np.zeros(len(pick), dtype=bool)
    seeds = free.library_seeds(targets)
    for k in range(seeds.shape[1]):
        rows = np.flatnonzero(~ok)
        if len(rows) == 0:
            break
        qk, okk = free.solve(targets[rows], placements[rows], free.library.q[seeds[rows, k]], opts.iters_seed)
        q[rows[okk]], ok[rows[okk]] = qk[okk], True
    if not ok.any():
        return (f"none of {len(pick)} sampled grasp poses has an IK solution for {robot.name} within its joint limits, "
                f"even ignoring collisions: they are out of reach; move the grid (--x, --y) toward the robot or the "
                f"robot's base (--base)")
    collider = Collider(robot, scene, obj_mesh)
    hits: dict[tuple[str, str], int] = {}
    for i in np.flatnonzero(ok):
        for h in set(collider.hit_parts(q[i], placements[i])):
            hits[h] = hits.get(h, 0) + 1
    solved = int(ok.sum())
    if hits:
        (part, what), n = max(hits.items(), key=lambda kv: kv[1])
        text = (f"{solved} of {len(pick)} sampled grasp poses have an IK solution, but {part} hits the {what} in {n} of "
                f"them")
        if what == "object" and part != "gripper":
            tcp = np.round(robot.gripper.tcp_in_hand[:3, 3], 6) + 0.0  # no -0 or 1e-17 in the hint
            return (f"{text}: the arm reaches into the part, so the gripper is probably mounted at the wrong place; give "
                    f"the tip-to-TCP transform (--mount x,y,z,roll,pitch,yaw; {robot.gripper.name} on a flange: "
                    f"--mount {tcp[0]:g},{tcp[1]:g},{tcp[2]:g},0,0,0)")
        return f"{text}; move the grid (--x, --y), the table (--table) or the robot's base (--base)"
    if opts.self_collide:
        pairs: dict[tuple[str, str], int] = {}
        checker = SelfCollision(robot)
        for i in np.flatnonzero(ok):
            for pair in checker.colliding(q[i]):
                pairs[pair] = pairs.get(pair, 0) + 1
        if pairs:
            (a, b), n = max(pairs.items(), key=lambda kv: kv[1])
            return (f"{solved} of {len(pick)} sampled grasp poses have an IK solution, but {a} and {b} collide in {n} of "
                    f"them; check the gripper mount (--mount) and the robot's SRDF")
    return (f"{solved} of {len(pick)} sampled grasp poses have a collision-free IK solution here, but the full search "
            f"found none; raise the IK effort (seeds, iterations) or check the retractions (--handx, --worldz)")


SERIAL_CLOSED_GRIPS = 800_000  # grips a 6-joint closed form solves in one process sooner than workers start (~2 s each)


def _one_process_sooner(robot: Robot, opts: IKOptions, grips: int) -> bool:
    """Whether the default worker count should be one: a 6-joint arm's closed form (no numerical fall-back) solves
    `grips` in less time than worker processes take to start and build their solvers."""
    return (robot.nq == 6 and grips <= SERIAL_CLOSED_GRIPS
            and not solver_kind(robot, opts).startswith("numerical"))


def iter_ik(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, handx: float, worldz: float,
            obj_mesh: trimesh.Trimesh | None = None, opts: IKOptions = IKOptions(), workers: int | None = None,
            skip: Callable[[np.ndarray], bool] | None = None, progress: bool = True, solver: IKSolver | None = None,
            pool: IKPool | None = None, worlda: float = WORLDA) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """IK feasibility chunk by chunk (Section IV): yields (grip indices, feasible (C, 5), joints (C, 5, n)) for the
    KINDS (grasp, handx, handxworldz, worlda, worldaworldz).

    `grips` follows the placements contract (rotmat: TCP poses in the world, placement_rotmat: object poses,
    idfreeairgrip, tabletopposition, idtabletopgrips). Chunks for which `skip(indices)` is True are not computed
    (already stored). With one worker the chunks are solved here (by `solver`, or one built for this run); with
    more (default: all cores, or one when a 6-joint closed form finishes sooner alone) by an `IKPool` (`pool`, or one made for this run), whose processes each build the
    solver once."""
    poses = check_poses(grips["rotmat"])
    placements = check_poses(grips["placement_rotmat"], "object placement")
    for label, value in (("handx", handx), ("worldz", worldz), ("worlda", worlda)):
        if not np.isfinite(value) or value < 0:
            raise RobotError(f"retraction {label} must be a finite distance >= 0 m, got {value}")
    order = neighbour_order(grips)
    bounds = chunk_bounds(len(order), opts.chunk)
    todo = [(s, e) for s, e in bounds if skip is None or not skip(order[s:e])]
    if not todo:
        return
    if workers is None and pool is None and _one_process_sooner(robot, opts, sum(e - s for s, e in todo)):
        workers = 1
    workers = pool.workers if pool is not None else (workers or os.cpu_count() or 1)
    workers = max(1, min(workers, len(todo)))
    if pool is not None and pool.key != (robot.spec.digest, scene, opts, _mesh_key(obj_mesh)):
        raise RobotError("the IK pool was made for another robot, scene, options or object; make a new one")
    own_pool = None
    # erased on a terminal; ended with a newline when piped, so the summary printed next starts its own line
    bar = tqdm(total=int(sum(e - s for s, e in todo)), desc=f"ik {robot.name}", unit="grip", disable=not progress,
               leave=not sys.stderr.isatty(), file=sys.stderr)
    try:
        if workers == 1 and pool is None:
            solver = solver or IKSolver(robot, scene, opts, obj_mesh)
            results = (solver.chunk(retract(poses[order[s:e]], handx, worldz, worlda), placements[order[s:e]])
                       for s, e in todo)
        else:
            with children_without_sigint():  # a worker half-started by an interrupted submit prints a traceback
                if pool is None:
                    pool = own_pool = IKPool(robot, scene, opts, obj_mesh, workers)
                futures = [pool.submit(poses[order[s:e]], placements[order[s:e]], handx, worldz, worlda)
                           for s, e in todo]
            results = (_result(f) for f in futures)
        for (s, e), (feas, joints) in zip(todo, results):
            bar.update(e - s)
            yield order[s:e], feas, joints
    finally:
        bar.close()
        if own_pool is not None:
            own_pool.close()


def ik_feasibility(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, handx: float, worldz: float,
                   obj_mesh: trimesh.Trimesh | None = None, opts: IKOptions = IKOptions(), workers: int | None = None,
                   progress: bool = True, worlda: float = WORLDA) -> IKResult:
    """IK feasibility of every grip at the five KINDS of pose (Section IV), in input order."""
    n = len(grips["rotmat"])
    feas = np.zeros((n, len(KINDS)), dtype=bool)
    joints = np.full((n, len(KINDS), robot.nq), np.nan)
    for ix, f, j in iter_ik(robot, grips, scene, handx, worldz, obj_mesh, opts, workers, progress=progress, worlda=worlda):
        feas[ix], joints[ix] = f, j
    return IKResult(feasible=feas, joints=joints, order=neighbour_order(grips))
