"""`workbench plan --db DB --object NAME --robot ROBOT --start P,X,Y,YAW --goal P,X,Y,YAW`: connect a start and a goal
pose to the regrasp graph, search it, plan and time its motions, print and write the plan (Wan & Harada,
Section V). Yaw in degrees on the command line, radians in the library."""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import replace
from pathlib import Path

from workbench.cli import warn
from workbench.cli.gripper import add_gripper_argument, stored_robot_gripper
from workbench.cli.ik import RETRACT
from workbench.cli.outputs import add_output, write_text
from workbench.cli.simulate import INSTALL, add_sim_arguments, print_simulation, sim_params
from workbench.errors import PlanningError
from workbench.params import cli_bound, parse_number
from workbench.planners.wan_harada.motions import DEFAULT_ACC, ExecOptions
from workbench.planners.wan_harada.query import PoseQuery, parse_pose
from workbench.planners.wan_harada.roadmap import NO_RESULT
from workbench.planners.wan_harada.stages import (
    empty_stage,
    load_planner,
    save_plans,
    stored_plan,
)
from workbench.robots.motion import MotionOptions
from workbench.robots.timing import to_csv, to_json, to_ros2_gripper_yaml, to_ros2_yaml
from workbench.simulation.stages import physics_check, simulate_in_memory, simulate_stored, stored_playback
from workbench.store import Store, open_reader
from workbench.store.robots import robot_grippers
from workbench.viewer.wan_harada import caption_track, plan_scene

ALTERNATIVES = cli_bound(0, 100, integer=True, help="next best plans")
ACC = cli_bound(0, 1000, lo_open=True, unit="rad/s^2", help="joint acceleration limit")
SPEED = cli_bound(0, 1, lo_open=True, help="share of the URDF's joint velocity limits")
BUDGET = cli_bound(0, 3600, lo_open=True, unit="s", help="RRT-Connect time budget per motion")
REMOVED = cli_bound(0, 100_000, integer=True, help="motions that may fail before giving up")
SEED = cli_bound(0, 2**32 - 1, integer=True, help="motion planner seed")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("plan", help="plan regrasps from a start to a goal pose on the table",
                            description="Poses are PLACEMENT,X,Y,YAW: a stable placement's number within the part (1, 2, ... as "
                                        "`workbench build` lists them, with how the part rests on each), "
                                        "x and y in metres on the table (top at z = 0), yaw in degrees about z (within "
                                        "[-360, 360]). Every plan comes with its motions: straight TCP lines to take and put "
                                        "down the part, collision-free joint-space transfers and transits (straight, else "
                                        "RRT-Connect), timed under the URDF's velocity limits (times --speed) and --acc.")
    parser.add_argument("--db", required=True, help="DuckDB store file (built with `workbench build`)")
    parser.add_argument("--object", required=True, help="object name in the store")
    parser.add_argument("--robot", required=True, help="the robot's name in the store: a built-in (panda, ur5, talos, "
                                                        "puma560) or a URDF robot's, as `build` printed it")
    parser.add_argument("--start", required=True, metavar="P,X,Y,YAW", help="start pose, yaw in degrees, e.g. 1,0.45,-0.1,0")
    parser.add_argument("--goal", required=True, metavar="P,X,Y,YAW", help="goal pose, yaw in degrees, e.g. 3,0.55,0.1,90")
    parser.add_argument("--alternatives", type=parse_number(ALTERNATIVES, "--alternatives", 2), default=2, metavar="N",
                        help=f"next best plans to list ({ALTERNATIVES.describe(True)}; default 2)")
    parser.add_argument("--handx", type=parse_number(RETRACT, "--handx"), default=None, metavar="M",
                        help="use the IK run with this handx retraction (m)")
    parser.add_argument("--worldz", type=parse_number(RETRACT, "--worldz"), default=None, metavar="M",
                        help="use the IK run with this worldz retraction (m)")
    parser.add_argument("--allow-partial", action="store_true",
                        help="plan on an IK stage that did not complete (killed part-way), with a warning; not stored")
    add_output(parser, "--json", "write the plan (and its alternatives) as JSON")
    add_output(parser, "--html", "write a meshcat animation of the plan as static HTML")
    parser.add_argument("--meshes", choices=["collision", "visual"], default="collision",
                        help="robot meshes in the HTML: collision (small file, default) or visual (nicer, larger)")
    parser.add_argument("--no-save", action="store_true", help="do not store the plans in the store's plan tables")
    add_motion_arguments(parser, "roadmap nodes or grips")
    add_output(parser, "--trajectory", suffixes=(".csv", ".yaml", ".yml", ".json"),
               help="write the best plan's timed trajectory for a controller: OUT.csv (one row per knot), OUT.yaml "
                    "(a ROS 2 trajectory_msgs/JointTrajectory with the URDF's joint names, and OUT.gripper.yaml with the jaw "
                    "width at the same times) or OUT.json")
    add_gripper_argument(parser)
    physics = parser.add_argument_group("physics", f"replay the best plan in MuJoCo, as `workbench simulate` does ({INSTALL})")
    physics.add_argument("--simulate", action="store_true",
                         help="simulate the best plan after planning, store the verdict and play the simulated part in --html")
    physics.add_argument("--require-physics", action="store_true",
                         help="a plan that fails in simulation counts as a failed motion: its failing step's roadmap node "
                              "or grip is removed and the graph searched again (up to --max-removed); implies --simulate")
    add_sim_arguments(physics)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    start, goal = parse_pose(args.start, "--start", degrees=True), parse_pose(args.goal, "--goal", degrees=True)
    opts = exec_options(args)
    if not Path(args.db).exists():
        raise PlanningError(f"store {args.db} does not exist; run `workbench build MESH --robot {args.robot} --db {args.db}` first")
    simulate = args.simulate or args.require_physics
    save = False
    # planning only reads: other processes may read the store meanwhile; the plans are written afterwards, briefly
    with Store(args.db, create=False) if simulate else open_reader(args.db) as store:
        gripper, stored = stored_robot_gripper(store, args.robot, args)
        others = [] if stored else robot_grippers(store, args.robot)
        if others:
            raise PlanningError(f"store {args.db} has robot {args.robot!r} with gripper {', '.join(others)}, not "
                                f"{gripper.name!r}; give --gripper the one it was built with, or build it with this one")
        args.robot = stored or args.robot
        reason = empty_stage(store, args.object, args.robot)
        if reason:
            warn(f"no plan for {args.object}: nothing to plan with; stage {reason}")
            return 0
        t0 = time.perf_counter()
        planner = load_planner(store, args.object, args.robot, args.handx, args.worldz, allow_partial=args.allow_partial,
                               gripper=gripper)
        t_load = time.perf_counter() - t0
        numbers = planner.numbers
        start, goal = store_placement(start, numbers, args.object, "--start"), store_placement(goal, numbers, args.object, "--goal")
        turn = (goal.yaw - start.yaw + math.pi) % (2 * math.pi) - math.pi
        if (start.idfreetabletopplacement == goal.idfreetabletopplacement in planner.placement_ids()
                and math.hypot(goal.x - start.x, goal.y - start.y) < 1e-6 and abs(turn) < 1e-9):
            print(f"the start is the goal ({args.start}): {args.object} is already in place; no plan to make")
            return 0
        report_graph(planner, t_load)
        params = sim_params(args) if simulate else None
        physics = physics_check(store, planner.robot, params) if args.require_physics else None
        try:
            plans = planner.plan(start, goal, alternatives=args.alternatives, exec_opts=opts, physics=physics)
        except PlanningError as exc:
            if getattr(exc, "reason", None) not in NO_RESULT:
                raise
            warn(f"no plan for {args.object}: {exc}")
            print(f"{args.object} with {args.robot}: 0 plans ({exc.reason}); nothing stored")
            if args.json:
                print(f"json: {write_json([], args.json, reason=exc.reason, message=str(exc)).resolve()}")
            return 0
        best = plans[0]
        print_plan(best, numbers)
        for p in plans[1:]:
            print(f"alternative {p.rank}: {p.regrasps} regrasp(s), {p.transfers} transfer(s), grasps {' -> '.join(map(str, p.grasps))}, "
                  f"trajectory {p.duration:.1f} s")
        print("validation: every listed plan passes (FK from the URDF, limits, collisions, stability, grasp, goal; its timed "
              "trajectory at every knot: position, velocity and acceleration limits, self-collision, arm, hand and part "
              "against the table, arm and hand against the resting part)")
        known = [stored_plan(store, p) for p in plans]
        if all(k is not None for k in known):
            print(f"answered from the store: plan ids {known} in {args.db} (the same query; not stored again)")
        elif getattr(planner, "partial", False):
            print("not stored: planned on an incomplete IK stage (--allow-partial)")
        elif not args.no_save:
            save = store.read_only
            if not save:
                known = save_plans(store, plans)
                print(f"stored plan ids {known} in {args.db}")
        playback = None
        if args.require_physics:
            gone = [f for f in planner.last_motion.failures if f.startswith("physics:")]
            print(f"physics: {len(gone)} plan(s) failed in simulation before this one, and their failing step's roadmap "
                  f"node or grip was removed" + "".join(f"\n  removed after {f}" for f in gone))
        if simulate:
            if known[0] is not None:
                out = simulate_stored(store, known[0], params, plan=best, robot=planner.robot)
                print_simulation(out, known[0], args.db)
                playback = stored_playback(store, known[0])
            else:
                res = simulate_in_memory(store, best, planner.robot, params)
                print(f"physics (not stored): {res.summary() if res.confirmed else res.failure.message}")
                playback = (res.playback_t, res.playback_pose)
    if save:
        with Store(args.db, create=False) as store:
            known = [stored_plan(store, p) for p in plans]  # another process may have stored the same query meanwhile
            if all(k is not None for k in known):
                print(f"answered from the store: plan ids {known} in {args.db} (the same query; not stored again)")
            else:
                print(f"stored plan ids {save_plans(store, plans)} in {args.db}")
    if args.json:
        write_json(plans, args.json)
        print(f"json: {Path(args.json).resolve()}")
    if args.trajectory:
        print(f"trajectory: {write_trajectory(best, args.trajectory)}")
    if args.html:

        print(f"html: {Path(plan_scene(best, planner, args.html, kind=args.meshes, simulated=playback)).resolve()}")
    return 0


def report_graph(planner, t_load: float) -> None:
    s = planner.roadmap.summary()
    print(f"regrasp graph of {planner.object.name} for {planner.robot.name}: {s['nodes']:,} nodes (IK-feasible of {s['grips']:,} "
          f"tabletop grips), {s['transfer_edges']:,} transfer and {s['transit_edges']:,} transit edges, {s['grasps']} grasps, "
          f"{s['placements']} placements, {s['components']} component(s); ready in {t_load:.2f} s")


def add_motion_arguments(parser: argparse.ArgumentParser, removed: str) -> None:
    """--acc, --speed, --budget, --max-removed (of `removed`, what a failing motion takes out) and --seed, read by
    `exec_options`."""
    parser.add_argument("--acc", type=parse_number(ACC, "--acc", DEFAULT_ACC), default=DEFAULT_ACC, metavar="X",
                        help=f"joint acceleration limit ({ACC.describe(True)}; default {DEFAULT_ACC:g})")
    parser.add_argument("--speed", type=parse_number(SPEED, "--speed", 1.0), default=1.0, metavar="X",
                        help=f"time the motions under this share of the URDF's joint velocity limits ({SPEED.describe(True)}; "
                             f"default 1): a URDF that states its drives' peak speeds gives motions at which a held "
                             f"part slips, which `--simulate` shows")
    parser.add_argument("--budget", type=parse_number(BUDGET, "--budget", 1.0), default=1.0, metavar="S",
                        help=f"RRT-Connect time budget per motion ({BUDGET.describe(True)}; default 1)")
    parser.add_argument("--max-removed", type=parse_number(REMOVED, "--max-removed", 10), default=10, metavar="N",
                        help=f"{removed} whose motions fail to remove before giving up ({REMOVED.describe(True)}; default 10)")
    parser.add_argument("--seed", type=parse_number(SEED, "--seed", 0), default=0, metavar="N",
                        help=f"seed of the motion planner ({SEED.describe(True)}; default 0)")


def exec_options(args: argparse.Namespace) -> ExecOptions:
    """Motion settings from --acc, --speed, --budget, --max-removed and --seed (their ranges checked while parsing)."""
    return ExecOptions(acc=args.acc, max_removed=args.max_removed, motion=MotionOptions(budget=args.budget, seed=args.seed),
                       speed=args.speed)


def write_trajectory(plan, out: str | Path) -> str:
    """The plan's timed trajectory for replay, by the file's suffix: CSV (one row per knot), YAML (a ROS 2
    `trajectory_msgs/JointTrajectory` of the arm, and beside it OUT.gripper.yaml, the jaw width at the same
    times) or JSON (per segment); the files written, for the command's output."""
    out = Path(out)
    if out.suffix.lower() in (".yaml", ".yml"):
        arm = write_text(out, to_ros2_yaml(plan.segments, plan.joint_names)).resolve()
        hand = write_text(out.with_name(f"{out.stem}.gripper{out.suffix}"), to_ros2_gripper_yaml(plan.segments)).resolve()
        return f"{arm} (gripper: {hand})"
    writer = to_csv if out.suffix.lower() == ".csv" else to_json
    return str(write_text(out, writer(plan.segments, plan.joint_names)).resolve())


def store_placement(query: PoseQuery, numbers: dict[int, int], name: str, flag: str) -> PoseQuery:
    """The query with its placement number (1, 2, ... within the part, as `build` lists them) as the store's id."""
    ids = {n: i for i, n in numbers.items()}
    if query.idfreetabletopplacement not in ids:
        raise PlanningError(f"{flag}: {name} has no placement {query.idfreetabletopplacement}; its placements are "
                            f"1-{len(ids)} (`workbench build` lists them, with how the part rests on each)")
    return replace(query, idfreetabletopplacement=ids[query.idfreetabletopplacement])


def print_plan(plan, numbers: dict[int, int] | None = None) -> None:
    """The plan's start, goal and steps as the plan view's footer names them (placements by `numbers`, the store's id
    -> its number within the part), and what it took."""
    print(f"start {plan.start.text_degrees(numbers)} -> goal {plan.goal.text_degrees(numbers)} "
          f"(PLACEMENT,X,Y,YAW in m and degrees)")
    for line in caption_track(plan, [], numbers=numbers)["footers"][1:]:
        print("  " + line)
    t = plan.timings
    print(f"{plan.regrasps} regrasp(s), {plan.transfers} transfer(s); time to connect {t.get('connect', 0) * 1000:.1f} ms, "
          f"search {t.get('search', 0) * 1000:.1f} ms")
    if plan.segments:
        methods = {}
        for s in plan.segments:
            methods[s.method] = methods.get(s.method, 0) + 1
        names = {"tcp-line": "straight TCP lines", "line": "straight joint lines", "rrtconnect": "RRT-Connect paths",
                 "dwell": "jaw actions"}
        parts = ", ".join(f"{n} {names.get(k, k)}" for k, n in sorted(methods.items()))
        print(f"motions: {len(plan.segments)} segments ({parts}); trajectory {plan.duration:.1f} s at "
              f"acceleration limit {max(plan.acc) if plan.acc else DEFAULT_ACC:g} rad/s^2"
              f"{f' and {plan.speed:.0%} of the velocity limits' if plan.speed < 1 else ''}; planned in {t.get('motion', 0):.2f} s; "
              f"{plan.removed} roadmap node(s) or grip(s) removed because their motions failed")


def write_json(plans, out: str | Path, **why: str) -> Path:
    """The best plan with its alternatives as one JSON file: {"plan": ..., "alternatives": [...]}; with no plan,
    {"plan": null, "alternatives": [], ...`why`} (reason and message)."""

    return write_text(out, json.dumps({"plan": plans[0].as_dict() if plans else None,
                                       "alternatives": [p.as_dict() for p in plans[1:]], **why}, indent=1))
