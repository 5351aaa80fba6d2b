"""The motions of a regrasp plan: waypoints to timed segments (Wan & Harada Section V as executed by wrs; issue 12).

A plan's steps give joint waypoints (retract, approach, grasp per step). `moves_of_steps` turns them into a list of
moves, each with a kind (`approach`, `retract`: straight TCP lines; `transit`, `transfer`: joint space; `gripper`:
the jaw closes or opens in place), a caption naming the plan step it serves (pick, transfer, release, regrasp,
place) and what the object does (resting at a pose, or held with a grasp). `solve_moves` plans and times them in
order; the first move that fails is returned so the search can remove what it used and search again.

Other waypoint schemes (lift straight up after closing, lower straight down before opening) are other move lists
over the same machinery.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..kinematics import forward
from .motion import MotionChecker, joint_motion, tcp_line_to
from .timing import (TimedSegment, Trajectory, check_limits, reversed_trajectory, time_line, time_spline, time_stops,
                     within_limits)

GRIPPER_SECONDS = 0.5
"""How long the jaw takes to close or open (the arm rests)."""


@dataclass
class Move:
    """One motion to plan: kind, caption, plan step index, start and end joint vectors, whether the object is held,
    the object's resting pose (world) or its grasp (TCP in the object frame), the jaw width during the move, and how
    it is planned: `path` (a given, already checked joint path, e.g. a straight TCP line), `joint` (straight joint
    line, else RRT-Connect) or `dwell` (the jaw moves, the arm rests)."""

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


@dataclass
class StepLines:
    """Consistent waypoints of one step (one IK branch along the straight TCP lines): retract, approach, grasp joint
    vectors and the joint paths retract -> approach and approach -> grasp; `anchor` names the stored configuration
    they were continued from."""

    q_retract: np.ndarray
    q_approach: np.ndarray
    q_grasp: np.ndarray
    down: list[np.ndarray]
    anchor: str


def _modes(step) -> tuple[tuple[bool, np.ndarray], tuple[bool, np.ndarray]]:
    """(holding, pose-or-grasp) before and after the jaw acts at this step."""
    pose, grasp = np.asarray(step.object_pose, dtype=np.float64), np.asarray(step.grasp, dtype=np.float64)
    taking = step.kind in ("pick", "regrasp")
    empty, held = (False, pose), (True, grasp)
    return (empty, held) if taking else (held, empty)


def _mode(checker: MotionChecker, mode: tuple[bool, np.ndarray]) -> None:
    checker.set_holding(mode[1]) if mode[0] else checker.set_resting(mode[1])


def step_lines(checker: MotionChecker, step) -> StepLines | None:
    """The step's retract -> approach -> grasp waypoints on one IK branch: the stored configurations may come from
    different branches (the IK rows solve each pose on its own), so the lines are continued by IK from one stored
    configuration (the grasp, else the approach, else the retract) to the other two poses. Every line is checked in
    both the state before the jaw acts (object resting, or held) and after. None when no anchor works."""
    robot = checker.robot
    qs = [np.asarray(step.q_retract, dtype=np.float64), np.asarray(step.q_approach, dtype=np.float64),
          np.asarray(step.q_grasp, dtype=np.float64)]
    _, _, r, t = forward(robot, np.stack(qs))
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = r, t
    before, after = _modes(step)
    for anchor in (2, 1, 0):
        chain: dict[int, np.ndarray] = {anchor: qs[anchor]}
        paths: dict[tuple[int, int], np.ndarray] = {}
        ok = True
        for a, b in [(i, i - 1) for i in range(anchor, 0, -1)] + [(i, i + 1) for i in range(anchor, 2)]:
            _mode(checker, before)
            p = tcp_line_to(robot, checker, chain[a], poses[b])
            if p is None:
                ok = False
                break
            _mode(checker, after)
            if not checker.path_free(p):
                ok = False
                break
            chain[b] = p[-1]
            paths[(min(a, b), max(a, b))] = p if a < b else p[::-1].copy()
        if ok:
            return StepLines(chain[0], chain[1], chain[2], [paths[(0, 1)], paths[(1, 2)]], ("retract", "approach", "grasp")[anchor])
    return None


def moves_of_steps(steps, lines: list[StepLines], jaw_open: float) -> list[Move]:
    """Today's waypoint scheme: at every step the hand goes retract -> approach -> grasp along straight TCP lines,
    closes (pick, regrasp) or opens (transfer, place), and comes back grasp -> approach -> retract; a transfer (held)
    or a transit (empty, the object where it was released) joins one step's retract to the next's."""
    out: list[Move] = []
    for i, (s, ln) in enumerate(zip(steps, lines)):
        taking = s.kind in ("pick", "regrasp")
        caption = {"pick": "pick", "regrasp": "regrasp", "transfer": "release", "place": "place"}[s.kind]
        (h0, x0), (h1, x1) = _modes(s)
        jaw0 = jaw_open if taking else float(s.jawwidth)
        jaw1 = float(s.jawwidth) if taking else jaw_open

        def mv(kind, path, holding, x, jaw, how="path"):
            out.append(Move(kind, caption, i, path[0].copy(), path[-1].copy(), holding, None if holding else x,
                            x if holding else None, jaw, how, path))

        mv("approach", ln.down[0], h0, x0, jaw0)
        mv("approach", ln.down[1], h0, x0, jaw0)
        mv("gripper", np.stack([ln.q_grasp, ln.q_grasp]), h1, x1, jaw1, "dwell")
        mv("retract", ln.down[1][::-1].copy(), h1, x1, jaw1)
        mv("retract", ln.down[0][::-1].copy(), h1, x1, jaw1)
        if i + 1 < len(steps):
            out.append(Move("transfer" if taking else "transit", "transfer" if taking else "regrasp", i, ln.q_retract.copy(),
                            lines[i + 1].q_retract.copy(), h1, None if h1 else x1, x1 if h1 else None, jaw1, "joint"))
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


def _set(checker: MotionChecker, m: Move) -> None:
    if m.holding:
        checker.set_holding(m.grasp)
    elif m.object_pose is not None:
        checker.set_resting(m.object_pose)
    else:
        checker.set_free()


def _knots_ok(checker: MotionChecker, traj: Trajectory) -> bool:
    return all(checker.valid(q) for q in traj.q)


def solve_moves(checker: MotionChecker, moves: list[Move], vlim: np.ndarray, alim: np.ndarray | float,
                seed: int | None = None) -> MotionResult:
    """Plan and time every move in order (see the module docstring); stops at the first that fails.

    Every trajectory's knots (at most 1 degree apart) are checked again after timing: a spline that strays from
    the checked path is replaced by rest-to-rest timing along its pieces."""
    robot = checker.robot
    vlim, alim = check_limits(vlim, alim, robot.nq)
    seed = checker.opts.seed if seed is None else seed
    t_start = time.perf_counter()
    segments: list[TimedSegment] = []
    t0, rrt = 0.0, 0
    methods: dict[str, int] = {}
    timed: dict[tuple, Trajectory] = {}
    for k, m in enumerate(moves):
        _set(checker, m)
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
    if len(path) == 2:
        return time_line(path[0], path[1], vlim, alim)
    traj = time_spline(path, vlim, alim)
    if not within_limits(traj, checker.robot.lower, checker.robot.upper, vlim, alim) and _knots_ok(checker, traj):
        return traj
    traj = time_stops(path, vlim, alim)
    return traj if _knots_ok(checker, traj) else None


def plan_motion(checker: MotionChecker, steps, vlim: np.ndarray, alim: np.ndarray | float, seed: int | None = None
                ) -> tuple[MotionResult, list[StepLines | None]]:
    """The timed motion of a whole plan (issue 12): consistent straight TCP lines at every step, then the moves in
    order. On failure `result.blame` is ("step", i) when step i's lines fail (its grip is unusable) or ("edge", i, i+1)
    when the transfer or transit from step i to step i+1 fails; the lines found so far are returned too."""
    t0 = time.perf_counter()
    lines: list[StepLines | None] = []
    for i, s in enumerate(steps):
        ln = step_lines(checker, s)
        lines.append(ln)
        if ln is None:
            res = MotionResult([], None, f"step {i + 1} ({s.kind}): no collision-free straight TCP lines between its retract, "
                               f"approach and grasp poses on one IK branch", time.perf_counter() - t0)
            res.failed, res.blame = -1, ("step", i)
            return res, lines
    moves = moves_of_steps(steps, lines, checker.robot.gripper.jaw_max)
    res = solve_moves(checker, moves, vlim, alim, seed)
    res.seconds = time.perf_counter() - t0
    if not res.ok:
        m = moves[res.failed]
        res.blame = ("edge", m.step, m.step + 1) if m.how == "joint" else ("step", m.step)
    return res, lines
