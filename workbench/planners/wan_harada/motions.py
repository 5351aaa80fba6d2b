"""The motions of a regrasp plan: waypoints to timed segments (Wan & Harada Section V as executed by wrs).

A plan's steps give joint waypoints (`PlanStep.waypoints()`: handxworldz, handx, grasp, worlda, worldaworldz).
`moves_of_steps` turns them into a list of moves, each with a kind (`approach`, `retract`, `lift`, `lower`: straight
TCP lines; `transit`, `transfer`: joint space; `gripper`: the jaw closes or opens in place), a caption naming the
plan step it serves (pick, transfer, release, regrasp, place) and what the object does (resting at a pose, or held
with a grasp). As the reference implementation moves, the empty hand comes in and backs off along the TCP's
approach axis, and the held part only moves straight up or down near the table: taking it is approach, close,
lift; putting it down is lower, open, retract. `solve_moves` plans and times the moves in order; the first move
that fails is returned so the search can remove what it used and search again.

Executable plans (`plan_executable`), as wrs does for the graph: the best route is searched and its motions
planned; when a motion fails, the roadmap node (or start / goal grip) it used is removed with its edges and the
graph searched again, up to `max_removed` times. A plan says how many it removed; a query that runs out of
alternatives says so in one line.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from workbench.errors import ParameterError, PlanningError
from workbench.grasping.grasps import pregrasp_widths
from workbench.planners.wan_harada.plans import make_plan
from workbench.planners.wan_harada.roadmap import build_roadmap
from workbench.planners.wan_harada.search import search
from workbench.robots.chain import forward
from workbench.robots.ik import WORLDA
from workbench.robots.motion import (
    MotionChecker,
    MotionOptions,
    joint_motion,
    tcp_line_to,
)
from workbench.robots.selfcollision import AllowedPairs, allowed_pairs
from workbench.robots.timing import (
    TimedSegment,
    Trajectory,
    check_limits,
    reversed_trajectory,
    time_line,
    time_spline,
    time_stops,
    within_limits,
)

GRIPPER_SECONDS = 0.5
"""How long the jaw takes to close or open (the arm rests)."""


@dataclass
class Move:
    """One motion to plan: kind, caption, plan step index, start and end joint vectors, whether the object is held,
    the object's resting pose (world) or its grasp (TCP in the object frame), the jaw width during the move, and how
    it is planned: `path` (a given, already checked joint path, e.g. a straight TCP line), `joint` (straight joint
    line, else RRT-Connect) or `dwell` (the jaw moves, the arm rests); `at_grasp`: the move ends or starts at the
    grasp, where the fingers may touch the resting object."""

    kind: str
    caption: str
    step: int
    q_from: np.ndarray
    q_to: np.ndarray
    holding: bool
    object_pose: np.ndarray | None
    grasp: np.ndarray | None
    jaw: float
    how: str
    path: np.ndarray | None = None
    at_grasp: bool = False


@dataclass
class StepLines:
    """Consistent waypoints of one step (one IK branch along the straight TCP lines): retract (handxworldz), approach
    (handx), grasp, worlda and worldaworldz joint vectors, the empty hand's joint paths retract -> approach ->
    grasp (`down`) and the held part's grasp -> worlda -> worldaworldz (`up`); `anchor` names the stored
    configuration they were continued from."""

    q_retract: np.ndarray
    q_approach: np.ndarray
    q_grasp: np.ndarray
    down: list[np.ndarray]
    anchor: str
    q_worlda: np.ndarray | None = None
    q_worldaworldz: np.ndarray | None = None
    up: list[np.ndarray] = field(default_factory=list)

    def shifted(self, shift: np.ndarray) -> "StepLines":
        return StepLines(self.q_retract + shift, self.q_approach + shift, self.q_grasp + shift, [d + shift for d in self.down],
                         self.anchor, self.q_worlda + shift, self.q_worldaworldz + shift, [u + shift for u in self.up])


def _modes(step) -> tuple[tuple[bool, np.ndarray], tuple[bool, np.ndarray]]:
    """(holding, pose-or-grasp) before and after the jaw acts at this step."""
    pose, grasp = np.asarray(step.object_pose, dtype=np.float64), np.asarray(step.grasp, dtype=np.float64)
    taking = step.kind in ("pick", "regrasp")
    empty, held = (False, pose), (True, grasp)
    return (empty, held) if taking else (held, empty)


def _mode(checker: MotionChecker, mode: tuple[bool, np.ndarray], fingers: bool = True) -> None:
    checker.set_holding(mode[1]) if mode[0] else checker.set_resting(mode[1], fingers)


def pregrasp_opening(step, jaw_max: float, margin: float | None) -> float:
    """The jaw opening of the empty hand approaching and leaving `step`'s grasp: its width plus `margin`, capped at
    `jaw_max` (None: full opening), CONVENTIONS.md (Gripper)."""
    return float(pregrasp_widths(np.array([float(step.jawwidth)]), jaw_max, margin)[0])


def step_lines(checker: MotionChecker, step, worlda: float, worldz: float,
               pregrasp_margin: float | None = None) -> StepLines | None:
    """The step's waypoints on one IK branch: the stored configurations may come from different branches (the IK rows
    solve each pose on its own), so the lines are continued by IK from one stored configuration (the grasp, else the
    approach, else the retract): the empty hand's retract -> approach -> grasp, checked with the object resting
    (the fingers may touch it next to the grasp), then the held part's lift grasp -> worlda -> worldaworldz
    (straight up by `worlda`, or back along the step's insertion `lift`; then up by `worldz`), checked with the object
    in the hand. The empty hand's fingers are at the step's pre-grasp opening (`pregrasp_opening`), the holding
    hand's at the grasp's. None when no anchor works."""
    robot = checker.robot
    qs = [np.asarray(step.q_retract, dtype=np.float64), np.asarray(step.q_approach, dtype=np.float64),
          np.asarray(step.q_grasp, dtype=np.float64)]
    _, _, r, t = forward(robot, np.stack(qs))
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = r, t
    resting = (False, np.asarray(step.object_pose, dtype=np.float64))
    held = (True, np.asarray(step.grasp, dtype=np.float64))
    jaw_pre = pregrasp_opening(step, robot.gripper.jaw_max, pregrasp_margin)
    for anchor in (2, 1, 0):
        checker.set_jaw(jaw_pre)
        chain: dict[int, np.ndarray] = {anchor: qs[anchor]}
        paths: dict[tuple[int, int], np.ndarray] = {}
        ok = True
        for a, b in [(i, i - 1) for i in range(anchor, 0, -1)] + [(i, i + 1) for i in range(anchor, 2)]:
            _mode(checker, resting, fingers=2 not in (a, b))  # the fingers may touch the part next to the grasp
            p = tcp_line_to(robot, checker, chain[a], poses[b])  # checked collision-free at the resolution
            if p is None:
                ok = False
                break
            chain[b] = p[-1]
            paths[(min(a, b), max(a, b))] = p if a < b else p[::-1].copy()
        if not ok:
            continue
        _mode(checker, held)
        checker.set_jaw(float(step.jawwidth))
        _, _, rg, tg = forward(robot, chain[2][None])
        lift = np.eye(4)
        lift[:3, :3], lift[:3, 3] = rg[0], tg[0]
        up, q = [], chain[2]
        first = step.lift_vector(worlda)
        for d in (first, first + [0.0, 0.0, worldz]):
            target = lift.copy()
            target[:3, 3] += d
            p = tcp_line_to(robot, checker, q, target)
            if p is None:
                break
            up.append(p)
            q = p[-1]
        if len(up) == 2:
            return StepLines(chain[0], chain[1], chain[2], [paths[(0, 1)], paths[(1, 2)]], ("retract", "approach", "grasp")[anchor],
                             up[0][-1], up[1][-1], up)
    return None


def unwrap_lines(robot, lines: StepLines, start: np.ndarray, near: np.ndarray) -> StepLines:
    """The same waypoints and lines with every revolute joint turned by the whole turns (2 pi k, the same poses and
    collisions) that bring the step's `start` configuration (one of its waypoints) nearest to `near`, within the
    joint limits: a joint whose range exceeds a turn (a UR's) otherwise makes moves between equivalent
    configurations needlessly long or hard."""
    allq = np.vstack([lines.q_retract, lines.q_approach, lines.q_grasp, *lines.down, *lines.up])
    lo, hi = allq.min(axis=0), allq.max(axis=0)
    shift = np.zeros(robot.nq)
    for j in np.flatnonzero(~np.asarray(robot.chain_prismatic)):
        k = np.arange(-3, 4)
        ok = (lo[j] + 2 * np.pi * k >= robot.lower[j] - 1e-12) & (hi[j] + 2 * np.pi * k <= robot.upper[j] + 1e-12)
        if ok.sum() > 1:
            cand = k[ok]
            shift[j] = 2 * np.pi * cand[np.argmin(np.abs(start[j] + 2 * np.pi * cand - near[j]))]
    return lines.shifted(shift) if shift.any() else lines


def _taking(step) -> bool:
    return step.kind in ("pick", "regrasp")


def moves_of_steps(steps, lines: list[StepLines], jaw_open: float, start_held: bool = False,
                   end_held: bool = False, pregrasp_margin: float | None = None) -> list[Move]:
    """The waypoint scheme of `PlanStep.waypoints()`: taking the part (pick, regrasp), the empty hand goes retract ->
    approach -> grasp, closes, and lifts the part straight up grasp -> worlda -> worldaworldz; putting it down
    (transfer, place), the held part goes worldaworldz -> worlda -> grasp, the hand opens and backs off grasp ->
    approach -> retract. A transfer (held) joins a taking step's worldaworldz to the next step's; a transit (empty,
    the part where it was released) joins a putting step's retract to the next step's. With `start_held` the first
    step begins with the part already in the hand at its grasp (no approach, no closing); with `end_held` the last
    ends there with it still in the hand (no opening, no retract). The empty hand's jaw is at the step's pre-grasp
    opening (`pregrasp_opening` with `pregrasp_margin`, capped at `jaw_open`; None: `jaw_open`): it opens to it
    before the approach and after the release; a transit between two steps has the wider of their two openings."""
    out: list[Move] = []
    for i, (s, ln) in enumerate(zip(steps, lines)):
        taking = _taking(s)
        caption = {"pick": "pick", "regrasp": "regrasp", "transfer": "release", "place": "place"}[s.kind]
        pose, grasp = np.asarray(s.object_pose, dtype=np.float64), np.asarray(s.grasp, dtype=np.float64)
        jaw_shut = float(s.jawwidth)
        jaw_pre = pregrasp_opening(s, jaw_open, pregrasp_margin)

        def mv(kind, path, holding, jaw, how="path", at_grasp=False):
            out.append(Move(kind, caption, i, path[0].copy(), path[-1].copy(), holding, None if holding else pose,
                            grasp if holding else None, jaw, how, path, at_grasp))

        if taking:
            if not (start_held and i == 0):
                mv("approach", ln.down[0], False, jaw_pre)
                mv("approach", ln.down[1], False, jaw_pre, at_grasp=True)
                mv("gripper", np.stack([ln.q_grasp, ln.q_grasp]), True, jaw_shut, "dwell", at_grasp=True)
            mv("lift", ln.up[0], True, jaw_shut)
            mv("lift", ln.up[1], True, jaw_shut)
            if i + 1 < len(steps):
                out.append(Move("transfer", "transfer", i, ln.q_worldaworldz.copy(), lines[i + 1].q_worldaworldz.copy(), True,
                                None, grasp, jaw_shut, "joint"))
        else:
            mv("lower", ln.up[1][::-1].copy(), True, jaw_shut)
            mv("lower", ln.up[0][::-1].copy(), True, jaw_shut)
            if end_held and i == len(steps) - 1:
                continue
            mv("gripper", np.stack([ln.q_grasp, ln.q_grasp]), False, jaw_pre, "dwell", at_grasp=True)
            mv("retract", ln.down[1][::-1].copy(), False, jaw_pre, at_grasp=True)
            mv("retract", ln.down[0][::-1].copy(), False, jaw_pre)
            if i + 1 < len(steps):
                out.append(Move("transit", "regrasp", i, ln.q_retract.copy(), lines[i + 1].q_retract.copy(), False, pose,
                                None, max(jaw_pre, pregrasp_opening(steps[i + 1], jaw_open, pregrasp_margin)), "joint"))
    return out


@dataclass
class MotionResult:
    """Timed segments of the solved moves (all of them when `failed` is None), the index of the first move that
    failed and why, and planning statistics (seconds, how many RRT-Connect calls)."""

    segments: list[TimedSegment]
    failed: int | None = None
    reason: str = ""
    seconds: float = 0.0
    rrt: int = 0
    stats: dict = field(default_factory=dict)
    blame: tuple = ()

    @property
    def ok(self) -> bool:
        return self.failed is None

    @property
    def duration(self) -> float:
        return (self.segments[-1].t0 + self.segments[-1].duration) if self.segments else 0.0


def _set(checker: MotionChecker, m: Move, jaw: float) -> None:
    checker.set_jaw(jaw)
    if m.holding:
        checker.set_holding(m.grasp)
    elif m.object_pose is not None:
        checker.set_resting(m.object_pose, fingers=not m.at_grasp)
    else:
        checker.set_free()


def _knots_ok(checker: MotionChecker, traj: Trajectory) -> bool:
    return all(checker.valid(q) for q in traj.q)


def solve_moves(checker: MotionChecker, moves: list[Move], vlim: np.ndarray, alim: np.ndarray | float,
                seed: int | None = None) -> MotionResult:
    """Plan and time every move in order (see the module docstring); stops at the first that fails.

    Every trajectory's knots (at most 1 degree and 5 mm of TCP travel apart) are checked again after timing: a
    spline that strays from the checked path is replaced by rest-to-rest timing along its pieces."""
    robot = checker.robot
    vlim, alim = check_limits(vlim, alim, robot.nq)
    seed = checker.opts.seed if seed is None else seed
    t_start = time.perf_counter()
    segments: list[TimedSegment] = []
    t0, rrt = 0.0, 0
    methods: dict[str, int] = {}
    timed: dict[tuple, Trajectory] = {}
    jaw = robot.gripper.jaw_max
    for k, m in enumerate(moves):
        # the fingers at the move's opening; while the jaw acts, at the wider of its two openings
        _set(checker, m, max(m.jaw, jaw) if m.how == "dwell" else m.jaw)
        jaw = m.jaw
        if m.how == "dwell":
            if not checker.valid(m.q_from):
                return MotionResult(segments, k, f"{m.caption}: the {m.kind} configuration collides ({', '.join(checker.why(m.q_from))})",
                                    time.perf_counter() - t_start, rrt, methods)
            traj = Trajectory(np.array([0.0, GRIPPER_SECONDS]), np.stack([m.q_from, m.q_from]), np.zeros((2, robot.nq)))
            method = "dwell"
        elif m.how == "path":
            key = (m.path[0].tobytes(), m.path[-1].tobytes(), len(m.path))
            back = (m.path[-1].tobytes(), m.path[0].tobytes(), len(m.path))
            if back in timed:
                traj = reversed_trajectory(timed[back])  # the way down played backwards
                if not _knots_ok(checker, traj):
                    traj = _timed(checker, m.path, vlim, alim)
            else:
                traj = _timed(checker, m.path, vlim, alim)
            if traj is not None:
                timed[key] = traj
            method = "tcp-line"
        else:
            jp = joint_motion(checker, m.q_from, m.q_to, seed=seed + k)
            if jp is None:
                return MotionResult(segments, k, f"{m.caption}: no collision-free {m.kind} motion within "
                                    f"{checker.opts.budget:g} s of RRT-Connect", time.perf_counter() - t_start, rrt + 1, methods)
            rrt += jp.method == "rrtconnect"
            traj, method = _timed(checker, jp.path, vlim, alim), jp.method
        if traj is None:
            return MotionResult(segments, k, f"{m.caption}: the timed {m.kind} leaves the checked path",
                                time.perf_counter() - t_start, rrt, methods)
        methods[method] = methods.get(method, 0) + 1
        segments.append(TimedSegment(m.kind, m.caption, m.step, m.holding, t0, traj, method, m.jaw))
        t0 += traj.duration
    return MotionResult(segments, None, "", time.perf_counter() - t_start, rrt, methods)


def _timed(checker: MotionChecker, path: np.ndarray, vlim: np.ndarray, alim: np.ndarray) -> Trajectory | None:
    """The path timed with knots at most 1 degree apart in every joint and the checker's `tcp_step` (5 mm) apart in
    TCP travel (a long arm turning at its base moves the TCP 15-20 mm per degree)."""
    def spacing(q: np.ndarray) -> float:
        return checker.tcp_gap(q) / checker.opts.tcp_step

    if len(path) == 2:
        return time_line(path[0], path[1], vlim, alim, spacing=spacing)
    traj = time_spline(path, vlim, alim, spacing=spacing)
    if not within_limits(traj, checker.robot.lower, checker.robot.upper, vlim, alim) and _knots_ok(checker, traj):
        return traj
    traj = time_stops(path, vlim, alim, spacing=spacing)
    return traj if _knots_ok(checker, traj) else None


def plan_motion(checker: MotionChecker, steps, vlim: np.ndarray, alim: np.ndarray | float, seed: int | None = None,
                worlda: float = WORLDA, worldz: float = 0.10, start_held: bool = False,
                end_held: bool = False, pregrasp_margin: float | None = None) -> tuple[MotionResult, list[StepLines | None]]:
    """The timed motion of a whole plan: consistent straight TCP lines at every step, then the moves in
    order (`moves_of_steps`, with the part in the hand at the start or the end when told). On failure `result.blame` is ("step", i) when step i's lines fail (its grip is unusable) or ("edge", i, i+1)
    when the transfer or transit from step i to step i+1 fails; the lines found so far are returned too. The empty
    hand moves at each step's pre-grasp opening (`pregrasp_margin`, None: fully open); the checker's fingers are
    left fully open afterwards."""
    try:
        return _plan_motion(checker, steps, vlim, alim, seed, worlda, worldz, start_held, end_held, pregrasp_margin)
    finally:
        checker.set_jaw(checker.robot.gripper.jaw_max)


def _plan_motion(checker, steps, vlim, alim, seed, worlda, worldz, start_held, end_held, pregrasp_margin):
    t0 = time.perf_counter()
    lines: list[StepLines | None] = []
    for i, s in enumerate(steps):
        ln = step_lines(checker, s, worlda, worldz, pregrasp_margin)
        lines.append(ln)
        if ln is None:
            res = MotionResult([], None, f"step {i + 1} ({s.kind}): no collision-free straight TCP lines between its retract, "
                               f"approach, grasp and lift poses on one IK branch", time.perf_counter() - t0)
            res.failed, res.blame = -1, ("step", i)
            return res, lines
    for i in range(1, len(lines)):  # the move into step i starts where step i - 1 ends
        prev = lines[i - 1]
        if _taking(steps[i - 1]):
            lines[i] = unwrap_lines(checker.robot, lines[i], lines[i].q_worldaworldz, prev.q_worldaworldz)
        else:
            lines[i] = unwrap_lines(checker.robot, lines[i], lines[i].q_retract, prev.q_retract)
    moves = moves_of_steps(steps, lines, checker.robot.gripper.jaw_max, start_held, end_held, pregrasp_margin)
    res = solve_moves(checker, moves, vlim, alim, seed)
    res.seconds = time.perf_counter() - t0
    if not res.ok:
        m = moves[res.failed]
        res.blame = ("edge", m.step, m.step + 1) if m.how == "joint" else ("step", m.step)
    return res, lines


# ----------------------------------------------------------------------------------------------------------------
# Search again when a motion fails (as wrs does).


DEFAULT_ACC = 3.0
"""Default joint acceleration limit (rad/s^2, m/s^2 for prismatic joints): URDFs carry no acceleration limits."""


@dataclass(frozen=True)
class ExecOptions:
    """Motion settings of a query: acceleration limit (scalar or per joint), the share `speed` in (0, 1] of the
    URDF's joint velocity limits the motions are timed under (a URDF may state a drive's peak, at which a held part
    slips), how many failing nodes or grips may be removed before giving up, and the motion planner's options
    (resolution, RRT-Connect budget, seed)."""

    acc: float | tuple[float, ...] = DEFAULT_ACC
    max_removed: int = 10
    motion: MotionOptions = field(default_factory=MotionOptions)
    speed: float = 1.0

    def __post_init__(self):
        if not (isinstance(self.speed, (int, float)) and 0 < self.speed <= 1):
            raise ParameterError(f"motion speed must be a share of the URDF's velocity limits in (0, 1], got {self.speed!r}")

    def velocity_limits(self, robot) -> np.ndarray:
        """The joint velocity limits (nv,) the motions are timed under: the URDF's, times `speed`."""
        return float(self.speed) * np.asarray(robot.model.velocityLimit, dtype=np.float64)


def motion_checker(planner, allowed: AllowedPairs | None = None, opts: MotionOptions = MotionOptions()) -> MotionChecker:
    """The planner's motion checker (robot, table, object), built once per planner and options and kept on it."""
    key = (opts, None if allowed is None else allowed.to_json())
    cached = getattr(planner, "_motion_checker", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    checker = MotionChecker(planner.robot, planner.scene, planner.object.mesh, allowed or allowed_pairs(planner.robot), opts)
    planner._motion_checker = (key, checker)
    return checker


def _node_rows(rm) -> dict[str, np.ndarray]:
    return {"idtabletopgrips": rm.idtabletopgrips, "idtabletopplacements": rm.idtabletopplacements,
            "idfreeairgrip": rm.idfreeairgrip, "rotmat": rm.tcp, "placement_rotmat": rm.placement,
            "tabletopposition": rm.position, "idfreetabletopplacement": rm.idfreetabletopplacement,
            "jawwidth": rm.jawwidth, "angle": rm.yaw, "joints": rm.joints}


@dataclass
class ExecResult:
    """The executable plan (its `segments` set), its motion result, how many nodes or grips were removed, the motion
    planning seconds summed over attempts, the reason of every failed attempt, how many searches ran, and
    executable alternatives (next best routes whose motions were all found)."""

    plan: object | None
    motion: MotionResult | None
    removed: int
    seconds: float
    failures: list[str]
    searched: int
    alternatives: list = field(default_factory=list)
    result: object = None


def plan_executable(planner, start, goal, opts: ExecOptions = ExecOptions(), allowed: AllowedPairs | None = None,
                    alternatives: int = 0, physics: Callable | None = None,
                    on_best: Callable[[ExecResult], None] | None = None) -> ExecResult:
    """The fewest-regrasp plan whose motions are all found (see the module docstring), and up to `alternatives` next
    best executable plans. Raises the search's PlanningError when start or goal is unreachable or unconnected;
    PlanningError(reason "exhausted") when every alternative failed or `max_removed` removals did not help.
    `physics(plan)` returns None or (failing step, why): a timed plan it fails is treated like a failed motion of
    that step (its node or grip removed, the graph searched again); alternatives are not checked by it.
    `on_best(result)` is called with the best executable plan before the alternatives are planned (a viewer shows it
    at once); the alternatives never change the best plan."""
    allowed = allowed if allowed is not None else getattr(planner, "allowed", None)
    checker = motion_checker(planner, allowed, opts.motion)
    robot = planner.robot
    vlim = opts.velocity_limits(robot)
    s_side, g_side = planner.side(start, "start"), planner.side(goal, "goal")
    full = planner.roadmap
    rm, keep = full, np.ones(full.n_nodes, dtype=bool)
    removed, seconds, failures, searched = 0, 0.0, [], 0
    while True:
        s_side.rindex, g_side.rindex = rm.grasp_index(s_side.grasp), rm.grasp_index(g_side.grasp)
        result = search(rm, s_side, g_side, planner.evaluate, 0, True)
        searched += 1
        if not result.routes:
            if removed == 0:
                planner.explain(result)
            err = PlanningError(f"no executable plan from {s_side.query.text(planner.numbers)} to {g_side.query.text(planner.numbers)}: the graph ran out of "
                                f"alternatives after removing {removed} node(s) or grip(s) whose motions failed "
                                f"(last: {failures[-1] if failures else 'none'})")
            err.reason = "exhausted"
            raise err
        route = result.routes[0]
        view = SimpleNamespace(roadmap=rm, object=planner.object, robot=robot, handx=planner.handx, worldz=planner.worldz, worlda=planner.worlda,
                               ids=planner.ids)
        plan = make_plan(view, result, route, 0)
        t0 = time.perf_counter()
        motion, lines = plan_motion(checker, plan.steps, vlim, opts.acc, opts.motion.seed, plan.worlda, plan.worldz,
                                    pregrasp_margin=planner.pregrasp_margin)
        seconds += time.perf_counter() - t0
        verdict = None
        if motion.ok:
            attach_motions(plan, motion, lines, removed, seconds, opts, robot.nq)
            verdict = physics(plan) if physics is not None else None
            if verdict is not None:
                motion.reason, motion.blame = verdict[1], ("step", int(verdict[0]))
        if motion.ok and verdict is None:
            out = ExecResult(plan, motion, removed, seconds, failures, searched, result=result)
            if on_best is not None:
                on_best(out)
            if alternatives > 0:
                more = search(rm, s_side, g_side, planner.evaluate, alternatives, True)
                for r in more.routes:
                    if (r.start_grip, r.goal_grip, r.regrasps) == (route.start_grip, route.goal_grip, route.regrasps):
                        continue
                    alt = make_plan(view, more, r, len(out.alternatives) + 1)
                    t1 = time.perf_counter()
                    m, ls = plan_motion(checker, alt.steps, vlim, opts.acc, opts.motion.seed, alt.worlda, alt.worldz,
                                        pregrasp_margin=planner.pregrasp_margin)
                    if m.ok:
                        attach_motions(alt, m, ls, removed, time.perf_counter() - t1, opts, robot.nq)
                        out.alternatives.append(alt)
                    if len(out.alternatives) >= alternatives:
                        break
            return out
        failures.append(motion.reason)
        if removed >= opts.max_removed:
            err = PlanningError(f"no executable plan from {s_side.query.text(planner.numbers)} to {g_side.query.text(planner.numbers)} after removing "
                                f"{removed} node(s) or grip(s) (limit --max-removed {opts.max_removed}"
                                f"{_physics_share(failures[:-1])}); last failure: {motion.reason}")
            err.reason = "exhausted"
            raise err
        # what the failing motion used: the step's node or grip, or for a transfer / transit the next step's
        i = motion.blame[1] if motion.blame[0] == "step" else motion.blame[2]
        nodes = _step_nodes(route, len(plan.steps))
        kind, idx = nodes[i]
        if kind == "start":
            s_side.state[idx] = -1
        elif kind == "goal":
            g_side.state[idx] = -1
        else:
            gone = np.flatnonzero(full.idtabletopgrips == rm.idtabletopgrips[idx])
            keep[gone] = False
            rm = build_roadmap(_node_rows(full), keep)
        removed += 1


def _physics_share(failures: list[str]) -> str:
    """', N of them after failing in simulation' when physics checks removed any (their reasons start 'physics:')."""
    n = sum(f.startswith("physics:") for f in failures)
    return f", {n} of them after failing in simulation" if n else ""


def attach_motions(plan, motion: MotionResult, lines: list[StepLines], removed: int, seconds: float,
                   opts: ExecOptions, nq: int) -> None:
    """Put the motions on the plan: waypoints on the IK branch the motions use, segments, removals, limits, time."""
    for step, ln in zip(plan.steps, lines):
        step.q_retract, step.q_approach, step.q_grasp = ln.q_retract, ln.q_approach, ln.q_grasp
        step.q_worlda, step.q_worldaworldz = ln.q_worlda, ln.q_worldaworldz
    plan.segments = motion.segments
    plan.removed = removed
    plan.acc = np.broadcast_to(np.asarray(opts.acc, dtype=np.float64), (nq,)).tolist()
    plan.speed = float(opts.speed)
    plan.timings["motion"] = seconds


def _step_nodes(route, n_steps: int) -> list[tuple[str, int]]:
    """Per plan step: ("start", grip), ("node", roadmap node) or ("goal", grip)."""
    out = [("start", route.start_grip)]
    for a, b in route.regrasps:
        out += [("node", a), ("node", b)]
    out.append(("goal", route.goal_grip))
    assert len(out) == n_steps
    return out
