"""Executable regrasp plans: search, plan the motions, and search again without what failed (issue 12).

As wrs does for Wan & Harada's graph (Section V): the best route is searched, its motions are planned
(`planmotion.plan_motion`); when a motion fails, the roadmap node (or start / goal grip) it used is removed with
its edges and the graph is searched again, up to `max_removed` times. A plan says how many it removed; a query
that runs out of alternatives says so in one line.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from ..errors import PlanningError
from ..regrasp import build_roadmap, search
from .motion import MotionChecker, MotionOptions
from .planmotion import MotionResult, plan_motion
from .selfcollision import AllowedPairs, allowed_pairs

DEFAULT_ACC = 3.0
"""Default joint acceleration limit (rad/s^2, m/s^2 for prismatic joints): URDFs carry no acceleration limits."""


@dataclass(frozen=True)
class ExecOptions:
    """Motion settings of a query: acceleration limit (scalar or per joint), how many failing nodes or grips may be
    removed before giving up, and the motion planner's options (resolution, RRT-Connect budget, seed)."""

    acc: float | tuple[float, ...] = DEFAULT_ACC
    max_removed: int = 10
    motion: MotionOptions = field(default_factory=MotionOptions)


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
    """The executable plan (with `motion`), how many nodes or grips were removed, the motion planning seconds
    summed over attempts, and the reason of every failed attempt."""

    plan: object | None
    motion: MotionResult | None
    removed: int
    seconds: float
    failures: list[str]
    searched: int


def plan_executable(planner, start, goal, opts: ExecOptions = ExecOptions(), allowed: AllowedPairs | None = None) -> ExecResult:
    """The fewest-regrasp plan whose motions are all found (see the module docstring). Raises the search's
    PlanningError when start or goal is unreachable or unconnected; PlanningError(reason "exhausted") when
    every alternative failed or `max_removed` removals did not help."""
    from ..plans import make_plan

    checker = motion_checker(planner, allowed, opts.motion)
    robot = planner.robot
    vlim = np.asarray(robot.model.velocityLimit, dtype=np.float64)
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
            err = PlanningError(f"no executable plan from {s_side.query.text()} to {goal_text(g_side)}: the graph ran out of "
                                f"alternatives after removing {removed} node(s) or grip(s) whose motions failed "
                                f"(last: {failures[-1] if failures else 'none'})")
            err.reason = "exhausted"
            raise err
        route = result.routes[0]
        view = SimpleNamespace(roadmap=rm, object=planner.object, robot=robot, handx=planner.handx, worldz=planner.worldz,
                               ids=planner.ids)
        plan = make_plan(view, result, route, 0)
        t0 = time.perf_counter()
        motion, lines = plan_motion(checker, plan.steps, vlim, opts.acc, opts.motion.seed)
        seconds += time.perf_counter() - t0
        if motion.ok:
            for step, ln in zip(plan.steps, lines):  # the waypoints on the IK branch the motions use
                step.q_retract, step.q_approach, step.q_grasp = ln.q_retract, ln.q_approach, ln.q_grasp
            plan.motion = motion
            plan.timings["motion"] = seconds
            plan.removed = removed
            return ExecResult(plan, motion, removed, seconds, failures, searched)
        failures.append(motion.reason)
        if removed >= opts.max_removed:
            err = PlanningError(f"no executable plan from {s_side.query.text()} to {goal_text(g_side)} after removing "
                                f"{removed} node(s) or grip(s) (limit --max-removed {opts.max_removed}); last failure: {motion.reason}")
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


def goal_text(side) -> str:
    return side.query.text()


def _step_nodes(route, n_steps: int) -> list[tuple[str, int]]:
    """Per plan step: ("start", grip), ("node", roadmap node) or ("goal", grip)."""
    out = [("start", route.start_grip)]
    for a, b in route.regrasps:
        out += [("node", a), ("node", b)]
    out.append(("goal", route.goal_grip))
    assert len(out) == n_steps
    return out
