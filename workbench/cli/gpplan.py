"""`workbench gpplan --db DB --object NAME --initial CLASS,THETA --goal CLASS,MIN:MAX`: a regrasp sequence by
backward chaining in a stored grasp-placement table (Tournassoud et al. 1987, Section 6); or, with
`--from P,PHI --to P,PHI`, the object from one placement to another; or, with `--pickup P,X,Y,PHI --destination
P,X,Y,PHI`, Fig. 1's task: the part taken where it lies among the pick-up's obstacles (`--pickup-obstacle`),
regrasped on the table as often as needed and put at the destination, inserted along `--insert` past the
destination's obstacles (Section 5.1: the first and last grasps' angles follow from them). Angles in degrees."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from workbench.cli.gripper import add_gripper_argument, gripper_from_args, grippers_of, stored_robot_gripper
from workbench.cli.ik import RETRACT
from workbench.cli.outputs import add_output, write_text
from workbench.cli.plan import add_motion_arguments, exec_options, write_trajectory
from workbench.errors import WorkbenchError
from workbench.params import parse_number
from workbench.planners.tournassoud.chaining import NoSequence, in_range, nearest_sample
from workbench.planners.tournassoud.table import runs
from workbench.planners.tournassoud.task import Obstacle, TaskEnd, end_mask
from workbench.planners.tournassoud.figures import table_html
from workbench.planners.tournassoud.plans import (
    Realiser,
    explanation,
    plan_grasp_query,
    plan_placement_query,
    plan_task_query,
)
from workbench.planners.tournassoud.stages import (
    load_planner,
    load_stored,
    save_plan,
    stored_scene,
    validate_stored,
)
from workbench.viewer.tournassoud import plan_page
from workbench.robots.collider import Scene, default_scene
from workbench.store import Store
from workbench.store.objects import stored_grippers


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
        cls, theta = int(c), float(t)
    except ValueError:
        raise WorkbenchError(f"{label} {text!r} must be CLASS,THETA (class index, degrees), e.g. 0,30") from None
    if cls < 0 or not np.isfinite(theta):
        raise WorkbenchError(f"{label} {text!r} must be CLASS,THETA with a class index >= 0 and a finite angle in degrees, "
                             f"e.g. 0,30")
    return cls, float(np.radians(theta))


def parse_goal(text: str) -> tuple[int, tuple[float, float]]:
    """CLASS,MIN:MAX (degrees) -> (class, (radians, radians))."""
    c, rng = _nums(text, "--goal", 2)
    try:
        lo, hi = (float(v) for v in _nums(rng, "--goal", 2, ":"))
        cls = int(c)
    except ValueError:
        raise WorkbenchError(f"--goal {text!r} must be CLASS,MIN:MAX (class index, degrees), e.g. 2,60:120") from None
    if cls < 0 or not (np.isfinite(lo) and np.isfinite(hi)):
        raise WorkbenchError(f"--goal {text!r} must be CLASS,MIN:MAX with a class index >= 0 and finite angles in degrees, "
                             f"e.g. 2,60:120")
    if hi < lo:
        raise WorkbenchError(f"--goal {text!r}: MAX {hi:g} is below MIN {lo:g}; give MIN:MAX with MIN <= MAX")
    return cls, (float(np.radians(lo)), float(np.radians(hi)))


DESCRIPTION = """\
Backward chaining in a grasp-placement table built by `workbench gptable` (Tournassoud, Lozano-Perez & Mazer 1987):
the fewest placements on the table between a start and a goal. Three kinds of query:

  --initial CLASS,THETA --goal CLASS,MIN:MAX   grasp to grasp (Section 6); MIN and MAX are both kept
  --from P,PHI --to P,PHI                      the part from one placement at the table point to another
  --pickup P,X,Y,PHI --destination P,X,Y,PHI   Fig. 1's task: the part taken where it lies among the
                                               --pickup-obstacle meshes, put where it goes past the
                                               --destination-obstacle meshes along --insert (Section 5.1:
                                               the first and last grasps' angles follow from them)

The answer is realised: IK with collisions, approach and lifts, and (unless --no-motion) timed motions. The table
assumes the arm's paths away, so a conjunction it allows can fail with the arm; it is then removed, with every
table sample needing the same change of arm configuration, and the chaining runs again (--max-removed motion
failures at most). The output names each removed conjunction (step, motion, reason) and gives the table's own
shortest sequence beside the executable one; --json carries both ("table_sequence", "removed")."""


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("gpplan", help="regrasp sequence by backward chaining in the grasp-placement table (Tournassoud et al.)",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--db", required=True, help="DuckDB store file with a table built by `workbench gptable`")
    p.add_argument("--object", default=None, help="object name in the store (needed unless --plan)")
    p.add_argument("--plan", type=int, default=None, metavar="ID",
                   help="reload a stored plan of this planner from the store alone (its steps, timed motions, the part "
                        "held at either end, the insertion and the obstacles), print it and validate it again; with "
                        "--json, --trajectory and --plan-html, export it")
    p.add_argument("--robot", default=None, help="robot name in the store (default: the newest table's robot)")
    p.add_argument("--initial", default=None, metavar="CLASS,THETA", help="initial grasp CLASS,THETA (degrees)")
    p.add_argument("--goal", default=None, metavar="CLASS,MIN:MAX",
                   help="goal class and theta range CLASS,MIN:MAX (degrees); a goal pose on the table is --to")
    p.add_argument("--from", dest="from_", default=None, metavar="P,PHI",
                   help="start placement P,PHI (PHI: the turn about the vertical, degrees), instead of --initial")
    p.add_argument("--to", default=None, metavar="P,PHI", help="goal placement P,PHI (degrees), instead of --goal")
    p.add_argument("--pickup", default=None,
                   help="the task's pick-up (Section 5.1, Fig. 1 (a)): the part resting in placement class P at X,Y (m) "
                        "turned by PHI (degrees) about the vertical, as P,X,Y,PHI; with --destination, the plan starts by "
                        "taking the part there with a grasp that clears the pick-up's obstacles (--initial, if given, "
                        "must be one of them)")
    p.add_argument("--pickup-obstacle", action="append", default=[], metavar="MESH@X,Y,Z[,ROLL,PITCH,YAW]",
                   help="an obstacle at the pick-up: a mesh file in metres at a world pose (m, degrees); repeatable")
    p.add_argument("--destination", default=None,
                   help="the task's destination (Fig. 1 (d)): P,X,Y,PHI as --pickup; the plan ends by putting the part "
                        "there with a grasp that clears the destination's obstacles and the insertion (--goal, if given, "
                        "restricts it)")
    p.add_argument("--destination-obstacle", action="append", default=[], metavar="MESH@X,Y,Z[,ROLL,PITCH,YAW]",
                   help="an obstacle at the destination (the fixture or hole the part goes into); repeatable")
    p.add_argument("--insert", default=None, metavar="DX,DY,DZ[,DEPTH]",
                   help="the final insertion: the direction the held part moves into place (world) and its length in "
                        "metres (default 0.02); the last grasp's hand must clear the destination's obstacles all along it "
                        "(the plan's last motion is that insertion: a straight line of the held part along it, checked "
                        "against the destination's obstacles)")
    p.add_argument("--start-held", action="store_true",
                   help="with --pickup: the part is already in the hand at the pick-up (the first grasp); the motions "
                        "begin there and lift it out, with no approach and no closing of the jaw")
    p.add_argument("--end-held", action="store_true",
                   help="with --destination: the part stays in the hand at the destination after the insertion; the "
                        "motions end there, with no opening of the jaw and no retract")
    p.add_argument("--table", default=None, help="table top corners in the world: XMIN,YMIN,XMAX,YMAX (m); default per robot")
    p.add_argument("--handx", type=parse_number(RETRACT, "--handx", 0.05), default=0.05, metavar="M",
                   help=f"approach distance along the hand's axis ({RETRACT.describe(True)}; default 0.05)")
    p.add_argument("--worldz", type=parse_number(RETRACT, "--worldz", 0.05), default=0.05, metavar="M",
                   help=f"lift after the approach ({RETRACT.describe(True)}; default 0.05)")
    p.add_argument("--no-save", action="store_true", help="do not store the plan in the store's plan tables")
    p.add_argument("--no-motion", action="store_true", help="waypoints only: do not plan and time the motions")
    add_motion_arguments(p, "conjunctions of the table")
    add_output(p, "--json", "write the sequence and its plan to this JSON file")
    add_output(p, "--html", "write the table with the sequence overlaid (Fig. 6) to this HTML file")
    add_output(p, "--plan-html", "write the plan's animation with its obstacles and insertion as static HTML")
    add_output(p, "--trajectory", suffixes=(".csv", ".yaml", ".yml", ".json"),
               help="write the plan's timed trajectory for a controller: OUT.csv (one row per knot), OUT.yaml (a ROS 2 "
                    "trajectory_msgs/JointTrajectory with the URDF's joint names, and OUT.gripper.yaml with the jaw "
                    "width at the same times) or OUT.json")
    add_gripper_argument(p)
    p.set_defaults(func=run)


def parse_end(text: str, label: str) -> tuple[int, float, float, float]:
    """P,X,Y,PHI (metres, degrees) -> (placement, x, y, phi radians)."""
    p, x, y, phi = _nums(text, label, 4)
    try:
        out = int(p), float(x), float(y), float(np.radians(float(phi)))
    except ValueError:
        raise WorkbenchError(f"{label} {text!r} must be P,X,Y,PHI (placement class, metres, degrees), e.g. 2,0.45,-0.12,30") from None
    if not np.isfinite(out[1:]).all():
        raise WorkbenchError(f"{label} {text!r}: X, Y and PHI must be finite")
    return out


def parse_obstacle(text: str, label: str) -> Obstacle:
    """MESH@X,Y,Z[,ROLL,PITCH,YAW] (metres, degrees) -> an obstacle (the mesh read in metres)."""
    path, _, pose = str(text).rpartition("@")
    vals = [v for v in pose.split(",")]
    if not path or len(vals) not in (3, 6) or not all(_is_float(v) for v in vals):
        raise WorkbenchError(f"{label} {text!r} must be MESH@X,Y,Z or MESH@X,Y,Z,ROLL,PITCH,YAW (metres, degrees)")
    v = [float(x) for x in vals] + [0.0] * (6 - len(vals))
    if not np.isfinite(v).all():
        raise WorkbenchError(f"{label} {text!r}: the pose must be finite")
    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # trimesh raises many kinds on a missing or broken file
        raise WorkbenchError(f"{label} {path!r}: cannot read the mesh ({exc})") from None
    m = np.eye(4)
    m[:3, :3] = Rotation.from_euler("xyz", v[3:], degrees=True).as_matrix()
    m[:3, 3] = v[:3]
    return Obstacle(mesh, m, f"{path}")


def parse_insert(text: str) -> tuple[np.ndarray, float]:
    """DX,DY,DZ[,DEPTH] -> (direction, depth in metres)."""
    vals = str(text).split(",")
    if len(vals) not in (3, 4) or not all(_is_float(v) for v in vals):
        raise WorkbenchError(f"--insert {text!r} must be DX,DY,DZ or DX,DY,DZ,DEPTH (a direction, metres)")
    v = [float(x) for x in vals]
    depth = v[3] if len(v) == 4 else 0.02
    if not np.isfinite(v).all() or depth <= 0:
        raise WorkbenchError(f"--insert {text!r}: the direction must be finite and the depth positive")
    return np.array(v[:3]), depth


def _task(args, r, realiser_args) -> tuple:
    """The task's two ends, their masks of legal grasps (restricted by --initial / --goal) and the obstacles."""
    ends = []
    for label, text, obst in (("--pickup", args.pickup, args.pickup_obstacle),
                              ("--destination", args.destination, args.destination_obstacle)):
        p, x, y, phi = parse_end(text, label)
        obstacles = [parse_obstacle(o, f"{label}-obstacle") for o in obst]
        ins, depth = parse_insert(args.insert) if (args.insert and label == "--destination") else (None, 0.0)
        ends.append(TaskEnd(p, x, y, phi, obstacles, ins, depth, approach=realiser_args["handx"]))
    pickup, destination = ends
    start, counts_s = end_mask(r.table, r.classes, pickup, r.robot, r.gripper)
    goal, counts_g = end_mask(r.table, r.classes, destination, r.robot, r.gripper)
    if args.initial:
        c, th = parse_grasp(args.initial)
        if not 0 <= c < len(r.classes):
            raise WorkbenchError(f"--initial {args.initial!r}: grasp class {c} does not exist (0..{len(r.classes) - 1})")
        one = np.zeros_like(start)
        one[c, nearest_sample(r.table.theta, th)] = True
        start &= one
    if args.goal:
        c, rng = parse_goal(args.goal)
        if not 0 <= c < len(r.classes):
            raise WorkbenchError(f"--goal {args.goal!r}: grasp class {c} does not exist (0..{len(r.classes) - 1})")
        keep = np.zeros_like(goal)
        keep[c] = in_range(r.table.theta, rng)
        goal &= keep
    return pickup, destination, start, goal, counts_s, counts_g


def _legal_text(table, mask: np.ndarray) -> str:
    parts = []
    for c in np.flatnonzero(mask.any(axis=1)):
        spans = runs(mask[c], np.degrees(table.theta))
        parts.append(f"class {c} at " + ", ".join(f"{a:.0f}" if a == b else f"{a:.0f}-{b:.0f}" for a, b in spans))
    return "; ".join(parts) or "none"


def _table_of(scene: Scene) -> tuple:
    return tuple(scene.table_min), tuple(scene.table_max), float(scene.table_thickness)


def _export(args, plan, robot, mesh, scene: Scene) -> None:
    """The plan's --trajectory and --plan-html files."""
    if args.trajectory and plan.segments:
        print(f"trajectory: {write_trajectory(plan, args.trajectory)}")
    elif args.trajectory:
        print("trajectory: not written, the plan has no timed motions (--no-motion)")
    if args.plan_html:
        print(f"plan html: {plan_page(plan, robot, mesh, _table_of(scene), args.plan_html)}")


def describe_task(plan) -> list[str]:
    """What a plan carries beyond its steps: the part held at either end, the insertion, the obstacles."""
    out = []
    for held, text in ((plan.start_held, "starts with the part in the hand at the pick-up"),
                       (plan.end_held, "ends with the part still in the hand at the destination")):
        if held:
            out.append(f"the plan {text}")
    if plan.insertion is not None:
        d = ", ".join(f"{v:+.3f}" for v in plan.insertion)
        out.append(f"the plan ends with an insertion of {plan.insertion_depth * 1000:.0f} mm along ({d})")
    if plan.obstacles:
        ends = {e: sum(o.end == e for o in plan.obstacles) for e in ("pickup", "destination")}
        out.append(f"obstacles: {ends['pickup']} at the pick-up, {ends['destination']} at the destination")
    return out


def run_stored(args: argparse.Namespace) -> int:
    """`--plan ID`: a stored plan reloaded from the store alone, printed, validated and exported."""
    plan = load_stored(args.db, args.plan)
    if args.object is not None and args.object != plan.object:
        raise WorkbenchError(f"plan {args.plan} in {args.db} is of {plan.object!r}, not --object {args.object!r}")
    with Store(args.db, read_only=True) as store:
        gripper = gripper_from_args(args, grippers_of(stored_grippers(store), robot=plan.robot),
                                    f"plan {args.plan} in store {args.db}")
    r = load_planner(args.db, plan.object, plan.robot, gripper=gripper, idtable=plan.ids["idtabletop"])
    scene = stored_scene(args.db, args.plan)
    print(f"plan {args.plan} from {args.db}: " + plan.summary())
    for line in plan.lines():
        print("  " + line)
    for line in describe_task(plan):
        print(line)
    report = validate_stored(args.db, r, args.plan, plan, require_motion=bool(plan.segments))
    print("validator: " + ("ok" if report.ok else "FAILED: " + "; ".join(report.errors[:3])))
    if args.json:
        write_text(args.json, json.dumps({"idplan": args.plan, "plan": plan.as_dict(), "validator":
                                          {"ok": report.ok, "errors": report.errors}}, indent=1))
        print(f"json: {args.json}")
    _export(args, plan, r.robot, r.obj.mesh, scene)
    return 0


def run(args: argparse.Namespace) -> int:
    if args.plan is not None:
        if any(getattr(args, k) is not None for k in ("initial", "goal", "from_", "to", "pickup", "destination", "html")):
            raise WorkbenchError("--plan ID reloads a stored plan: give no query (--initial, --goal, --from, --to, "
                                 "--pickup, --destination) and no --html with it")
        return run_stored(args)
    if args.object is None:
        raise WorkbenchError("--object NAME is needed with a query (or --plan ID to reload a stored plan)")
    task_mode = args.pickup is not None or args.destination is not None
    grasp_mode = not task_mode and (args.initial is not None or args.goal is not None)
    place_mode = args.from_ is not None or args.to is not None
    if task_mode and (args.pickup is None or args.destination is None or place_mode):
        raise WorkbenchError("a task needs both --pickup P,X,Y,PHI and --destination P,X,Y,PHI (with --initial / --goal "
                             "to restrict its first and last grasps), and no --from / --to")
    if (args.pickup_obstacle or args.destination_obstacle or args.insert or args.start_held or args.end_held) and not task_mode:
        raise WorkbenchError("--pickup-obstacle, --destination-obstacle, --insert, --start-held and --end-held need "
                             "--pickup and --destination")
    if not task_mode and (grasp_mode == place_mode or (grasp_mode and (args.initial is None or args.goal is None)) or
                          (place_mode and (args.from_ is None or args.to is None))):
        raise WorkbenchError("give either --initial CLASS,THETA with --goal CLASS,MIN:MAX, or --from P,PHI with --to P,PHI, "
                             "or a task: --pickup P,X,Y,PHI with --destination P,X,Y,PHI")
    if grasp_mode:  # the query is read before the store is opened: a malformed one costs nothing
        initial, (gc, rng) = parse_grasp(args.initial), parse_goal(args.goal)
    elif place_mode:
        start, goal = parse_grasp(args.from_, "--from"), parse_grasp(args.to, "--to")
    robot = args.robot
    if robot is not None:
        with Store(args.db, read_only=True) as store:
            gripper, stored = stored_robot_gripper(store, robot, args)
            robot = stored or robot
    else:
        with Store(args.db, read_only=True) as store:
            gripper = gripper_from_args(args, grippers_of(stored_grippers(store), obj=args.object),
                                        f"object {args.object!r} in store {args.db}")
    r = load_planner(args.db, args.object, robot, gripper=gripper)
    scene = default_scene(r.robot.name)
    if args.table:
        t = [float(v) for v in _nums(args.table, "--table", 4)] if all(
            _is_float(v) for v in str(args.table).split(",")) else []
        if len(t) != 4 or not np.isfinite(t).all() or t[0] >= t[2] or t[1] >= t[3]:
            raise WorkbenchError(f"--table {args.table!r} must be XMIN,YMIN,XMAX,YMAX in metres with XMIN < XMAX, YMIN < YMAX")
        scene = Scene(table_min=(t[0], t[1]), table_max=(t[2], t[3]), table_thickness=scene.table_thickness,
                      workspace_min=scene.workspace_min, workspace_max=scene.workspace_max)
    obstacles: list = []
    if task_mode:
        pickup, destination, start_mask, goal_mask, counts_s, counts_g = _task(args, r, {"handx": args.handx})
        obstacles = [(o.mesh, o.pose) for o in pickup.obstacles + destination.obstacles]
        for name, mask, counts in (("pick-up", start_mask, counts_s), ("destination", goal_mask, counts_g)):
            print(f"{name}: {int(mask.sum())} legal grasp sample(s) ({_legal_text(r.table, mask)}); refused: "
                  f"{counts['table']} into the table, {counts['ik']} out of reach, {counts['obstacles']} hitting an obstacle")
    realiser = Realiser(r.robot, scene, r.obj.mesh, args.handx, args.worldz, obstacles=obstacles)
    motions = None if args.no_motion else exec_options(args)
    try:
        if task_mode:
            seq, plan = plan_task_query(r.table, r.classes, realiser, r.robot, r.obj.name, pickup, destination,
                                        start_mask, goal_mask, motions, args.start_held, args.end_held)
        elif grasp_mode:
            seq, plan = plan_grasp_query(r.table, r.classes, realiser, r.robot, r.obj.name, initial, gc, rng, motions)
        else:
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
    print(f"{r.obj.name} with {r.robot.name}: {seq.regrasps} regrasp(s), {len(seq.grasps)} grasp(s); backward chaining "
          f"{seq.levels} level(s) in {seq.seconds * 1000:.2f} ms")
    for k, (c, ti) in enumerate(seq.grasps):
        print(f"  grasp {k}: class {c} ({r.classes[c].kind}) theta {np.degrees(t.theta[ti]):6.1f} deg")
    for k, (j, fi) in enumerate(seq.placements):
        end = {0: "start", len(seq.placements) - 1: "goal"}.get(k) if "start_xy" in seq.extra else None
        if end is not None:  # the task's pick-up or destination, at its own position and exact angle
            x, y = seq.extra[f"{end}_xy"]
            print(f"  placement {k}: class {j} phi {np.degrees(seq.extra[f'phi_{end}']):6.1f} deg at "
                  f"({x:g}, {y:g}), the {'pick-up' if end == 'start' else 'destination'}")
        else:
            print(f"  placement {k}: class {j} phi {np.degrees(t.phi[fi]):6.1f} deg")
    for line in explanation(t, None, seq.extra.get("removals", []), seq, seq.extra.get("table")):
        print(line)
    if plan is None:
        print("the initial grasp is already in the goal range: nothing to do")
    else:
        print(plan.summary())
        for line in describe_task(plan):
            print(line)
        if args.no_save:
            report = validate_stored(args.db, r, None, plan, require_motion=motions is not None, scene=scene)
        else:
            idplan, plan = save_plan(args.db, r, plan, scene, realiser.opts)
            print(f"stored plan id {idplan} in {args.db} (planner tournassoud; tables plan, planstep, plansegment, "
                  f"planobstacle); `workbench gpplan --db {args.db} --plan {idplan}` reloads it")
            stored = load_stored(args.db, idplan)  # what the store holds is what is checked and exported
            report = validate_stored(args.db, r, idplan, stored, require_motion=motions is not None)
        print("validator: " + ("ok" if report.ok else "FAILED: " + "; ".join(report.errors[:3])))
        _export(args, plan if args.no_save else stored, r.robot, r.obj.mesh, scene)
    if args.json:
        doc = {"sequence": seq.as_dict(t), "plan": None if plan is None else plan.as_dict(),
               "table_sequence": seq.extra.get("table"), "removed": seq.extra.get("removed", [])}
        if task_mode:
            doc["task"] = {name: end.as_dict() for name, end in (("pickup", pickup), ("destination", destination))}
            doc["task"]["pickup"]["legal"] = np.argwhere(start_mask).tolist()
            doc["task"]["destination"]["legal"] = np.argwhere(goal_mask).tolist()
        write_text(args.json, json.dumps(doc, indent=1))
        print(f"json: {args.json}")
    if args.html:
        write_text(args.html, table_html(t, r.classes, seq, title=f"{r.obj.name} with {r.robot.name}"))
        print(f"html: {args.html}")
    sys.stdout.flush()
    return 0
