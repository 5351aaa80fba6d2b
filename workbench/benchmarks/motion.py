"""Executable plans: motion planning and timing of searched regrasp plans (Wan & Harada Section V as
executed by wrs).

For each object and robot: the store is built once under --dir (the demo grid) and reused; --pairs seeded random
start/goal poses are searched; every searched plan gets its motions (straight TCP lines, straight joint lines or
RRT-Connect + shortcuts, TOPP-RA / trapezoidal timing), failing nodes or grips are removed and the graph searched
again (up to --max-removed). Printed: the share of searched plans that become executable, removals, motion
planning time per plan (median and 95th percentile), trajectory duration, and plans the independent trajectory
validator rejects.
"""

from __future__ import annotations

import argparse
import statistics

import numpy as np

from workbench.benchmarks import print_table
from workbench.benchmarks.regrasp import built_planners, random_pairs
from workbench.errors import PlanningError, WorkbenchError
from workbench.planners.wan_harada.motions import ExecOptions, plan_executable
from workbench.planners.wan_harada.stages import DEMO_GRID


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", default="tube,bracket", help="comma-separated bundled objects (default tube,bracket)")
    parser.add_argument("--robots", default="panda,ur5",
                        help="comma-separated robots: built-in, or ur10, xarm7, kinova loaded from example-robot-data's URDF "
                             "files as a user's robot (default panda,ur5)")
    parser.add_argument("--pairs", type=int, default=30, help="random start/goal pairs per object and robot (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random pairs")
    parser.add_argument("--acc", type=float, default=3.0, help="joint acceleration limit, rad/s^2 (default 3)")
    parser.add_argument("--max-removed", type=int, default=10, help="nodes or grips removed before giving up (default 10)")
    parser.add_argument("--no-validate", action="store_true", help="skip the independent trajectory validator")
    parser.add_argument("--dir", default="build/bench/motion", help="folder of the reused stores")
    parser.add_argument("--workers", type=int, default=None, help="IK processes when building (default: all cores)")


def bench_motion(planner, pairs: list[tuple], acc: float, max_removed: int, validate: bool = True) -> dict:
    """Per pair: searched (a route exists), executable, removals, motion planning seconds, trajectory duration,
    validator rejections."""
    validator = planner.trajectory_validator(acc) if validate else None
    out = {"searched": 0, "executable": 0, "removed": [], "seconds": [], "duration": [], "invalid": 0, "exhausted": 0}
    opts = ExecOptions(acc=acc, max_removed=max_removed)
    for start, goal in pairs:
        try:
            res = plan_executable(planner, start, goal, opts)
        except PlanningError as exc:
            if getattr(exc, "reason", "") == "exhausted":
                out["searched"] += 1
                out["exhausted"] += 1
            continue
        out["searched"] += 1
        out["executable"] += 1
        out["removed"].append(res.removed)
        out["seconds"].append(res.seconds)
        out["duration"].append(res.motion.duration)
        if validator is not None and validator.check(res.plan, res.motion.segments)[0]:
            out["invalid"] += 1
    return out


def run(args: argparse.Namespace) -> int:
    if args.pairs < 1 or args.acc <= 0 or args.max_removed < 0:
        raise WorkbenchError(f"--pairs must be >= 1, --acc > 0 and --max-removed >= 0 (got {args.pairs}, {args.acc}, {args.max_removed})")
    rows = []
    for name, robot, planner, t_build in built_planners(args.objects, args.robots, args.dir, DEMO_GRID, args.workers):
        pairs = random_pairs(planner.placement_ids(), DEMO_GRID, args.pairs, args.seed)
        bench_motion(planner, pairs[:1], args.acc, args.max_removed, False)  # warm-up (imports, caches), not counted
        r = bench_motion(planner, pairs, args.acc, args.max_removed, not args.no_validate)
        sec, dur, rem = r["seconds"], r["duration"], r["removed"]
        share = f"{100.0 * r['executable'] / r['searched']:.0f}% ({r['executable']}/{r['searched']})" if r["searched"] else "-"
        rows.append([name, robot, len(pairs), share, sum(rem) if rem else 0, max(rem) if rem else 0,
                     statistics.median(sec) if sec else "-", float(np.percentile(sec, 95)) if sec else "-",
                     statistics.median(dur) if dur else "-", max(dur) if dur else "-", r["exhausted"],
                     "-" if args.no_validate else r["invalid"], round(t_build, 1)])
    print_table(["object", "robot", "pairs", "executable", "removed", "max rm", "motion med s", "motion p95 s", "traj med s",
                 "traj max s", "exhausted", "invalid", "store s"], rows,
                title=f"Motion planning of searched plans: {args.pairs} random start/goal pairs per object and robot (seed {args.seed}), "
                      f"acceleration limit {args.acc:g} rad/s^2; executable = searched plans whose motions were all found (after "
                      "removing failing nodes or grips, counted in 'removed'); motion = motion planning and timing time per plan; "
                      "traj = trajectory duration; invalid = plans the independent trajectory validator rejects. "
                      "Targets: >= 95% executable, median motion time <= 0.5 s")
    return 0
