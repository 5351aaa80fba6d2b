"""`workbench demo --out build/demo`: the main job end to end on a bundled object (Wan & Harada, Sections III-V):
build every stage into OUT/regrasp.duckdb, pick a start and a goal that need at least one regrasp, plan, validate,
write OUT/plan.json and OUT/plan.html (a meshcat animation that opens without a server)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from ..tabletop import TabletopParams

DEMO_GRID = TabletopParams(x_min=0.35, x_max=0.65, nx=5, y_min=-0.2, y_max=0.2, ny=3, angles=8, max_grasps=60)


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("demo", help="build a bundled object, plan a regrasp task and write the animation")
    parser.add_argument("--out", default="build/demo", help="output folder (default build/demo)")
    parser.add_argument("--object", default="tube", help="bundled object (default tube)")
    parser.add_argument("--robot", default="panda", help="robot (default panda)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the start/goal choice")
    parser.add_argument("--workers", type=int, default=None, help="IK processes (default: all cores)")
    parser.set_defaults(func=run)


def choose_task(planner, seed: int = 0, tries: int = 40, grid: TabletopParams = DEMO_GRID,
                min_regrasps: int = 1) -> tuple:
    """A start and a goal (PoseQuery) on the grid's area that need at least `min_regrasps` regrasps: seeded random
    pairs of different stable placements; the one needing the most regrasps among the first solvable ones."""
    from ..errors import PlanningError
    from ..regrasp import PoseQuery

    rng = np.random.default_rng(seed)
    ids = planner.placement_ids()
    best = None
    for _ in range(tries):
        a, b = rng.choice(ids, size=2, replace=len(ids) < 2)
        q = [PoseQuery(int(p), float(rng.uniform(grid.x_min, grid.x_max)), float(rng.uniform(grid.y_min, grid.y_max)),
                       float(rng.uniform(-np.pi, np.pi))) for p in (a, b)]
        try:
            res = planner.search(q[0], q[1], alternatives=0)
        except PlanningError:
            continue
        k = res.routes[0].n_regrasps
        if k >= min_regrasps and (best is None or k > best[0]):
            best = (k, q[0], q[1])
            if k >= min_regrasps + 1:
                break
    if best is None:
        raise PlanningError(f"no start/goal pair among {tries} random ones needs {min_regrasps}+ regrasps; try another --seed")
    return best[1], best[2]


def run(args: argparse.Namespace) -> int:
    from ..errors import WorkbenchError
    from ..objects import load_object
    from ..regrasp import load_planner
    from ..resources import bundled_objects
    from ..store import Store
    from ..validate import validate_plan
    from ..viz.plan import plan_scene
    from .build import build_all, print_build
    from .plan import print_plan, report_graph, write_json

    objs = bundled_objects()
    if args.object not in objs:
        raise WorkbenchError(f"unknown bundled object {args.object!r}; use one of {', '.join(objs)}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
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
        print_plan(best)
        rep = validate_plan(best, planner)
        rep.raise_if_failed()
        print(f"validation: ok ({rep.checks} checks: FK from the URDF, joint limits, arm/gripper-table and arm-object collisions, "
              f"stable placements, constant grasp along transfers, object at the goal)")
        from ..plans import save_plan

        save_plan(store, best)
    write_json(plans, out / "plan.json")
    html = plan_scene(best, planner, out / "plan.html")
    print(f"plan: {(out / 'plan.json').resolve()}")
    print(f"open in a browser: {Path(html).resolve()}")
    print(f"demo done in {time.perf_counter() - t_all:.1f} s")
    return 0
