"""Collision-free motions between a plan's waypoints (CONVENTIONS.md, Plans and motions).

As wrs, the first author's framework, does for Wan & Harada's plans (Section V): approach and retract are straight
TCP lines, transit (empty hand) and transfer (object in the hand) run in joint space: the straight joint line
when it is free, else OMPL's RRT-Connect within a time budget, then shortcutting.

Collision model (`MotionChecker`, pinocchio + coal on the URDF's collision geometry, `selfcollision.robot_parts`):
- self-collision of the arm and the planning gripper (`SelfCollision`, allowed pairs from the SRDF or sampled);
- the arm's moving links and the gripper against the table slab (the robot's fixed base stands on it);
- empty hand: the arm and the gripper (fingers at the move's opening, `set_jaw`: the pre-grasp opening while
  approaching and retracting; full opening by default) against the object where it rests, the fingers excepted on
  the line between the approach and the grasp (CONVENTIONS.md: the fingers at the grasp);
- holding: the object, attached to the TCP with its grasp, never below the table top's plane (z = 0 lowered by
  `table_tol`, since a placed object touches it; beside the table too), against the arm's links and the robot's
  fixed parts. The gripper's own parts hold it rigidly and are not checked against it.

Resolution (CONVENTIONS.md): a joint-space segment is checked at samples at most `resolution` (1 degree) apart in
every joint and `tcp_step` (5 mm) apart in TCP travel, both; a TCP line is solved by IK at samples at most
`tcp_step` and 1 degree of TCP rotation apart, and the joint path between them is checked the same way. The timed
trajectories' knots keep both bounds too (`planners.wan_harada.motions`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
import trimesh
from scipy.spatial.transform import Rotation, Slerp

from workbench.errors import PlanningError
from workbench.robots.chain import forward, tcp_positions
from workbench.robots.collider import Scene
from workbench.robots.ik import converge
from workbench.robots.model import Robot
from workbench.robots.selfcollision import (
    GRIPPER_FINGERS,
    GRIPPER_HAND,
    AllowedPairs,
    SelfCollision,
    coal_mesh,
    robot_parts,
)

ONE_DEGREE = math.radians(1.0)
FLOOR_SIZE, FLOOR_DEPTH = 20.0, 1.0  # the slab below the table top's plane that a held object must not enter (m)


@dataclass(frozen=True)
class MotionOptions:
    """Motion planning settings: check resolution (rad per joint, m of TCP travel), RRT-Connect's time budget (s),
    shortcut attempts, the seed of OMPL's and the shortcutter's random numbers, the held object's allowance below
    the table top (m), and the largest joint jump between consecutive TCP-line samples (rad)."""

    resolution: float = ONE_DEGREE
    tcp_step: float = 0.005
    budget: float = 1.0
    shortcuts: int = 20
    seed: int = 0
    table_tol: float = 1e-3
    max_jump: float = 0.2

    def __post_init__(self) -> None:
        if not (0 < self.resolution <= ONE_DEGREE + 1e-12) or not (0 < self.tcp_step <= 0.005 + 1e-12):
            raise PlanningError(f"motion resolution must be at most 1 degree and 5 mm, got {math.degrees(self.resolution):.3f} deg "
                                f"and {self.tcp_step * 1000:.2f} mm")
        if not self.budget > 0:
            raise PlanningError(f"motion planning budget must be > 0 s, got {self.budget}")


def _se3(m: np.ndarray) -> pin.SE3:
    m = np.asarray(m, dtype=np.float64)
    return pin.SE3(m[:3, :3].copy(), m[:3, 3].copy())


def _inv(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


class MotionChecker:
    """Validity of configurations and segments for one robot, table and object (see the module docstring).

    `set_resting(pose)` puts the object on the table at `pose` (world) with an empty hand; `set_holding(grasp)`
    attaches it to the TCP with `grasp` (TCP in the object frame); `set_free()` removes it."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None, allowed: AllowedPairs | None = None,
                 opts: MotionOptions = MotionOptions(), obstacles: tuple = ()):
        """`obstacles`: (mesh, world pose) pairs fixed in the world (a task's tray, fixture or neighbouring parts),
        checked against the arm, the hand and the held object."""
        self.robot, self.scene, self.opts = robot, scene, opts
        self.self_collision = SelfCollision(robot, allowed)
        parts = robot_parts(robot)
        gm = pin.GeometryModel()
        for p in parts:
            gm.addGeometryObject(pin.GeometryObject(p.name, p.joint, _se3(p.placement), p.geometry))
        base_inv = _inv(robot.base)
        tmin = np.array([scene.table_min[0], scene.table_min[1], -scene.table_thickness])
        tmax = np.array([scene.table_max[0], scene.table_max[1], 0.0])
        table = np.eye(4)
        table[:3, 3] = 0.5 * (tmin + tmax)
        self.k_table = gm.addGeometryObject(pin.GeometryObject("table", 0, _se3(base_inv @ table), coal.Box(*(tmax - tmin))))
        # the held object never goes below the table top's plane (beyond the tolerance), on the table or beside it
        low = table.copy()
        low[2, 3] = -opts.table_tol - 0.5 * FLOOR_DEPTH
        self.k_table_low = gm.addGeometryObject(pin.GeometryObject(
            "below_table_top", 0, _se3(base_inv @ low), coal.Box(FLOOR_SIZE, FLOOR_SIZE, FLOOR_DEPTH)))
        self.base_inv = base_inv
        self.k_rest = self.k_held = None
        if obj_mesh is not None:
            geo = coal_mesh(obj_mesh)
            self.k_rest = gm.addGeometryObject(pin.GeometryObject("object_resting", 0, pin.SE3.Identity(), geo))
            self.k_held = gm.addGeometryObject(pin.GeometryObject("object_held", robot.nq, pin.SE3.Identity(), geo))
        k_obstacles = [gm.addGeometryObject(pin.GeometryObject(f"obstacle_{i}", 0, _se3(base_inv @ np.asarray(pose, dtype=np.float64)),
                                                               coal_mesh(mesh)))
                       for i, (mesh, pose) in enumerate(obstacles)]
        moving = [k for k, p in enumerate(parts) if p.joint > 0]
        gripper = [k for k, p in enumerate(parts) if p.link in (GRIPPER_HAND, GRIPPER_FINGERS)]
        arm_all = [k for k, p in enumerate(parts) if p.link not in (GRIPPER_HAND, GRIPPER_FINGERS)]
        self.pairs: dict[str, list[int]] = {"self": [], "table": [], "rest": [], "rest_fingers": [], "held": []}

        def add(a: int, b: int, group: str) -> None:
            self.pairs[group].append(len(gm.collisionPairs))
            gm.addCollisionPair(pin.CollisionPair(min(a, b), max(a, b)))

        checked = {frozenset(p) for p in self.self_collision.allowed.checked}
        for i, a in enumerate(parts):  # self-collision pairs in the same model: one C++ call per configuration
            for j in range(i + 1, len(parts)):
                if a.link != parts[j].link and frozenset((a.link, parts[j].link)) in checked:
                    add(i, j, "self")
        for k in moving:
            add(k, self.k_table, "table")
            for o in k_obstacles:
                add(k, o, "table")
        if obj_mesh is not None:
            for k in moving:
                add(k, self.k_rest, "rest_fingers" if parts[k].link == GRIPPER_FINGERS else "rest")
            add(self.k_held, self.k_table_low, "held")
            for o in k_obstacles:
                add(self.k_held, o, "held")
            for k in arm_all:
                add(k, self.k_held, "held")
        self.gripper_parts = gripper
        self.finger_parts = [k for k, p in enumerate(parts) if p.link == GRIPPER_FINGERS]  # in `finger_poses` order
        self.jaw = robot.gripper.jaw_max
        self.gm, self.parts = gm, parts
        self.gd = pin.GeometryData(gm)
        self.data = robot.model.createData()
        self.names = [p.name for p in parts] + ["table", "table"] + [f"obstacle {i}" for i in range(len(k_obstacles))] + \
            ["object", "object"]
        self._lo, self._hi = robot.lower - 1e-9, robot.upper + 1e-9
        # broad phase (dynamic AABB tree) over the same model: it honours the active pairs of `gd`
        self.broad = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(robot.model, gm, self.gd)
        self.mode, self.fingers = "free", True
        self._apply()

    # -- state -----------------------------------------------------------------------------------------------------

    def _apply(self) -> None:
        gd = self.gd
        for group, ks in self.pairs.items():
            on = (group in ("self", "table") or (group == "rest" and self.mode == "resting")
                  or (group == "rest_fingers" and self.mode == "resting" and self.fingers) or (group == "held" and self.mode == "holding"))
            for k in ks:
                gd.activateCollisionPair(k) if on else gd.deactivateCollisionPair(k)

    def set_free(self) -> None:
        """No object: only self-collision and the table."""
        self.mode = "free"
        self._apply()

    def set_resting(self, pose: np.ndarray, fingers: bool = True) -> None:
        """Empty hand, the object resting at `pose` (world); with `fingers` False the fingers may touch it (the line
        between the approach and the grasp: CONVENTIONS.md allows the fingers' contact at the grasp)."""
        if self.k_rest is None:
            return self.set_free()
        self.gm.geometryObjects[self.k_rest].placement = _se3(self.base_inv @ np.asarray(pose, dtype=np.float64))
        self.mode, self.fingers = "resting", bool(fingers)
        self._apply()

    def set_jaw(self, width: float) -> None:
        """Move the fingers to opening `width` (clipped to the stroke): every later check sees them there."""
        g = self.robot.gripper
        width = float(np.clip(width, g.jaw_min, g.jaw_max))
        if width == self.jaw:
            return
        for k, (_, pose) in zip(self.finger_parts, g.finger_poses(width)):
            self.gm.geometryObjects[k].placement = _se3(self.robot.tip_in_joint @ pose)
        self.jaw = width

    def set_holding(self, grasp: np.ndarray) -> None:
        """The object in the hand, held with `grasp` (TCP pose in the object frame)."""
        if self.k_held is None:
            return self.set_free()
        self.gm.geometryObjects[self.k_held].placement = _se3(self.robot.tip_in_joint @ _inv(np.asarray(grasp, dtype=np.float64)))
        self.mode = "holding"
        self._apply()

    # -- checks ----------------------------------------------------------------------------------------------------

    def in_limits(self, q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        return ((q >= self.robot.lower - 1e-9) & (q <= self.robot.upper + 1e-9)).all(axis=1)

    def valid(self, q: np.ndarray) -> bool:
        """Whether one joint vector is within limits and collision-free (self, table, object)."""
        q = np.asarray(q, dtype=np.float64)
        if (q < self._lo).any() or (q > self._hi).any():
            return False
        return not pin.computeCollisions(self.robot.model, self.data, self.broad, q, True)

    def valid_narrow(self, q: np.ndarray) -> bool:
        """`valid` without the broad phase (every active pair through the narrow phase), for cross-checks."""
        q = np.asarray(q, dtype=np.float64)
        if (q < self._lo).any() or (q > self._hi).any():
            return False
        return not pin.computeCollisions(self.robot.model, self.data, self.gm, self.gd, q, True)

    def valid_many(self, q: np.ndarray) -> np.ndarray:
        """(B,) validity of joint vectors (B, n)."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        return np.array([self.valid(x) for x in q], dtype=bool)

    def why(self, q: np.ndarray) -> list[str]:
        """What collides at one joint vector (for messages)."""
        q = np.asarray(q, dtype=np.float64)
        out = []
        pin.computeCollisions(self.robot.model, self.data, self.gm, self.gd, q, False)
        for cp, r, act in zip(self.gm.collisionPairs, self.gd.collisionResults, self.gd.activeCollisionPairs):
            if act and r.isCollision():
                out.append(f"{self.gm.geometryObjects[cp.first].name} hits {self.gm.geometryObjects[cp.second].name}")
        if not self.in_limits(q)[0]:
            out.append("joint limits")
        return out

    def line_samples(self, qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
        """Samples of the straight joint line qa -> qb at most `resolution` apart in every joint and `tcp_step` apart
        in TCP travel (both ends included; a long arm turning at its base moves the TCP 15-20 mm per degree)."""
        qa, qb = np.asarray(qa, dtype=np.float64), np.asarray(qb, dtype=np.float64)
        n = max(1, int(math.ceil(np.abs(qb - qa).max() / self.opts.resolution - 1e-9)))
        for _ in range(8):
            s = qa + np.linspace(0.0, 1.0, n + 1)[:, None] * (qb - qa)
            gap = self.tcp_gap(s)
            if gap <= self.opts.tcp_step:
                return s
            n = int(math.ceil(n * 1.1 * gap / self.opts.tcp_step))
        return s

    def tcp_gap(self, q: np.ndarray) -> float:
        """The largest TCP travel (m) between consecutive joint vectors of q (K, n), K >= 2 (batched FK)."""
        return float(np.linalg.norm(np.diff(tcp_positions(self.robot, q), axis=0), axis=1).max())

    def line_free(self, qa: np.ndarray, qb: np.ndarray) -> bool:
        """Whether the straight joint line qa -> qb is valid at every sample (checked coarse-to-fine)."""
        s = self.line_samples(qa, qb)
        for i in _bisection_order(len(s)):
            if not self.valid(s[i]):
                return False
        return True

    def path_free(self, path: np.ndarray) -> bool:
        """Whether every straight joint piece of a path (K, n) is valid."""
        return all(self.line_free(a, b) for a, b in zip(path[:-1], path[1:]))


def _bisection_order(n: int) -> list[int]:
    """0..n-1, ends first, then midpoints of ever finer halves (finds a collision early)."""
    out, seen = [0, n - 1] if n > 1 else [0], {0, n - 1}
    step = n - 1
    while step > 1:
        half = step // 2
        for i in range(half, n - 1, step):
            if i not in seen:
                seen.add(i)
                out.append(i)
        step = half
    out.extend(i for i in range(n) if i not in seen)
    return out


# ----------------------------------------------------------------------------------------------------------------
# Straight TCP lines.


def _line_targets(robot: Robot, q_from: np.ndarray, target: np.ndarray, tcp_step: float) -> np.ndarray:
    """TCP poses (world) from FK(q_from) to `target` on the straight line (rotation by slerp), at most `tcp_step` and
    1 degree apart, the start excluded, the target included."""
    _, _, r, t = forward(robot, q_from[None])
    r0, t0 = r[0], t[0]
    r1, t1 = np.asarray(target)[:3, :3], np.asarray(target)[:3, 3]
    dist = float(np.linalg.norm(t1 - t0))
    ang = float(Rotation.from_matrix(r0.T @ r1).magnitude())
    n = max(1, int(math.ceil(max(dist / tcp_step, ang / ONE_DEGREE) - 1e-9)))
    s = np.linspace(0.0, 1.0, n + 1)[1:]
    out = np.tile(np.eye(4), (n, 1, 1))
    out[:, :3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([r0, r1])))(s).as_matrix()
    out[:, :3, 3] = t0 + s[:, None] * (t1 - t0)
    return out


def tcp_line_to(robot: Robot, checker: MotionChecker, q_from: np.ndarray, target: np.ndarray, iters: int = 40) -> np.ndarray | None:
    """The joint path (K, n) from q_from moving the TCP on the straight line to the pose `target` (world), solved by
    IK at samples at most `tcp_step` and 1 degree apart (all seeded from q_from in one batch; where that jumps
    branches, sample by sample from the previous solution). None when IK fails, a joint jumps more than
    `max_jump`, or a piece is not collision-free at the resolution."""
    o = checker.opts
    q_from = np.asarray(q_from, dtype=np.float64)
    targets = _line_targets(robot, q_from, target, o.tcp_step)
    q, ok = converge(robot, targets, np.repeat(q_from[None], len(targets), axis=0), iters)
    path = np.vstack([q_from, q])
    if not ok.all() or np.abs(np.diff(path, axis=0)).max() > o.max_jump:
        prev, rows = q_from, [q_from]
        for tgt in targets:
            qi, oki = converge(robot, tgt[None], prev[None], iters)
            if not oki[0]:
                return None
            prev = qi[0]
            rows.append(prev)
        path = np.array(rows)
        if np.abs(np.diff(path, axis=0)).max() > o.max_jump:
            return None
    if not checker.path_free(path):
        return None
    return path


def tcp_line(robot: Robot, checker: MotionChecker, q_from: np.ndarray, q_to: np.ndarray, iters: int = 40) -> np.ndarray | None:
    """The straight TCP line from FK(q_from) to FK(q_to) that ends at q_to itself (seeded along the joint line);
    None when IK fails, the solution ends elsewhere (another IK branch), jumps, or collides."""
    o = checker.opts
    q_from, q_to = np.asarray(q_from, dtype=np.float64), np.asarray(q_to, dtype=np.float64)
    _, _, r, t = forward(robot, q_to[None])
    target = np.eye(4)
    target[:3, :3], target[:3, 3] = r[0], t[0]
    targets = _line_targets(robot, q_from, target, o.tcp_step)[:-1]
    if len(targets):
        s = np.linspace(0.0, 1.0, len(targets) + 2)[1:-1, None]
        q, ok = converge(robot, targets, q_from + s * (q_to - q_from), iters)
        if not ok.all():
            return None
        path = np.vstack([q_from, q, q_to])
    else:
        path = np.stack([q_from, q_to])
    if np.abs(np.diff(path, axis=0)).max() > o.max_jump or not checker.path_free(path):
        return None
    return path


# ----------------------------------------------------------------------------------------------------------------
# Joint space: straight line, RRT-Connect, shortcuts.


@dataclass
class JointPlan:
    """A joint-space path (K, n) and how it was found: `method` is `line` or `rrtconnect`; seconds spent."""

    path: np.ndarray
    method: str
    seconds: float = 0.0
    vertices_before: int = 0


def rrt_connect(checker: MotionChecker, qa: np.ndarray, qb: np.ndarray, budget: float, seed: int) -> np.ndarray | None:
    """OMPL RRT-Connect from qa to qb within `budget` seconds, motions checked at `resolution` per joint; OMPL's
    random numbers seeded with `seed` (same seed, same path). None when no exact solution is found."""
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    robot = checker.robot
    n = robot.nq
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LOG_NONE)
    try:
        ou.RNG.setSeed(int(seed) % (2 ** 31 - 1) + 1)
        space = ob.RealVectorStateSpace(n)
        bounds = ob.RealVectorBounds(n)
        for i in range(n):
            bounds.setLow(i, float(robot.lower[i]))
            bounds.setHigh(i, float(robot.upper[i]))
        space.setBounds(bounds)
        ss = og.SimpleSetup(space)
        buf = np.empty(n)

        def valid(state) -> bool:
            for i in range(n):
                buf[i] = state[i]
            return checker.valid(buf)

        ss.setStateValidityChecker(valid)
        si = ss.getSpaceInformation()
        # L2 steps of one resolution bound every joint's step by it
        si.setStateValidityCheckingResolution(checker.opts.resolution / space.getMaximumExtent())
        start, goal = si.allocState(), si.allocState()
        for i in range(n):
            start[i], goal[i] = float(qa[i]), float(qb[i])
        ss.setStartAndGoalStates(start, goal)
        ss.setPlanner(og.RRTConnect(si))
        ss.solve(float(budget))
        if not ss.haveExactSolutionPath():
            return None
        p = ss.getSolutionPath()
        path = np.array([[p.getState(k)[i] for i in range(n)] for k in range(p.getStateCount())])
        ss.clear()
        return path
    finally:
        ou.setLogLevel(level)


def shortcut(checker: MotionChecker, path: np.ndarray, attempts: int, seed: int) -> np.ndarray:
    """Shortcut a joint path: greedily join each vertex to the farthest later vertex it sees in a straight free line,
    then `attempts` seeded random shortcuts between points on two pieces (path simplification)."""
    path = np.asarray(path, dtype=np.float64)
    out, i = [path[0]], 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not checker.line_free(path[i], path[j]):
            j -= 1
        out.append(path[j])
        i = j
    path = np.array(out)
    rng = np.random.default_rng(seed)
    for _ in range(attempts):
        if len(path) < 3:
            break
        a, b = sorted(rng.choice(len(path) - 1, size=2, replace=False))
        if a == b:
            continue
        ta, tb = rng.uniform(0, 1, size=2)
        pa = path[a] + ta * (path[a + 1] - path[a])
        pb = path[b] + tb * (path[b + 1] - path[b])
        old = np.linalg.norm(pa - path[a + 1]) + np.linalg.norm(np.diff(path[a + 1:b + 1], axis=0), axis=1).sum() + np.linalg.norm(pb - path[b])
        if np.linalg.norm(pb - pa) < old - 1e-6 and checker.line_free(pa, pb):
            path = np.vstack([path[:a + 1], pa, pb, path[b + 1:]])
    keep = np.ones(len(path), dtype=bool)
    keep[1:] = np.abs(np.diff(path, axis=0)).max(axis=1) > 1e-9
    return path[keep]


def joint_motion(checker: MotionChecker, qa: np.ndarray, qb: np.ndarray, seed: int | None = None) -> JointPlan | None:
    """Transit or transfer (Section V as in wrs): the straight joint line when free, else RRT-Connect within the
    budget and shortcutting; the returned path is checked piece by piece at the resolution. None when not found."""
    o = checker.opts
    seed = o.seed if seed is None else seed
    t0 = time.perf_counter()
    qa, qb = np.asarray(qa, dtype=np.float64), np.asarray(qb, dtype=np.float64)
    if not checker.valid(qa) or not checker.valid(qb):
        return None
    if checker.line_free(qa, qb):
        return JointPlan(np.stack([qa, qb]), "line", time.perf_counter() - t0, 2)
    raw = rrt_connect(checker, qa, qb, o.budget, seed)
    if raw is None:
        return None
    raw[0], raw[-1] = qa, qb
    path = shortcut(checker, raw, o.shortcuts, seed)
    if not checker.path_free(path):  # the final path at the stated resolution
        return None
    return JointPlan(path, "rrtconnect", time.perf_counter() - t0, len(raw))
