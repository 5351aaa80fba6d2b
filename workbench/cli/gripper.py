"""The shared `--gripper` option of every command that plans grasps or motions (CONVENTIONS.md, Gripper).

`add_gripper_argument(parser)` adds `--gripper` and the options naming a URDF gripper's parts;
`gripper_from_args(args)` loads the gripper they name (one line and exit 2 on a bad file or field)."""

from __future__ import annotations

import argparse

from workbench.cli import warn
from workbench.robots.gripper import BUNDLED, Gripper, load_gripper


def add_gripper_argument(parser: argparse.ArgumentParser) -> None:
    """--gripper NAME|FILE|own and --gripper-hand, --gripper-fingers, --gripper-tcp (for a URDF or `own`)."""
    g = parser.add_argument_group("gripper")
    g.add_argument("--gripper", default="franka", metavar="NAME|FILE|own",
                   help=f"the parallel-jaw gripper: {', '.join(BUNDLED)} (bundled; default franka), a spec file "
                        f"(.json/.yaml: stroke, tcp, pad, finger, palm), a gripper URDF (.urdf, its parts named by the "
                        f"options below or by NAME.gripper.yaml beside it), or own: the robot's own hand in its URDF "
                        f"(--robot URDF --tip LINK --gripper-fingers LEFT,RIGHT)")
    g.add_argument("--gripper-hand", metavar="LINK", default=None,
                   help="a URDF gripper's hand link (own: default the --tip link)")
    g.add_argument("--gripper-fingers", metavar="LEFT,RIGHT", default=None,
                   help="a URDF gripper's two finger joints (prismatic, revolute or mimic linkages)")
    g.add_argument("--gripper-tcp", metavar="FRAME", default=None,
                   help="a URDF gripper's TCP frame (default: midway between the pads, +z away from the hand link)")


def gripper_from_args(args: argparse.Namespace) -> Gripper:
    """The gripper named by `add_gripper_argument`'s options (for `own`, from the command's --robot and --tip)."""
    fingers = tuple(f.strip() for f in (args.gripper_fingers or "").split(",") if f.strip())
    own = args.gripper == "own"
    gripper = load_gripper(args.gripper, hand_link=args.gripper_hand, finger_joints=fingers, tcp_frame=args.gripper_tcp,
                           robot_urdf=getattr(args, "robot", None) if own else None, tip=getattr(args, "tip", None))
    for note in gripper.notes:  # what the parallel-jaw model approximates (a linkage's pads moving along the approach)
        warn(f"gripper {gripper.name}: {note}")
    return gripper
