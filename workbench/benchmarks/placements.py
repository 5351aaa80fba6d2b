"""Placements and the tabletop roadmap data (Section IV) beside Table I's #-fp, #-fpg, t-fp, #-tp and #-tpg.

`--protocol paper` (default) measures what Table I measures: every free tabletop grip of every free placement at
each of the paper's 168 tabletop placements per free placement (21 positions x 8 angles), with all grasps, so
#-tp = 168 x #-fp and #-tpg = 168 x the sum of #-fpg. `--protocol interactive` adds Fig. 7's 91-position grid and
honours `--max-grasps` (a quick look), labelled as such."""

from __future__ import annotations

import argparse
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import trimesh

from workbench.benchmarks import median_time, print_table
from workbench.benchmarks.organic import ORGANIC
from workbench.benchmarks.paper import TABLE_I, bench_objects
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import (
    PlacementParams,
    free_tabletop_grips,
    stable_placements,
)
from workbench.planners.wan_harada.stages import ensure_grasps, ensure_placements
from workbench.planners.wan_harada.tabletop import TabletopParams, paper_grid
from workbench.robots.gripper import franka_hand
from workbench.store import Store
from workbench.store.grasps import load_grasps


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=3, help="runs per object (the median is printed)")
    parser.add_argument("--objects", choices=["all", "bundled", "paper"], default="all")
    parser.add_argument("--protocol", choices=["paper", "interactive"], default="paper",
                        help="paper: Table I's 168 placements per free placement, all grasps; interactive: also Fig. 7's grid, "
                             "--max-grasps honoured")
    parser.add_argument("--max-grasps", type=int, default=0, help="interactive protocol only: cap the roadmap's grasps (0: all)")
    parser.add_argument("--set", dest="set", choices=["paper", "organic"], default="paper",
                        help="paper: Table I's protocol on the bundled and paper objects; organic: each placement's "
                             "quasi-static rest probability beside its stability, on procedural scans, rings, cups, "
                             "faceted bars and a pin with two flats")


def run(args: argparse.Namespace) -> int:
    if args.set == "organic":
        return _organic(args)
    hand = franka_hand()
    cap = args.max_grasps or None if args.protocol == "interactive" else None
    grids = {"T-I 21x8": TabletopParams(max_grasps=cap)}
    if args.protocol == "interactive":
        grids["Fig.7 91x8"] = TabletopParams(**{**paper_grid().as_dict(), "max_grasps": cap})
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for label, row, obj in bench_objects(args.objects):
            db = Path(tmp) / f"{obj.name}.duckdb"
            g = ensure_grasps(db, obj, hand, GraspParams())
            with Store(db) as store:
                grasps = load_grasps(store, g.idobject, g.idparamset)

            def placements():
                pl = stable_placements(obj)
                return pl, free_tabletop_grips(pl, grasps["rotmat"], hand)

            t_fp, (pl, ftg) = median_time(placements, args.repeats)
            fpg = [int((ftg[0] == k).sum()) for k in range(len(pl))]
            paper = TABLE_I.get(row)
            for name, grid in grids.items():
                writes = []
                for rep in range(args.repeats):
                    rdb = Path(tmp) / f"{obj.name}-{name[:4]}-{rep}.duckdb"
                    ensure_grasps(rdb, obj, hand, GraspParams())
                    t0 = time.perf_counter()
                    r = ensure_placements(rdb, g.idobject, obj, g.idparamset, hand, PlacementParams(), grid)
                    writes.append(time.perf_counter() - t0)
                    rdb.unlink()
                writes.sort()
                per = grid.nx * grid.ny * grid.angles
                rows.append([label, name, grid.grasps_label(), len(pl), ",".join(map(str, fpg)), t_fp, r.n_tabletop_placements,
                             r.n_tabletop_grips, f"{per} x {sum(fpg):,} = {per * sum(fpg):,}", writes[len(writes) // 2],
                             paper[3] if paper else "-", ",".join(map(str, paper[4])) if paper else "-",
                             paper[5] if paper else "-", paper[6] if paper else "-", paper[7] if paper else "-"])
    print_table(["object", "grid", "grasps", "#-fp", "#-fpg", "t-fp s", "#-tp", "#-tpg", "check", "t-store s", "paper #-fp",
                 "paper #-fpg", "paper t-fp s", "paper #-tp", "paper #-tpg"], rows,
                title=f"Placements and tabletop grips, protocol {args.protocol} (median of {args.repeats}; t-store = compute and "
                      "write the tabletop stages into DuckDB; check = placements per free placement x sum of #-fpg, which "
                      "#-tpg equals when every grasp enters the roadmap)")
    return 0


def _organic_parts() -> dict:
    """The organic set plus shapes whose sides roll: a 12-sided bar, a hexagonal bar and a round pin with flats."""
    parts = {name: make for name, make in ORGANIC.items()}
    parts["bar 12 sides"] = lambda: trimesh.creation.cylinder(radius=0.015, height=0.06, sections=12)
    parts["bar 6 sides"] = lambda: trimesh.creation.cylinder(radius=0.015, height=0.06, sections=6)
    parts["pin, 2 flats"] = lambda: trimesh.boolean.intersection(
        [trimesh.creation.cylinder(radius=0.0185, height=0.05, sections=24), trimesh.creation.box((0.04, 0.025, 0.06))],
        engine="manifold")
    return parts


def _organic(args: argparse.Namespace) -> int:
    rows = []
    for name, make in _organic_parts().items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obj = from_trimesh(make(), name)
        t, pl = median_time(lambda: stable_placements(obj), args.repeats)
        rows.append([name, len(pl), " ".join(f"{p:.2f}/{s:.2f}" + ("r" if r else "")
                                              for p, s, r in zip(pl.probability, pl.stability, pl.rocking)),
                     int(np.sum(pl.rocking)), f"{float(np.sum(pl.probability)):.2f}", t])
    print_table(["part", "#-fp", "probability/stability, r: rocks (most likely first)", "#-rocking", "sum p kept", "t-fp s"],
                rows,
                title=f"Placements with their quasi-static rest probability (a part dropped at random; it rolls on from "
                      f"a rocking support, a faceted round side, when a steadier support is within reach) beside the "
                      f"support-polygon stability (median of {args.repeats} runs)")
    return 0
