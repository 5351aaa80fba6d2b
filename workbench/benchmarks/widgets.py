"""Notebook widgets, driven headless: latency from a widget change until its scene and text are updated.

Each notebook's main explorer is built as the notebook builds it, with a real meshcat server (its messages are
acknowledged by the server before a change returns), then each change is made `--repeats` times, alternating
between two values, and the median is printed with the geometry messages (set_object) it sent. Targets: a
view-only change at most 100 ms and no geometry sent; a threshold change on the tube at most 500 ms; a plan search
in notebook 04 at most 1 s once the planner is loaded.
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
from workbench.planners.wan_harada.stages import ensure_grasps
from workbench.resources import bundled_objects
from workbench.robots.gripper import franka_hand
from workbench.viewer.scenes import geometry_sent
from workbench.widgets.grasping import GraspExplorer
from workbench.widgets.wan_harada import PlacementExplorer

NOTEBOOKS = ("01", "02", "03", "04", "05", "06")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=5, help="changes per widget (median)")
    parser.add_argument("--notebooks", default=",".join(NOTEBOOKS), help="which notebooks' widgets, e.g. 01,04")
    parser.add_argument("--db", type=Path, default=None, help="store for notebooks 02-04 (default: a temporary one)")


def measure(widget, values: tuple, repeats: int, vis, after=None) -> tuple[float, float, int]:
    """(median, max seconds, geometry messages per change) setting `widget.value` to `values` in turn."""
    times, sent = [], []
    for i in range(repeats):
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
    _row(rows, "01", "threshold tau (recompute)", "recompute", "500 ms",
         measure(ex.tau, (tau + 2, tau), max(2, repeats // 2), ex.vis))
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


BENCHES = {"01": bench_grasps, "02": bench_placements}


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
