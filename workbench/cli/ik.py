"""`workbench ik`: IK feasibility of every tabletop grip of an object for a robot (Wan & Harada Section IV).

`run_ik` is the stage runner used by the command, the notebook and `workbench build`: it loads the tabletop
grips, writes the robot, scene and ikret rows in one transaction, then computes and writes the `ik` rows chunk
by chunk (each chunk in its own transaction), skipping chunks already stored, so an interrupted run resumes and a
re-run with the same inputs computes nothing.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.spatial.transform import Rotation

from workbench.cli import warn
from workbench.cli.gripper import add_gripper_argument, gripper_from_args, grippers_of
from workbench.errors import RobotError
from workbench.params import add_param, cli_bound, parse_number
from workbench.planners.wan_harada.stages import empty_stage, run_ik
from workbench.robots.collider import Scene, default_scene
from workbench.robots.ik import SOLVERS, WORLDA, IKOptions, solver_kind
from workbench.robots.model import ROBOTS, Robot, get_robot, pose_xyz_yaw
from workbench.store import Store
from workbench.store.objects import stored_grippers

HANDX = 0.05
WORLDZ = 0.10


def _floats(text: str, n: int, label: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise RobotError(f"{label} must be {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n or not np.isfinite(vals).all():
        raise RobotError(f"{label} must be {n} comma-separated finite numbers, got {text!r}")
    return vals


def _radians(values: list[float], names: tuple[str, ...], option: str) -> None:
    """Refuse an angle outside [-2 pi, 2 pi]: these options take radians, as URDF does, and 90 there is a typed degree."""
    for name, v in zip(names, values):
        if abs(v) > 2 * np.pi + 1e-9:
            raise RobotError(f"{option} {name} {v:g} is in radians and must lie within [-2 pi, 2 pi]; for {v:g} degrees "
                             f"give {np.radians(v):.6g}")


def parse_base(text: str) -> np.ndarray:
    """--base X,Y,Z,YAW (m, rad) as the robot's base pose in the world."""
    vals = _floats(text, 4, "--base (X,Y,Z,YAW in m and rad)")
    _radians(vals[3:], ("yaw",), "--base")
    return pose_xyz_yaw(*vals)


def parse_mount(text: str) -> np.ndarray:
    """--mount x,y,z,roll,pitch,yaw (m, rad) as the tip-to-TCP transform."""
    x, y, z, roll, pitch, yaw = _floats(text, 6, "--mount (x,y,z,roll,pitch,yaw in m and rad)")
    _radians([roll, pitch, yaw], ("roll", "pitch", "yaw"), "--mount")
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    out[:3, 3] = (x, y, z)
    return out


RETRACT = cli_bound(0, 1.0, unit="m", help="retraction distance")
WORKERS = cli_bound(1, 1024, integer=True, help="IK processes")
TABLETOP = cli_bound(1, None, integer=True, help="tabletop parameter set id")


def add_retraction_arguments(p: argparse.ArgumentParser) -> None:
    """--handx, --worldz, --worlda, --workers and --ik, shared by `ik` and `build`."""
    p.add_argument("--handx", type=parse_number(RETRACT, "--handx", HANDX), default=HANDX, metavar="M",
                   help=f"retraction along the hand ({RETRACT.describe(True)}; default {HANDX})")
    p.add_argument("--worldz", type=parse_number(RETRACT, "--worldz", WORLDZ), default=WORLDZ, metavar="M",
                   help=f"then up along world z ({RETRACT.describe(True)}; default {WORLDZ})")
    p.add_argument("--worlda", type=parse_number(RETRACT, "--worlda", WORLDA), default=WORLDA, metavar="M",
                   help=f"lift of the held object straight up along world z ({RETRACT.describe(True)}; default {WORLDA}); "
                        f"then worldz more")
    p.add_argument("--workers", type=parse_number(WORKERS, "--workers"), default=None, metavar="N",
                   help=f"IK processes ({WORKERS.describe(True)}; default: all cores, or one where a 6-joint arm's closed form "
                        f"finishes sooner alone)")
    p.add_argument("--ik", choices=SOLVERS, default="auto",
                   help="auto (default): the arm's closed form where its axes admit one (all branches; spherical wrist, "
                        "spherical shoulder, three parallel axes, a 7-joint arm's last joint swept), else the numerical "
                        "solver; numerical: always Levenberg-Marquardt from seeds")


def add_robot_arguments(p: argparse.ArgumentParser) -> None:
    """--robot (built-in name or URDF path), --base, --tip, --mount, --table and --table-thickness, shared by `ik` and
    `build`."""
    p.add_argument("--robot", required=True, help=f"one of {', '.join(ROBOTS)}, or the path of a URDF (then --tip)")
    p.add_argument("--base", help="robot base in the world: X,Y,Z,YAW (m, rad); default per robot")
    p.add_argument("--tip", help="the arm's tip frame (required for a URDF path)")
    p.add_argument("--mount", help="tip frame to gripper TCP: x,y,z,roll,pitch,yaw (m, rad); default per robot")
    p.add_argument("--hand-links", metavar="PREFIX,...",
                   help="with a URDF: links of the robot's own hand, replaced by the planning gripper (name prefixes; "
                        "default: the links past --tip)")
    p.add_argument("--table", help="table top corners in the world: XMIN,YMIN,XMAX,YMAX (m); default per robot")
    add_param(p, Scene, "table_thickness", default=None)
    add_gripper_argument(p)


def robot_and_scene(args: argparse.Namespace, stored: list[dict] | None = None, what: str = "") -> tuple[Robot, Scene]:
    """The robot and table of `add_robot_arguments`' options (`stored`, `what`: the default gripper's, see
    `gripper_from_args`)."""
    base = parse_base(args.base) if args.base else None
    mount = parse_mount(args.mount) if args.mount else None
    hand = tuple(h.strip() for h in (args.hand_links or "").split(",") if h.strip())
    robot = get_robot(args.robot, base=base, tip_frame=args.tip, mount=mount, hand_links=hand, gripper=gripper_from_args(args, stored, what))
    scene = default_scene(robot.name)
    if args.table or args.table_thickness is not None:
        t = _floats(args.table, 4, "--table (XMIN,YMIN,XMAX,YMAX)") if args.table else [*scene.table_min, *scene.table_max]
        scene = Scene(table_min=(t[0], t[1]), table_max=(t[2], t[3]),
                      table_thickness=scene.table_thickness if args.table_thickness is None else args.table_thickness,
                      workspace_min=scene.workspace_min, workspace_max=scene.workspace_max)
    return robot, scene


def stored_as(robot: Robot, stored: str) -> str:
    """A note when the store keeps `robot` under another name (another base, mount or model took its name first)."""
    if stored == robot.name:
        return ""
    return (f"; stored as robot {stored!r}: a robot named {robot.name!r} with another model, base or mount is in the "
            f"store, so plan with --robot {stored}")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ik", help="IK feasibility of every tabletop grip for a robot (paper Section IV: ik, ikret)")
    p.add_argument("--db", required=True, help="DuckDB store file")
    p.add_argument("--object", required=True, help="object name in the store")
    add_robot_arguments(p)
    add_retraction_arguments(p)
    p.add_argument("--tabletop", type=parse_number(TABLETOP, "--tabletop"), default=None, metavar="ID",
                   help="tabletop parameter set id (default: the latest)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:

    with Store(args.db, create=False) as store:
        robot, scene = robot_and_scene(args, grippers_of(stored_grippers(store), obj=args.object),
                                       f"object {args.object!r} in store {args.db}")
        opts = IKOptions(solver=args.ik, self_collide=True)
        run = run_ik(store, args.object, robot, scene, args.handx, args.worldz, opts, args.workers,
                     progress=not args.no_progress, idtabletop=args.tabletop, worlda=args.worlda)
    what = "reused" if run.reused else f"computed {run.computed:,}"
    print(f"ik {run.robot}: {run.grips:,} tabletop grips ({what}); feasible grasp {run.feasible:,}, "
          f"at all five poses (retractions and lifts) {run.feasible_all:,}; robot {run.idrobot}, scene {run.idscene}, ikret {run.idikret}; "
          f"{run.seconds:.1f} s; IK {solver_kind(robot, opts)}{stored_as(robot, run.robot)}")
    reason = run.empty_reason()  # this run's scene and retractions; other runs may share the robot row
    if reason is None:
        with Store(args.db) as store:
            reason = empty_stage(store, args.object, run.robot)
    if reason:
        warn(f"no reachable tabletop grip of {args.object}; stage {reason}")
    return 0
