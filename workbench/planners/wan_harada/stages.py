"""Stage runners of the roadmap planner (Wan & Harada, Sections III-V) against a DuckDB store.

Each stage is computed once per input and parameters and reused from the store: grasps (`ensure_grasps`),
placements and the tabletop roadmap (`ensure_placements`), IK with retractions (`run_ik`, `ensure_ik`), the whole
build (`build_all`), the regrasp graph (`load_planner`, with an explicit `PlannerCache`) and plans (`save_plan`).
This is the only module of the planner that talks to the store; computations run outside write transactions.
"""

from __future__ import annotations

import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import trimesh

from workbench.errors import PartialStageWarning, PlanningError, RobotError, StoreError
from workbench.geometry.objects import MeshWarning, ObjectModel, from_arrays, mesh_digest
from workbench.grasping.grasps import GraspParams, GraspPlan, plan_grasps, table_friction_hint
from workbench.grasping.placements import (
    PlacementParams,
    empty_placement_stage,
    free_tabletop_grips,
    stable_placements,
)
from workbench.planners.wan_harada.planner import Planner
from workbench.planners.wan_harada.plans import Plan, PlanObstacle, PlanStep, plan_rows
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.roadmap import build_roadmap, check_graph_memory, grid_index
from workbench.planners.wan_harada.tabletop import (
    TabletopParams,
    plan_tabletop,
)
from workbench.robots.collider import Collider, Scene, default_scene
from workbench.robots.gripper import Gripper, franka_hand
from workbench.robots.ik import WORLDA, IKOptions, diagnose_unreachable, iter_ik, solver_kind
from workbench.robots.model import ROBOTS, Robot, RobotSpec, builtin_robot, get_robot
from workbench.robots.selfcollision import AllowedPairs, allowed_pairs
from workbench.robots.solvers import revision as solver_revision
from workbench.robots.timing import TimedSegment, Trajectory
from workbench.store import Store
from workbench.store import robots as robot_sql
from workbench.store import wan_harada as sql
from workbench.store.grasps import find_grasps, latest_paramset_for, load_grasps, save_grasps
from workbench.store.objects import gripper_row, object_name, object_row, put_object, stored_grippers
from workbench.store.placements import (
    find_placements,
    find_tabletop,
    TABLETOP_STAGE,
    latest_tabletop_paramset,
    load_free_tabletop_grips,
    load_placements,
    load_tabletop_grips,
    save_placements,
    save_tabletop,
    tabletop_counts,
    tabletop_grasp_count,
)
from workbench.store.robots import ik_runs, ikret_row, robot_row, robot_with_gripper, scene_row

if TYPE_CHECKING:  # pragma: no cover

    from workbench.geometry.objects import ObjectModel
    from workbench.robots.collider import Scene
    from workbench.robots.ik import IKOptions
    from workbench.robots.model import Robot
    from workbench.store import Store


@dataclass
class GraspsResult:
    """The free-air grasp stage's result (Section III): its object and parameter set, whether the rows were reused,
    and the grasps' TCP poses (N, 4, 4) in the object frame with their jaw widths (N,) in metres."""

    idobject: int
    idparamset: int
    reused: bool
    count: int
    poses: np.ndarray
    widths: np.ndarray
    plan: GraspPlan | None


def ensure_grasps(db: str | Path | Store, obj: ObjectModel, gripper: Gripper, params: GraspParams) -> GraspsResult:
    """Free-air grasps of `obj` in the store `db`: planned and stored, or reused when already stored."""
    store = db if isinstance(db, Store) else Store(db)
    try:
        oid = put_object(store, obj)
        pid = find_grasps(store, oid, gripper, params)
        plan = None
        if pid is None:
            with store.released():  # other processes may write the store while this one plans
                plan = plan_grasps(obj, gripper, params)
            pid, _ = save_grasps(store, oid, gripper, params, plan.grasps)
        else:
            store.mark_used(pid)
        rows = load_grasps(store, oid, pid)
        return GraspsResult(idobject=oid, idparamset=pid, reused=plan is None, count=len(rows["jawwidth"]),
                            poses=rows["rotmat"], widths=rows["jawwidth"], plan=plan)
    finally:
        if not isinstance(db, Store):
            store.close()


@dataclass
class PlacementsResult:
    """The placement stage's result (Section IV): the parameter sets of the free and tabletop placements, whether
    they were reused, the placements, the free tabletop grips per placement and the tabletop counts."""

    idplacements: int
    idtabletop: int
    reused: bool
    placements: dict
    n_free_grips: np.ndarray
    n_tabletop_placements: int
    n_tabletop_grips: int
    timings: dict
    n_usable_grasps: int = 0
    n_roadmap_grasps: int = 0
    grasps_label: str = "all grasps"


def ensure_placements(db: str | Path | Store, idobject: int, obj: ObjectModel, grasp_pid: int, gripper: Gripper,
                      pparams: PlacementParams, tparams: TabletopParams) -> PlacementsResult:
    """Free placements, free tabletop grips, tabletop placements and grips of a stored grasp set (Section IV)."""
    store = db if isinstance(db, Store) else Store(db)
    timings: dict[str, float] = {}
    try:
        reused = True
        grasps = None
        pl_pid = find_placements(store, idobject, grasp_pid, pparams)
        if pl_pid is None:
            reused = False
            t0 = time.perf_counter()
            grasps = load_grasps(store, idobject, grasp_pid)
            with store.released():
                placements = stable_placements(obj, pparams)
                ftg = free_tabletop_grips(placements, grasps["rotmat"], gripper, pparams)
            timings["placements"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            pl_pid = save_placements(store, idobject, grasp_pid, pparams, placements, grasps, ftg)
            timings["write_placements"] = time.perf_counter() - t0
        stored = load_placements(store, pl_pid)
        ftg = load_free_tabletop_grips(store, pl_pid)
        fp_index = np.searchsorted(stored["idfreetabletopplacement"], ftg["idfreetabletopplacement"])
        tt_pid = find_tabletop(store, idobject, pl_pid, tparams)
        if tt_pid is None:
            reused = False
            t0 = time.perf_counter()
            grasps = load_grasps(store, idobject, grasp_pid) if grasps is None else grasps
            g_index = np.searchsorted(grasps["idfreeairgrip"], ftg["idfreeairgrip"])
            with store.released():
                tt = plan_tabletop(stored["rotmat"], fp_index, g_index, ftg["rotmat"], grasps["rotmat"], tparams)
            timings["tabletop"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            tt_pid = save_tabletop(store, idobject, pl_pid, tparams, tt, ftg, stored["idfreetabletopplacement"])
            timings["write_tabletop"] = time.perf_counter() - t0
        if reused:
            store.mark_used(pl_pid)
            store.mark_used(tt_pid)
        n_tp, n_tg = tabletop_counts(store, tt_pid)
        n_roadmap = tabletop_grasp_count(store, tt_pid)
        return PlacementsResult(idplacements=pl_pid, idtabletop=tt_pid, reused=reused, placements=stored,
                                n_free_grips=np.bincount(fp_index, minlength=len(stored["stability"])),
                                n_tabletop_placements=int(n_tp), n_tabletop_grips=int(n_tg), timings=timings,
                                n_usable_grasps=len(np.unique(ftg["idfreeairgrip"])),
                                n_roadmap_grasps=n_roadmap, grasps_label=tparams.grasps_label(n_roadmap))
    finally:
        if not isinstance(db, Store):
            store.close()


class PlannerCache:
    """Loaded planners kept by the key of every input that changes them (store file, object digest, tabletop
    parameter set, robot digest, scene, retractions, a fingerprint of the `ik` rows), so repeated queries only
    connect and search. Hold one where planners are loaded repeatedly (a notebook, a benchmark)."""

    def __init__(self, size: int = 8):
        self.size = int(size)
        self._planners: dict[tuple, Planner] = {}

    def get(self, key: tuple) -> Planner | None:
        return self._planners.get(key)

    def put(self, key: tuple, planner: Planner) -> None:
        if len(self._planners) >= self.size:
            self._planners.pop(next(iter(self._planners)))
        self._planners[key] = planner

    def clear(self) -> None:
        self._planners.clear()


def load_planner(db: str | Path | Store, object_name: str, robot_name: str | int, handx: float | None = None, worldz: float | None = None,
                 idtabletop: int | None = None, idscene: int | None = None, cache: PlannerCache | None = None,
                 gripper: Gripper | None = None, worlda: float | None = None, allow_partial: bool = False) -> Planner:
    """The regrasp graph of `object_name` for `robot_name` (a stored robot name or idrobot) from a store (path or
    Store), built from the latest tabletop parameter set and the IK run with the most rows (or the one with these
    retractions or this scene); with a `cache`, a planner already loaded for the same inputs is returned.
    `gripper` is the planning gripper the robot was stored with (default: the Franka hand; the stored robot
    digest covers it). An IK run killed part-way is refused unless `allow_partial` (then a PartialStageWarning)."""

    store = db if isinstance(db, Store) else Store(db, create=False)
    try:
        oid, obj = get_object(store, object_name)
        rrow = robot_row(store, robot_name)
        if idtabletop is not None:
            tt = int(idtabletop)
        elif rrow["idgripper"] is not None:  # the latest tabletop grips of the robot's gripper
            tt = latest_paramset_for(store, TABLETOP_STAGE, oid, gripper_row(store, rrow["idgripper"])["digest"], "placements")
        else:
            tt = latest_tabletop_paramset(store, oid)
        # the run with the most rows (then the newest) first: (idscene, idikret)
        runs = [(int(r["idscene"]), int(r["idikret"])) for r in
                sorted(ik_runs(store, idtabletop=tt, idrobot=rrow["idrobot"]), key=lambda r: (-r["rows"], -r["last"]))]
        if handx is not None or worldz is not None:
            runs = [r for r in runs if _ret_match(ikret_row(store, r[1]), handx, worldz)]
        if worlda is not None:
            runs = [r for r in runs if abs(ikret_row(store, r[1])["worlda"] - worlda) < 1e-9]
        if idscene is not None:
            runs = [r for r in runs if r[0] == int(idscene)]
        if not runs:
            raise PlanningError(f"store {store.path} has no IK of {object_name}'s tabletop grips for robot {robot_name}"
                                f"{'' if handx is None and worldz is None else f' with handx {handx}, worldz {worldz}'}; "
                                f"run `workbench ik --db {store.path} --object {object_name} --robot {robot_name}` first")
        idscene, idikret = runs[0][0], runs[0][1]
        rows_done, grips, complete = robot_sql.ik_progress(store, tt, rrow["idrobot"], idscene, idikret)
        check_graph_memory(grips)
        if not complete:
            ret = ikret_row(store, idikret)  # the run's own retractions, so that the command resumes this run
            given = "".join(f" --{k} {ret[k]:g}" for k, default in (("handx", HANDX), ("worldz", WORLDZ), ("worlda", WORLDA))
                            if abs(ret[k] - default) > 1e-12)
            what = (f"the IK stage of {object_name} for robot {rrow['name']} in {store.path} is incomplete ({rows_done:,} of "
                    f"{grips:,} tabletop grips); finish it with `workbench ik --db {store.path} --object {object_name} "
                    f"--robot {rrow['name']}{given}` (it resumes)")
            if not allow_partial:
                raise PlanningError(f"{what}, or plan on the partial graph with --allow-partial")
            warnings.warn(f"{what}; planning on the partial graph (--allow-partial)", PartialStageWarning, stacklevel=2)
        fp = sql.ik_fingerprint(store, tt, rrow["idrobot"], idscene, idikret)
        key = (str(store.path.resolve()), oid, tt, rrow["idrobot"], rrow["digest"], idscene, idikret, fp, obj.digest)
        if cache is not None and cache.get(key) is not None:
            return cache.get(key)
        t0 = time.perf_counter()
        robot = _robot_from_row(rrow, gripper)
        rows = sql.roadmap_rows(store, tt, rrow["idrobot"], idscene, idikret, robot.nq)
        t_load = time.perf_counter() - t0
        roadmap = build_roadmap(rows, rows["feasible"])
        roadmap.timings["load"] = t_load
        pl = sql.placements_of_tabletop(store, tt)
        free = load_placements(store, pl)
        ftg = load_free_tabletop_grips(store, pl)
        stored = scene_row(store, idscene)
        scene, opts = stored.scene, stored.ik
        ret = ikret_row(store, idikret)
        ids = {"idobject": oid, "idrobot": rrow["idrobot"], "idscene": idscene, "idikret": idikret, "idtabletop": tt, "idplacements": pl}
        planner = Planner(roadmap, free, ftg, obj, robot, scene, ret["handx"], ret["worldz"], ids, opts, grid=grid_index(rows),
                          worlda=ret["worlda"])
        planner.partial = not complete
        # the grasps' parameters (via the placements that consumed them): grasps stored before the pre-grasp
        # opening existed were checked fully open, and are approached so
        gparams = store.params_of(int(store.params_of(pl).get("grasps", -1)))
        planner.pregrasp_margin = gparams.get("pregrasp_margin")
        roadmap.key = key
        _, orow = object_row(store, object_name)
        gid = rrow["idgripper"]
        planner.rows = {"robot": rrow, "scene": stored, "object": orow,  # raw store rows, for the independent validator
                        "gripper": gripper_row(store, gid) if gid is not None else None}
        planner.allowed = (AllowedPairs.from_json(rrow["allowed_pairs"]) if rrow.get("allowed_pairs")
                           else allowed_pairs(robot))  # self-collision pairs of the robot row (older stores: computed)
        planner.ik.solver  # build the IK solver and its seed library now, not during the first query
        if cache is not None:
            cache.put(key, planner)
        return planner
    finally:
        if store is not db:
            store.close()


def _ret_match(ret: dict[str, float], handx: float | None, worldz: float | None) -> bool:
    return (handx is None or abs(ret["handx"] - handx) < 1e-9) and (worldz is None or abs(ret["worldz"] - worldz) < 1e-9)


def _robot_from_row(row: dict, gripper: Gripper | None = None) -> Robot:
    """The library robot of a stored `robot` row, rebuilt from the row itself (URDF text, frames, mount, base,
    joints, locked joints, dropped hand geometry, mesh folders) with the planning `gripper`; it must reproduce
    the stored digest, which also covers the gripper."""
    spec = RobotSpec(name=row["name"], urdf=row["urdf"], urdf_path="", tip_frame=row["tip_frame"],
                     tcp_frame=row["tcp_frame"], mount=row["mount"], base=row["base"],
                     drop_geometry=tuple(row.get("drop_geometry") or ()), package_dirs=tuple(row.get("package_dirs") or ()),
                     locked=tuple((str(k), float(v)) for k, v in dict(row.get("locked") or {}).items()), gripper=gripper)
    builtin = row["name"] if row["name"] in ROBOTS else row["name"].rsplit("-", 1)[0]
    if spec.digest != row["digest"] and builtin in ROBOTS:  # a built-in stored with its own joint selection
        spec = builtin_robot(builtin, base=row["base"], gripper=gripper).spec
    if spec.digest != row["digest"]:
        raise PlanningError(f"robot {row['name']!r} in the store was computed with other kinematics or another gripper "
                            f"(URDF, frames, base, locked joints, hand) than given here; rebuild its IK stage "
                            f"(workbench build / ik) in a new store, or pass the gripper it was built with")
    robot = Robot(spec)
    if list(robot.joint_names) != list(row["joint_names"]):
        raise PlanningError(f"robot {row['name']!r}: the stored joint order {row['joint_names']} differs from the library's "
                            f"{list(robot.joint_names)}; rebuild the ik stage")
    return robot


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
    empty: str | None = None  # the stage that kept nothing, with what to try (no graph then)


def build_all(db, obj, robot: str | Robot, gparams: GraspParams = GraspParams(), pparams: PlacementParams = PlacementParams(),
              tparams: TabletopParams = TabletopParams(), handx: float = HANDX, worldz: float = WORLDZ,
              workers: int | None = None, progress: bool = True, worlda: float = WORLDA,
              scene: Scene | None = None, ik: IKOptions | None = None) -> BuildResult:
    """Grasps, placements, tabletop grips, IK and the regrasp graph of `obj` (an ObjectModel) for `robot` (a Robot, or a
    built-in robot's name; on `scene`, default the robot's table) in the store `db` (path or Store), each stage reused
    when stored with the same inputs and parameters. `BuildResult.robot` is the robot's name in the store."""

    store = db if isinstance(db, Store) else Store(db)
    robot = get_robot(robot) if isinstance(robot, str) else robot
    out = BuildResult(name=obj.name, robot=robot.name)
    try:
        hand = robot.gripper
        t0 = time.perf_counter()
        g = ensure_grasps(store, obj, hand, gparams)
        out.timings["grasps"], out.reused["grasps"], out.counts["grasps"] = time.perf_counter() - t0, g.reused, g.count
        t0 = time.perf_counter()
        p = ensure_placements(store, g.idobject, obj, g.idparamset, hand, pparams, tparams)
        out.timings["placements"], out.reused["placements"] = time.perf_counter() - t0, p.reused
        out.counts.update(placements=len(p.placements["stability"]), tabletop_placements=p.n_tabletop_placements,
                          tabletop_grips=p.n_tabletop_grips, usable_grasps=p.n_usable_grasps, roadmap_grasps=p.n_roadmap_grasps,
                          grasps_label=p.grasps_label)
        t0 = time.perf_counter()
        run = ensure_ik(store, g.idobject, obj, p.idtabletop, robot, handx, worldz, workers, progress, worlda=worlda,
                        scene=scene, opts=ik)
        ik_ids = {"idrobot": run.idrobot, "idscene": run.idscene, "idikret": run.idikret}
        out.robot = run.robot
        out.timings["ik"], out.reused["ik"] = time.perf_counter() - t0, run.reused
        out.empty = (g.plan.empty_reason if g.plan is not None and g.count == 0
                     else run.empty_reason() or empty_stage(store, obj.name, run.robot, hand))
        if out.empty is not None:  # zero is a result: no graph to build, the stage that emptied is named
            out.ids = {"idgrasps": g.idparamset, "idplacements_set": p.idplacements, **ik_ids}
            return out
        t0 = time.perf_counter()
        planner = load_planner(store, obj.name, ik_ids["idrobot"], handx, worldz, idtabletop=p.idtabletop,
                               idscene=ik_ids["idscene"], worlda=worlda, gripper=robot.gripper)
        out.timings["graph"] = time.perf_counter() - t0
        out.counts.update({f"graph_{k}": v for k, v in planner.roadmap.summary().items()})
        out.counts["placement_ids"] = planner.placement_ids(gripped=True)
        out.counts["placements_nogrip"] = sorted(set(planner.placement_ids()) - set(out.counts["placement_ids"]))
        out.counts["placement_rotmats"] = {int(i): np.asarray(m) for i, m in
                                           zip(planner.free["idfreetabletopplacement"], planner.free["rotmat"])}
        out.counts["placement_rocking"] = {int(i): bool(r == 1) for i, r in
                                           zip(planner.free["idfreetabletopplacement"], planner.free["rocking"])}
        out.ids = {"idgrasps": g.idparamset, "idplacements_set": p.idplacements, **planner.ids}
        return out
    finally:
        if store is not db:
            store.close()


@dataclass
class IKRun:
    """What one `run_ik` did: the ids of the run, the grips, how many were computed now, the feasible counts."""

    idrobot: int
    idscene: int
    idikret: int
    idtabletop: int
    grips: int
    computed: int
    feasible: int
    feasible_all: int
    seconds: float
    reason: str | None = None  # with no feasible grasp pose: why (`robots.ik.diagnose_unreachable`)
    robot: str = ""  # the stored name (`robot.name`, or with a digest suffix when that name holds another robot)

    @property
    def reused(self) -> bool:
        return self.computed == 0

    def empty_reason(self) -> str | None:
        """"ik: why; what to try" when this run (its robot, scene and retractions) has grips but none feasible at all
        five poses, else None."""
        if not self.grips or self.feasible_all > 0:
            return None
        return f"ik: {self.reason}" if self.reason else (
            f"ik: no tabletop grip is feasible at all five poses for {self.robot} (grasp poses {self.feasible:,}); lower "
            f"the retractions (--handx, --worldz, --worlda) or move the grid toward the robot")


def scene_params(robot: Robot, scene: Scene, opts: IKOptions) -> dict:
    """Everything besides the robot row and the grips that changes the `ik` rows (stored in `scene.params`)."""
    return {**scene.as_dict(), "ik": opts.as_dict(), "ik_solver": solver_kind(robot, opts),
            "ik_revision": solver_revision(robot, numerical=opts.solver == "numerical"), "home": robot.home().tolist(),
            "robot": {"locked": {k: v for k, v in robot.spec.locked}, "drop_geometry": list(robot.spec.drop_geometry),
                      "gripper": robot.gripper.digest}}


IK_WRITE_SECONDS = 5.0  # solved chunks are written together at most this often (each write reopens the store)


def run_ik(store, obj_name: str, robot: Robot, scene: Scene | None = None, handx: float = HANDX, worldz: float = WORLDZ,
           opts: IKOptions = IKOptions(self_collide=True), workers: int | None = None, progress: bool = True,
           idtabletop: int | None = None, worlda: float = WORLDA) -> IKRun:
    """Compute (or reuse) the `ik` rows of every tabletop grip of `obj_name` for `robot` at the five poses of
    `robots.ik.KINDS` (Section IV; `worlda` lifts the held object straight up), rejecting self-colliding solutions."""

    t0 = time.perf_counter()
    scene = scene or default_scene(robot.name)
    hit = Collider(robot, scene, None).fixed_parts_hit_table()
    if hit:
        raise RobotError(f"the fixed links ({', '.join(hit[:3])}) of robot {robot.name!r} cut into the table; move its base "
                         f"(--base) or the table (--table)")
    oid, obj = get_object(store, obj_name)
    if idtabletop is None:  # the latest tabletop grips of this robot's gripper
        idtabletop = latest_paramset_for(store, TABLETOP_STAGE, oid, robot.gripper, "placements")
    grips = load_tabletop_grips(store, oid, idtabletop)
    pid = int(np.asarray(grips["idparamset"])) if "idparamset" in grips else int(idtabletop if idtabletop is not None else -1)
    ids = np.asarray(grips["idtabletopgrips"], dtype=np.int64)
    check_graph_memory(len(ids))  # before the IK, whose rows only the graph uses
    rid, sid, kid = robot_sql.prepare_run(store, robot, scene_params(robot, scene, opts), handx, worldz, worlda,
                                          lambda: allowed_pairs(robot).to_json())
    done = robot_sql.stored_grips(store, rid, sid, kid)

    def skip(ix: np.ndarray) -> bool:
        return bool(np.isin(ids[ix], done, assume_unique=True).all())

    computed = 0
    arrays = {k: v for k, v in grips.items() if isinstance(v, np.ndarray) and v.shape[:1] == ids.shape}
    pending: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def write() -> int:
        if not pending:
            return 0
        parts = [np.concatenate(p) for p in zip(*pending)]
        pending.clear()
        return robot_sql.insert_ik(store, rid, sid, kid, *parts)

    last = time.monotonic()
    with store.released():  # each write takes the store briefly: another process's stages run beside
        for ix, feas, joints in iter_ik(robot, arrays, scene, handx, worldz, obj.mesh, opts, workers, skip=skip,
                                        progress=progress, worlda=worlda):
            todo = ~np.isin(ids[ix], done)
            pending.append((ids[ix][todo], feas[todo], joints[todo]))
            if time.monotonic() - last > IK_WRITE_SECONDS:  # an interrupted run keeps what was written
                computed += write()
                last = time.monotonic()
        computed += write()
    robot_sql.mark_ik_complete(store, pid, rid, sid, kid)
    counts = robot_sql.run_counts(store, rid, sid, kid, pid)
    reason = diagnose_unreachable(robot, arrays, scene, obj.mesh, opts) if len(ids) and counts[0] == 0 else None
    return IKRun(rid, sid, kid, pid, len(ids), computed, counts[0], counts[1], time.perf_counter() - t0, reason,
                 robot_sql.robot_name(store, rid))


def ensure_ik(store, idobject: int, obj, idtabletop: int, robot: str | Robot, handx: float = HANDX, worldz: float = WORLDZ,
              workers: int | None = None, progress: bool = True, worlda: float = WORLDA, scene: Scene | None = None,
              opts: IKOptions | None = None) -> IKRun:
    """`run_ik` for a robot (or a built-in robot's name), with the signature `workbench build` expects (default
    options: the fastest solver, self-collisions rejected)."""
    robot = get_robot(robot) if isinstance(robot, str) else robot
    return run_ik(store, obj.name, robot, scene, handx, worldz, opts or IKOptions(self_collide=True), workers, progress,
                  idtabletop, worlda=worlda)


DEMO_GRID = TabletopParams(x_min=0.35, x_max=0.65, nx=5, y_min=-0.2, y_max=0.2, ny=3, angles=8, max_grasps=60)


def choose_task(planner, seed: int = 0, tries: int = 40, grid: TabletopParams = DEMO_GRID,
                min_regrasps: int = 1) -> tuple:
    """A start and a goal (PoseQuery) on the grid's area that need at least `min_regrasps` regrasps: seeded random
    pairs of different stable placements; the one needing the most regrasps among the first solvable ones."""

    rng = np.random.default_rng(seed)
    ids = planner.placement_ids(gripped=True)
    best = None
    for _ in range(tries):
        a, b = rng.choice(ids, size=2, replace=len(ids) < 2)
        q = [PoseQuery(int(p), float(rng.uniform(grid.x_min, grid.x_max)), float(rng.uniform(grid.y_min, grid.y_max)),
                       float(rng.uniform(-np.pi, np.pi))) for p in (a, b)]
        try:
            res = planner.search(q[0], q[1], alternatives=0)
        except PlanningError:
            continue
        k = res.routes[0].n_regrasps
        if k >= min_regrasps and (best is None or k > best[0]):
            best = (k, q[0], q[1])
            if k >= min_regrasps + 1:
                break
    if best is None:
        raise PlanningError(f"no start/goal pair among {tries} random ones needs {min_regrasps}+ regrasps; try another --seed")
    return best[1], best[2]


def save_plan(store: Store, plan: Plan) -> int:
    """Store a plan, its steps and its timed motions (tables `plan`, `planstep`, `plansegment`) in one transaction;
    returns idplan (the stored plan's id when the same query was answered before: no duplicate)."""
    return sql.save_plan(store, *plan_rows(plan))


def save_plans(store: Store, plans: list[Plan]) -> list[int]:
    """Store a plan and its alternatives in one transaction; returns their idplan."""
    rows = [plan_rows(p) for p in plans]
    with store.transaction():
        return [sql.save_plan(store, *r) for r in rows]


def stored_plan(store: Store, plan: Plan) -> int | None:
    """The id of a stored plan answering the same query as `plan` with the same motions, or None."""
    row, _, segments = plan_rows(plan)
    return sql.find_plan(store, row, segments)


def get_object(store: Store, name: str) -> tuple[int, ObjectModel]:
    """The stored object `name` rebuilt as an ObjectModel (mesh in metres, the stored centre of mass). A stored mesh
    whose bytes still give its stored digest is the repaired mesh itself and is used as it is; one that does not (a
    row changed outside the workbench) is validated and repaired again, and its model carries the new digest."""
    oid, row = object_row(store, name)
    vertices, faces = row["vertices"], row["faces"]
    if mesh_digest(vertices, faces) == row["digest"]:
        mesh, digest = trimesh.Trimesh(vertices, faces, process=False, validate=False), row["digest"]
        if row["com_method"] == "volume":  # weighted by volume only when closed and consistently wound (from_arrays)
            mesh._cache["is_watertight"] = mesh._cache["is_winding_consistent"] = True
    else:
        with warnings.catch_warnings():  # the stored mesh was repaired, and its warnings shown, when it was loaded
            warnings.simplefilter("ignore", MeshWarning)
            obj = from_arrays(vertices, faces, scale=1.0, name=name, source=row["source"])
        mesh, digest = obj.mesh, obj.digest
    return oid, ObjectModel(name=name, mesh=mesh, com=np.asarray(row["com"], dtype=np.float64),
                            com_method=row["com_method"], scale=row["scale"], source=row["source"], digest=digest)


# ----------------------------------------------------------------------------------------------------------------
# Zero results: which stage stored no rows, and what to try.


def empty_stage(store: Store, object_name: str, robot_name: str | None = None,
                gripper: Gripper | None = None) -> str | None:
    """The first stage of `object_name`'s latest stored runs that kept nothing, as "stage: why; what to try", or None
    when every stage (grasps, placements, free tabletop grips, tabletop grips, and IK for `robot_name`) has rows.
    With the `gripper` of the grasps, no grasp clearing the table also names the --friction that would give some
    (`grasps.table_friction_hint`)."""
    oid, obj = get_object(store, object_name)
    try:
        grasps = load_grasps(store, oid)
    except StoreError:  # no grasp stage run (tabletop grips given otherwise): nothing is empty
        grasps = {"jawwidth": [None]}
    if len(grasps["jawwidth"]) == 0:
        return (f"grasps: {object_name} has no free-air grasp; `workbench grasps` names the filter that removed the last "
                f"candidate")
    try:
        tt = latest_tabletop_paramset(store, oid)
    except StoreError:  # no placements run yet: nothing empty so far
        return None
    pl = sql.placements_of_tabletop(store, tt)
    stored = store.params_of(pl)
    pparams, poses = PlacementParams.from_dict(stored), load_placements(store, pl)["rotmat"]
    hint = None if gripper is None else lambda: table_friction_hint(  # noqa: E731 (the grasps' parameters, read only then)
        obj, gripper, GraspParams.from_dict(store.params_of(int(stored.get("grasps", -1)))), poses, pparams.clearance)
    reason = empty_placement_stage(obj, pparams, poses, len(load_free_tabletop_grips(store, pl)["idfreeairgrip"]), hint,
                                   grasps.get("rotmat"), gripper)
    if reason is not None:
        return reason
    if tabletop_counts(store, tt)[1] == 0:
        return "tabletop grips: no grasp is kept on the tabletop grid; raise --max-grasps or widen the grid"
    if robot_name is not None:
        all_runs = ik_runs(store, idtabletop=tt)
        runs = [r for r in all_runs if r["robot"] == robot_name]
        if runs and max(r["feasible_all"] for r in runs) == 0:
            # a robot stored again with another base or mount gets the name NAME-DIGEST8 (`store.robots.put_robot`)
            base = re.sub(r"-[0-9a-f]{8}$", "", robot_name)
            other = {r["robot"]: r["feasible_all"] for r in all_runs if r["feasible_all"] > 0 and r["robot"] != robot_name
                     and (r["robot"] == base or r["robot"].startswith(f"{base}-"))}
            hint = "".join(f"; robot {k} (the same name with another model, base or mount) reaches {v:,}: plan with "
                           f"--robot {k}" for k, v in sorted(other.items())[:2])
            return (f"ik: no tabletop grip is reachable by {robot_name} with its retractions; move the grid (--x, --y) "
                    f"toward the robot{hint}")
    return None


def grasp_reason(store: Store, object_name: str, gripper: Gripper, params: GraspParams) -> str | None:
    """Why the stored grasp set of these parameters is empty (re-planned: the store keeps rows, not the filters)."""
    _, obj = get_object(store, object_name)
    return plan_grasps(obj, gripper, params).empty_reason


def load_plan(store: Store, idplan: int) -> Plan:
    """A stored plan (either planner's) rebuilt from its `plan`, `planstep`, `plansegment` and `planobstacle` rows,
    with its timed motions (knot times from the plan's start), the grasps as TCP in the object frame, and a task's
    held ends, lifts, insertion and obstacles."""
    row, steps = sql.load_plan_rows(store, idplan)
    seg = sql.load_plan_segments(store, idplan).to_pydict()
    nq = len(robot_row(store, int(row["idrobot"]))["joint_names"])
    ret = ikret_row(store, int(row["idikret"]))
    s = steps.to_pydict()
    out = []
    for i in range(len(s["seq"])):
        obj_pose = np.asarray(s["object"][i], dtype=np.float64).reshape(4, 4)
        tcp = np.asarray(s["tcp"][i], dtype=np.float64).reshape(4, 4)
        q = {k: None if s[k][i] is None else np.asarray(s[k][i], dtype=np.float64)
             for k in ("jnt_approach", "jnt_grasp", "jnt_retract", "jnt_worlda", "jnt_worldaworldz")}
        out.append(PlanStep(kind=s["kind"][i], idfreeairgrip=int(s["idfreeairgrip"][i]),
                            idfreetabletopplacement=int(s["idfreetabletopplacement"][i]),
                            position=np.asarray(s["position"][i], dtype=np.float64), yaw=float(s["yaw"][i]), object_pose=obj_pose,
                            tcp=tcp, grasp=np.linalg.inv(obj_pose) @ tcp, jawwidth=float(s["jawwidth"][i]),
                            q_approach=q["jnt_approach"], q_grasp=q["jnt_grasp"], q_retract=q["jnt_retract"],
                            idtabletopgrips=s["idtabletopgrips"][i], q_worlda=q["jnt_worlda"], q_worldaworldz=q["jnt_worldaworldz"],
                            lift=None if s.get("lift", [None] * (i + 1))[i] is None else np.asarray(s["lift"][i], dtype=np.float64)))
    segments = []
    for k in range(len(seg["seq"])):
        t = np.asarray(seg["t"][k], dtype=np.float64)
        traj = Trajectory(t - float(seg["t0"][k]), np.asarray(seg["q"][k], dtype=np.float64).reshape(len(t), nq),
                          np.asarray(seg["qd"][k], dtype=np.float64).reshape(len(t), nq))
        segments.append(TimedSegment(seg["kind"][k], seg["caption"][k], int(seg["step"][k]), bool(seg["holding"][k]),
                                     float(seg["t0"][k]), traj, seg["method"][k] or "", float(seg["jaw"][k] or 0.0)))
    query = lambda p, xyyaw: PoseQuery(int(p), *map(float, xyyaw))  # noqa: E731
    ids = {k: int(row[k]) for k in ("idobject", "idrobot", "idscene", "idikret", "idtabletop") if row.get(k) is not None}
    return Plan(object=object_name(store, int(row["idobject"])), robot=robot_row(store, int(row["idrobot"]))["name"],
                joint_names=list(robot_row(store, int(row["idrobot"]))["joint_names"]),
                start=query(row["start_placement"], row["start_xyyaw"]), goal=query(row["goal_placement"], row["goal_xyyaw"]),
                start_pose=out[0].object_pose.copy(), goal_pose=out[-1].object_pose.copy(), steps=out, handx=ret["handx"],
                worldz=ret["worldz"], worlda=ret["worlda"], rank=int(row["rank"] or 0), ids=ids, segments=segments,
                removed=int(row.get("removed") or 0), acc=list(row.get("acc") or []),
                speed=float(row.get("speed") or 1.0), planner=row.get("planner") or "wan_harada",
                start_held=bool(row.get("start_held") or False), end_held=bool(row.get("end_held") or False),
                obstacles=[PlanObstacle(**o) for o in sql.load_plan_obstacles(store, idplan)],
                insertion=None if row.get("insertion") is None else np.asarray(row["insertion"], dtype=np.float64),
                insertion_depth=float(row.get("insertion_depth") or 0.0))


def stored_robot(store: Store, idrobot: int, gripper: Gripper | None = None) -> Robot:
    """The library robot of a stored robot row, with its planning gripper (default: the Franka hand)."""
    return _robot_from_row(robot_row(store, int(idrobot)), gripper)


def grippers_in_store(db: str | Path) -> list[dict]:
    """The grippers with grasps or robots in store `db` (name, digest, objects, robots), none when it does not exist yet."""
    if not Path(db).is_file():
        return []
    with Store(db, read_only=True) as store:
        return stored_grippers(store)


def robot_name_for(db: str | Path, robot: str, gripper: Gripper) -> str:
    """The stored name of robot `robot` built with `gripper` (NAME, or NAME-DIGEST when another gripper took the name
    first); `robot` itself when the store has none (loading then says what is missing)."""
    if not Path(db).is_file():
        return robot
    with Store(db, read_only=True) as store:
        return robot_with_gripper(store, robot, gripper.digest) or robot
