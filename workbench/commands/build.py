"""`workbench build MESH --robot ROBOT --db DB`: every stage of Wan & Harada Sections III-V for one object and robot
(grasps, placements, tabletop grips, IK with retractions, the regrasp graph), reusing what the store has."""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path

from ..grasps import GraspParams
from ..placements import PlacementParams
from ..tabletop import TabletopParams

HANDX, WORLDZ = 0.05, 0.10


@dataclass
class BuildResult:
    """Ids of every stage's rows, whether each was reused, counts and seconds per stage."""

    name: str
    robot: str
    ids: dict = field(default_factory=dict)
    reused: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)


def ensure_ik_rows(store, idobject: int, obj, idtabletop: int, robot_name: str, handx: float = HANDX, worldz: float = WORLDZ,
                   workers: int | None = None, progress: bool = True) -> tuple[dict, bool]:
    """IK feasibility of the tabletop grips for a robot (Section IV's ik and ikret tables), computed or reused by the
    IK stage's runner (`workbench.commands.ik.ensure_ik`); returns the run's ids and whether it was reused."""
    from .ik import ensure_ik

    run = ensure_ik(store, idobject, obj, idtabletop, robot_name, handx=handx, worldz=worldz, workers=workers, progress=progress)
    return {"idrobot": run.idrobot, "idscene": run.idscene, "idikret": run.idikret}, run.reused


def build_all(db, obj, robot_name: str, gparams: GraspParams = GraspParams(), pparams: PlacementParams = PlacementParams(),
              tparams: TabletopParams = TabletopParams(), handx: float = HANDX, worldz: float = WORLDZ,
              workers: int | None = None, progress: bool = True) -> BuildResult:
    """Grasps, placements, tabletop grips, IK and the regrasp graph of `obj` (an ObjectModel) for `robot_name` in the
    store `db` (path or Store), each stage reused when stored with the same inputs and parameters."""
    from ..gripper import franka_hand
    from ..pipeline import ensure_grasps, ensure_placements
    from ..regrasp import load_planner
    from ..store import Store

    store = db if isinstance(db, Store) else Store(db)
    out = BuildResult(name=obj.name, robot=robot_name)
    try:
        hand = franka_hand()
        t0 = time.perf_counter()
        g = ensure_grasps(store, obj, hand, gparams)
        out.timings["grasps"], out.reused["grasps"], out.counts["grasps"] = time.perf_counter() - t0, g.reused, g.count
        t0 = time.perf_counter()
        p = ensure_placements(store, g.idobject, obj, g.idparamset, hand, pparams, tparams)
        out.timings["placements"], out.reused["placements"] = time.perf_counter() - t0, p.reused
        out.counts.update(placements=len(p.placements["stability"]), tabletop_placements=p.n_tabletop_placements,
                          tabletop_grips=p.n_tabletop_grips)
        t0 = time.perf_counter()
        ik_ids, reused = ensure_ik_rows(store, g.idobject, obj, p.idtabletop, robot_name, handx, worldz, workers, progress)
        out.timings["ik"], out.reused["ik"] = time.perf_counter() - t0, reused
        t0 = time.perf_counter()
        planner = load_planner(store, obj.name, ik_ids["idrobot"], handx, worldz, idtabletop=p.idtabletop,
                               idscene=ik_ids["idscene"])
        out.timings["graph"] = time.perf_counter() - t0
        out.counts.update({f"graph_{k}": v for k, v in planner.roadmap.summary().items()})
        out.counts["placement_ids"] = planner.placement_ids()
        out.ids = {"idgrasps": g.idparamset, "idplacements_set": p.idplacements, **planner.ids}
        return out
    finally:
        if store is not db:
            store.close()


def register(sub: argparse._SubParsersAction) -> None:
    from .grasps import add_grasp_arguments, add_object_arguments
    from .placements import add_placement_arguments

    parser = sub.add_parser("build", help="run every stage for a mesh and a robot (grasps, placements, IK, regrasp graph)")
    add_object_arguments(parser)
    parser.add_argument("--robot", required=True, help="robot: panda, ur5 or talos")
    parser.add_argument("--db", required=True, help="DuckDB store file (created when missing)")
    parser.add_argument("--handx", type=float, default=HANDX, help=f"retraction along the approach axis (m, default {HANDX})")
    parser.add_argument("--worldz", type=float, default=WORLDZ, help=f"retraction up along world z (m, default {WORLDZ})")
    parser.add_argument("--workers", type=int, default=None, help="IK processes (default: all cores)")
    add_placement_arguments(parser)
    add_grasp_arguments(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..errors import WorkbenchError
    from ..objects import load_object
    from .grasps import grasp_params
    from .placements import placement_params

    for label, v in (("--handx", args.handx), ("--worldz", args.worldz)):
        if not v >= 0:
            raise WorkbenchError(f"{label} must be a distance >= 0 m, got {v}")
    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name)
    pparams, tparams = placement_params(args)
    t0 = time.perf_counter()
    res = build_all(args.db, obj, args.robot, grasp_params(args), pparams, tparams, args.handx, args.worldz, args.workers)
    print_build(res, args.db, time.perf_counter() - t0)
    return 0


def print_build(res: BuildResult, db, seconds: float) -> None:
    c, t, r = res.counts, res.timings, res.reused
    verb = lambda k: "reused" if r.get(k) else "computed"  # noqa: E731
    print(f"{res.name}: {c['grasps']} free-air grasps ({verb('grasps')}, {t['grasps']:.1f} s); {c['placements']} stable placements, "
          f"{c['tabletop_placements']:,} tabletop placements, {c['tabletop_grips']:,} tabletop grips ({verb('placements')}, "
          f"{t['placements']:.1f} s)")
    print(f"IK for {res.robot} ({verb('ik')}, {t['ik']:.1f} s); regrasp graph: {c['graph_nodes']:,} nodes, {c['graph_transfer_edges']:,} "
          f"transfer and {c['graph_transit_edges']:,} transit edges, {c['graph_grasps']} grasps, {c['graph_placements']} placements, "
          f"{c['graph_components']} component(s) ({t['graph']:.1f} s)")
    print(f"store {Path(db).resolve()} ready in {seconds:.1f} s; stable placements for --start/--goal "
          f"(PLACEMENT,X,Y,YAW): {', '.join(map(str, c['placement_ids']))}")
