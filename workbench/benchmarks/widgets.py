"""Notebook widgets, driven headless: latency from a widget change until its scene and text are updated.

Each notebook's main explorer is built as the notebook builds it, with a real meshcat server (its messages are
acknowledged by the server before a change returns), then each change is made `--repeats` times, alternating
between two values, and the median is printed with the geometry messages (set_object) it sent. Targets: a
view-only change at most 100 ms and no geometry sent; a threshold change on the tube at most 500 ms; a plan search
in notebook 04 at most 1 s once the planner is loaded (the independent validation runs when asked, timed on its own
row).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from workbench.benchmarks import print_table
from workbench.geometry.objects import load_object
from workbench.grasping.grasps import GraspParams
from workbench.grasping.memo import forget
from workbench.grasping.placements import PlacementParams
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.wan_harada.stages import (
    HANDX,
    WORLDZ,
    build_all,
    choose_task,
    ensure_grasps,
    ensure_placements,
    run_ik,
)
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.resources import bundled_objects
from workbench.robots.gripper import franka_hand
from workbench.robots.collider import default_scene
from workbench.robots.model import get_robot
from workbench.store import Store
from workbench.store import robots as sql
from workbench.viewer.scenes import geometry_sent, new_scene
from workbench.widgets.grasping import GraspExplorer
from workbench.widgets.phoka_sudsang import FingersExplorer
from workbench.widgets.wan_harada import IKBrowser, PlacementExplorer, RegraspExplorer

NOTEBOOKS = ("01", "02", "03", "04", "05")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=5, help="changes per widget (median)")
    parser.add_argument("--notebooks", default=",".join(NOTEBOOKS), help="which notebooks' widgets, e.g. 01,04")
    parser.add_argument("--db", type=Path, default=None, help="store for notebooks 02-04 (default: a temporary one)")


def measure(widget, values: tuple, repeats: int, vis, after=None, before=None) -> tuple[float, float, int]:
    """(median, max seconds, geometry messages per change) setting `widget.value` to `values` in turn (`before`
    runs untimed ahead of each change)."""
    times, sent = [], []
    for i in range(repeats):
        if before is not None:
            before()
        n = geometry_sent(vis)
        t0 = time.perf_counter()
        widget.value = values[i % len(values)]
        if after is not None:
            after()
        times.append(time.perf_counter() - t0)
        sent.append(geometry_sent(vis) - n)
    return statistics.median(times), max(times), max(sent)


def _row(rows: list, nb: str, change: str, kind: str, target: str, result: tuple[float, float, int]) -> None:
    med, worst, sent = result
    rows.append([nb, change, kind, f"{med * 1e3:.1f}", f"{worst * 1e3:.1f}", sent, target])


def bench_grasps(rows: list, repeats: int, db: Path) -> None:
    obj, hand = load_object(bundled_objects()["tube"]), franka_hand()
    ex = GraspExplorer(obj, hand)
    ex.run()
    view = "view only"
    _row(rows, "01", "highlighted facet", view, "100 ms", measure(ex.facet, (3, 9), repeats, ex.vis))
    _row(rows, "01", "hands drawn", view, "100 ms", measure(ex.hands, (12, 3), repeats, ex.vis))
    _row(rows, "01", "selected grasp", view, "100 ms", measure(ex.selected, (50, 400), repeats, ex.vis))
    _row(rows, "01", "layer: all samples", view, "100 ms",
         measure(ex.layers["all samples"], (True, False), repeats, ex.vis))
    tau = ex.tau.value
    ex.cache.size = 0  # every threshold change recomputes (the cache would answer the second visit)
    # values never planned before, a degree or a few from the last, as a slider moves: the jaw axes of the facets
    # that keep their normals come from the part's memo
    fresh = tuple(tau + s * k for k in range(1, repeats + 2) for s in (1, -1))[:max(2, repeats // 2)]
    _row(rows, "01", "threshold tau, a new value (recompute)", "recompute", "500 ms",
         measure(ex.tau, fresh, len(fresh), ex.vis))
    _row(rows, "01", "  the same with nothing remembered", "recompute", "-",
         measure(ex.tau, (tau + 2, tau), max(2, repeats // 2), ex.vis, before=lambda: forget(obj.mesh)))
    ex.cache.size = 8
    ex.tau.value = tau + 2
    ex.tau.value = tau
    _row(rows, "01", "threshold tau (cached)", "recompute", "500 ms", measure(ex.tau, (tau + 2, tau), repeats, ex.vis))


def bench_placements(rows: list, repeats: int, db: Path) -> None:
    obj, hand = load_object(bundled_objects()["tube"]), franka_hand()
    grasps = ensure_grasps(db, obj, hand, GraspParams())
    ex = PlacementExplorer(obj, hand, grasps.poses, grasps.widths)
    ex.run()
    ids = [v for _, v in ex.which.options]
    _row(rows, "02", "selected placement", "view only", "100 ms", measure(ex.which, (ids[-1], ids[0]), repeats, ex.vis))
    _row(rows, "02", "grips drawn", "view only", "100 ms", measure(ex.hands, (20, 4), repeats, ex.vis))
    _row(rows, "02", "every placement on the roadmap", "view only", "100 ms",
         measure(ex.roadmap, (True, False), repeats, ex.vis))
    nx = ex.nx.value
    _row(rows, "02", "grid positions along x (cached after 2)", "recompute", "-",
         measure(ex.nx, (nx + 2, nx), repeats, ex.vis))
    s = ex.stability.value
    _row(rows, "02", "stability threshold (cached after 2)", "recompute", "500 ms",
         measure(ex.stability, (s + 0.1, s), repeats, ex.vis))


def bench_regrasp(rows: list, repeats: int, db: Path) -> None:
    grid = TabletopParams(x_min=0.4, x_max=0.6, nx=3, y_min=-0.15, y_max=0.15, ny=3, angles=8, max_grasps=40)
    ex = RegraspExplorer(db, bundled_objects(), tparams=grid,
                         build=lambda db, obj, robot, gripper: build_all(db, obj, get_robot(robot, gripper=gripper),
                                                                         tparams=grid, progress=False))
    planner = ex.load()  # notebook 04's grid; the build is not timed
    start, goal = choose_task(planner, seed=0, grid=grid)
    ex.set_query(start, goal)
    ex.run()  # warm: the planner's caches and the scene

    def search():
        n = geometry_sent(ex.vis)
        t0 = time.perf_counter()
        ex.run()
        return ex.shown_at - t0, time.perf_counter() - t0, geometry_sent(ex.vis) - n

    runs = [search() for _ in range(max(1, repeats // 2))]
    shown, total = [r[0] for r in runs], [r[1] for r in runs]
    rows.append(["04", "search: the best plan shown (graph, timed motions, view)", "recompute",
                 f"{statistics.median(shown) * 1e3:.1f}", f"{max(shown) * 1e3:.1f}", max(r[2] for r in runs), "1 s"])
    rows.append(["04", f"  then its {ex.alternatives.value} alternatives planned (whole search)", "recompute",
                 f"{statistics.median(total) * 1e3:.1f}", f"{max(total) * 1e3:.1f}", "-", "-"])
    t = ex.plans[0].timings
    rows.append(["04", "  of which graph search (connect + search)", "-", f"{(t.get('connect', 0) + t.get('search', 0)) * 1e3:.1f}",
                 "-", "-", "-"])
    rows.append(["04", "  of which motions (last run)", "-", f"{t.get('motion', 0) * 1e3:.1f}", "-", "-", "-"])
    checks = []
    for _ in range(max(1, repeats // 2)):
        ex.reports = {}
        t0 = time.perf_counter()
        ex.check()
        checks.append(time.perf_counter() - t0)
    rows.append(["04", "validate the shown plan (button)", "recompute", f"{statistics.median(checks) * 1e3:.1f}",
                 f"{max(checks) * 1e3:.1f}", 0, "-"])
    if len(ex.which.options) > 1:
        _row(rows, "04", "animate another alternative", "view only", "100 ms",
             measure(ex.which, (1, 0), repeats, ex.vis))
    _row(rows, "04", "show the graph's nodes", "view only", "100 ms", measure(ex.nodes, (True, False), repeats, ex.vis))


def bench_reach(rows: list, repeats: int, db: Path) -> None:
    obj, hand = load_object(bundled_objects()["tube"]), franka_hand()
    grid = TabletopParams(nx=3, ny=2, angles=4, max_grasps=40)  # notebook 03's grid
    grasps = ensure_grasps(db, obj, hand, GraspParams())
    tabletop = ensure_placements(db, grasps.idobject, obj, grasps.idparamset, hand, PlacementParams(), grid)
    robot = get_robot("panda")
    with Store(db) as store:  # as notebook 03 computes them (not timed)
        run = run_ik(store, obj.name, robot, default_scene(robot.name), HANDX, WORLDZ, progress=False,
                     idtabletop=tabletop.idtabletop)
        rows_ik = sql.load_ik(store, run.idrobot, run.idscene, run.idikret, grasps.idobject, tabletop.idtabletop)
    vis = new_scene()
    browser = IKBrowser(vis, robot, rows_ik, obj.mesh)
    top = max(browser.slider.max, 1)
    _row(rows, "03", "feasible grip", "view only", "100 ms", measure(browser.slider, (top // 2, top), repeats, vis))
    _row(rows, "03", "grasp / handx / handxworldz", "view only", "100 ms",
         measure(browser.kind, ("handx", "grasp"), repeats, vis))


def bench_fingers(rows: list, repeats: int, db: Path) -> None:
    ex = FingersExplorer(load_object(bundled_objects()["wheel"]), ClusterParams(), faces=500)
    ex.build()
    result = ex.run_query(seed=1)
    if result.sequence is not None and len(result.sequence) > 1:
        last = len(result.sequence) - 1
        _row(rows, "05", "switch (finger step)", "view only", "100 ms", measure(ex.step, (last, 0), repeats, ex.vis))


BENCHES = {"01": bench_grasps, "02": bench_placements, "03": bench_reach, "04": bench_regrasp, "05": bench_fingers}


def run(args: argparse.Namespace) -> int:
    wanted = set(args.notebooks.split(","))
    rows: list = []
    with tempfile.TemporaryDirectory() as tmp:
        db = args.db or Path(tmp) / "widgets.duckdb"
        for nb, bench in BENCHES.items():
            if nb in wanted:
                bench(rows, args.repeats, db)
    print_table(["notebook", "change", "kind", "median ms", "max ms", "geometry msgs", "target"], rows,
                f"widget latency, change to scene updated (median of {args.repeats})")
    return 0
