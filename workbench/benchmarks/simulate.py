"""Plans confirmed by physics: searched, executable regrasp plans replayed in MuJoCo.

For each part (bundled, and with --organic the procedural organic set) and robot: the store is built once under
--dir (the demo grid) and reused; --pairs seeded random start/goal poses are searched and their motions planned;
every executable plan is replayed (`workbench simulate`'s scene and verdict, default parameters). Printed: the share
confirmed, the failures by kind (shove at closing, slip or drop in the hand, roll after release, pose at a
waypoint, goal), the stepping time per simulated second (its inverse is the speed over real time) and per plan,
and the convex decomposition's time (once per part, then read from its cache).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

from workbench.benchmarks import print_table
from workbench.benchmarks.organic import organic_set
from workbench.benchmarks.regrasp import bench_robot, random_pairs
from workbench.errors import PlanningError, WorkbenchError
from workbench.geometry.objects import from_arrays, load_object
from workbench.planners.wan_harada.motions import ExecOptions, plan_executable
from workbench.planners.wan_harada.stages import DEMO_GRID, build_all, load_planner
from workbench.resources import bundled_objects
from workbench.simulation.decomposition import Decomposition, cache_dir, convex_parts
from workbench.simulation.replay import FAILURES, SimParams
from workbench.simulation.stages import simulate_in_memory
from workbench.store import Store


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", default="tube,bracket,wheel,planebody,tail,drill",
                        help="comma-separated bundled parts (default: all six)")
    parser.add_argument("--organic", action="store_true", help="also the procedural organic set (scans, blobs, tori, cups...)")
    parser.add_argument("--robots", default="panda,ur5", help="comma-separated robots (default panda,ur5)")
    parser.add_argument("--pairs", type=int, default=30, help="random start/goal pairs per part and robot (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random pairs")
    parser.add_argument("--grip-force", type=float, default=None, help="finger force, N (default the gripper's)")
    parser.add_argument("--dir", default="build/bench/simulate", help="folder of the reused stores")
    parser.add_argument("--workers", type=int, default=None, help="IK processes when building (default: all cores)")


def parts(objects: str, organic: bool) -> list:
    """The ObjectModels to bench: the named bundled parts, then the organic set."""
    objs = bundled_objects()
    names = [n.strip() for n in objects.split(",") if n.strip()]
    unknown = [n for n in names if n not in objs]
    if unknown:
        raise WorkbenchError(f"unknown bundled objects {unknown}; use some of {', '.join(objs)}")
    out = [load_object(objs[n]) for n in names]
    if organic:
        out += [from_arrays(m.vertices, m.faces, scale=1.0, name=n, source=f"organic:{n}") for n, m in organic_set().items()]
    return out


def run(args: argparse.Namespace) -> int:
    if args.pairs < 1:
        raise WorkbenchError(f"--pairs must be >= 1, got {args.pairs}")
    params = SimParams(grip_force=args.grip_force)
    rows, totals = [], {k: 0 for k in FAILURES}
    load = os.getloadavg()
    for obj in parts(args.objects, args.organic):
        db = Path(args.dir) / f"{obj.name}.duckdb"
        cached = any(cache_dir().glob(f"{obj.digest}-{Decomposition().key}.npz"))
        t0 = time.perf_counter()
        hulls = convex_parts(obj.mesh, obj.digest, obj.name)
        t_decomp = time.perf_counter() - t0
        for label in [r.strip() for r in args.robots.split(",") if r.strip()]:
            res = build_all(db, obj, bench_robot(label), tparams=DEMO_GRID, workers=args.workers, progress=False)
            if res.empty is not None:
                rows.append([obj.name, label, args.pairs, 0, "-", "-", "-", "-", "-", "-", f"no graph ({res.empty.split(':')[0]})"])
                continue
            with Store(db) as store:
                planner = load_planner(store, obj.name, res.robot)
                plans = []
                for start, goal in random_pairs(planner.placement_ids(gripped=True), DEMO_GRID, args.pairs, args.seed):
                    try:
                        plans.append(plan_executable(planner, start, goal, ExecOptions()).plan)
                    except PlanningError:
                        continue
                kinds = {k: 0 for k in FAILURES}
                confirmed, per_plan, per_second, per_cpu = 0, [], [], []
                for plan in plans:
                    t1 = time.perf_counter()
                    out = simulate_in_memory(store, plan, planner.robot, params)
                    per_plan.append(time.perf_counter() - t1)
                    per_second.append(out.seconds / out.simulated)
                    per_cpu.append(out.cpu_seconds / out.simulated)
                    confirmed += out.confirmed
                    if out.failure is not None:
                        kinds[out.failure.kind] += 1
                        totals[out.failure.kind] += 1
            n = len(plans)
            fails = ", ".join(f"{k} {v}" for k, v in kinds.items() if v) or "-"
            rows.append([obj.name, label, args.pairs, n, f"{100.0 * confirmed / n:.0f}% ({confirmed}/{n})" if n else "-", fails,
                         round(statistics.median(per_second), 4) if n else "-",
                         round(1.0 / statistics.median(per_second), 1) if n else "-",
                         round(1.0 / statistics.median(per_cpu), 1) if n else "-",
                         round(statistics.median(per_plan), 2) if n else "-",
                         f"{t_decomp:.2f} ({'cached' if cached else 'computed'}, {len(hulls)} hulls)"])
    print_table(["part", "robot", "pairs", "plans", "confirmed", "failures (first per plan)", "s per sim s", "x real time",
                 "x (CPU)",
                 "s per plan", "decomposition s"], rows,
                title=f"Plans replayed in MuJoCo (timestep {params.timestep:g} s, grip force "
                      f"{'the gripper default' if args.grip_force is None else f'{args.grip_force:g} N'}, goal tolerance "
                      f"{params.goal_tol * 1000:g} mm / 5 deg): {args.pairs} random start/goal pairs per part and robot (seed "
                      f"{args.seed}), each executable plan simulated once; s per plan includes building the scene; x (CPU): simulated "
                      f"seconds per CPU second of stepping (the speed on a free core). Load "
                      f"average {load[0]:.1f}. Targets: >= 20x real time, <= 2 s per plan with the decomposition cached")
    print("failures, all parts: " + (", ".join(f"{k} {v}" for k, v in totals.items() if v) or "none"))
    return 0
