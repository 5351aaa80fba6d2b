"""Units of work of a catalogue, run on Dask workers: pure functions from inputs to Arrow tables.

- `part_unit`: load a mesh, plan free-air grasps (Wan & Harada Section III), stable placements, free tabletop
  grips and the tabletop grid (Section IV); returns the result dataclasses as Arrow tables (`part_tables`).
- `ik_unit`: IK feasibility with retractions of one chunk of a part's tabletop grips for a robot (Section IV's
  ik table); the chunk is a slice of the grips in `neighbour_order`, so its rows equal those of a serial run.
- `graph_unit`: the size and connected components of the regrasp graph (Section V) from the grips and their IK.

Workers never touch the store. The IK solver (robot, seed library, collision models) is built once per worker
process and kept in an explicit `SolverCache` keyed on a digest of every input.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, fields

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import trimesh

from workbench.geometry.objects import ObjectModel, load_object
from workbench.grasping.grasps import GraspParams, GraspSet, plan_grasps, table_friction_hint
from workbench.grasping.placements import (
    PlacementParams,
    Placements,
    empty_placement_stage,
    free_tabletop_grips,
    stable_placements,
)
from workbench.planners.wan_harada.roadmap import build_roadmap
from workbench.planners.wan_harada.tabletop import (
    Tabletop,
    TabletopParams,
    plan_tabletop,
)
from workbench.robots.collider import Scene
from workbench.robots.gripper import Gripper, franka_hand
from workbench.robots.ik import IKOptions, IKSolver, check_poses, retract
from workbench.robots.model import RobotSpec, robot_from_spec

SHAPE_KEY = b"shape"


# ----------------------------------------------------------------------------------------------------------------
# numpy <-> Arrow: (N, ...) arrays become fixed-size list columns carrying their row shape in the field metadata.


def arrays_table(columns: dict[str, np.ndarray]) -> pa.Table:
    """An Arrow table of equal-length numpy columns; (N, a, b, ...) arrays keep their row shape."""
    arrays, names, fields_ = [], [], []
    for name, value in columns.items():
        arr = np.asarray(value)
        if arr.ndim == 1:
            col = pa.array(arr)
            meta = None
        else:
            flat = np.ascontiguousarray(arr.reshape(len(arr), int(np.prod(arr.shape[1:]))))
            col = pa.FixedSizeListArray.from_arrays(pa.array(flat.ravel()), flat.shape[1])
            meta = {SHAPE_KEY: json.dumps(list(arr.shape[1:])).encode()}
        arrays.append(col)
        names.append(name)
        fields_.append(pa.field(name, col.type, metadata=meta))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields_))


def table_arrays(table: pa.Table) -> dict[str, np.ndarray]:
    """The inverse of `arrays_table`."""
    out = {}
    for field in table.schema:
        col = table.column(field.name).combine_chunks()
        if field.metadata and SHAPE_KEY in field.metadata:
            shape = json.loads(field.metadata[SHAPE_KEY])
            out[field.name] = col.flatten().to_numpy(zero_copy_only=False).reshape(len(col), *shape)
        else:
            out[field.name] = col.to_numpy(zero_copy_only=False)
    return out


def _ragged(points: list[np.ndarray]) -> pa.Array:
    """(k_i, 3) arrays as a list<double> column of flattened rows."""
    return pa.array([np.asarray(p, dtype=np.float64).ravel() for p in points], type=pa.list_(pa.float64()))


# ----------------------------------------------------------------------------------------------------------------
# The part unit.


@dataclass
class PartResult:
    """A part's stages as the result dataclasses (what the driver hands to the store's stage writers)."""

    obj: ObjectModel
    grasps: GraspSet
    placements: Placements
    ftg: tuple[np.ndarray, np.ndarray, np.ndarray]
    tabletop: Tabletop
    seconds: dict
    reason: str | None = None  # when a stage kept nothing: "stage: why; what to try" (as `workbench build` says)


def part_stages(obj: ObjectModel, gparams: GraspParams, pparams: PlacementParams, tparams: TabletopParams,
                hand: Gripper | None = None) -> PartResult:
    """Grasps (Section III), stable placements, free tabletop grips and the tabletop grid (Section IV) of one part;
    the grasps carried into the roadmap are chosen as `workbench build` chooses them."""
    hand = hand or franka_hand()
    t0 = time.perf_counter()
    plan = plan_grasps(obj, hand, gparams)
    grasps = plan.grasps
    t1 = time.perf_counter()
    placements = stable_placements(obj, pparams)
    p_idx, g_idx, poses = free_tabletop_grips(placements, grasps.poses, hand, pparams)
    reason = plan.empty_reason or empty_placement_stage(
        obj, pparams, placements.poses, len(p_idx),
        lambda: table_friction_hint(obj, hand, gparams, placements.poses, pparams.clearance), grasps.poses, hand)
    t2 = time.perf_counter()
    tt = plan_tabletop(placements.poses, p_idx, g_idx, poses, grasps.poses, tparams)
    t3 = time.perf_counter()
    return PartResult(obj, grasps, placements, (p_idx, g_idx, poses), tt,
                      {"grasps": t1 - t0, "placements": t2 - t1, "tabletop": t3 - t2}, reason)


def part_unit(path: str, name: str, scale: float | None, units: str | None, gparams: GraspParams,
              pparams: PlacementParams, tparams: TabletopParams, hand: Gripper | None = None) -> dict[str, pa.Table]:
    """The worker's task for one part: `part_stages` of the mesh at `path` with `hand` (default the Franka hand),
    returned as Arrow tables."""
    t0, c0 = time.perf_counter(), time.thread_time()
    obj = load_object(path, scale=scale, units=units, name=name)
    res = part_stages(obj, gparams, pparams, tparams, hand or worker_state().hand())
    res.seconds["load"] = time.perf_counter() - t0 - sum(res.seconds.values())
    tables = part_tables(res)
    tables["meta"] = stamp(tables["meta"], t0, c0)
    return tables


def part_tables(res: PartResult) -> dict[str, pa.Table]:
    """A `PartResult` as Arrow tables: object (1 row), grasps, placements, ftg, tabletop placements and grips, meta."""
    o = res.obj
    obj = pa.table({"name": [o.name], "source": [o.source], "digest": [o.digest], "scale": [float(o.scale)],
                    "com_method": [o.com_method], "reason": pa.array([res.reason], type=pa.string())})
    pl = res.placements
    place = arrays_table({"poses": pl.poses, "stability": pl.stability, "normals": pl.normals,
                          "probability": pl.probability, "rocking": pl.rocking})
    place = place.append_column("supports", _ragged(pl.supports))
    tt = res.tabletop
    return {
        "object": obj,
        "mesh_vertices": arrays_table({"v": np.asarray(o.mesh.vertices, dtype=np.float64)}),
        "mesh_faces": arrays_table({"f": np.asarray(o.mesh.faces, dtype=np.int64)}),
        "com": arrays_table({"com": np.asarray(o.com, dtype=np.float64)[None]}),
        "grasps": arrays_table({f.name: getattr(res.grasps, f.name) for f in fields(GraspSet)}),
        "placements": place,
        "ftg": arrays_table({"placement": res.ftg[0], "grasp": res.ftg[1], "poses": res.ftg[2]}),
        "tabletop_placements": arrays_table({"placement": tt.placement, "angle": tt.angle, "position": tt.position,
                                             "poses": tt.poses, "moves": tt.moves}),
        "tabletop_grips": arrays_table({"grip_tp": tt.grip_tp, "grip_ftg": tt.grip_ftg, "grip_poses": tt.grip_poses}),
        "meta": pa.table({"stage": list(res.seconds), "seconds": list(res.seconds.values()),
                          "worker": [worker_name()] * len(res.seconds)}),
    }


def part_from_tables(tables: dict[str, pa.Table]) -> PartResult:
    """The inverse of `part_tables` (on the driver)."""
    o = tables["object"].to_pylist()[0]
    mesh = trimesh.Trimesh(table_arrays(tables["mesh_vertices"])["v"], table_arrays(tables["mesh_faces"])["f"], process=False)
    obj = ObjectModel(name=o["name"], mesh=mesh, com=table_arrays(tables["com"])["com"][0], com_method=o["com_method"],
                      scale=o["scale"], source=o["source"], digest=o["digest"])
    g = table_arrays(tables["grasps"])
    p = table_arrays(tables["placements"].drop_columns(["supports"]))
    supports = [np.asarray(s, dtype=np.float64).reshape(-1, 3) for s in tables["placements"].column("supports").to_pylist()]
    placements = Placements(poses=p["poses"], stability=p["stability"], supports=supports, normals=p["normals"],
                            rejected_poses=np.zeros((0, 4, 4)), rejected_stability=np.zeros(0),
                            probability=p["probability"], rocking=p["rocking"])
    f = table_arrays(tables["ftg"])
    tp, tg = table_arrays(tables["tabletop_placements"]), table_arrays(tables["tabletop_grips"])
    tt = Tabletop(placement=tp["placement"], angle=tp["angle"], position=tp["position"], poses=tp["poses"], moves=tp["moves"],
                  grip_tp=tg["grip_tp"], grip_ftg=tg["grip_ftg"], grip_poses=tg["grip_poses"])
    meta = tables["meta"].to_pydict()
    return PartResult(obj, GraspSet(**g), placements, (f["placement"], f["grasp"], f["poses"]), tt,
                      dict(zip(meta["stage"], meta["seconds"])), o.get("reason"))


# ----------------------------------------------------------------------------------------------------------------
# The IK unit.


class SolverCache:
    """IK solvers of one worker process keyed on (robot digest, scene, options, mesh digest); keeps the latest few.
    The robot's part of a solver (seed library, self-collision model, reachability filter: most of its build time)
    is built once per (robot, scene, options) and shared by the solvers of every object (`IKSolver.for_object`)."""

    def __init__(self, size: int = 4):
        self.size = size
        self.solvers: dict[tuple, IKSolver] = {}
        self.robots: dict[tuple, IKSolver] = {}

    def get(self, spec: RobotSpec, scene: Scene, opts: IKOptions, mesh_digest: str, mesh: trimesh.Trimesh | None) -> IKSolver:
        key = (spec.digest, scene, opts, mesh_digest)
        if key not in self.solvers:
            if len(self.solvers) >= self.size:
                self.solvers.pop(next(iter(self.solvers)))
            base = self.robots.get(key[:3])
            if base is None:
                base = self.robots[key[:3]] = IKSolver(robot_from_spec(spec), scene, opts, mesh)
                self.solvers[key] = base
            else:
                self.solvers[key] = base.for_object(mesh)
        return self.solvers[key]


class WorkerState:
    """What a worker process keeps between units: the Franka hand (loading its URDF and meshes takes a second or
    two) and the IK solvers."""

    def __init__(self) -> None:
        self.solvers = SolverCache()
        self._hand: Gripper | None = None

    def hand(self) -> Gripper:
        if self._hand is None:
            self._hand = franka_hand()
        return self._hand


def worker_state() -> WorkerState:
    """The `WorkerState` of this Dask worker (created on first use), or a fresh one outside a worker."""
    try:
        from distributed import get_worker

        w = get_worker()
    except ValueError:
        return WorkerState()
    state = getattr(w, "workbench_state", None)
    if state is None:
        state = w.workbench_state = WorkerState()
    return state


def warm_worker() -> str:
    """Import the units' modules and build the worker's Franka hand before the first unit (run on every worker when a
    cluster starts, so a build's timed region holds no start-up); returns the worker's name."""
    worker_state().hand()
    return worker_name()


def stamp(table: pa.Table, t0: float, c0: float, **extra: object) -> pa.Table:
    """`table` with the unit's timings in its schema metadata: seconds (wall), cpu (CPU seconds of the thread that ran it),
    start and end (epoch seconds, for the workers' timeline) and the worker's name."""
    meta = {b"seconds": str(time.perf_counter() - t0), b"cpu": str(time.thread_time() - c0), b"end": str(time.time()),
            b"worker": worker_name(), **{k.encode(): str(v) for k, v in extra.items()}}
    meta[b"start"] = str(float(meta[b"end"]) - float(meta[b"seconds"]))
    return table.replace_schema_metadata({k: v.encode() for k, v in meta.items()})


def worker_name() -> str:
    """This process's Dask worker address and pid (or "local pid N" outside a worker), for failure reports."""
    try:
        from distributed import get_worker

        return f"{get_worker().address} pid {os.getpid()}"
    except ValueError:
        return f"local pid {os.getpid()}"


def ik_unit(spec: RobotSpec, scene: Scene, opts: IKOptions, handx: float, worldz: float, worlda: float,
            mesh_digest: str, vertices: np.ndarray, faces: np.ndarray, grip_ids: np.ndarray, poses: np.ndarray,
            placements: np.ndarray, cache: SolverCache | None = None, shard: str | None = None) -> pa.Table:
    """IK feasibility of one chunk of tabletop grips (given in `neighbour_order`) at the five poses of
    `robots.ik.KINDS` (grasp, handx, handxworldz, worlda, worldaworldz): a table of idtabletopgrips, feasible (C, 5)
    and joints (C, 5, nq), NaN where infeasible.

    With `shard` (a Parquet path), the table is written there instead (to a temporary name first, then renamed: the
    file exists whole or not at all) and the returned table holds its counts only: the rows never travel through the
    scheduler and the driver."""
    t0, c0 = time.perf_counter(), time.thread_time()
    mesh = trimesh.Trimesh(vertices, faces, process=False) if opts.collide else None
    solver = (cache or worker_state().solvers).get(spec, scene, opts, mesh_digest, mesh)
    feas, joints = solver.chunk(retract(poses, handx, worldz, worlda), placements)
    table = arrays_table({"idtabletopgrips": np.asarray(grip_ids, dtype=np.int64), "feasible": feas, "joints": joints})
    if shard is None:
        return stamp(table, t0, c0)
    write_shard(table, shard)
    counts = pa.table({"grips": [len(feas)], "feasible": [int(feas[:, 0].sum())], "feasible_all": [int(feas.all(axis=1).sum())]})
    return stamp(counts, t0, c0, shard=shard)


def ik_unit_files(spec: RobotSpec, scene: Scene, opts: IKOptions, handx: float, worldz: float, worlda: float,
                  folder: str, chunk: int, shard: str) -> pa.Table:
    """`ik_unit` of row group `chunk` of a part folder's grips in IK order (`ik_grips.parquet`, written by the part
    unit), the part's mesh from its `object.parquet`: the worker reads what it needs, not the store or the driver."""
    grips = table_arrays(pq.ParquetFile(f"{folder}/ik_grips.parquet").read_row_group(chunk))
    obj = pq.read_table(f"{folder}/object.parquet", columns=["digest", "vertices", "faces"])
    verts = obj.column("vertices").combine_chunks().flatten().flatten().to_numpy(zero_copy_only=False).reshape(-1, 3)
    faces = obj.column("faces").combine_chunks().flatten().flatten().to_numpy(zero_copy_only=False).reshape(-1, 3)
    return ik_unit(spec, scene, opts, handx, worldz, worlda, obj.column("digest")[0].as_py(), verts.astype(np.float64),
                   faces.astype(np.int64), grips["idtabletopgrips"], check_poses(grips["rotmat"]),
                   check_poses(grips["placement_rotmat"], "object placement"), shard=shard)


def write_shard(table: pa.Table, path: str) -> None:
    """Write a unit's table to the Parquet file `path` atomically (a killed writer leaves only a `.tmp` file)."""
    tmp = f"{path}.{os.getpid()}.tmp"
    pq.write_table(table, tmp, compression="none")
    os.replace(tmp, path)


def graph_unit(rows: dict[str, np.ndarray], feasible: np.ndarray) -> pa.Table:
    """The regrasp graph's sizes (Section V): grips, nodes, transfer and transit edges, grasps, placements,
    components, largest component; one row."""
    t0, c0 = time.perf_counter(), time.thread_time()
    s = build_roadmap(rows, feasible).summary()
    return stamp(pa.table({k: [int(v)] for k, v in s.items()}), t0, c0)
