"""The shared `--gripper` option of every command that plans grasps or motions (CONVENTIONS.md, Gripper).

`add_gripper_argument(parser)` adds `--gripper` and the options naming a URDF gripper's parts;
`gripper_from_args(args)` loads the gripper they name (one line and exit 2 on a bad file or field);
`stored_robot_gripper(store, name, args)` does so for a command planning on a stored robot, where `own` is the hand
in the stored robot's URDF; `add_grippers_argument` and `grippers_from_args` give a catalogue its several grippers."""

from __future__ import annotations

import argparse
from dataclasses import replace

from workbench.cli import warn
from workbench.errors import GripperError, StoreError
from workbench.robots.gripper import BUNDLED, Gripper, load_gripper
from workbench.store import Store
from workbench.store.objects import gripper_row, stored_grippers
from workbench.store.robots import robot_grippers, robot_ids, robot_row, robot_with_gripper


def add_gripper_argument(parser: argparse.ArgumentParser) -> None:
    """--gripper NAME|FILE|own and --gripper-hand, --gripper-fingers, --gripper-tcp (for a URDF or `own`)."""
    g = parser.add_argument_group("gripper")
    g.add_argument("--gripper", default=None, metavar="NAME|FILE|own",
                   help=f"the parallel-jaw gripper: {', '.join(BUNDLED)} (bundled; default franka, or, for a command "
                        f"reading the store, the one gripper it was built with), a spec file "
                        f"(.json/.yaml: stroke, tcp, pad, finger, palm), a gripper URDF (.urdf, its parts named by the "
                        f"options below or by NAME.gripper.yaml beside it), or own: the robot's own hand in its URDF "
                        f"(--robot URDF --tip LINK --gripper-fingers LEFT,RIGHT)")
    g.add_argument("--gripper-hand", metavar="LINK", default=None,
                   help="a URDF gripper's hand link (own: default the --tip link)")
    g.add_argument("--gripper-fingers", metavar="LEFT,RIGHT", default=None,
                   help="a URDF gripper's two finger joints (prismatic, revolute or mimic linkages)")
    g.add_argument("--gripper-tcp", metavar="FRAME", default=None,
                   help="a URDF gripper's TCP frame (default: midway between the pads, +z away from the hand link)")


def add_grippers_argument(parser: argparse.ArgumentParser) -> None:
    """--grippers NAME|FILE,...: several grippers (a catalogue's), beside `add_gripper_argument`'s options."""
    parser.add_argument("--grippers", metavar="NAME|FILE,...", default=None,
                        help=f"several grippers, comma-separated, instead of --gripper: bundled names ({', '.join(BUNDLED)}), "
                             f"spec files or gripper URDFs (these take the --gripper-* options); each is a column of the "
                             f"catalogue with every robot")


def grippers_from_args(args: argparse.Namespace) -> list[Gripper] | None:
    """The grippers of --grippers (or of a --gripper other than the default), None when neither is given."""
    if args.grippers is None:
        return None if args.gripper in (None, "franka") else [gripper_from_args(args)]
    if args.gripper not in (None, "franka"):
        raise GripperError("give --gripper or --grippers, not both")
    names = [n.strip() for n in args.grippers.split(",") if n.strip()]
    if not names:
        raise GripperError("--grippers needs at least one gripper, e.g. franka,robotiq-2f85")
    return [gripper_from_args(argparse.Namespace(**{**vars(args), "gripper": n})) for n in names]


def gripper_from_args(args: argparse.Namespace, stored: list[dict] | None = None, what: str = "") -> Gripper:
    """The gripper named by `add_gripper_argument`'s options (for `own`, from the command's --robot and --tip).

    Without --gripper it is the Franka hand, unless `stored` (the store's grippers this command could read: dicts
    with name and digest, `what` saying of what) holds just one other: that one when it is bundled, else a one-line
    GripperError naming it, since a spec file or URDF is not kept in the store."""
    if args.gripper is None:
        return _stored_default(stored or [], what)
    fingers = _fingers(args)
    own = args.gripper == "own"
    gripper = load_gripper(args.gripper, hand_link=args.gripper_hand, finger_joints=fingers, tcp_frame=args.gripper_tcp,
                           robot_urdf=getattr(args, "robot", None) if own else None, tip=getattr(args, "tip", None))
    return _noted(gripper)


def _stored_default(stored: list[dict], what: str) -> Gripper:
    digests = {g["digest"]: g["name"] for g in stored}
    default = load_gripper("franka")
    if len(digests) != 1 or default.digest in digests:
        return default
    (digest, name), = digests.items()
    for choice in BUNDLED:
        if choice != "franka":
            gripper = load_gripper(choice)
            if gripper.digest == digest:
                return _noted(gripper)
    raise GripperError(f"{what} was built with gripper {name!r}, a spec file or URDF the store does not keep; give it "
                       f"with --gripper FILE (and --gripper-fingers etc. as given to build)")


def grippers_of(stored: list[dict], obj: str | None = None, robot: str | None = None) -> list[dict]:
    """The entries of `store.objects.stored_grippers` with grasps of object `obj`, or with robot `robot` (NAME or
    NAME-DIGEST) when given."""
    if obj is not None:
        return [g for g in stored if obj in g["objects"]]
    return [g for g in stored if any(r == robot or r.startswith(f"{robot}-") for r in g["robots"])]


def _noted(gripper: Gripper) -> Gripper:
    for note in gripper.notes:  # what the parallel-jaw model approximates (a linkage's pads moving along the approach)
        warn(f"gripper {gripper.name}: {note}")
    return gripper


def _fingers(args: argparse.Namespace) -> tuple[str, ...]:
    return tuple(f.strip() for f in (args.gripper_fingers or "").split(",") if f.strip())


def stored_robot_gripper(store: Store, name: str, args: argparse.Namespace) -> tuple[Gripper, str | None]:
    """The gripper of `add_gripper_argument`'s options for planning on stored robot `name`, and the stored name of
    that robot with this gripper (NAME, or NAME-DIGEST when another gripper took the name first; None when none is).

    `own` is the robot's own hand rebuilt from each stored row of the robot (its URDF text, mesh folders and tip,
    or --gripper-hand) with --gripper-fingers, the newest row whose gripper digest it reproduces; so
    `build --gripper own` and `plan --gripper own` name the same rows, as the URDF form would."""
    if args.gripper != "own":
        gripper = gripper_from_args(args, grippers_of(stored_grippers(store), robot=name),
                                    f"robot {name!r} in store {store.path}")
        return gripper, robot_with_gripper(store, name, gripper.digest)
    ids = robot_ids(store, name)
    if not ids:
        raise StoreError(f"store {store.path} has no robot {name!r} to take its own hand from; build it first "
                         f"(`workbench build MESH --robot URDF --tip LINK --gripper own --gripper-fingers LEFT,RIGHT`)")
    fingers, first, loaded = _fingers(args), None, False
    for idrobot in ids:
        row = robot_row(store, idrobot)
        if row["idgripper"] is None:
            continue
        stored = gripper_row(store, row["idgripper"])
        try:
            gripper = load_gripper("own", hand_link=args.gripper_hand, finger_joints=fingers, tcp_frame=args.gripper_tcp,
                                   robot_urdf=f"robot {row['name']!r} in store {store.path}", tip=row["tip_frame"],
                                   package_dirs=row["package_dirs"], robot_text=row["urdf"])
        except GripperError as exc:  # this row's URDF has no such hand (another robot took the name): try the next
            first = first or exc
            continue
        loaded = True
        if gripper.digest == stored["digest"]:
            return _noted(replace(gripper, name=stored["name"])), row["name"]
    if first is not None and not loaded:  # no stored URDF has this hand: say why, for the newest
        raise first
    raise GripperError(f"store {store.path} has robot {name!r} with gripper {', '.join(robot_grippers(store, name))}, "
                       f"not its own hand at {args.gripper_hand or 'its tip'} with finger joints {', '.join(fingers)}; "
                       f"give --gripper and --gripper-fingers as given to build")
