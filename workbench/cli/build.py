"""`workbench build MESH --robot ROBOT --db DB`: every stage of Wan & Harada Sections III-V for one object and robot
(grasps, placements, tabletop grips, IK with retractions, the regrasp graph), reusing what the store has."""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from workbench.cli import warn
from workbench.cli.grasps import add_grasp_arguments, add_object_arguments, grasp_params
from workbench.cli.ik import add_retraction_arguments, add_robot_arguments, robot_and_scene, stored_as
from workbench.cli.placements import (
    add_placement_arguments,
    placement_params,
    roadmap_grasps_line,
)
from workbench.geometry.objects import load_object
from workbench.grasping.naming import per_part_numbers, placement_lines
from workbench.planners.wan_harada.stages import BuildResult, build_all
from workbench.robots.ik import IKOptions, solver_kind


def register(sub: argparse._SubParsersAction) -> None:

    parser = sub.add_parser("build", help="run every stage for a mesh and a robot (grasps, placements, IK, regrasp graph)")
    add_object_arguments(parser)
    parser.add_argument("--db", required=True, help="DuckDB store file (created when missing)")
    add_robot_arguments(parser)
    add_retraction_arguments(parser)
    add_placement_arguments(parser)
    add_grasp_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    robot, scene = robot_and_scene(args)  # before any work: a bad URDF or option is refused first
    opts = IKOptions(solver=args.ik, self_collide=True)
    pparams, tparams = placement_params(args)
    gparams = grasp_params(args)
    if args.handx > gparams.approach_length:  # the hand retracts that far: its grasps must clear the part that far back
        gparams = replace(gparams, approach_length=args.handx)
    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name, accept_size=args.accept_size)
    t0 = time.perf_counter()
    res = build_all(args.db, obj, robot, gparams, pparams, tparams, args.handx, args.worldz, args.workers,
                    worlda=args.worlda, scene=scene, ik=opts)
    print_build(res, args.db, time.perf_counter() - t0, f"; IK {solver_kind(robot, opts)}{stored_as(robot, res.robot)}")
    return 0


def print_build(res: BuildResult, db, seconds: float, note: str = "") -> None:
    c, t, r = res.counts, res.timings, res.reused
    verb = lambda k: "reused" if r.get(k) else "computed"  # noqa: E731
    if res.empty is not None:
        print(f"{res.name}: {c['grasps']} free-air grasps ({verb('grasps')}, {t['grasps']:.1f} s); {c['placements']} stable "
              f"placements, {c['tabletop_placements']:,} tabletop placements, {c['tabletop_grips']:,} tabletop grips; "
              f"IK for {res.robot} ({verb('ik')}, {t['ik']:.1f} s){note}; store {Path(db).resolve()} in {seconds:.1f} s")
        warn(f"no regrasp graph for {res.name}; stage {res.empty}")
        return
    print(f"{res.name}: {c['grasps']} free-air grasps ({verb('grasps')}, {t['grasps']:.1f} s); {c['placements']} stable placements, "
          f"{c['tabletop_placements']:,} tabletop placements, {c['tabletop_grips']:,} tabletop grips ({verb('placements')}, "
          f"{t['placements']:.1f} s); {roadmap_grasps_line(c['grasps_label'], c['roadmap_grasps'], c['usable_grasps'])}")
    print(f"IK for {res.robot} ({verb('ik')}, {t['ik']:.1f} s{note}); regrasp graph: {c['graph_nodes']:,} nodes, {c['graph_transfer_edges']:,} "
          f"transfer and {c['graph_transit_edges']:,} transit edges, {c['graph_grasps']} grasps, {c['graph_placements']} placements, "
          f"{c['graph_components']} component(s) ({t['graph']:.1f} s)")
    number = per_part_numbers(np.array(list(c["placement_rotmats"]), dtype=np.int64))  # the store's ids -> 1, 2, ...
    nogrip = (f" (no grasp clears the table on {', '.join(str(number[i]) for i in c['placements_nogrip'])})"
              if c["placements_nogrip"] else "")
    print(f"store {Path(db).resolve()} ready in {seconds:.1f} s; stable placements for --start/--goal "
          f"(PLACEMENT,X,Y,YAW): {', '.join(str(number[i]) for i in c['placement_ids'])}{nogrip}")
    for line in placement_lines(c["placement_rotmats"], c.get("placement_rocking")):
        print(f"  {line}")
