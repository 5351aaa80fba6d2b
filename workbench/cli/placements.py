"""`workbench placements --db DB --object NAME`: stable placements, free tabletop grips, tabletop placements and
grips over a table grid (Wan & Harada, Section IV)."""

from __future__ import annotations

import argparse
import time

import numpy as np

from workbench.cli import warn
from workbench.grasping.placements import PlacementParams
from workbench.params import add_param, bounds, cli_bound, parse_number
from workbench.planners.wan_harada.stages import (
    empty_stage,
    ensure_placements,
    get_object,
)
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.cli.gripper import add_gripper_argument, gripper_from_args, grippers_of
from workbench.store import Store
from workbench.store.objects import stored_grippers
from workbench.store.grasps import STAGE as GRASP_STAGE, latest_paramset_for


def add_placement_arguments(parser: argparse.ArgumentParser) -> None:
    """Stability and table-grid options (metres; the grid is in the world frame, table top at z = 0)."""
    t = TabletopParams()
    add_param(parser, PlacementParams, "min_stability")
    add_param(parser, PlacementParams, "min_probability")
    add_param(parser, PlacementParams, "clearance")
    parser.add_argument("--reject-rocking", action="store_true",
                        help="a placement that rocks (a tilt of half the rock angle, 17.5 degrees, tips it onto a "
                             "neighbouring face within 35 degrees, as on a faceted round side) is not stable")
    for axis, lo, hi, n in (("x", t.x_min, t.x_max, t.nx), ("y", t.y_min, t.y_max, t.ny)):
        parser.add_argument(f"--{axis}", type=_grid(axis), default=(lo, hi, n), metavar="MIN,MAX,N",
                            help=f"grid along {axis}: MIN and MAX in [-10, 10] m, N positions in [1, 1000] "
                                 f"(default {lo:g},{hi:g},{n}; negative values parse: --{axis} -0.3,0.3,3)")
    add_param(parser, TabletopParams, "angles")
    parser.add_argument("--max-grasps", type=parse_number(MAX_GRASPS, "--max-grasps"), default=0, metavar="N",
                        help=f"cap the free-air grasps carried into the roadmap, for a quick look ({MAX_GRASPS.describe(True)}; "
                             f"default 0: all, as the paper)")


MAX_GRASPS = cli_bound(0, 1_000_000, integer=True, help="free-air grasps carried into the roadmap")


def _grid(axis: str):
    """An argparse type for MIN,MAX,N along `axis`, checked with TabletopParams' declared ranges."""
    b = bounds(TabletopParams)
    lo_b, hi_b, n_b = b[f"{axis}_min"][0], b[f"{axis}_max"][0], b[f"n{axis}"][0]

    def parse(text: str) -> tuple[float, float, int]:
        parts = text.split(",")
        if len(parts) != 3:
            raise argparse.ArgumentTypeError(f"expected MIN,MAX,N such as 0.35,0.65,7, got {text!r}")
        try:
            lo, hi, n = float(parts[0]), float(parts[1]), float(parts[2])
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected MIN,MAX,N numbers such as 0.35,0.65,7, got {text!r}") from None
        for name, bound, v in (("MIN", lo_b, lo), ("MAX", hi_b, hi), ("N", n_b, n)):
            problem = bound.problem(v)
            if problem is not None:
                raise argparse.ArgumentTypeError(f"{name} {v:g} in {text!r} {problem}: {bound.help} must be {bound.describe()}")
        if lo > hi:
            raise argparse.ArgumentTypeError(f"MIN {lo:g} is above MAX {hi:g} in {text!r}; give MIN,MAX,N with MIN <= MAX")
        return lo, hi, int(n)

    parse.__name__ = "grid"
    return parse


def placement_params(args: argparse.Namespace) -> tuple[PlacementParams, TabletopParams]:
    return (PlacementParams(min_stability=args.min_stability, min_probability=args.min_probability,
                            clearance=args.clearance, reject_rocking=args.reject_rocking),
            TabletopParams(x_min=args.x[0], x_max=args.x[1], nx=args.x[2], y_min=args.y[0], y_max=args.y[1], ny=args.y[2],
                           angles=args.angles, max_grasps=args.max_grasps or None))


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("placements", help="compute and store placements and the tabletop roadmap data")
    parser.add_argument("--db", required=True, help="DuckDB store file")
    parser.add_argument("--object", required=True, help="object name in the store")
    add_placement_arguments(parser)
    add_gripper_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    pparams, tparams = placement_params(args)
    t0 = time.perf_counter()
    with Store(args.db, create=False) as store:
        oid, obj = get_object(store, args.object)
        gripper = gripper_from_args(args, grippers_of(stored_grippers(store), obj=args.object),
                                    f"object {args.object!r} in store {args.db}")
        grasps = latest_paramset_for(store, GRASP_STAGE, oid, gripper, "grasps")
        result = ensure_placements(store, oid, obj, grasps, gripper, pparams, tparams)
        reason = empty_stage(store, args.object, gripper=gripper)
    print_placements(args.object, result, time.perf_counter() - t0)
    if reason:
        warn(f"no tabletop grip of {args.object}; stage {reason}")
    return 0


def roadmap_grasps_line(label: str, roadmap: int, usable: int) -> str:
    """One line naming how many free-air grasps the roadmap carries, and the cap when there is one."""
    if label == "all grasps":
        return f"roadmap grasps: all {roadmap} usable grasps"
    return f"roadmap grasps: {roadmap} of {usable} usable, {label}"


def print_placements(name: str, result, seconds: float) -> None:
    stab = result.placements["stability"]
    prob = result.placements.get("probability", np.full(len(stab), np.nan))
    rock = result.placements.get("rocking", np.full(len(stab), np.nan))
    if len(stab):
        print(f"{name}: {len(stab)} stable placements, most likely first (probability / stability, \"rocks\" where a "
              f"small tilt rolls the part onto the next face: "
              f"{', '.join(f'{p:.2f}/{s:.2f}' + (' rocks' if r == 1 else '') for p, s, r in zip(prob, stab, rock))})")
        print(f"free tabletop grips per placement: {', '.join(str(int(n)) for n in result.n_free_grips)}")
    else:
        print(f"{name}: 0 stable placements")
    print(roadmap_grasps_line(result.grasps_label, result.n_roadmap_grasps, result.n_usable_grasps))
    print(f"{'reused' if result.reused else 'stored'} {result.n_tabletop_placements} tabletop placements and "
          f"{result.n_tabletop_grips} tabletop grips (parameter sets {result.idplacements}, {result.idtabletop}) in {seconds:.2f} s")
