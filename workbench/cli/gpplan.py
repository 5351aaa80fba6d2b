"""`workbench gpplan --db DB --object NAME --initial CLASS,THETA --goal CLASS,MIN:MAX`: a regrasp sequence by
backward chaining in a stored grasp-placement table (Tournassoud et al. 1987, Section 6); or, with
`--from P,PHI --to P,PHI`, the object from one placement to another. Angles in degrees."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from workbench.cli.gripper import add_gripper_argument, gripper_from_args
from workbench.cli.outputs import add_output, write_text
from workbench.cli.plan import add_motion_arguments, exec_options
from workbench.errors import WorkbenchError
from workbench.planners.tournassoud.chaining import NoSequence
from workbench.planners.tournassoud.figures import table_html
from workbench.planners.tournassoud.plans import (
    Realiser,
    plan_grasp_query,
    plan_placement_query,
)
from workbench.planners.tournassoud.stages import (
    load_planner,
    plan_validator,
    save_plan,
    validate_stored,
)
from workbench.robots.collider import Scene, default_scene
from workbench.store import Store
from workbench.store.robots import robot_with_gripper


def _nums(text: str, label: str, n: int, sep: str = ",") -> list[str]:
    parts = [p.strip() for p in str(text).split(sep)]
    if len(parts) != n:
        raise WorkbenchError(f"{label} {text!r} is malformed; see `workbench gpplan --help`")
    return parts


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def parse_grasp(text: str, label: str = "--initial") -> tuple[int, float]:
    """CLASS,THETA (degrees) -> (class, radians)."""
    c, t = _nums(text, label, 2)
    try:
        return int(c), float(np.radians(float(t)))
    except ValueError:
        raise WorkbenchError(f"{label} {text!r} must be CLASS,THETA (class index, degrees), e.g. 0,30") from None


def parse_goal(text: str) -> tuple[int, tuple[float, float]]:
    """CLASS,MIN:MAX (degrees) -> (class, (radians, radians))."""
    c, rng = _nums(text, "--goal", 2)
    try:
        lo, hi = (float(v) for v in _nums(rng, "--goal", 2, ":"))
        cls = int(c)
    except ValueError:
        raise WorkbenchError(f"--goal {text!r} must be CLASS,MIN:MAX (class index, degrees), e.g. 2,60:120") from None
    if hi < lo:
        raise WorkbenchError(f"--goal {text!r}: MAX {hi:g} is below MIN {lo:g}; give MIN:MAX with MIN <= MAX")
    return cls, (float(np.radians(lo)), float(np.radians(hi)))


def explanation(table, own, removals: list, seq=None, own_dict: dict | None = None) -> list[str]:
    """Lines explaining how the executable answer differs from the table's own: each conjunction removed (which motion
    or collision, at which step, why), then the table's shortest sequence beside the shortest executable one."""
    if own is not None:
        own_dict = own.as_dict(table)
    if own_dict is None:
        return []
    n = own_dict["regrasps"]
    if not removals:
        return [f"the table's shortest sequence has {n} regrasp(s); the arm executes it as it is"] if seq is not None else []
    lines = [f"  removed {x.text(table)}" for x in removals]
    own_pairs = set()
    g, p = own_dict["grasps"], own_dict["placements"]
    if own_dict["kind"] == "grasp":
        for k, pl in enumerate(p):
            own_pairs |= {(tuple(g[k]), tuple(pl)), (tuple(g[k + 1]), tuple(pl))}
    else:
        own_pairs = {(tuple(a), tuple(b)) for a, b in zip(g, p)} | {(tuple(a), tuple(b)) for a, b in zip(g, p[1:])}
    mine = sum(tuple(map(tuple, x.conjunction)) in own_pairs for x in removals)
    kinds = sorted({x.motion for x in removals})
    lines.append(f"the table's shortest sequence has {n} regrasp(s); {mine} of its conjunctions and "
                 f"{len(removals) - mine} of the later tries' fail with the arm ({', '.join(kinds)}); the shortest "
                 f"executable one has {'none' if seq is None else seq.regrasps}")
    return lines


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("gpplan", help="regrasp sequence by backward chaining in the grasp-placement table (Tournassoud et al.)")
    p.add_argument("--db", required=True, help="DuckDB store file with a table built by `workbench gptable`")
    p.add_argument("--object", required=True, help="object name in the store")
    p.add_argument("--robot", default=None, help="robot name in the store (default: the newest table's robot)")
    p.add_argument("--initial", default=None, help="initial grasp CLASS,THETA (degrees)")
    p.add_argument("--goal", default=None, help="goal class and theta range CLASS,MIN:MAX (degrees)")
    p.add_argument("--from", dest="from_", default=None, help="start placement P,PHI (degrees), instead of --initial")
    p.add_argument("--to", default=None, help="goal placement P,PHI (degrees), instead of --goal")
    p.add_argument("--table", default=None, help="table top corners in the world: XMIN,YMIN,XMAX,YMAX (m); default per robot")
    p.add_argument("--handx", type=float, default=0.05, help="approach distance along the hand's axis (m)")
    p.add_argument("--worldz", type=float, default=0.05, help="lift after the approach (m)")
    p.add_argument("--no-save", action="store_true", help="do not store the plan in the store's plan tables")
    p.add_argument("--no-motion", action="store_true", help="waypoints only: do not plan and time the motions")
    add_motion_arguments(p, "conjunctions of the table")
    add_output(p, "--json", "write the sequence and its plan to this JSON file")
    add_output(p, "--html", "write the table with the sequence overlaid (Fig. 6) to this HTML file")
    add_gripper_argument(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    grasp_mode = args.initial is not None or args.goal is not None
    place_mode = args.from_ is not None or args.to is not None
    if grasp_mode == place_mode or (grasp_mode and (args.initial is None or args.goal is None)) or \
            (place_mode and (args.from_ is None or args.to is None)):
        raise WorkbenchError("give either --initial CLASS,THETA with --goal CLASS,MIN:MAX, or --from P,PHI with --to P,PHI")
    for label, v in (("--handx", args.handx), ("--worldz", args.worldz)):
        if not np.isfinite(v) or v < 0:
            raise WorkbenchError(f"{label} {v} must be a non-negative distance in metres")
    gripper = gripper_from_args(args)
    robot = args.robot
    if robot is not None:
        with Store(args.db, read_only=True) as store:
            robot = robot_with_gripper(store, robot, gripper.digest) or robot
    r = load_planner(args.db, args.object, robot, gripper=gripper)
    scene = default_scene(r.robot.name)
    if args.table:
        t = [float(v) for v in _nums(args.table, "--table", 4)] if all(
            _is_float(v) for v in str(args.table).split(",")) else []
        if len(t) != 4 or not np.isfinite(t).all() or t[0] >= t[2] or t[1] >= t[3]:
            raise WorkbenchError(f"--table {args.table!r} must be XMIN,YMIN,XMAX,YMAX in metres with XMIN < XMAX, YMIN < YMAX")
        scene = Scene(table_min=(t[0], t[1]), table_max=(t[2], t[3]), table_thickness=scene.table_thickness,
                      workspace_min=scene.workspace_min, workspace_max=scene.workspace_max)
    realiser = Realiser(r.robot, scene, r.obj.mesh, args.handx, args.worldz)
    motions = None if args.no_motion else exec_options(args)
    try:
        if grasp_mode:
            initial = parse_grasp(args.initial)
            gc, rng = parse_goal(args.goal)
            seq, plan = plan_grasp_query(r.table, r.classes, realiser, r.robot, r.obj.name, initial, gc, rng, motions)
        else:
            start = parse_grasp(args.from_, "--from")
            goal = parse_grasp(args.to, "--to")
            seq, plan = plan_placement_query(r.table, r.classes, realiser, r.robot, r.obj.name, start, goal, motions)
    except NoSequence as exc:
        print(f"warning: {exc}", file=sys.stderr)
        print(f"{r.obj.name} with {r.robot.name}: no regrasp sequence (0 results)")
        removals = getattr(exc, "removals", [])
        for line in explanation(r.table, exc.table_sequence, removals, None):
            print(line)
        if args.json:
            own = exc.table_sequence
            write_text(args.json, json.dumps({"sequence": None, "plan": None, "reason": str(exc),
                                              "table_sequence": None if own is None else own.as_dict(r.table),
                                              "removed": [x.as_dict() for x in removals]}, indent=1))
        if args.html:  # the table alone (Fig. 5): where the query's grasps and placements are
            write_text(args.html, table_html(r.table, r.classes, None, title=f"{r.obj.name} with {r.robot.name}: no sequence"))
        return 0
    t = r.table
    print(f"{r.obj.name} with {r.robot.name}: {seq.regrasps} regrasp(s), chaining {seq.levels} step(s) in {seq.seconds * 1000:.2f} ms")
    for k, (c, ti) in enumerate(seq.grasps):
        print(f"  grasp {k}: class {c} ({r.classes[c].kind}) theta {np.degrees(t.theta[ti]):6.1f} deg")
    for k, (j, fi) in enumerate(seq.placements):
        print(f"  placement {k}: class {j} phi {np.degrees(t.phi[fi]):6.1f} deg")
    for line in explanation(t, None, seq.extra.get("removals", []), seq, seq.extra.get("table")):
        print(line)
    if plan is None:
        print("the initial grasp is already in the goal range: nothing to do")
    else:
        print(plan.summary())
        if args.no_save:
            report = plan_validator(args.db, r, scene).check(plan)
        else:
            idplan, plan = save_plan(args.db, r, plan, scene, realiser.opts)
            print(f"stored plan id {idplan} in {args.db} (planner tournassoud; tables plan, planstep)")
            report = validate_stored(args.db, r, idplan, plan, require_motion=motions is not None)
        print("validator: " + ("ok" if report.ok else "FAILED: " + "; ".join(report.errors[:3])))
    if args.json:
        doc = {"sequence": seq.as_dict(t), "plan": None if plan is None else plan.as_dict(),
               "table_sequence": seq.extra.get("table"), "removed": seq.extra.get("removed", [])}
        write_text(args.json, json.dumps(doc, indent=1))
        print(f"json: {args.json}")
    if args.html:
        write_text(args.html, table_html(t, r.classes, seq, title=f"{r.obj.name} with {r.robot.name}"))
        print(f"html: {args.html}")
    sys.stdout.flush()
    return 0
