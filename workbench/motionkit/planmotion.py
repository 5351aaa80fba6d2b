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

from .motion import MotionChecker, joint_motion, tcp_line
from .timing import TimedSegment, Trajectory, check_limits, time_line, time_spline, time_stops

GRIPPER_SECONDS = 0.5
"""How long the jaw takes to close or open (the arm rests)."""


@dataclass
class Move:
    """One motion to plan: kind, caption, plan step index, start and end joint vectors, whether the object is held,
    the object's resting pose (world) or its grasp (TCP in the object frame), the jaw width after the move, and how
    it is planned: `tcp` (straight TCP line), `joint` (straight joint line, else RRT-Connect) or `dwell`."""

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


def moves_of_steps(steps, jaw_open: float) -> list[Move]:
    """Today's waypoint scheme: at every step the hand goes retract -> approach -> grasp along straight TCP lines,
    closes (pick, regrasp) or opens (transfer, place), and comes back grasp -> approach -> retract; a transfer (held)
    or a transit (empty, the object where it was released) joins one step's retract to the next's."""
    out: list[Move] = []
    for i, s in enumerate(steps):
        taking = s.kind in ("pick", "regrasp")
        caption = {"pick": "pick", "regrasp": "regrasp", "transfer": "release", "place": "place"}[s.kind]
        pose, grasp = np.asarray(s.object_pose, dtype=np.float64), np.asarray(s.grasp, dtype=np.float64)
        before_jaw = jaw_open if taking else float(s.jawwidth)
        after_jaw = float(s.jawwidth) if taking else jaw_open

        def mv(kind, a, b, holding, jaw, how):
            out.append(Move(kind, caption, i, np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64), holding,
                            None if holding else pose, grasp if holding else None, jaw, how))

        mv("approach", s.q_retract, s.q_approach, not taking, before_jaw, "tcp")
        mv("approach", s.q_approach, s.q_grasp, not taking, before_jaw, "tcp")
        mv("gripper", s.q_grasp, s.q_grasp, taking, after_jaw, "dwell")
        mv("retract", s.q_grasp, s.q_approach, taking, after_jaw, "tcp")
        mv("retract", s.q_approach, s.q_retract, taking, after_jaw, "tcp")
        if i + 1 < len(steps):
            nxt = steps[i + 1]
            if taking:
                out.append(Move("transfer", "transfer", i, np.asarray(s.q_retract, dtype=np.float64),
                                np.asarray(nxt.q_retract, dtype=np.float64), True, None, grasp, after_jaw, "joint"))
            else:
                out.append(Move("transit", "regrasp", i, np.asarray(s.q_retract, dtype=np.float64),
                                np.asarray(nxt.q_retract, dtype=np.float64), False, pose, None, after_jaw, "joint"))
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
    for k, m in enumerate(moves):
        _set(checker, m)
        if m.how == "dwell":
            if not checker.valid(m.q_from):
                return MotionResult(segments, k, f"{m.caption}: the {m.kind} configuration collides ({', '.join(checker.why(m.q_from))})",
                                    time.perf_counter() - t_start, rrt, methods)
            traj = Trajectory(np.array([0.0, GRIPPER_SECONDS]), np.stack([m.q_from, m.q_from]), np.zeros((2, robot.nq)))
            method = "dwell"
        elif m.how == "tcp":
            path = tcp_line(robot, checker, m.q_from, m.q_to)
            if path is None:
                return MotionResult(segments, k, f"{m.caption}: no collision-free straight TCP line for the {m.kind}",
                                    time.perf_counter() - t_start, rrt, methods)
            traj, method = _timed(checker, path, vlim, alim), "tcp-line"
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
    if _knots_ok(checker, traj) and (traj.q >= checker.robot.lower - 1e-9).all() and (traj.q <= checker.robot.upper + 1e-9).all():
        return traj
    traj = time_stops(path, vlim, alim)
    return traj if _knots_ok(checker, traj) else None
