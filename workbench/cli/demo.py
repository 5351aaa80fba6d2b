"""`workbench demo --out build/demo`: the main job end to end on a bundled object (Wan & Harada, Sections III-V):
build every stage into OUT/regrasp.duckdb, pick a start and a goal that need at least one regrasp, plan, validate,
write OUT/plan.json and OUT/plan.html (a meshcat animation that opens without a server)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from workbench.cli.build import build_all, print_build
from workbench.cli.ik import WORKERS
from workbench.cli.plan import print_plan, report_graph, write_json, write_trajectory
from workbench.errors import WorkbenchError
from workbench.geometry.objects import load_object
from workbench.grasping.naming import per_part_numbers
from workbench.params import cli_bound, parse_number
from workbench.planners.wan_harada.stages import (
    DEMO_GRID,
    choose_task,
    load_planner,
    save_plan,
)
from workbench.resources import bundled_objects
from workbench.store import Store
from workbench.viewer.wan_harada import plan_scene

SEED = cli_bound(0, 2**32 - 1, integer=True, help="seed")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("demo", help="build a bundled object, plan a regrasp task and write the animation")
    parser.add_argument("--out", default="build/demo", help="output folder (default build/demo)")
    parser.add_argument("--object", default="tube", help="bundled object (default tube)")
    parser.add_argument("--robot", default="panda", help="robot (default panda)")
    parser.add_argument("--seed", type=parse_number(SEED, "--seed", 0), default=0, metavar="N",
                        help=f"seed of the start/goal choice ({SEED.describe(True)}; default 0)")
    parser.add_argument("--workers", type=parse_number(WORKERS, "--workers"), default=None, metavar="N",
                        help=f"IK processes ({WORKERS.describe(True)}; default: all cores)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    objs = bundled_objects()
    if args.object not in objs:
        raise WorkbenchError(f"unknown bundled object {args.object!r}; use one of {', '.join(objs)}")
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise WorkbenchError(f"--out {out} cannot be a folder ({exc.strerror}: {exc.filename}); give another --out") from None
    db = out / "regrasp.duckdb"
    t_all = time.perf_counter()
    obj = load_object(objs[args.object])
    res = build_all(db, obj, args.robot, tparams=DEMO_GRID, workers=args.workers)
    print_build(res, db, time.perf_counter() - t_all)
    with Store(db) as store:
        t0 = time.perf_counter()
        planner = load_planner(store, obj.name, args.robot)
        report_graph(planner, time.perf_counter() - t0)
        start, goal = choose_task(planner, args.seed)
        plans = planner.plan(start, goal, alternatives=2)
        best = plans[0]
        print_plan(best, per_part_numbers(planner.free["idfreetabletopplacement"]))
        rep = planner.validate(best, require_motion=True)
        rep.raise_if_failed()
        print(f"validation: ok ({rep.checks} checks: FK from the URDF, joint limits, arm/gripper-table and arm-object collisions, "
              f"stable placements, constant grasp along transfers, object at the goal; every knot of the timed trajectory: "
              f"position, velocity and acceleration limits, self-collision, arm, hand and part against the table, arm and "
              f"hand against the resting part)")

        save_plan(store, best)
    write_json(plans, out / "plan.json")
    print(f"trajectory for a controller: {write_trajectory(best, out / 'trajectory.csv')}")
    html = plan_scene(best, planner, out / "plan.html")
    print(f"plan: {(out / 'plan.json').resolve()}")
    print(f"open in a browser: {Path(html).resolve()}")
    print(f"demo done in {time.perf_counter() - t_all:.1f} s")
    return 0
