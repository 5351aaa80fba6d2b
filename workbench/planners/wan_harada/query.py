"""Start and goal of a regrasp query (Wan & Harada, Section V, "Searching the graph").

A start or goal pose is a stable placement at a position and a yaw that need not be on the grid (`PoseQuery`,
or a 4x4 object pose matched to its placement). Its grips are the placement's free tabletop grips moved to the
pose; each needs IK at the grasp, both retractions and both lifts without arm-table or arm-object collision, as the
precomputation does (`GripIK`, on the precomputation's `robots.ik.IKSolver`). `Side` holds one end's grips and
their IK state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Union

import numpy as np
from scipy.spatial import cKDTree

from workbench.errors import PlanningError
from workbench.planners.wan_harada.roadmap import _failure
from workbench.planners.wan_harada.tabletop import yaw
from workbench.robots.ik import (
    KINDS,
    WORLDA,
    IKOptions,
    IKSolver,
    chain_turns,
    held_placements,
    retract,
)

if TYPE_CHECKING:  # pragma: no cover
    import trimesh

    from workbench.robots.collider import Scene
    from workbench.robots.ik import IKOptions
    from workbench.robots.model import Robot


Query = Union["PoseQuery", np.ndarray, str]
"""A start or goal: a PoseQuery, a `PLACEMENT,X,Y,YAW` string, or a 4x4 object pose on a stable placement."""


@dataclass(frozen=True)
class PoseQuery:
    """An object pose on the table: stable placement `idfreetabletopplacement` moved to (x, y) and turned by `yaw`
    about world z: translate(x, y, 0) @ yaw(theta) @ freetabletopplacement.rotmat."""

    idfreetabletopplacement: int
    x: float
    y: float
    yaw: float

    def move(self) -> np.ndarray:
        """The planar move applied to the free placement."""
        m = yaw(self.yaw)
        m[:2, 3] = (self.x, self.y)
        return m

    def text(self, numbers: dict[int, int] | None = None) -> str:
        """`PLACEMENT,X,Y,YAW deg` for messages: the yaw in degrees with its unit, as the command line takes it; the
        placement by its number within the part where `numbers` (store id -> number) are given."""
        return f"{self.text_degrees(numbers)} deg"

    def text_degrees(self, numbers: dict[int, int] | None = None) -> str:
        """`PLACEMENT,X,Y,YAW` with the yaw in degrees, as the command line takes it (placement as in `text`)."""
        place = (numbers or {}).get(self.idfreetabletopplacement, self.idfreetabletopplacement)
        return f"{place},{self.x:g},{self.y:g},{math.degrees(self.yaw):.6g}"

    def as_dict(self) -> dict:
        return {"placement": self.idfreetabletopplacement, "x": self.x, "y": self.y, "yaw": self.yaw}


def parse_pose(text: str, label: str = "pose", degrees: bool = False) -> PoseQuery:
    """`PLACEMENT,X,Y,YAW` (placement id, metres, metres, radians; degrees with `degrees`, as on the command line,
    where a yaw outside [-360, 360] is refused) as a PoseQuery (yaw in radians); PlanningError on bad input."""
    unit = "deg" if degrees else "rad"
    example = "1,0.5,0.1,45" if degrees else "1,0.5,0.1,0.785"
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 4:
        raise PlanningError(f"{label} {text!r} must be PLACEMENT,X,Y,YAW (placement id, x and y in m, yaw in {unit}), e.g. {example}")
    try:
        pid = int(parts[0])
        x, y, yaw = (float(v) for v in parts[1:])
    except ValueError:
        raise PlanningError(f"{label} {text!r}: PLACEMENT must be an integer id and X, Y, YAW numbers (m, m, {unit})") from None
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise PlanningError(f"{label} {text!r} has NaN or infinite values; give finite x, y (m) and yaw ({unit})")
    if degrees:
        if abs(yaw) > 360:
            raise PlanningError(f"{label} {text!r}: yaw {yaw:g} deg is outside [-360, 360]; give the yaw in degrees, e.g. {example}")
        yaw = math.radians(yaw)
    return check_query(PoseQuery(pid, x, y, yaw), label)


def check_query(query: PoseQuery, label: str) -> PoseQuery:
    """A PoseQuery with finite values, or a PlanningError naming `label`."""
    if not all(math.isfinite(v) for v in (query.x, query.y, query.yaw)):
        raise PlanningError(f"{label} ({query.text()}) has NaN or infinite values; give finite x, y (m) and yaw (rad)")
    return query


def match_pose(pose: np.ndarray, free_ids: np.ndarray, free_poses: np.ndarray, label: str = "pose",
               tol_pos: float = 2e-3, tol_rot: float = 0.02) -> PoseQuery:
    """The stable placement, position and yaw of an object pose in the world (4x4), within `tol_pos` m of the
    table contact height and `tol_rot` rad of tilt; PlanningError when the pose is not on a stable placement."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.isfinite(pose).all():
        raise PlanningError(f"{label} must be a finite 4x4 transform, got shape {pose.shape}")
    r = pose[:3, :3]
    if np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0:
        raise PlanningError(f"{label} is not a rigid transform; give a rotation with orthonormal columns")
    best = (np.inf, -1, 0.0)
    for k, f in enumerate(np.asarray(free_poses)):
        m = r @ f[:3, :3].T  # should be a rotation about z
        tilt = float(np.arccos(np.clip(m[2, 2], -1.0, 1.0)))
        dz = abs(float(pose[2, 3] - f[2, 3]))
        score = tilt + dz / max(tol_pos, 1e-12) * tol_rot
        if score < best[0]:
            best = (score, k, tilt, dz)
    if best[1] < 0:
        raise PlanningError(f"{label}: the object has no stable placements; run `workbench placements` first")
    _, k, tilt, dz = best
    if tilt > tol_rot or dz > tol_pos:
        raise _failure("unstable", f"{label} is not on a stable placement: the nearest (id {int(free_ids[k])}) is {np.degrees(tilt):.1f} deg "
                            f"tilted and {dz * 1000:.1f} mm off in height; give a pose resting on one of the placements "
                            f"{', '.join(str(int(i)) for i in free_ids)}")
    f = free_poses[k]
    m = r @ f[:3, :3].T
    theta = math.atan2(m[1, 0], m[0, 0])
    xy = pose[:2, 3] - (yaw(theta)[:3, :3] @ f[:3, 3])[:2]
    return PoseQuery(int(free_ids[k]), float(xy[0]), float(xy[1]), float(theta))


class GripIK:
    """IK at the five poses of `robots.ik.KINDS` (grasp, handx, handxworldz, worlda, worldaworldz) for grips at start
    and goal poses (Section IV's ik columns; the held object moves with the hand at the lifts),
    with the precomputation's solver (`robots.ik.IKSolver`: same seed library, collider and pre-filter).

    Tier 1 solves every pose from the stored roadmap solution whose TCP pose is nearest (k-d tree over position
    and weighted rotation), capped at `tier1_iters` iterations (most poses converge in a few); tier 2 retries the
    rest from all their other seeds at once (second-nearest stored solution, the grasp's own solution for the
    retractions, the solver's library seeds). A grip is feasible when all five poses are."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None, handx: float, worldz: float,
                 seed_q: np.ndarray, seed_tcp: np.ndarray, opts: IKOptions | None = None, rho: float = 0.1,
                 tier1_iters: int = 15, worlda: float = WORLDA):
        self.robot, self.scene = robot, scene
        self.handx, self.worldz, self.worlda = float(handx), float(worldz), float(worlda)
        self.opts = opts or IKOptions()
        self.tier1_iters = min(int(tier1_iters), self.opts.iters_warm)
        self.rho = rho
        seed_q = np.asarray(seed_q, dtype=np.float64).reshape(-1, robot.nq)
        seed_tcp = np.asarray(seed_tcp, dtype=np.float64).reshape(-1, 4, 4)
        ok = np.isfinite(seed_q).all(axis=1)
        self.seed_q = seed_q[ok]
        self.tree = cKDTree(self._embed(seed_tcp[ok])) if ok.any() else None
        self._obj_mesh = obj_mesh
        self._solver: IKSolver | None = None

    @property
    def solver(self) -> IKSolver:
        """The precomputation's solver for this robot, scene and object (built on first use)."""
        if self._solver is None:
            self._solver = IKSolver(self.robot, self.scene, self.opts, self._obj_mesh)
        return self._solver

    def _embed(self, poses: np.ndarray) -> np.ndarray:
        return np.concatenate([poses[:, :3, 3], self.rho * poses[:, :3, :3].reshape(len(poses), 9)], axis=1)

    def targets(self, tcp: np.ndarray) -> np.ndarray:
        """(n, 5, 4, 4) TCP poses of the KINDS."""
        return retract(np.asarray(tcp, dtype=np.float64).reshape(-1, 4, 4), self.handx, self.worldz, self.worlda)

    def solve(self, tcp: np.ndarray, placements: np.ndarray, known: np.ndarray | None = None, warm: bool = True,
              fallback: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Feasible (n,) and joints (n, 5, nq) for TCP poses (n, 4, 4) of grips of the object at `placements` (n, 4, 4).

        `known` (n, 5, nq) holds poses already solved (NaN elsewhere), e.g. by tier 1. Joints are returned for every
        solved pose, also of infeasible grips (NaN where unsolved)."""
        o, robot, solver = self.opts, self.robot, self.solver
        n, nk = len(tcp), len(KINDS)
        q_out = np.full((n * nk, robot.nq), np.nan)
        if known is not None:
            q_out[:] = np.asarray(known, dtype=np.float64).reshape(n * nk, robot.nq)
        good = np.isfinite(q_out).all(axis=1)
        if n == 0:
            return np.zeros(0, dtype=bool), q_out.reshape(0, nk, robot.nq)
        targets = self.targets(tcp)
        flat = targets.reshape(n * nk, 4, 4)  # row = grip * nk + kind
        place = held_placements(targets, np.asarray(placements, dtype=np.float64).reshape(-1, 4, 4)).reshape(n * nk, 4, 4)
        pre = np.asarray(solver.prefilter(flat), dtype=bool)
        alive = np.repeat(pre.reshape(n, nk).all(axis=1), nk)  # a grip needs all five poses

        near = None
        rows = np.flatnonzero(alive & ~good)
        if self.tree is not None and len(rows):
            k = min(2, len(self.seed_q))
            _, near = self.tree.query(self._embed(flat[rows]), k=k)
            near = np.asarray(near).reshape(len(rows), k)
            if warm:
                q, ok = solver.solve(flat[rows], place[rows], self.seed_q[near[:, 0]], self.tier1_iters)
                q_out[rows[ok]], good[rows[ok]] = q[ok], True
        if fallback:
            left = ~good[rows]
            rows2, near2 = rows[left], (near[left] if near is not None else None)
            if len(rows2):
                seeds, owner = [], []
                if near2 is not None and near2.shape[1] > 1:  # the nearest stored solution was tier 1's seed
                    seeds.append(self.seed_q[near2[:, 1]])
                    owner.append(np.arange(len(rows2)))
                kind = rows2 % nk
                own = (kind > 0) & good[rows2 - kind]
                if own.any():
                    seeds.append(q_out[rows2[own] - kind[own]])
                    owner.append(np.flatnonzero(own))
                if o.seeds > 0:
                    lib = solver.library_seeds(flat[rows2])
                    seeds.append(solver.library.q[lib.ravel()])
                    owner.append(np.repeat(np.arange(len(rows2)), lib.shape[1]))
                if seeds:
                    owner = np.concatenate(owner)
                    q, ok = solver.solve(flat[rows2[owner]], place[rows2[owner]], np.concatenate(seeds), o.iters_seed)
                    hit = np.flatnonzero(ok)
                    win = hit[np.unique(owner[hit], return_index=True)[1]]
                    q_out[rows2[owner[win]]], good[rows2[owner[win]]] = q[win], True
        feas = good.reshape(n, nk).all(axis=1) & alive.reshape(n, nk)[:, 0]
        return feas, chain_turns(robot, q_out.reshape(n, nk, robot.nq))


@dataclass
class Side:
    """The grips of a start or goal pose: free-air grasp ids, TCP poses in the world, jaw widths, roadmap grasp index
    (-1 when the grasp has no roadmap node), IK state (0 unknown, 1 feasible, -1 infeasible, -2 not solved from the
    nearest stored solution, the fall-back seeds still untried), joints (NaN where unsolved), and `prior`:
    the share of the nearest grid placements where the same grasp is IK-feasible (evaluation order only), and
    `robust`: each grasp's contact robustness (1 at the pads' centres, 0 at an edge; NaN unknown), which orders
    routes of equal cost."""

    label: str
    query: PoseQuery
    pose: np.ndarray
    grasp: np.ndarray
    tcp: np.ndarray
    jawwidth: np.ndarray
    rindex: np.ndarray
    state: np.ndarray
    joints: np.ndarray
    prior: np.ndarray | None = None
    robust: np.ndarray | None = None

    @property
    def n_feasible(self) -> int:
        return int((self.state > 0).sum())

    @property
    def n_evaluated(self) -> int:
        return int((self.state != 0).sum())
