"""Plans confirmed by physics: searched, executable regrasp plans replayed in MuJoCo.

By default every bundled part and the procedural organic set (scans, blobs, tori, cups...) with two robots (Panda,
UR5) and 30 seeded random start/goal poses each; `--quick`: the tube and the bracket with the Panda, 5 poses.
Each part's store is built once under --dir (the demo grid) and reused; the poses are searched and their motions
planned; every executable plan is replayed (`workbench simulate`'s scene and verdict, default parameters).
Printed: the share confirmed, the failures by kind (collision of the robot, shove at closing, slip or drop in the
hand, roll after release, pose at a waypoint, goal), the stepping time per simulated second (its inverse is the
speed over real time) and per plan, and the convex decomposition's time (once per part, then read from its cache).

`--study`: the contact settings behind the defaults. The demo task of each bundled part (the Panda) replayed over
a grid of timestep x impratio x pad friction: confirmed or the first failure, the largest slip in the hand, the
final error against the goal.
"""

from __future__ import annotations

import argparse
import itertools
import math
import os
import statistics
import sys
import time
from pathlib import Path

from tqdm import tqdm

from workbench.benchmarks import print_table
from workbench.benchmarks.organic import organic_set
from workbench.benchmarks.regrasp import bench_robot, random_pairs
from workbench.errors import PlanningError, SimulationError, WorkbenchError
from workbench.geometry.objects import from_arrays, load_object
from workbench.geometry.symmetry import part_symmetry
from workbench.planners.wan_harada.motions import ExecOptions, plan_executable
from workbench.planners.wan_harada.stages import DEMO_GRID, build_all, choose_task, load_planner
from workbench.resources import bundled_objects
from workbench.simulation.decomposition import cache_dir, convex_parts
from workbench.simulation.replay import FAILURES, SimParams
from workbench.simulation.stages import simulate_in_memory
from workbench.store import Store

BUNDLED = "tube,bracket,wheel,planebody,tail,drill"
QUICK = {"objects": "tube,bracket", "organic": False, "robots": "panda", "pairs": 5}
STUDY = {"timestep": (0.001, 0.002, 0.004), "impratio": (1.0, 10.0), "friction": (0.3, 0.5, 1.0)}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--quick", action="store_true", help="the tube and the bracket with the Panda, 5 pairs each")
    parser.add_argument("--study", action="store_true",
                        help="the contact settings study: each bundled part's demo plan over timestep x impratio x friction")
    parser.add_argument("--objects", default=None, help=f"comma-separated bundled parts (default: all six, {BUNDLED})")
    parser.add_argument("--organic", action=argparse.BooleanOptionalAction, default=None,
                        help="also the procedural organic set (default: yes, --no-organic leaves it out)")
    parser.add_argument("--robots", default=None, help="comma-separated robots (default panda,ur5)")
    parser.add_argument("--pairs", type=int, default=None, help="random start/goal pairs per part and robot (default 30)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random pairs")
    parser.add_argument("--grip-force", type=float, default=None, help="finger force, N (default the gripper's)")
    parser.add_argument("--dir", default="build/bench/simulate", help="folder of the reused stores")
    parser.add_argument("--workers", type=int, default=None, help="IK processes when building (default: all cores)")


def _settings(args: argparse.Namespace) -> dict:
    """The run's parts, robots and pairs: --quick's, else the full benchmark's, each overridden when given."""
    base = QUICK if args.quick else {"objects": BUNDLED, "organic": True, "robots": "panda,ur5", "pairs": 30}
    out = {k: getattr(args, k) if getattr(args, k) is not None else v for k, v in base.items()}
    if out["pairs"] < 1:
        raise WorkbenchError(f"--pairs must be >= 1, got {out['pairs']}")
    return out


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


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0][:90]


def run(args: argparse.Namespace) -> int:
    if args.study:
        return study(args)
    cfg = _settings(args)
    params = SimParams(grip_force=args.grip_force)
    rows, totals = [], {k: 0 for k in FAILURES}
    n_all = n_ok = 0
    load = os.getloadavg()
    t_all = time.perf_counter()
    robots = [r.strip() for r in cfg["robots"].split(",") if r.strip()]
    objs = parts(cfg["objects"], cfg["organic"])
    bar = tqdm(total=len(objs) * len(robots), desc="simulate bench", unit="part x robot", file=sys.stderr)
    for obj in objs:
        bar.set_postfix_str(obj.name)
        db = Path(args.dir) / f"{obj.name}.duckdb"
        cached = (cache_dir() / f"{obj.digest}-{params.decomposition.key}.npz").is_file()
        t0 = time.perf_counter()
        try:
            hulls = convex_parts(obj.mesh, obj.digest, obj.name, params.decomposition)
        except WorkbenchError as exc:
            rows += [[obj.name, r, cfg["pairs"], 0, "-", "-", "-", "-", "-", "-", f"failed: {_first_line(exc)}"] for r in robots]
            bar.update(len(robots))
            continue
        t_decomp = time.perf_counter() - t0
        decomp = f"{t_decomp:.2f} ({'cached' if cached else 'computed'}, {len(hulls)} hulls)"
        symmetry = part_symmetry(obj.mesh)
        for label in robots:
            bar.update(1)
            try:
                res = build_all(db, obj, bench_robot(label), tparams=DEMO_GRID, workers=args.workers, progress=False)
            except WorkbenchError as exc:
                rows.append([obj.name, label, cfg["pairs"], 0, "-", f"build: {_first_line(exc)}", "-", "-", "-", "-", decomp])
                continue
            if res.empty is not None:
                rows.append([obj.name, label, cfg["pairs"], 0, "-", f"no graph ({res.empty.split(':')[0]})", "-", "-", "-", "-", decomp])
                continue
            with Store(db) as store:
                planner = load_planner(store, obj.name, res.robot)
                plans = []
                for start, goal in random_pairs(planner.placement_ids(gripped=True), DEMO_GRID, cfg["pairs"], args.seed):
                    try:
                        plans.append(plan_executable(planner, start, goal, ExecOptions()).plan)
                    except PlanningError:
                        continue
                kinds = {k: 0 for k in FAILURES}
                confirmed, per_plan, per_second, per_cpu = 0, [], [], []
                for plan in plans:
                    t1 = time.perf_counter()
                    try:
                        out = simulate_in_memory(store, plan, planner.robot, params, symmetry)
                    except SimulationError:
                        kinds["diverged"] = kinds.get("diverged", 0) + 1
                        totals["diverged"] = totals.get("diverged", 0) + 1
                        continue
                    per_plan.append(time.perf_counter() - t1)
                    per_second.append(out.seconds / out.simulated)
                    per_cpu.append(out.cpu_seconds / out.simulated)
                    confirmed += out.confirmed
                    if out.failure is not None:
                        kinds[out.failure.kind] += 1
                        totals[out.failure.kind] += 1
            n = len(plans)
            n_all, n_ok = n_all + n, n_ok + confirmed
            fails = ", ".join(f"{k} {v}" for k, v in kinds.items() if v) or "-"
            rows.append([obj.name, label, cfg["pairs"], n, f"{100.0 * confirmed / n:.0f}% ({confirmed}/{n})" if n else "-", fails,
                         round(statistics.median(per_second), 4) if n else "-",
                         round(1.0 / statistics.median(per_second), 1) if n else "-",
                         round(1.0 / statistics.median(per_cpu), 1) if n else "-",
                         round(statistics.median(per_plan), 2) if n else "-", decomp])
            bar.write("  " + " | ".join(map(str, rows[-1])), file=sys.stderr)  # each row as it is done, for long runs
    bar.close()
    print_table(["part", "robot", "pairs", "plans", "confirmed", "failures (first per plan)", "s per sim s", "x real time",
                 "x (CPU)", "s per plan", "decomposition s"], rows,
                title=f"Plans replayed in MuJoCo (timestep {params.timestep:g} s, impratio {params.impratio:g}, grip force "
                      f"{'the gripper default' if args.grip_force is None else f'{args.grip_force:g} N'}, goal tolerance "
                      f"{params.goal_tol * 1000:g} mm / 5 deg): {cfg['pairs']} random start/goal pairs per part and robot (seed "
                      f"{args.seed}), each executable plan simulated once; s per plan includes building the scene; x (CPU): simulated "
                      f"seconds per CPU second of stepping (the speed on a free core). Load "
                      f"average {load[0]:.1f} at the start. Targets: >= 20x real time, <= 2 s per plan with the decomposition cached")
    print(f"all parts: {n_ok}/{n_all} plans confirmed ({100.0 * n_ok / max(n_all, 1):.0f}%); first failures: "
          + (", ".join(f"{k} {v}" for k, v in totals.items() if v) or "none")
          + f"; {time.perf_counter() - t_all:.0f} s in all; load average {os.getloadavg()[0]:.1f} at the end")
    return 0


def study(args: argparse.Namespace) -> int:
    """The contact settings table (module docstring): each bundled part's demo task with the Panda, planned once,
    replayed for every timestep x impratio x friction."""
    load = os.getloadavg()
    names = args.objects or BUNDLED
    rows = []
    tally: dict[tuple, list[int]] = {}
    for obj in parts(names, False):
        db = Path(args.dir) / f"{obj.name}.duckdb"
        res = build_all(db, obj, "panda", tparams=DEMO_GRID, workers=args.workers, progress=False)
        if res.empty is not None:
            rows.append([obj.name, "-", "-", "-", f"no graph ({res.empty.split(':')[0]})", "-", "-", "-"])
            continue
        with Store(db) as store:
            planner = load_planner(store, obj.name, res.robot)
            try:
                start, goal = choose_task(planner, args.seed)
                plan = plan_executable(planner, start, goal, ExecOptions()).plan
            except PlanningError as exc:
                rows.append([obj.name, "-", "-", "-", f"no plan ({_first_line(exc)})", "-", "-", "-"])
                continue
            symmetry = part_symmetry(obj.mesh)
            for dt, imp, mu in itertools.product(*STUDY.values()):
                p = SimParams(timestep=dt, impratio=imp, friction=mu, grip_force=args.grip_force)
                t0 = time.perf_counter()
                try:
                    out = simulate_in_memory(store, plan, planner.robot, p, symmetry)
                except SimulationError:
                    tally.setdefault((dt, imp, mu), []).append(0)
                    rows.append([obj.name, f"{dt * 1000:g}", f"{imp:g}", f"{mu:g}", "diverged", "-", "-",
                                 f"{time.perf_counter() - t0:.2f}"])
                    continue
                slip = max((x for x in out.steps["slip"] if not math.isnan(x)), default=math.nan)
                tally.setdefault((dt, imp, mu), []).append(int(out.confirmed))
                rows.append([obj.name, f"{dt * 1000:g}", f"{imp:g}", f"{mu:g}",
                             "confirmed" if out.confirmed else f"{out.failure.kind} at step {out.failure.step + 1}",
                             f"{slip * 1000:.1f}", f"{out.final_error * 1000:.1f} / {math.degrees(out.final_angle):.1f}",
                             f"{time.perf_counter() - t0:.2f}"])
    print_table(["part", "timestep ms", "impratio", "friction", "verdict", "max slip mm", "goal error mm / deg", "s"], rows,
                title=f"Contact settings study: each bundled part's demo task (seed {args.seed}) with the Panda, one plan, "
                      f"replayed at every timestep x impratio x pad friction (grip force "
                      f"{'the gripper default' if args.grip_force is None else f'{args.grip_force:g} N'}). Load average "
                      f"{load[0]:.1f}")
    print_table(["timestep ms", "impratio", "friction", "confirmed"],
                [[f"{k[0] * 1000:g}", f"{k[1]:g}", f"{k[2]:g}", f"{sum(v)}/{len(v)}"] for k, v in tally.items()],
                title="Confirmed per setting, over the parts")
    return 0
