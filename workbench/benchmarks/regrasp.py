"""Regrasp search time and regrasp count (gs, nr) beside the right half of Table I (Wan & Harada, Sections V-VI).

For each object and robot: the store is built once (grasps, placements on Table I's grid of 21 positions and 8
angles, IK with retractions) under --dir and reused; then --pairs seeded random start/goal poses (a random stable
placement at a uniform position on the grid's area and a uniform yaw) are connected and searched. gs is the time
to compute the IK-feasible grasps at the start and goal, connect them to the graph and search it (median and max
over the pairs); nr the regrasps of the best plan (median over solved pairs). Every pair ends in a plan, or in a
PlanningError saying the start or goal is unreachable or the two are not connected; every plan is checked by the
independent validator.

That is `--protocol interactive` (warm caches: a warm-up query first, lazy IK at the start and goal, random pairs).
`--protocol paper` (default) measures what Table I's gs and nr measure: one fixed task per object, stated in the
output (start: the first stable placement at x 0.45, y -0.10, yaw 0; goal: the second at x 0.55, y 0.10, yaw 90
degrees, the same placement turned when there is only one), in the spirit of Fig. 10; every repeat loads a fresh
planner (no cache) and times the search with every start and goal grip's IK evaluated (lazy=False), so gs covers
the IK at the initial and goal poses, connecting them and the search. The store keeps every grasp (Table I's
#-tpg) unless --max-grasps is given, which the output names.
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from workbench.benchmarks import print_table
from workbench.benchmarks.paper import BUNDLED_ROW, TABLE_I
from workbench.errors import PlanningError, RobotWarning, WorkbenchError
from workbench.geometry.objects import load_object
from workbench.planners.wan_harada.plans import make_plan
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.stages import build_all, load_planner
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.resources import bundled_objects, erd_robots, paper_objects
from workbench.robots.gripper import franka_hand
from workbench.robots.model import ROBOTS, get_robot, pose_xyz_yaw
from workbench.store import Store


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", default="tube,planebody,wheel,bracket,tail,drill",
                        help="comma-separated bundled objects or Table I rows of the paper's objects (TU, PB, PW, PS, PT, ED)")
    parser.add_argument("--robots", default="panda,ur5,talos", help="comma-separated robots (default panda,ur5,talos)")
    parser.add_argument("--protocol", choices=["paper", "interactive"], default="paper",
                        help="paper: a fixed task per object, cold planner, IK at start and goal included; interactive: "
                             "random pairs, warm caches, lazy IK")
    parser.add_argument("--repeats", type=int, default=3, help="paper protocol: cold repeats of the task (median)")
    parser.add_argument("--max-grasps", type=int, default=0, help="cap the roadmap's grasps (0: all, as Table I)")
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


def paper_task(placement_ids: list[int]) -> tuple[PoseQuery, PoseQuery]:
    """The fixed task of the paper protocol: the first stable placement at (0.45, -0.10), yaw 0, to the second at
    (0.55, 0.10), yaw 90 degrees (the first again, turned, when the object has one stable placement)."""
    ids = sorted(placement_ids)
    return PoseQuery(ids[0], 0.45, -0.10, 0.0), PoseQuery(ids[1 % len(ids)], 0.55, 0.10, float(np.pi / 2))


def paper_task_objects(spec: str) -> list[tuple[str, str, object]]:
    """(label, Table I row, loaded object) for bundled names and paper rows (millimetre meshes in ../shared)."""
    objs, paper = bundled_objects(), paper_objects()
    out = []
    for name in [n.strip() for n in spec.split(",") if n.strip()]:
        if name in objs:
            out.append((name, BUNDLED_ROW.get(name, "-"), load_object(objs[name])))
        elif name in paper:
            out.append((f"{name} (paper)", name, load_object(paper[name], units="mm", name=name)))
        else:
            raise WorkbenchError(f"unknown object {name!r}; use bundled objects ({', '.join(objs)}) or paper rows "
                                 f"({', '.join(paper) or 'none found: set WORKBENCH_SHARED to the shared folder'})")
    return out


# Arms of example-robot-data loaded from their URDF files as a user's robot would be (`workbench build --robot PATH
# --tip ... --mount ...`), the Franka hand 103.4 mm out on the flange: (URDF below example-robot-data's robots
# folder, tip frame, hand links replaced by the planning gripper; empty: the links past the tip).
URDF_ARMS = {
    "ur10": ("ur_description/urdf/ur10_robot.urdf", "tool0", ()),
    "xarm7": ("xarm_description/urdf/xarm7.urdf", "link_eef", ()),
    "kinova": ("kinova_description/robots/kinova.urdf", "j2s6s200_end_effector", ("j2s6s200_link_finger",)),
}


def bench_robot(name: str):
    """A built-in robot's name, or the Robot of a `URDF_ARMS` arm loaded from its URDF."""
    if name in ROBOTS:
        return name
    if name not in URDF_ARMS:
        raise WorkbenchError(f"unknown robot {name!r}; use some of {', '.join((*ROBOTS, *URDF_ARMS))}")
    path, tip, hand = URDF_ARMS[name]
    with warnings.catch_warnings():  # the bounded joints and replaced links are as intended here
        warnings.simplefilter("ignore", RobotWarning)
        return get_robot(str(erd_robots() / path), tip_frame=tip, mount=franka_hand().tcp_in_hand,
                         hand_links=hand)


def built_planners(objects: str, robots: str, folder: str | Path, grid: TabletopParams, workers: int | None):
    """(object name, robot, planner, build seconds) for each comma-separated bundled object and robot (built-in, or
    a `URDF_ARMS` arm from its URDF): the store `folder/<object>.duckdb` is built once (its stages reused on later
    runs) and its planner loaded."""
    objs = bundled_objects()
    names = [n.strip() for n in objects.split(",") if n.strip()]
    unknown = [n for n in names if n not in objs]
    if unknown:
        raise WorkbenchError(f"unknown bundled objects {unknown}; use some of {', '.join(objs)}")
    arms = {r: bench_robot(r) for r in [r.strip() for r in robots.split(",") if r.strip()]}
    for name in names:
        obj = load_object(objs[name])
        db = Path(folder) / f"{name}.duckdb"
        for label, robot in arms.items():
            t0 = time.perf_counter()
            res = build_all(db, obj, robot, tparams=grid, workers=workers)
            t_build = time.perf_counter() - t0
            yield name, label, load_planner(db, obj.name, res.robot), t_build


def run(args: argparse.Namespace) -> int:
    grid = TabletopParams(max_grasps=args.max_grasps or None)
    folder = Path(args.dir)
    rows = []
    for label, row, obj in paper_task_objects(args.objects):
        db = folder / f"{obj.name}{'' if grid.max_grasps is None else f'-cap{grid.max_grasps}'}.duckdb"
        for robot in [r.strip() for r in args.robots.split(",") if r.strip()]:
            t0 = time.perf_counter()
            build_all(db, obj, robot, tparams=grid, workers=args.workers)
            t_build = time.perf_counter() - t0
            paper = TABLE_I.get(row)
            ref = [f"{paper[10]:g} / {paper[11]:g}" if paper else "-", f"{paper[12]} / {paper[13]}" if paper else "-"]
            if args.protocol == "paper":
                rows.append([label, row, robot, *_paper_task(db, obj.name, robot, args.repeats), *ref, round(t_build, 1)])
                continue
            with Store(db) as store:
                planner = load_planner(store, obj.name, robot)
                ids = planner.placement_ids()
                pairs = random_pairs(ids, grid, args.pairs, args.seed)
                bench_pairs(planner, pairs[:1], args.alternatives)  # warm-up (caches), not counted
                out = bench_pairs(planner, pairs, args.alternatives)
            gs, nr = out["gs"], out["nr"]
            rows.append([label, row, robot, planner.roadmap.n_grips, planner.roadmap.n_nodes,
                         statistics.median(gs) * 1000 if gs else "-", max(gs) * 1000 if gs else "-",
                         statistics.median(nr) if nr else "-", max(nr) if nr else "-", f"{out['solved']}/{len(pairs)}",
                         out["nogrip"], out["unreachable"], out["unconnected"], out["invalid"], *ref, round(t_build, 1)])
    if args.protocol == "paper":
        print_table(["object", "T-I", "robot", "#-tpg", "nodes", "task (placement,x,y,yaw deg)", "gs s", "gs range s", "nr",
                     "outcome", "load s", "paper gs n/h s", "paper nr n/h", "store s"], rows,
                    title=f"Regrasp search, protocol paper (Table I's gsn/gsh, nrn/nrh): one fixed task per object, "
                          f"{grid.grasps_label()}; each of {args.repeats} repeats loads a fresh planner (load s, not in gs) "
                          "and times IK at every start and goal grip + connect + search (gs, median); nr = regrasps of the "
                          "best plan. Paper: Nextage (n) / HRP5P (h), Xeon 2.8 GHz, its Fig. 10 tasks")
        return 0
    print_table(["object", "T-I", "robot", "#-tpg", "nodes", "gs med ms", "gs max ms", "nr med", "nr max", "solved", "no grip",
                 "unreach", "unconn", "invalid", "paper gs n/h s", "paper nr n/h", "store s"], rows,
                title=f"Regrasp search, protocol interactive (warm caches, lazy IK; not Table I's protocol): {args.pairs} random "
                      f"start/goal pairs per object and robot (seed {args.seed}), {grid.grasps_label()}, "
                      f"best plan + {args.alternatives} alternatives; gs = IK at start/goal + connect + search, over the solved "
                      "pairs; unsolved pairs: a placement with no grasp clearing the table (no grip), no IK-feasible grip at start "
                      "or goal (unreach), not connected (unconn); invalid = plans the validator rejects. "
                      "Paper: Nextage (n) / HRP5P (h), Xeon 2.8 GHz, its Fig. 10 tasks")
    return 0


def _paper_task(db: Path, name: str, robot: str, repeats: int) -> list:
    """#-tpg, nodes, the task, gs median and range (s), nr, outcome and load time of the paper protocol's task."""
    gs, loads, nr, outcome = [], [], "-", "solved"
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        with Store(db) as store:
            planner = load_planner(store, name, robot)   # fresh: no planner cache
        loads.append(time.perf_counter() - t0)
        start, goal = paper_task(planner.placement_ids())
        t0 = time.perf_counter()
        try:
            res = planner.search(start, goal, alternatives=0, lazy=False)
            nr = res.routes[0].n_regrasps
        except PlanningError as exc:
            outcome = getattr(exc, "reason", "failed")
        gs.append(time.perf_counter() - t0)
    task = " -> ".join(f"{q.idfreetabletopplacement},{q.x:.2f},{q.y:.2f},{np.degrees(q.yaw):.0f}" for q in (start, goal))
    return [planner.roadmap.n_grips, planner.roadmap.n_nodes, task, statistics.median(gs),
            f"{min(gs):.2f}-{max(gs):.2f}", nr, outcome, statistics.median(loads)]
