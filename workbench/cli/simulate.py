"""`workbench simulate --db DB --plan ID`: replay a stored plan in MuJoCo physics and judge it (CONVENTIONS.md,
Simulation): the part's pose error at every waypoint, slip in the hand during each transfer, settling after each
release, the final pose against the goal. The result is stored (tables `simulation`, `simulationstep`)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from workbench.cli.gripper import add_gripper_argument, gripper_from_args
from workbench.errors import PlanningError
from workbench.params import add_param, from_cli
from workbench.simulation.replay import SimParams
from workbench.simulation.stages import StoredSimulation, plan_gripper, simulate_stored
from workbench.store import Store

HELP = "replay a stored plan in MuJoCo physics: does the part stay in the hand and end at its goal?"
INSTALL = "needs MuJoCo and CoACD: pip install 'regrasp-workbench[physics]'"
OPTIONS = ("timestep", "impratio", "density", "grip_force", "friction", "table_friction", "goal_tol", "goal_tol_angle",
           "waypoint_tol", "waypoint_tol_angle", "slip_tol", "slip_tol_angle", "settle_speed", "settle_time", "hold_end", "collision_depth",
           "hull_concavity", "max_hulls", "hull_resolution")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("simulate", help=HELP,
                            description=f"{HELP} The robot follows the plan's timed trajectory with position actuators, the "
                                        f"planning gripper closes with a force-limited drive, the part (mass from its mesh "
                                        f"and --density, collision from a convex decomposition cached per mesh) starts "
                                        f"resting at the start pose. A plan is confirmed when every error is within its "
                                        f"tolerance; otherwise the first failing step is named with how it failed (shove "
                                        f"at closing, slip or drop in the hand, roll after release, pose, goal). It {INSTALL}.")
    parser.add_argument("--db", required=True, help="DuckDB store holding the plan")
    parser.add_argument("--plan", required=True, type=int, metavar="ID", help="plan id (printed by `workbench plan`)")
    add_sim_arguments(parser)
    add_gripper_argument(parser)
    parser.set_defaults(func=run)


def add_sim_arguments(parser: argparse.ArgumentParser) -> None:
    """The simulation parameters' options (ranges from SimParams), read back by `sim_params`."""
    for name in OPTIONS:
        add_param(parser, SimParams, name)


def sim_params(args: argparse.Namespace) -> SimParams:
    return SimParams(**{n: from_cli(SimParams, n, getattr(args, n)) for n in OPTIONS})


def run(args: argparse.Namespace) -> int:
    params = sim_params(args)
    if not Path(args.db).is_file():
        raise PlanningError(f"store {args.db} does not exist; make a plan with `workbench plan --db {args.db} ...` first")
    with Store(args.db, create=False) as store:
        gripper = gripper_from_args(args, plan_gripper(store, args.plan), f"plan {args.plan} in store {args.db}")
        out = simulate_stored(store, args.plan, params, gripper=gripper)
    print_simulation(out, args.plan, args.db)
    return 0


def print_simulation(out: StoredSimulation, idplan: int, db: str | Path) -> None:
    """The verdict, the table of waypoints (when just simulated) and where it is stored."""
    res = out.result
    if res is not None:
        s = res.steps
        print("  seq step caption  motion      t (s)  error (mm)  angle (deg)  slip (mm)  settle (s)")
        for i in range(len(s["seq"])):
            slip = "" if math.isnan(s["slip"][i]) else f"{s['slip'][i] * 1000:9.1f}"
            settle = "" if math.isnan(s["settle"][i]) else f"{s['settle'][i]:10.2f}"
            print(f"  {i:3d} {s['step'][i] + 1:4d} {s['caption'][i]:8s} {s['kind'][i]:9s} {s['t'][i]:7.2f} {s['error'][i] * 1000:11.1f} "
                  f"{math.degrees(s['angle'][i]):12.1f} {slip:>10s} {settle:>11s}{'' if s['ok'][i] else '  *'}")
        print(f"plan {idplan}: {res.summary()}")
        for f in res.failures[1:4]:
            print(f"  then: {f.message}")
    else:
        verdict = (f"confirmed (the part ends {out.final_error * 1000:.1f} mm and {math.degrees(out.final_angle):.1f} deg from "
                   f"its goal)" if out.confirmed else f"not confirmed: {out.message}")
        print(f"plan {idplan}: {verdict}")
    print(f"{'answered from' if out.reused else 'stored in'} {db}: simulation id {out.idsimulation}")
