"""Regrasp search time and regrasp count (gs, nr) beside the right half of Table I (Wan & Harada, Sections V-VI).

For each object and robot: the store is built once (grasps, placements on Table I's grid of 21 positions and 8
angles, IK with retractions) under --dir and reused; then --pairs seeded random start/goal poses (a random stable
placement at a uniform position on the grid's area and a uniform yaw) are connected and searched. gs is the time
to compute the IK-feasible grasps at the start and goal, connect them to the graph and search it (median and max
over the pairs); nr the regrasps of the best plan (median over solved pairs). Every pair ends in a plan, or in a
PlanningError saying the start or goal is unreachable or the two are not connected; every plan is checked by the
independent validator.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np

from workbench.benchmarks import print_table
from workbench.benchmarks.paper import BUNDLED_ROW, TABLE_I
from workbench.errors import PlanningError, WorkbenchError
from workbench.geometry.objects import load_object
from workbench.planners.wan_harada.plans import make_plan
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.stages import build_all, load_planner
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.resources import bundled_objects


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", default="tube,planebody,wheel,bracket,tail,drill",
                        help="comma-separated bundled objects (default: all six)")
    parser.add_argument("--robots", default="panda,ur5,talos", help="comma-separated robots (default panda,ur5,talos)")
    parser.add_argument("--pairs", type=int, default=30, help="random start/goal pairs per object and robot (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random pairs")
    parser.add_argument("--alternatives", type=int, default=2, help="next best plans searched per pair (default 2)")
    parser.add_argument("--dir", default="build/bench/regrasp", help="folder of the reused stores")
    parser.add_argument("--workers", type=int, default=None, help="IK processes when building (default: all cores)")


def random_pairs(placement_ids: list[int], grid, n: int, seed: int) -> list[tuple]:
    """`n` seeded (start, goal) PoseQuery pairs over the grid's area."""

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        q = []
        for _ in range(2):
            q.append(PoseQuery(int(rng.choice(placement_ids)), float(rng.uniform(grid.x_min, grid.x_max)),
                               float(rng.uniform(grid.y_min, grid.y_max)), float(rng.uniform(-np.pi, np.pi))))
        out.append(tuple(q))
    return out


def bench_pairs(planner, pairs: list[tuple], alternatives: int = 2) -> dict:
    """gs (s) and regrasps per solved pair, outcome counts (solved; nogrip: a placement with no grasp clearing the
    table; unreachable: no IK-feasible grip at the start or goal; unconnected) and plans failing validation."""

    checker = planner.validator
    gs, nr = [], []
    counts = {"solved": 0, "nogrip": 0, "unreachable": 0, "unconnected": 0, "invalid": 0}
    for start, goal in pairs:
        try:
            res = planner.search(start, goal, alternatives)
        except PlanningError as exc:
            reason = getattr(exc, "reason", "other")
            counts[reason] = counts.get(reason, 0) + 1
            continue
        gs.append(res.timings["connect"] + res.timings["search"])
        counts["solved"] += 1
        nr.append(res.routes[0].n_regrasps)
        for rank, r in enumerate(res.routes):
            if not checker.check(make_plan(planner, res, r, rank)).ok:
                counts["invalid"] += 1
    return {"gs": gs, "nr": nr, **counts}


def built_planners(objects: str, robots: str, folder: str | Path, grid: TabletopParams, workers: int | None):
    """(object name, robot, planner, build seconds) for each comma-separated bundled object and robot: the store
    `folder/<object>.duckdb` is built once (its stages reused on later runs) and its planner loaded."""
    objs = bundled_objects()
    names = [n.strip() for n in objects.split(",") if n.strip()]
    unknown = [n for n in names if n not in objs]
    if unknown:
        raise WorkbenchError(f"unknown bundled objects {unknown}; use some of {', '.join(objs)}")
    for name in names:
        obj = load_object(objs[name])
        db = Path(folder) / f"{name}.duckdb"
        for robot in [r.strip() for r in robots.split(",") if r.strip()]:
            t0 = time.perf_counter()
            build_all(db, obj, robot, tparams=grid, workers=workers)
            t_build = time.perf_counter() - t0
            yield name, robot, load_planner(db, obj.name, robot), t_build


def run(args: argparse.Namespace) -> int:
    grid = TabletopParams()
    rows = []
    for name, robot, planner, t_build in built_planners(args.objects, args.robots, args.dir, grid, args.workers):
        ids = planner.placement_ids()
        pairs = random_pairs(ids, grid, args.pairs, args.seed)
        bench_pairs(planner, pairs[:1], args.alternatives)  # warm-up (caches), not counted
        out = bench_pairs(planner, pairs, args.alternatives)
        row = BUNDLED_ROW.get(name, "-")
        paper = TABLE_I.get(row)
        gs, nr = out["gs"], out["nr"]
        rows.append([name, row, robot, planner.roadmap.n_grips, planner.roadmap.n_nodes,
                     statistics.median(gs) * 1000 if gs else "-", max(gs) * 1000 if gs else "-",
                     statistics.median(nr) if nr else "-", max(nr) if nr else "-", f"{out['solved']}/{len(pairs)}",
                     out["nogrip"], out["unreachable"], out["unconnected"], out["invalid"],
                     f"{paper[10]:g} / {paper[11]:g}" if paper else "-", f"{paper[12]} / {paper[13]}" if paper else "-",
                     round(t_build, 1)])
    print_table(["object", "T-I", "robot", "#-tpg", "nodes", "gs med ms", "gs max ms", "nr med", "nr max", "solved", "no grip",
                 "unreach", "unconn", "invalid", "paper gs n/h s", "paper nr n/h", "store s"], rows,
                title=f"Regrasp search (Table I right half): {args.pairs} random start/goal pairs per object and robot (seed {args.seed}), "
                      f"best plan + {args.alternatives} alternatives; gs = IK at start/goal + connect + search, over the solved "
                      "pairs; unsolved pairs: a placement with no grasp clearing the table (no grip), no IK-feasible grip at start "
                      "or goal (unreach), not connected (unconn); invalid = plans the validator rejects. "
                      "Paper: Nextage (n) / HRP5P (h), Xeon 2.8 GHz, its Fig. 10 tasks")
    return 0
