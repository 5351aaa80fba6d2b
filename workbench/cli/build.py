"""`workbench build MESH --robot ROBOT --db DB`: every stage of Wan & Harada Sections III-V for one object and robot
(grasps, placements, tabletop grips, IK with retractions, the regrasp graph), reusing what the store has."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from workbench.cli import warn
from workbench.cli.grasps import add_grasp_arguments, add_object_arguments, grasp_params
from workbench.cli.placements import (
    add_placement_arguments,
    placement_params,
    roadmap_grasps_line,
)
from workbench.errors import WorkbenchError
from workbench.geometry.objects import load_object
from workbench.planners.wan_harada.stages import HANDX, WORLDZ, BuildResult, build_all
from workbench.robots.ik import WORLDA


def register(sub: argparse._SubParsersAction) -> None:

    parser = sub.add_parser("build", help="run every stage for a mesh and a robot (grasps, placements, IK, regrasp graph)")
    add_object_arguments(parser)
    parser.add_argument("--robot", required=True, help="robot: panda, ur5 or talos")
    parser.add_argument("--db", required=True, help="DuckDB store file (created when missing)")
    parser.add_argument("--handx", type=float, default=HANDX, help=f"retraction along the approach axis (m, default {HANDX})")
    parser.add_argument("--worldz", type=float, default=WORLDZ, help=f"retraction up along world z (m, default {WORLDZ})")
    parser.add_argument("--worlda", type=float, default=WORLDA,
                        help=f"lift of the held object straight up along world z (m, default {WORLDA})")
    parser.add_argument("--workers", type=int, default=None, help="IK processes (default: all cores)")
    add_placement_arguments(parser)
    add_grasp_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    for label, v in (("--handx", args.handx), ("--worldz", args.worldz), ("--worlda", args.worlda)):
        if not v >= 0:
            raise WorkbenchError(f"{label} must be a distance >= 0 m, got {v}")
    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name)
    pparams, tparams = placement_params(args)
    t0 = time.perf_counter()
    res = build_all(args.db, obj, args.robot, grasp_params(args), pparams, tparams, args.handx, args.worldz, args.workers,
                    worlda=args.worlda)
    print_build(res, args.db, time.perf_counter() - t0)
    return 0


def print_build(res: BuildResult, db, seconds: float) -> None:
    c, t, r = res.counts, res.timings, res.reused
    verb = lambda k: "reused" if r.get(k) else "computed"  # noqa: E731
    if res.empty is not None:
        print(f"{res.name}: {c['grasps']} free-air grasps ({verb('grasps')}, {t['grasps']:.1f} s); {c['placements']} stable "
              f"placements, {c['tabletop_placements']:,} tabletop placements, {c['tabletop_grips']:,} tabletop grips; "
              f"IK for {res.robot} ({verb('ik')}, {t['ik']:.1f} s); store {Path(db).resolve()} in {seconds:.1f} s")
        warn(f"no regrasp graph for {res.name}; stage {res.empty}")
        return
    print(f"{res.name}: {c['grasps']} free-air grasps ({verb('grasps')}, {t['grasps']:.1f} s); {c['placements']} stable placements, "
          f"{c['tabletop_placements']:,} tabletop placements, {c['tabletop_grips']:,} tabletop grips ({verb('placements')}, "
          f"{t['placements']:.1f} s); {roadmap_grasps_line(c['grasps_label'], c['roadmap_grasps'], c['usable_grasps'])}")
    print(f"IK for {res.robot} ({verb('ik')}, {t['ik']:.1f} s); regrasp graph: {c['graph_nodes']:,} nodes, {c['graph_transfer_edges']:,} "
          f"transfer and {c['graph_transit_edges']:,} transit edges, {c['graph_grasps']} grasps, {c['graph_placements']} placements, "
          f"{c['graph_components']} component(s) ({t['graph']:.1f} s)")
    print(f"store {Path(db).resolve()} ready in {seconds:.1f} s; stable placements for --start/--goal "
          f"(PLACEMENT,X,Y,YAW): {', '.join(map(str, c['placement_ids']))}")
