"""Stages of the grasp-placement table planner against the store (the only module of the planner that imports
`workbench.store`). Tournassoud, Lozano-Perez & Mazer (1987), Sections 2-6.

- `classes_stage`: grasp classes of an object for a gripper and parameters (stage `tournassoud.classes`);
- `table_stage`: placement classes and the table Q_ij for a robot and table parameters (stage `tournassoud.table`);
- `load_planner`: a stored table with its classes, object and robot, ready for queries;
- `save_plan`: a plan of this planner in the store's `plan` / `planstep` tables (`plan.planner` = 'tournassoud'),
  with the `freetabletopplacement` and `freeairgrip` rows its steps reference; `stored_validator` checks it
  with the independent validator rebuilt from those rows.

Each stage computes outside any transaction and writes in one; a re-run with the same inputs and parameters loads
the stored rows (keyed by the parameter-set digest) instead of computing again.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import numpy as np

from workbench.errors import WorkbenchError
from workbench.geometry.objects import ObjectModel
from workbench.grasping.placements import PlacementParams, stable_placements
from workbench.planners.tournassoud.classes import (
    ClassParams,
    GraspClass,
    grasp_classes,
)
from workbench.planners.tournassoud.table import (
    GraspPlacementTable,
    TableParams,
    build_table,
    grid,
    table_frame,
)
from workbench.planners.wan_harada.motions import DEFAULT_ACC
from workbench.planners.wan_harada.plans import Plan, obstacle_rows, plan_rows
from workbench.planners.wan_harada.stages import get_object, load_plan, scene_params
from workbench.robots.collider import Scene
from workbench.robots.gripper import Gripper, franka_hand
from workbench.robots.ik import IKOptions
from workbench.robots.model import Robot, RobotSpec, get_robot, robot_from_spec
from workbench.robots.selfcollision import allowed_pairs
from workbench.store import Store
from workbench.store import tournassoud as sql
from workbench.store import wan_harada as plan_sql
from workbench.store.objects import gripper_row, object_row, put_gripper, put_object
from workbench.store.robots import (
    StoredScene,
    put_ikret,
    put_robot,
    put_scene,
    robot_row,
    scene_row,
)
from workbench.validation import (
    PlanValidator,
    TrajectoryValidator,
    ValidationReport,
    trajectory_validator_from_rows,
    validator_from_rows,
)

CLASSES = "tournassoud.classes"
TABLE = "tournassoud.table"


@dataclass
class TableRun:
    """A built or loaded table with everything needed to answer queries."""

    obj: ObjectModel
    robot: Robot
    gripper: Gripper
    classes: list[GraspClass]
    table: GraspPlacementTable
    idclasses: int
    idtable: int
    reused: tuple[bool, bool]
    seconds: float = 0.0
    narrow: tuple[int, float] = (0, 0.0)  # classes dropped as narrower than `min_range`, the widest of them (rad)


def classes_stage(store: Store, obj: ObjectModel, gripper: Gripper, params: ClassParams,
                  progress: bool = False) -> tuple[int, list[GraspClass], bool]:
    """Grasp classes of `obj` (Sections 2, 5.1): (paramset, classes, reused from the store). Classes dropped as
    narrower than `params.min_range` are stored apart (`sql.dropped_classes` counts them)."""
    sql.ensure_schema(store)
    idobject = put_object(store, obj)
    key = {"classes": params.as_dict(), "gripper": gripper.digest}
    pid = store.find_paramset(CLASSES, key, idobject)
    if pid is not None:
        return pid, [GraspClass(**d) for d in sql.load_classes(store, pid)], True
    dropped: list[GraspClass] = []
    classes = grasp_classes(obj, gripper, params, progress=progress, dropped=dropped)
    return sql.save_classes(store, CLASSES, key, idobject, classes, dropped), classes, False


def _table_key(idclasses: int, robot: Robot, params: TableParams, placement: PlacementParams) -> dict:
    tp = params.as_dict()
    tp.pop("chunk", None)
    return {"classes": idclasses, "robot": robot.spec.digest, "table": tp, "placements": placement.as_dict()}


def table_stage(store: Store, obj: ObjectModel, robot: Robot, gripper: Gripper | None = None,
                class_params: ClassParams = ClassParams(), params: TableParams = TableParams(),
                placement: PlacementParams = PlacementParams(), progress: bool = False) -> TableRun:
    """Classes, placement classes and the grasp-placement table (Sections 2-5), stored or reused."""
    t0 = time.perf_counter()
    gripper = gripper or robot.gripper or franka_hand()
    idc, classes, reused_c = classes_stage(store, obj, gripper, class_params, progress)
    idobject = put_object(store, obj)
    put_gripper(store, gripper)
    with store.transaction():
        idrobot = put_robot(store, robot)
    key = _table_key(idc, robot, params, placement)
    pid = store.find_paramset(TABLE, key, idobject)
    narrow = sql.dropped_classes(store, idc)
    if pid is not None:
        return TableRun(obj, robot, gripper, classes, _table_from_rows(sql.load_table(store, pid)), idc, pid,
                        (reused_c, True), time.perf_counter() - t0, narrow)
    pl = stable_placements(obj, placement)
    table = build_table(classes, pl.poses, robot, gripper, params, progress=progress)
    pid = sql.save_table(store, TABLE, key, idobject, idrobot, idc, table, pl.normals, pl.stability)
    return TableRun(obj, robot, gripper, classes, table, idc, pid, (reused_c, False), time.perf_counter() - t0, narrow)


def table_stage_at(db: str, obj: ObjectModel, robot: Robot, class_params: ClassParams = ClassParams(),
                   params: TableParams = TableParams(), placement: PlacementParams = PlacementParams(),
                   progress: bool = False) -> TableRun:
    """`table_stage` on the store file `db` (opened and closed here), with the robot's planning gripper."""
    with Store(db) as store:
        return table_stage(store, obj, robot, robot.gripper, class_params, params, placement, progress)


def _table_from_rows(rows: dict) -> GraspPlacementTable:
    return GraspPlacementTable(theta=grid(2 * np.pi / rows["ntheta"]), phi=grid(2 * np.pi / rows["nphi"]),
                               hand_object=rows["hand_object"], hand_table=rows["hand_table"], q=rows["q"],
                               placements=rows["placements"], frame=table_frame(rows["table_point"]), timings=rows["timings"])


def load_planner(db: str, object_name: str, robot_name: str | None = None, gripper: Gripper | None = None,
                 idtable: int | None = None) -> TableRun:
    """The newest stored table of `object_name` (and robot), or the table of paramset `idtable`, its classes,
    object and robot rebuilt from the store with the planning `gripper` it was built with (default: the Franka
    hand)."""
    with Store(db, read_only=True) as store:
        idobject, obj = get_object(store, object_name)
        idrobot = None
        if robot_name is not None:
            idrobot = robot_row(store, robot_name)["idrobot"]
        pid = sql.latest_table(store, idobject, idrobot) if idtable is None else int(idtable)
        rows = sql.load_table(store, pid)
        classes = [GraspClass(**d) for d in sql.load_classes(store, rows["idclasses"])]
        r = robot_row(store, rows["idrobot"])
        r["gripper_name"] = gripper_row(store, r["idgripper"])["name"] if r["idgripper"] is not None else None
    robot = _robot(r, gripper)
    return TableRun(obj, robot, robot.gripper, classes, _table_from_rows(rows), rows["idclasses"], pid, (True, True))


def _robot(row: dict, gripper: Gripper | None = None) -> Robot:
    """The stored robot rebuilt: the built-in of that name when its kinematics digest matches, else from the row."""
    name = row["name"]
    try:
        robot = get_robot(name, gripper=gripper)
        if robot.spec.digest == row["digest"]:
            return robot
    except WorkbenchError:
        pass
    spec = RobotSpec(name=name, urdf=row["urdf"], urdf_path="", tip_frame=row["tip_frame"], tcp_frame=row["tcp_frame"],
                     mount=row["mount"], base=row["base"], drop_geometry=tuple(row["drop_geometry"]),
                     locked=tuple((k, float(v)) for k, v in row["locked"].items()), gripper=gripper)
    robot = robot_from_spec(spec)
    if robot.spec.digest != row["digest"]:
        built = f" ({row['gripper_name']})" if row.get("gripper_name") else ""
        raise WorkbenchError(f"robot {name!r} in the store was built with another gripper{built} than "
                             f"{robot.gripper.name!r}; give gpplan the --gripper it was built with")
    return robot


def plan_validator(db: str, run: TableRun, scene: Scene) -> PlanValidator:
    """The independent plan validator rebuilt from the store's rows of this table (robot, object, gripper) and the
    scene's table; the placement classes are the stable placements it checks start and goal poses against."""
    return _validators(db, run, None, scene=scene)[0]


def _grasp_columns(run: TableRun, plan: Plan) -> dict[str, np.ndarray]:
    """The free-air grasp columns of a plan's steps (class from the step's table-local id class * T + theta sample,
    theta read off the step's grasp pose)."""
    t_n = len(run.table.theta)
    cols: dict[str, list] = {k: [] for k in ("cls", "theta", "rotmat", "jawwidth", "contactpoint0", "contactpoint1",
                                             "contactnormal0", "contactnormal1")}
    for s in plan.steps:
        c = int(s.idfreeairgrip) // t_n
        g = run.classes[c]
        z = np.asarray(s.grasp)[:3, 2]
        cols["cls"].append(c)
        cols["theta"].append(float(np.mod(np.arctan2(z @ g.v, z @ g.u), 2 * np.pi)))
        cols["rotmat"].append(np.asarray(s.grasp, dtype=np.float64))
        cols["jawwidth"].append(g.opening)
        cols["contactpoint0"].append(g.point + g.opening / 2 * g.normal)
        cols["contactpoint1"].append(g.point - g.opening / 2 * g.normal)
        cols["contactnormal0"].append(g.normal)
        cols["contactnormal1"].append(-g.normal)
    return {k: np.asarray(v) for k, v in cols.items()}


def save_plan(db: str, run: TableRun, plan: Plan, scene: Scene, ik: IKOptions) -> tuple[int, Plan]:
    """Store a plan of this planner like the roadmap planner's (tables `plan`, `planstep`, `plansegment`; Section 6's
    sequence with its joint vectors), named `tournassoud`, in one transaction: the placements and grasps it uses
    become `freetabletopplacement` / `freeairgrip` rows. Returns (idplan, the plan with the store's ids); a plan
    answering the same query is not stored again."""
    with Store(db) as store:
        ids = sql.table_ids(store, run.idtable)
        stability = sql.placement_stability(store, run.idtable)
        with store.transaction():
            fp = sql.placement_rows(store, run.idtable, ids["idobject"], run.table.placements, stability)
            idgripper = sql.gripper_id(store, run.gripper.digest)
            fg = sql.grasp_rows(store, ids["idclasses"], ids["idobject"], idgripper, _grasp_columns(run, plan))
            stored = copy.deepcopy(plan)
            stored.planner = "tournassoud"
            for s, g in zip(stored.steps, fg):
                s.idfreeairgrip = int(g)
                s.idfreetabletopplacement = int(fp[s.idfreetabletopplacement])
            stored.start = replace(plan.start, idfreetabletopplacement=int(fp[plan.start.idfreetabletopplacement]))
            stored.goal = replace(plan.goal, idfreetabletopplacement=int(fp[plan.goal.idfreetabletopplacement]))
            put_robot(store, run.robot, allowed_pairs(run.robot).to_json())  # for the trajectory validator
            stored.ids = {"idobject": ids["idobject"], "idrobot": ids["idrobot"],
                          "idscene": put_scene(store, scene_params(run.robot, scene, ik)),
                          "idikret": put_ikret(store, plan.handx, plan.worldz, plan.worlda), "idtabletop": run.idtable}
            pid = plan_sql.save_plan(store, *plan_rows(stored), obstacle_rows(stored))
    return pid, stored


def load_stored(db: str, idplan: int) -> Plan:
    """A stored plan of this planner rebuilt from the store alone (`wan_harada.stages.load_plan`: its steps and
    lifts, timed motions, held ends, insertion and obstacles)."""
    with Store(db, read_only=True) as store:
        plan = load_plan(store, idplan)
    if plan.planner != "tournassoud":
        raise WorkbenchError(f"plan {idplan} in {db} was made by the {plan.planner} planner, not by `workbench gpplan`; "
                             f"use `workbench plan` or `workbench simulate` for it")
    return plan


def stored_scene(db: str, idplan: int) -> Scene:
    """The scene (table top, workspace) a stored plan was planned and checked in."""
    with Store(db, read_only=True) as store:
        return scene_row(store, sql.plan_scene(store, idplan)).scene


def stored_validator(db: str, run: TableRun, idplan: int) -> PlanValidator:
    """The independent plan validator rebuilt from the store's rows only (robot, object, gripper, the stored plan's
    scene) with this table's `freetabletopplacement` rows as its stable placements (ids as in a stored plan)."""
    return _validators(db, run, idplan)[0]


def _validators(db: str, run: TableRun, idplan: int | None, acc=None, obstacles: tuple = (),
                scene: Scene | None = None) -> tuple[PlanValidator, TrajectoryValidator | None]:
    """The validators of a stored plan (its scene, the table's `freetabletopplacement` rows), or with `idplan` None
    of a plan not stored (`scene`, the table's placement classes by index)."""
    with Store(db, read_only=True) as store:
        _, obj = object_row(store, run.obj.name)
        r = robot_row(store, sql.table_robot(store, run.idtable))
        g = gripper_row(store, sql.gripper_id(store, run.gripper.digest))
        if idplan is None:
            free = dict(enumerate(run.table.placements))
            stored = StoredScene(idscene=0, scene=scene, ik=IKOptions(), robot={})
        else:
            free = sql.stored_placements(store, run.idtable)
            stored = scene_row(store, sql.plan_scene(store, idplan))
    rows = {"robot": r, "object": obj, "gripper": g, "scene": stored}
    pv = validator_from_rows(rows, free_poses=free)
    return pv, (None if acc is None else trajectory_validator_from_rows(rows, pv, acc, obstacles))


def validate_stored(db: str, run: TableRun, idplan: int | None, plan: Plan, require_motion: bool = False,
                    obstacles: tuple | None = None, scene: Scene | None = None) -> ValidationReport:
    """A stored plan (with the store's ids, as `save_plan` returns it or `load_stored` reloads it) checked like the
    roadmap planner's plans (`wan_harada.planner.Planner.validate`): its waypoints, and its timed trajectory when it
    has one (required with `require_motion`), by the independent validators rebuilt from the store's rows, the
    trajectory also against the task's `obstacles` ((mesh, world pose) pairs; default the plan's own). With
    `idplan` None, a plan not stored (its table-local ids) in `scene`."""
    obstacles = plan.obstacle_pairs() if obstacles is None else obstacles
    acc = None
    if plan.segments:
        acc = np.broadcast_to(np.asarray(plan.acc or DEFAULT_ACC, dtype=np.float64), (len(plan.joint_names),))
    pv, tv = _validators(db, run, idplan, acc, obstacles, scene)
    report = pv.check(plan)
    if tv is not None:
        errors, knots = tv.check(plan, plan.segments)
        report = ValidationReport(report.ok and not errors, report.errors + errors, report.checks + knots)
    elif require_motion:
        report = ValidationReport(False, report.errors + ["the plan has no timed motions"], report.checks + 1)
    return report
