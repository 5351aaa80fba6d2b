"""Grasp-placement table (Tournassoud, Lozano-Perez & Mazer 1987): classes, build times, chaining, closed-form IK,
and regrasp counts beside the roadmap planner's for the same start and goal placements.

Per object (the L-shaped part of Fig. 1, a box, the bundled parts, the organic set; the Wan-Harada objects when
present): grasp classes by kind, placement classes, non-empty cells; the seconds of each stage on the part's own
classes: hand-object (Section 5.1: the feature pairs, grasp points and legal theta ranges, i.e. the grasp classes),
hand-table and IK (Section 5.2) of the 5 x 5 degree table, and their sum; the 1 x 1 degree table (skipped, with its
pose count, when it would need more than --max-poses IK poses); the backward-chaining time of a grasp query (median
over seeded random queries); and, with --compare, the regrasps of this planner and of the roadmap planner (Wan &
Harada, built for the same robot with its IK on a one-position grid at H) for the same seeded start and goal
placements at H. Then the synthetic table of the target's size, 100 classes x 10 placements, made by repeating the
largest real table's classes and placements (its hand-table and IK stages only: repeated classes need no new
hand-object stage), beside the sum over every real part. The closed-form IK throughput is measured once.
Targets: 100 classes x 10 placements at 5 x 5 degrees <= 2 s; a query <= 10 ms; IK >= 500,000 poses/s.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import numpy as np
import trimesh

from workbench.benchmarks import print_table
from workbench.benchmarks.organic import ORGANIC
from workbench.benchmarks.paper import bench_objects
from workbench.errors import PlanningError, WorkbenchError
from workbench.geometry.objects import ObjectModel, from_trimesh
from workbench.grasping.placements import stable_placements
from workbench.planners.tournassoud.chaining import (
    NoSequence,
    grasp_query,
    placement_query,
)
from workbench.planners.tournassoud.classes import KINDS, ClassParams, grasp_classes
from workbench.planners.tournassoud.plans import Realiser, plan_grasp_query, plan_placement_query
from workbench.planners.tournassoud.shapes import l_part
from workbench.planners.tournassoud.table import TableParams, build_table, grid, rz
from workbench.planners.wan_harada.motions import ExecOptions
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.stages import build_all, load_planner
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.analytic import analytic_ik, reachable, solve
from workbench.robots.collider import default_scene
from workbench.robots.model import get_robot
from workbench.store import Store


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--objects", default="L,box,tube,planebody,wheel,bracket,tail,organic",
                        help="comma-separated: L, box, bundled object names, organic (the procedural organic set, or one "
                             "of its names), paper (the Wan-Harada objects when present)")
    parser.add_argument("--robot", default="puma560", help="robot (default puma560)")
    parser.add_argument("--table-point", default="0.45,0.1", help="H as X,Y (m)")
    parser.add_argument("--queries", type=int, default=50, help="random grasp queries per object for the chaining time")
    parser.add_argument("--max-poses", type=float, default=1.2e7, help="skip the 1 x 1 degree table above this many IK poses")
    parser.add_argument("--compare", default="L,box", help="objects compared with the roadmap planner ('' for none)")
    parser.add_argument("--pairs", type=int, default=5, help="start/goal placement pairs per compared object")
    parser.add_argument("--seed", type=int, default=0, help="seed of the queries and pairs")
    parser.add_argument("--points", type=int, default=3, help="grasp points per feature pair of the second compared table")
    parser.add_argument("--dir", default="build/bench/gptable", help="folder of the roadmap planner's stores")
    parser.add_argument("--executable", type=int, default=9,
                        help="seeded grasp queries of the L part from the robot's default pedestal realised with their "
                             "timed motions (0: skip)")


def _objects(spec: str) -> list[tuple[str, ObjectModel]]:
    names = [n.strip() for n in spec.split(",") if n.strip()]
    pool = {label.split(" ")[0]: obj for label, _, obj in bench_objects("all")}
    out = []
    for n in names:
        if n == "L":
            out.append(("L (Fig. 1)", l_part()))
        elif n == "box":
            out.append(("box", from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")))
        elif n == "paper":
            out += [(label, obj) for label, _, obj in bench_objects("paper")]
        elif n == "organic":
            out += [(f"organic {k}", from_trimesh(make(), k)) for k, make in ORGANIC.items()]
        elif n in ORGANIC:
            out.append((f"organic {n}", from_trimesh(ORGANIC[n](), n)))
        elif n in pool:
            out.append((n, pool[n]))
        else:
            raise WorkbenchError(f"unknown object {n!r}: use L, box, paper or one of {', '.join(pool)}")
    return out


def ik_throughput(robot, n: int = 200_000, repeats: int = 5) -> dict[str, tuple[float, float]]:
    """Closed-form IK poses per second on FK of random configurations, all 8 branches with limits, best of `repeats`:
    per wall-clock second and per CPU second of this process (what a dedicated core gives on a shared machine), for
    `solve` (joint values of every branch) and for `reachable` (validity only, the grasp-placement table's pass)."""
    ik = analytic_ik(robot)
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(256, robot.nq))
    poses = np.array([robot.tcp_pose(x) for x in q])
    poses = np.tile(poses, (n // len(poses) + 1, 1, 1))[:n]
    out = {}
    for label, fn in (("joints", lambda p: solve(ik, p)), ("validity", lambda p: reachable(ik, p))):
        best, best_cpu = np.inf, np.inf
        for _ in range(repeats):
            t0, c0 = time.perf_counter(), time.process_time()
            for s in range(0, n, 20000):
                fn(poses[s:s + 20000])
            best, best_cpu = min(best, time.perf_counter() - t0), min(best_cpu, time.process_time() - c0)
        out[label] = (n / best, n / best_cpu)
    return out


def target_table(classes, placements: np.ndarray, robot, hand, params, runs: int = 3) -> tuple[float, float, int]:
    """The issue's target size, 100 classes x 10 placements at `params`: the given classes and placements repeated
    up to that size (each repeat of a placement turned about the vertical, still a resting pose), built `runs`
    times: (median wall s, median CPU s of this process, IK poses)."""
    cl = [classes[i % len(classes)] for i in range(100)]
    n = len(placements)
    pl = np.array([rz(np.radians(37.0 * (k // n)))[0] @ placements[k % n] for k in range(10)])
    wall, cpu, poses = [], [], 0
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        t = build_table(cl, pl, robot, hand, params, progress=False)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        poses = t.timings.get("ik_poses", 0)
    return statistics.median(wall), statistics.median(cpu), poses


def chaining_times(table, classes, queries: int, seed: int) -> list[float]:
    """Seconds of `queries` seeded grasp queries (any outcome; the chaining and the sequence's reconstruction)."""
    rng = np.random.default_rng(seed)
    out = []
    table.matrix()  # the chaining's layout of Q is built once per table, not per query
    legal = np.argwhere(table.hand_object)
    if not len(legal):
        return out
    for _ in range(queries):
        c, t = legal[rng.integers(len(legal))]
        g = int(rng.integers(len(classes)))
        lo = float(rng.uniform(0, 2 * np.pi))
        t0 = time.perf_counter()
        try:
            grasp_query(table, (int(c), float(table.theta[t])), g, (lo, lo + np.pi / 2))
        except PlanningError:
            pass
        out.append(time.perf_counter() - t0)
    return out


def compare_roadmap(name: str, obj: ObjectModel, robot_name: str, tables: list, point, pairs: int, seed: int,
                    folder: Path, classes=None) -> tuple[list[list], list, list[str]]:
    """Per table of `tables` (same placements, e.g. one and several grasp points per class), this planner's regrasps
    over seeded start/goal placement pairs at H, the roadmap planner's (Wan & Harada) for the same pairs (None: no
    plan), and why the first table has no answer where it has none."""
    table = tables[0]
    tp = TabletopParams(x_min=point[0], x_max=point[0], nx=1, y_min=point[1], y_max=point[1], ny=1, angles=8)
    folder.mkdir(parents=True, exist_ok=True)
    db = folder / f"{name.split(' ')[0]}_{robot_name}.duckdb"
    build_all(db, obj, robot_name, tparams=tp, progress=False)
    rng = np.random.default_rng(seed)
    ours, theirs, why = [[] for _ in range(len(tables) + 1)], [], []
    robot = get_robot(robot_name)
    realiser = Realiser(robot, default_scene(robot_name), obj.mesh)
    with Store(db) as store:
        planner = load_planner(store, obj.name, robot_name)
        free_ids, free_poses = planner.free["idfreetabletopplacement"], planner.free["rotmat"]
        # the same stable placements: match the table's placement classes to the stored free placements
        match = {}
        for j, p in enumerate(table.placements):
            hit = [int(i) for i, f in zip(free_ids, free_poses) if np.allclose(f, p, atol=1e-6)]
            if hit:
                match[j] = hit[0]
        js = sorted(match)
        for _ in range(pairs if js else 0):
            (a, b), (fa, fb) = rng.choice(js, 2), rng.uniform(0, 2 * np.pi, 2)
            for k, t in enumerate(tables):
                try:
                    ours[k].append(placement_query(t, (int(a), float(fa)), (int(b), float(fb))).regrasps)
                except NoSequence as exc:
                    ours[k].append(None)
                    if k == 0:
                        why.append(f"{int(a)}->{int(b)}: {str(exc).split('connect them: ', 1)[-1]}")
            try:  # the first table's answer realised: IK with self-collisions, approach and lifts (no motions)
                ours[-1].append(plan_placement_query(table, classes, realiser, robot, obj.name, (int(a), float(fa)),
                                                     (int(b), float(fb)))[1].regrasps)
            except PlanningError:
                ours[-1].append(None)
            try:
                res = planner.search(PoseQuery(match[int(a)], point[0], point[1], float(fa)),
                                     PoseQuery(match[int(b)], point[0], point[1], float(fb)), 0)
                theirs.append(res.routes[0].n_regrasps)
            except PlanningError:
                theirs.append(None)
    return ours, theirs, why


def executable_queries(robot, point, n: int, seed: int) -> tuple[list[str], list[float]]:
    """`n` seeded grasp queries of the L part that the table answers (a legal initial grasp, another class's whole
    range as the goal; queries without a table answer are drawn again) planned with their timed motions at the
    default limit, as `gpplan` does: one outcome per query and each query's seconds."""
    part = l_part()
    classes = grasp_classes(part, robot.gripper)
    table = build_table(classes, stable_placements(part).poses, robot, robot.gripper, TableParams(table_point=point),
                        progress=False)
    realiser = Realiser(robot, default_scene(robot.name), part.mesh)
    rng = np.random.default_rng(seed)
    legal = np.argwhere(table.hand_object)
    out, secs = [], []
    for _ in range(50 * n):
        if len(out) == n:
            break
        c, t = legal[rng.integers(len(legal))]
        goal = int((c + rng.integers(1, len(classes))) % len(classes))
        try:
            grasp_query(table, (int(c), float(table.theta[t])), goal, (0.0, 2 * np.pi))
        except PlanningError:
            continue
        t0 = time.perf_counter()
        try:
            seq, _plan = plan_grasp_query(table, classes, realiser, robot, "L", (int(c), float(table.theta[t])), goal,
                                          (0.0, 2 * np.pi), ExecOptions())
            k = len(seq.extra.get("removed", []))
            out.append(f"ok ({seq.regrasps} regrasps, table {seq.extra['table']['regrasps']}, {k} removed)")
        except NoSequence as exc:
            k = len(getattr(exc, "removals", ()))
            out.append(f"none after {k} removals ({exc})")
        secs.append(time.perf_counter() - t0)
    return out, secs


def run(args: argparse.Namespace) -> int:
    point = tuple(float(v) for v in args.table_point.split(","))
    robot = get_robot(args.robot)
    hand = robot.gripper
    compare = {n.strip() for n in args.compare.split(",") if n.strip()}
    rows, cmp_rows, why = [], [], []
    biggest = None
    total = {"classes": 0, "placements": 0, "hand_object": 0.0, "hand_table": 0.0, "ik": 0.0, "ik_poses": 0}
    for label, obj in _objects(args.objects):
        t0 = time.perf_counter()
        classes = grasp_classes(obj, hand)
        t_cls = time.perf_counter() - t0
        pl = stable_placements(obj)
        p5 = TableParams(table_point=point)
        t0 = time.perf_counter()
        table = build_table(classes, pl.poses, robot, hand, p5, progress=False)
        t5 = time.perf_counter() - t0
        # the 1 x 1 degree table: estimate its IK poses from the hand-table stage of a 1-degree theta grid
        n1 = len(grid(np.radians(1.0)))
        est = int(table.hand_table.sum() * (n1 / len(table.theta)) * n1)
        if est <= args.max_poses:
            t0 = time.perf_counter()
            build_table(classes, pl.poses, robot, hand, TableParams(theta_step=np.radians(1.0), phi_step=np.radians(1.0),
                                                                     table_point=point), progress=False)
            t1 = f"{time.perf_counter() - t0:.2f}"
        else:
            t1 = f"skipped ({est / 1e6:.0f} M poses)"
        times = chaining_times(table, classes, args.queries, args.seed)
        if classes and len(pl) and (biggest is None or len(classes) * len(pl) > len(biggest[1]) * len(biggest[2])):
            biggest = (label, classes, pl.poses, p5)
        kinds = [sum(c.kind == k for c in classes) for k in KINDS]
        tm = table.timings
        for k, v in (("classes", len(classes)), ("placements", len(pl)), ("hand_object", t_cls),
                     ("hand_table", tm.get("hand_table", 0.0)), ("ik", tm.get("ik", 0.0)), ("ik_poses", tm.get("ik_poses", 0))):
            total[k] += v
        rows.append([label, obj.n_triangles, *kinds, len(pl), f"{int(table.q.any(axis=(2, 3)).sum())}/{len(classes) * len(pl)}",
                     round(t_cls, 2), round(tm.get("hand_table", 0.0), 3), round(tm.get("ik", 0.0), 3), round(t_cls + t5, 2),
                     tm.get("ik_poses", 0), t1,
                     statistics.median(times) * 1000 if times else "-", max(times) * 1000 if times else "-"])
        if label.split(" ")[0] in compare:
            more = build_table(grasp_classes(obj, hand, ClassParams(points=args.points)), pl.poses, robot, hand, p5, progress=False)
            ours, theirs, w = compare_roadmap(label, obj, args.robot, [table, more], point, args.pairs, args.seed, Path(args.dir),
                                              classes)
            fmt = lambda v: "-" if v is None else str(v)  # noqa: E731
            cmp_rows.append([label, len(theirs), " ".join(map(fmt, ours[0])), f"{' '.join(map(fmt, ours[1]))} ({more.q.shape[0]} classes)",
                             " ".join(map(fmt, ours[2])), " ".join(map(fmt, theirs))])
            why += [f"{label}, {x}" for x in w]
    print_table(["object", "#tri", "face/face", "face/edge", "face/vertex", "placements", "non-empty cells",
                 "hand-object s", "hand-table s", "IK s", "all stages 5x5 s", "IK poses 5x5", "table 1x1 s", "chain med ms",
                 "chain max ms"], rows,
                title=f"Grasp-placement table for {args.robot} at H = {point} (Tournassoud et al. 1987), each part's own "
                      "classes; hand-object = the grasp classes with their legal theta ranges (Section 5.1), hand-table and "
                      "IK at 5 x 5 deg (Section 5.2); targets: 100 classes x 10 placements at 5x5 deg <= 2 s, a query <= 10 ms")
    print(f"every real part above together: {total['classes']} classes and {total['placements']} placements; hand-object "
          f"{total['hand_object']:.2f} s, hand-table {total['hand_table']:.2f} s, IK {total['ik']:.2f} s for "
          f"{total['ik_poses']:,} poses (5 x 5 deg), all stages {total['hand_object'] + total['hand_table'] + total['ik']:.2f} s")
    if biggest is not None:
        label, classes, poses, p5 = biggest
        wall_t, cpu_t, n_poses = target_table(classes, poses, robot, hand, p5)
        print(f"synthetic target table, 100 classes x 10 placements at 5 x 5 deg ({label}'s {len(classes)} classes and "
              f"{len(poses)} placements repeated; hand-table and IK only, no hand-object stage): {wall_t:.2f} s wall, "
              f"{cpu_t:.2f} s CPU (median of 3; {n_poses:,} IK poses; target <= 2 s)")
    print()
    rates = ik_throughput(robot)
    (wall, cpu), (wall_v, cpu_v) = rates["joints"], rates["validity"]
    print(f"closed-form IK ({args.robot}, 8 branches, joint limits, one process): {wall:,.0f} poses per second, {cpu:,.0f} per "
          f"CPU second with every branch's joints; {wall_v:,.0f} ({cpu_v:,.0f} per CPU second) validity only, the table's "
          f"pass (target >= 500,000; best of 5)")
    if args.executable > 0:
        outcomes, secs = executable_queries(robot, point, args.executable, args.seed)
        ok = sum(o.startswith("ok") for o in outcomes)
        print()
        print(f"executable from {args.robot}'s default pedestal: {ok} of {len(outcomes)} seeded grasp queries of the L part "
              f"that the table answers "
              f"(motions planned, default --max-removed 10; median {statistics.median(secs):.1f} s per query, wall):")
        for k, o in enumerate(outcomes):
            print(f"  query {k + 1}: {o}")
    if cmp_rows:
        print()
        print_table(["object", "pairs", "regrasps (this planner)", f"this planner, {args.points} points per pair",
                     "this planner, realised", "regrasps (roadmap planner)"], cmp_rows,
                    title="Same start/goal placements at H, seeded ('-': no plan); this planner's table answers with one "
                          f"grasp point per class (the paper's method) and with up to {args.points} (its Handey remedy, "
                          "Section 2.3), and the first realised (IK with self-collisions, approach and lifts, as the "
                          "roadmap planner's IK stage); the roadmap planner's graph search")
        for line in why:
            print(f"  no plan (one point per class): {line}")
    return 0
