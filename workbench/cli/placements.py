"""`workbench placements --db DB --object NAME`: stable placements, free tabletop grips, tabletop placements and
grips over a table grid (Wan & Harada, Section IV)."""

from __future__ import annotations

import argparse
import time

from workbench.cli import warn
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import (
    empty_stage,
    ensure_placements,
    get_object,
)
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.gripper import franka_hand
from workbench.store import Store
from workbench.store.grasps import latest_grasp_paramset


def add_placement_arguments(parser: argparse.ArgumentParser) -> None:
    """Stability and table-grid options (metres; the grid is in the world frame, table top at z = 0)."""
    p, t = PlacementParams(), TabletopParams()
    parser.add_argument("--min-stability", type=float, default=p.min_stability,
                        help="smallest stability (support margin / centre-of-mass height)")
    parser.add_argument("--clearance", type=float, default=p.clearance, help="hand clearance above the table (m)")
    parser.add_argument("--x", type=_range, default=(t.x_min, t.x_max, t.nx), metavar="MIN,MAX,N", help="grid along x")
    parser.add_argument("--y", type=_range, default=(t.y_min, t.y_max, t.ny), metavar="MIN,MAX,N", help="grid along y")
    parser.add_argument("--angles", type=int, default=t.angles, help="rotations about z (the angle table)")
    parser.add_argument("--max-grasps", type=int, default=0,
                        help="cap the free-air grasps carried into the roadmap, for a quick look (default 0: all, as the paper)")


def _range(text: str) -> tuple[float, float, int]:
    try:
        lo, hi, n = text.split(",")
        return float(lo), float(hi), int(n)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX,N such as 0.35,0.65,7, got {text!r}") from None


def placement_params(args: argparse.Namespace) -> tuple[PlacementParams, TabletopParams]:
    return (PlacementParams(min_stability=args.min_stability, clearance=args.clearance),
            TabletopParams(x_min=args.x[0], x_max=args.x[1], nx=args.x[2], y_min=args.y[0], y_max=args.y[1], ny=args.y[2],
                           angles=args.angles, max_grasps=args.max_grasps or None))


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("placements", help="compute and store placements and the tabletop roadmap data")
    parser.add_argument("--db", required=True, help="DuckDB store file")
    parser.add_argument("--object", required=True, help="object name in the store")
    add_placement_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:

    pparams, tparams = placement_params(args)
    t0 = time.perf_counter()
    with Store(args.db) as store:
        oid, obj = get_object(store, args.object)
        result = ensure_placements(store, oid, obj, latest_grasp_paramset(store, oid), franka_hand(), pparams, tparams)
        reason = empty_stage(store, args.object)
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
    print(f"{name}: {len(stab)} stable placements (stability {', '.join(f'{s:.2f}' for s in stab)})")
    print(f"free tabletop grips per placement: {', '.join(str(int(n)) for n in result.n_free_grips)}")
    print(roadmap_grasps_line(result.grasps_label, result.n_roadmap_grasps, result.n_usable_grasps))
    print(f"{'reused' if result.reused else 'stored'} {result.n_tabletop_placements} tabletop placements and "
          f"{result.n_tabletop_grips} tabletop grips (parameter sets {result.idplacements}, {result.idtabletop}) in {seconds:.2f} s")
