"""`workbench grasps MESH --db DB`: plan free-air grasps and store them (Wan & Harada, Section III)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from workbench.cli import warn
from workbench.cli.outputs import add_output
from workbench.cli.gripper import add_gripper_argument, gripper_from_args
from workbench.geometry.objects import load_object
from workbench.grasping.grasps import DEFAULT_FRICTION, GraspParams, GraspPlan, plan_grasps
from workbench.params import HAND_SIZED, PART_SIZE, SCALE, add_param, from_cli, parse_number
from workbench.planners.wan_harada.stages import ensure_grasps
from workbench.viewer.scenes import grasp_scene



def add_object_arguments(parser: argparse.ArgumentParser) -> None:
    """MESH, --scale/--units and --name, shared by the commands that load an object."""
    parser.add_argument("mesh", help="mesh file of the object (STL, OBJ, PLY, OFF, glTF/GLB or COLLADA DAE)")
    unit = parser.add_mutually_exclusive_group()
    unit.add_argument("--scale", type=parse_number(SCALE, "--scale"), default=None, metavar="X",
                      help=f"factor from the file's units to metres, e.g. 0.001 ({SCALE.describe(True)})")
    unit.add_argument("--units", choices=["m", "cm", "mm", "in"], default=None, help="the file's unit")
    parser.add_argument("--accept-size", action="store_true",
                        help=f"read in metres (no --units or --scale), a part over {HAND_SIZED.hi:g} m across is refused "
                             f"as a likely unit mistake; this plans it in metres anyway (up to {PART_SIZE.hi:g} m)")
    parser.add_argument("--name", default=None, help="object name in the store (default: the file's stem)")


def add_grasp_arguments(parser: argparse.ArgumentParser) -> None:
    """Grasp-planning parameters; angles in degrees, lengths in metres."""
    add_param(parser, GraspParams, "tau")
    parser.add_argument("--segmentation", choices=["over", "conventional"], default=GraspParams().segmentation,
                        help="over: a facet grown from every seed triangle, facets overlapping (Wan & Harada's "
                             "over-segmentation); conventional: each triangle in one facet (default: %(default)s)")
    for name in ("density", "neighbour_radius", "dist_min", "dist_max", "parallel_angle", "com_max", "rotations", "seed"):
        add_param(parser, GraspParams, name)
    parser.add_argument("--contact-model", choices=["pads", "paper"], default=GraspParams().contact_model,
                        help="pads: each pad closes until it first touches (CONVENTIONS.md); paper: parallel facet pairs "
                             "and swept cylinders")
    add_param(parser, GraspParams, "friction", cli_default=None,
              help=f"pad friction coefficient, the cone of the pad model (default: the gripper spec's `friction`, "
                   f"else {DEFAULT_FRICTION:g})")
    for name in ("finger_clearance", "fingertip_margin", "pregrasp_margin", "approach_length"):
        add_param(parser, GraspParams, name)
    parser.add_argument("--full-opening", action="store_true",
                        help="approach every grasp with the jaw fully open instead of at the grasp's opening plus "
                             "--pregrasp-margin")
    parser.add_argument("--no-fingertip", action="store_true",
                        help="centre-of-pad grasps only (no fingertip grasps of thin parts)")
    parser.add_argument("--no-support-grasps", action="store_true",
                        help="jaw axes along the facet normals only (no levelled axes approaching straight down onto "
                             "the supports the part rests on)")
    parser.add_argument("--no-gap-grasps", action="store_true",
                        help="pads start outside the part only (no grasps of a wall with one finger inside a hole or "
                             "cavity)")
    parser.add_argument("--fixed-lengths", action="store_true",
                        help="use --neighbour-radius, --dist-min/max and --com-max as given instead of scaling them "
                             f"with the part (size sqrt(area / 6) over {GraspParams().reference_size * 1e3:.0f} mm)")


def grasp_params(args: argparse.Namespace) -> GraspParams:
    return GraspParams(tau=from_cli(GraspParams, "tau", args.tau_deg), segmentation=args.segmentation, density=args.density,
                       neighbour_radius=args.neighbour_radius, dist_min=args.dist_min, dist_max=args.dist_max,
                       parallel_angle=from_cli(GraspParams, "parallel_angle", args.parallel_deg), com_max=args.com_max,
                       rotations=args.rotations, seed=args.seed, contact_model=args.contact_model,
                       friction=args.friction, finger_clearance=args.finger_clearance,
                       fingertip_margin=None if args.no_fingertip else args.fingertip_margin,
                       support_grasps=not args.no_support_grasps, gap_grasps=not args.no_gap_grasps,
                       pregrasp_margin=None if args.full_opening else args.pregrasp_margin,
                       approach_length=args.approach_length,
                       lengths="fixed" if args.fixed_lengths else "adaptive")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("grasps", help="plan free-air grasps of a mesh and store them")
    add_object_arguments(parser)
    parser.add_argument("--db", required=True, help="DuckDB store file")
    add_grasp_arguments(parser)
    add_gripper_argument(parser)
    add_output(parser, "--html", "write a meshcat scene of the grasps to this HTML file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    params = grasp_params(args)
    gripper = gripper_from_args(args)
    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name, accept_size=args.accept_size)
    t0 = time.perf_counter()
    result = ensure_grasps(args.db, obj, gripper, params)
    dt = time.perf_counter() - t0
    verb = "reused" if result.reused else "stored"
    print(f"{obj.name}: {obj.n_triangles} triangles, centre of mass {np.round(obj.com, 4).tolist()} m ({obj.com_method})")
    for note in obj.repairs:
        print(f"repaired: {note}")
    stated = gripper.spec_value("friction")
    if args.friction is None and stated is not None:
        print(f"friction {stated:g}: the friction gripper {gripper.name}'s spec states (--friction overrides it)")
    if result.plan is not None:
        print(grasp_counts(result.plan))
    print(f"{verb} {result.count} free-air grasps for gripper {gripper.name} in {args.db} (parameter set {result.idparamset}) in {dt:.2f} s")
    if result.count == 0:
        reason = result.plan.empty_reason if result.plan is not None else \
            plan_grasps(obj, gripper, params).empty_reason
        warn(f"no grasp of {obj.name}; stage {reason}")
    if args.html:

        path = grasp_scene(obj, gripper, result.poses, result.widths, args.html)
        print(f"scene: {path}")
    return 0


def grasp_counts(plan: GraspPlan) -> str:
    """The candidates left after every stage, in order, and the lengths used (scaled with the part or fixed)."""
    c, L = plan.counts, plan.lengths
    head = (f"facets {c['facets']}, samples {c['samples']} -> {c['samples_neighbour']} neighbour filter -> "
            f"{c['facet_samples_distance']} of {c['facet_samples']} facet samples after the boundary distance")
    if "pads_width" in c:
        body = (f"hand poses {c['hand_poses']} -> {c['pads_left']} first pad in the friction cone -> {c['pads_width']} "
                f"opening fits -> {c['pads_cone']} both pads in the friction cone -> "
                f"{c['pads_com']} near the centre of mass -> {c['hand_open']} approach free -> {c['grasps']} fingers free")
    else:
        body = (f"contact pairs {c['contact_pairs']} -> {c['pairs_width']} jaw -> {c['pairs_com']} com -> "
                f"{c['pairs_level1']} level 1; hand poses {c['hand_poses']} -> {c['hand_open']} approach free -> "
                f"{c['grasps']} fingers free")
    lengths = (f"lengths x{L['scale']:.2f}: neighbour radius {L['neighbour_radius'] * 1e3:.3g} mm, boundary distance "
               f"{L['dist_min'] * 1e3:.3g}-{L['dist_max'] * 1e3:.3g} mm, centre-of-mass distance {L['com_max'] * 1e3:.3g} mm")
    if L.get("com_hole", 0.0) > 0:
        lengths += (f" (the centre of mass lies in a hole, {L['com_hole'] * 1e3:.3g} mm from the part: grasps across "
                    f"the material nearest it are kept)")
    return f"{head}\n{body}\n{lengths}"
