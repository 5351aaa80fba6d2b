"""Placements and the tabletop roadmap data (Section IV) beside Table I's #-fp, #-fpg, t-fp, #-tp and #-tpg.

`--protocol paper` (default) measures what Table I measures: every free tabletop grip of every free placement at
each of the paper's 168 tabletop placements per free placement (21 positions x 8 angles), with all grasps, so
#-tp = 168 x #-fp and #-tpg = 168 x the sum of #-fpg. `--protocol interactive` adds Fig. 7's 91-position grid and
honours `--max-grasps` (a quick look), labelled as such."""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from workbench.benchmarks import median_time, print_table
from workbench.benchmarks.paper import TABLE_I, bench_objects
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


def run(args: argparse.Namespace) -> int:
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
