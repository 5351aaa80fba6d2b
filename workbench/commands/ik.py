"""`workbench ik`: IK feasibility of every tabletop grip of an object for a robot (Wan & Harada Section IV).

`run_ik` is the stage runner used by the command, the notebook and `workbench build`: it loads the tabletop
grips, writes the robot, scene and ikret rows in one transaction, then computes and writes the `ik` rows chunk
by chunk (each chunk in its own transaction), skipping chunks already stored, so an interrupted run resumes and a
re-run with the same inputs computes nothing.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from ..errors import RobotError
from ..kinematics import Collider, IKOptions, Scene, default_scene, iter_ik
from ..robots import ROBOTS, Robot, get_robot, pose_xyz_yaw

HANDX = 0.05
WORLDZ = 0.10


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

    @property
    def reused(self) -> bool:
        return self.computed == 0


def scene_params(robot: Robot, scene: Scene, opts: IKOptions) -> dict:
    """Everything besides the robot row and the grips that changes the `ik` rows (stored in `scene.params`)."""
    return {**scene.as_dict(), "ik": opts.as_dict(),
            "robot": {"locked": {k: v for k, v in robot.spec.locked}, "drop_geometry": list(robot.spec.drop_geometry),
                      "gripper": robot.gripper.name}}


def run_ik(store, obj_name: str, robot: Robot, scene: Scene | None = None, handx: float = HANDX, worldz: float = WORLDZ,
           opts: IKOptions = IKOptions(), workers: int | None = None, progress: bool = True,
           idtabletop: int | None = None) -> IKRun:
    """Compute (or reuse) the `ik` rows of every tabletop grip of `obj_name` for `robot` (Section IV)."""
    from ..store import robots as sql
    from ..store.objects import get_object
    from ..store.placements import load_tabletop_grips

    t0 = time.perf_counter()
    scene = scene or default_scene(robot.name)
    hit = Collider(robot, scene, None).fixed_parts_hit_table()
    if hit:
        raise RobotError(f"the fixed links ({', '.join(hit[:3])}) of robot {robot.name!r} cut into the table; move its base "
                         f"(--base) or the table (--table)")
    oid, obj = get_object(store, obj_name)
    grips = load_tabletop_grips(store, oid, idtabletop)
    pid = int(np.asarray(grips["idparamset"])) if "idparamset" in grips else int(idtabletop if idtabletop is not None else -1)
    ids = np.asarray(grips["idtabletopgrips"], dtype=np.int64)
    rid, sid, kid = sql.prepare_run(store, robot, scene_params(robot, scene, opts), handx, worldz)
    done = sql.stored_grips(store, rid, sid, kid)

    def skip(ix: np.ndarray) -> bool:
        return bool(np.isin(ids[ix], done, assume_unique=True).all())

    computed = 0
    arrays = {k: v for k, v in grips.items() if isinstance(v, np.ndarray) and v.shape[:1] == ids.shape}
    for ix, feas, joints in iter_ik(robot, arrays, scene, handx, worldz, obj.mesh, opts, workers, skip=skip, progress=progress):
        todo = ~np.isin(ids[ix], done)
        computed += sql.insert_ik(store, rid, sid, kid, ids[ix][todo], feas[todo], joints[todo])
    counts = sql.run_counts(store, rid, sid, kid, pid)
    return IKRun(rid, sid, kid, pid, len(ids), computed, counts[0], counts[1], time.perf_counter() - t0)


def ensure_ik(store, idobject: int, obj, idtabletop: int, robot_name: str, handx: float = HANDX, worldz: float = WORLDZ,
              workers: int | None = None, progress: bool = True) -> IKRun:
    """`run_ik` for a built-in robot (or URDF path) by name, with the signature `workbench build` expects."""
    return run_ik(store, obj.name, get_robot(robot_name), None, handx, worldz, IKOptions(), workers, progress, idtabletop)


def _floats(text: str, n: int, label: str) -> list[float]:
    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError:
        raise RobotError(f"{label} must be {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n or not np.isfinite(vals).all():
        raise RobotError(f"{label} must be {n} comma-separated finite numbers, got {text!r}")
    return vals


def _mount(text: str) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, roll, pitch, yaw = _floats(text, 6, "--mount (x,y,z,roll,pitch,yaw in m and rad)")
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", [roll, pitch, yaw]).as_matrix()
    out[:3, 3] = (x, y, z)
    return out


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ik", help="IK feasibility of every tabletop grip for a robot (paper Section IV: ik, ikret)")
    p.add_argument("--db", required=True, help="DuckDB store file")
    p.add_argument("--object", required=True, help="object name in the store")
    p.add_argument("--robot", required=True, help=f"one of {', '.join(ROBOTS)}, or the path of a URDF (then --tip)")
    p.add_argument("--base", help="robot base in the world: X,Y,Z,YAW (m, rad); default per robot")
    p.add_argument("--tip", help="the arm's tip frame (required for a URDF path)")
    p.add_argument("--mount", help="tip frame to gripper TCP: x,y,z,roll,pitch,yaw (m, rad); default per robot")
    p.add_argument("--table", help="table top corners in the world: XMIN,YMIN,XMAX,YMAX (m); default per robot")
    p.add_argument("--table-thickness", type=float, default=None, help="table slab thickness (m)")
    p.add_argument("--handx", type=float, default=HANDX, help=f"retraction along the hand (m, default {HANDX})")
    p.add_argument("--worldz", type=float, default=WORLDZ, help=f"then up along world z (m, default {WORLDZ})")
    p.add_argument("--tabletop", type=int, default=None, help="tabletop parameter set id (default: the latest)")
    p.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    from ..store import Store

    base = pose_xyz_yaw(*_floats(args.base, 4, "--base (X,Y,Z,YAW)")) if args.base else None
    mount = _mount(args.mount) if args.mount else None
    robot = get_robot(args.robot, base=base, tip_frame=args.tip, mount=mount)
    scene = default_scene(robot.name)
    if args.table or args.table_thickness is not None:
        t = _floats(args.table, 4, "--table (XMIN,YMIN,XMAX,YMAX)") if args.table else [*scene.table_min, *scene.table_max]
        scene = Scene(table_min=(t[0], t[1]), table_max=(t[2], t[3]),
                      table_thickness=scene.table_thickness if args.table_thickness is None else args.table_thickness,
                      workspace_min=scene.workspace_min, workspace_max=scene.workspace_max)
    with Store(args.db) as store:
        run = run_ik(store, args.object, robot, scene, args.handx, args.worldz, IKOptions(), args.workers,
                     progress=not args.no_progress, idtabletop=args.tabletop)
    what = "reused" if run.reused else f"computed {run.computed:,}"
    print(f"ik {robot.name}: {run.grips:,} tabletop grips ({what}); feasible grasp {run.feasible:,}, "
          f"with retractions {run.feasible_all:,}; robot {run.idrobot}, scene {run.idscene}, ikret {run.idikret}; "
          f"{run.seconds:.1f} s")
    return 0
