"""`workbench gptable MESH --robot ROBOT --db DB`: grasp classes, placement classes and the grasp-placement table
(Tournassoud, Lozano-Perez & Mazer 1987, Sections 2-5), built and stored (or reused from the store)."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from workbench.cli.grasps import add_object_arguments
from workbench.cli.ik import parse_base
from workbench.errors import WorkbenchError
from workbench.geometry.objects import load_object
from workbench.grasping.placements import PlacementParams
from workbench.params import add_param, bounds
from workbench.planners.tournassoud.classes import KINDS, ClassParams, no_class_reason
from workbench.planners.tournassoud.stages import table_stage_at
from workbench.planners.tournassoud.table import TableParams
from workbench.cli.gripper import add_gripper_argument, gripper_from_args
from workbench.robots.model import get_robot


def parse_point(text: str, label: str = "--table-point") -> tuple[float, float]:
    """`X,Y` in metres."""
    try:
        x, y = (float(v) for v in str(text).split(","))
    except ValueError:
        raise WorkbenchError(f"{label} {text!r} must be X,Y in metres, e.g. 0.45,0.1") from None
    return x, y


def add_table_arguments(parser: argparse.ArgumentParser) -> None:
    """Class and table parameters (degrees and metres on the command line)."""
    c, t = ClassParams(), TableParams()
    parser.add_argument("--robot", default="puma560", help="a built-in robot or the path of a URDF (then --tip)")
    parser.add_argument("--tip", default=None, help="tip frame of a URDF robot")
    parser.add_argument("--base", default=None, help="robot base in the world: X,Y,Z,YAW (m, rad); default per robot")
    for cls, name, default in ((TableParams, "theta_step", np.degrees(t.theta_step)),
                               (TableParams, "phi_step", np.degrees(t.phi_step)), (TableParams, "clearance", t.clearance),
                               (ClassParams, "edge_angle", np.degrees(c.edge_angle)),
                               (ClassParams, "min_face_area", c.min_face_area),
                               (ClassParams, "min_contact_area", c.min_contact_area),
                               (ClassParams, "min_range", np.degrees(c.min_range)), (ClassParams, "points", c.points)):
        add_param(parser, cls, name, cli_default=float(default) if isinstance(default, float) else default)
    parser.add_argument("--table-point", default=",".join(f"{v:g}" for v in t.table_point), metavar="X,Y",
                        help="the table point H as X,Y in metres (world frame, in the robot's dextrous workspace; each "
                             f"{bounds(TableParams)['table_point'][0].describe(True)})")


def params_from_args(args: argparse.Namespace):
    cp = ClassParams(min_face_area=args.min_face_area, edge_angle=float(np.radians(args.edge_angle)),
                     theta_step=float(np.radians(args.theta_step)), bisection=min(float(np.radians(0.1)), float(np.radians(args.theta_step))),
                     min_contact_area=args.min_contact_area, min_range=float(np.radians(args.min_range)),
                     points=args.points)
    tp = TableParams(theta_step=float(np.radians(args.theta_step)), phi_step=float(np.radians(args.phi_step)),
                     table_point=parse_point(args.table_point), clearance=args.clearance)
    return cp, tp


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("gptable", help="grasp classes and the grasp-placement table (Tournassoud et al. 1987)")
    add_object_arguments(p)
    p.add_argument("--db", required=True, help="DuckDB store file")
    add_table_arguments(p)
    add_param(p, PlacementParams, "min_stability")
    add_gripper_argument(p)
    p.set_defaults(func=run)


def summary(run) -> list[str]:
    """Counts of a table run: classes by kind, placement classes, non-empty cells, timings."""
    t = run.table
    kinds = {k: sum(c.kind == k for c in run.classes) for k in KINDS}
    c_n, p_n, t_n, f_n = t.q.shape
    cells = int(t.q.any(axis=(2, 3)).sum())
    tm = t.timings
    return [f"{run.obj.name}: {len(run.classes)} grasp classes ({', '.join(f'{v} {k}' for k, v in kinds.items())}), "
            f"{p_n} placement classes, theta x phi grid {t_n} x {f_n}",
            f"table: {cells} of {c_n * p_n} cells non-empty, {int(t.q.sum())} legal (theta, phi) samples"
            + (" (reused from the store)" if run.reused[1] else
               f"; built in {tm.get('total', 0.0):.2f} s (IK {tm.get('ik', 0.0):.2f} s for {tm.get('ik_poses', 0)} poses)")]


def run(args: argparse.Namespace) -> int:
    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name, accept_size=args.accept_size)
    cp, tp = params_from_args(args)
    base = parse_base(args.base) if args.base else None
    robot = get_robot(args.robot, base=base, tip_frame=args.tip, gripper=gripper_from_args(args))
    r = table_stage_at(args.db, obj, robot, cp, tp, PlacementParams(min_stability=args.min_stability),
                       progress=sys.stderr.isatty())
    for line in summary(r):
        print(line)
    if r.narrow[0]:
        print(f"warning: {r.narrow[0]} grasp class(es) dropped as narrower than --min-range {args.min_range:g} deg (the "
              f"widest of them {np.degrees(r.narrow[1]):.1f} deg); --min-range 0 keeps them", file=sys.stderr)
    if not r.classes:
        print(f"warning: no grasp class: {no_class_reason(obj, robot.gripper, cp)}", file=sys.stderr)
    elif not r.table.q.any():
        print(f"warning: the table is empty; stage {r.table.empty_reason()}", file=sys.stderr)
    print(f"store {args.db}: classes paramset {r.idclasses}, table paramset {r.idtable}")
    return 0
