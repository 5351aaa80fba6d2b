"""The catalogue's store side: the only module of `workbench.catalog` that talks to the store.

The driver hands it finished units; each is written with the Wan & Harada stage writers of `workbench.store`
(object, free-air grasps, placements, free tabletop grips, tabletop placements and grips, `ik` rows) together with
its `catalog_unit` row in one transaction (`workbench.store.catalog`), so a unit is stored whole or not at all.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from workbench.catalog.units import (
    PartResult,
    arrays_table,
    graph_unit,
    part_stages,
    stamp,
    table_arrays,
    worker_state,
)
from workbench.errors import StoreError
from workbench.geometry.objects import ObjectModel, load_object
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import get_object, scene_params
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.collider import Scene
from workbench.robots.gripper import Gripper
from workbench.robots.ik import IKOptions, neighbour_order
from workbench.robots.model import Robot
from workbench.robots.selfcollision import allowed_pairs
from workbench.store import Store
from workbench.store import catalog as sql
from workbench.store.grasps import load_grasps, save_grasps
from workbench.store.objects import object_row, put_gripper, put_object
from workbench.store.placements import (
    find_placements,
    find_tabletop,
    load_free_tabletop_grips,
    load_placements,
    load_tabletop_grips,
    save_placements,
    save_tabletop,
)
from workbench.store.robots import prepare_run
from workbench.store.wan_harada import roadmap_rows

done_units = sql.done_units
unit_digests = sql.unit_digests
record_failure = sql.record_failure
summary = sql.summary
failures = sql.failures
unit_times = sql.unit_times
IK_GRIPS = "ik_grips.parquet"  # a part's tabletop grips in IK order (`neighbour_order`), one row group per IK unit
RECORD = "record.json"


FORMS = ("duckdb", "parquet")


def open_store(db: str | Path, read_only: bool = False, form: str = "duckdb") -> Store:
    """The catalogue's store (created with its `catalog_unit` table when new): a DuckDB file, or with `form`
    "parquet" a folder of Hive-partitioned Parquet files (see `workbench.store.catalog`); an existing folder is
    opened as the Parquet catalogue it is, whatever `form`."""
    if form not in FORMS:
        raise StoreError(f"a catalogue's form is {' or '.join(FORMS)}, got {form!r}")
    if not read_only and (form == "parquet" or Path(db).is_dir()):
        sql.create_dataset(Path(db))
    store = Store(db, read_only=read_only)
    if not read_only:
        sql.ensure_catalog_tables(store)
        if store.dataset is not None:
            sql.sweep_dataset(store)
        sql.single_thread(store)  # the driver shares the machine with the workers
    elif not sql.has_catalog(store):
        store.close()
        raise StoreError(f"store {db} holds no catalogue; build one with `workbench catalog build`")
    return store


@contextmanager
def batch(store: Store) -> Iterator[None]:
    """Several finished units in one transaction (each unit whole; they share the commit), which names the files it
    writes in a Parquet catalogue."""
    with sql.merge_batch(store):
        yield


def write_part(store: Store, unit: dict, res: PartResult, hand: Gripper, gparams: GraspParams, pparams: PlacementParams,
               tparams: TabletopParams) -> None:
    """A part unit's rows (Sections III-IV) and its catalog_unit row; fills the unit's ids, counts and the number of
    stage rows written (stages already stored with the same parameters, by `workbench build` say, are reused)."""
    tt = res.tabletop
    with sql.unit_transaction(store, unit):
        oid = put_object(store, res.obj)
        gid, had_grasps = save_grasps(store, oid, hand, gparams, res.grasps)
        grasps = load_grasps(store, oid, gid)
        had_placements = find_placements(store, oid, gid, pparams) is not None  # stored by `workbench build`
        pid = save_placements(store, oid, gid, pparams, res.placements, grasps, res.ftg)
        fp_ids = load_placements(store, pid)["idfreetabletopplacement"]
        ftg = load_free_tabletop_grips(store, pid)
        had_tabletop = find_tabletop(store, oid, pid, tparams) is not None
        tid = save_tabletop(store, oid, pid, tparams, tt, ftg, fp_ids)
        counts = {"grasps": len(res.grasps), "placements": len(res.placements), "free_tabletop_grips": len(res.ftg[0]),
                  "tabletop_placements": len(tt.placement), "tabletop_grips": len(tt.grip_tp), "seconds": res.seconds}
        if res.reason:
            counts["reason"] = res.reason
        nrows = ((0 if had_grasps else len(res.grasps)) + (0 if had_placements else len(res.placements) + len(res.ftg[0]))
                 + (0 if had_tabletop else len(tt.placement) + len(tt.grip_tp)))
        unit.update(idobject=oid, idgrasps=gid, idplacements=pid, idtabletop=tid, counts=counts, nrows=nrows)


def part_meshes(store: Store, names: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The stored meshes (vertices, faces) of these parts."""
    out = {}
    for name in names:
        _, row = object_row(store, name)
        out[name] = (np.asarray(row["vertices"], dtype=np.float64).reshape(-1, 3),
                     np.asarray(row["faces"], dtype=np.int64).reshape(-1, 3))
    return out


def checkpoint(store: Store) -> None:
    """Write the merged rows into the store file itself (not only its write-ahead log)."""
    sql.checkpoint(store)


def object_names(store: Store) -> set[str]:
    """The names of the objects the store holds."""
    return sql.object_names(store)


def gripper_id(store: Store, hand: Gripper) -> int:
    """The store's row of the build's gripper (created when new)."""
    with store.transaction():
        return put_gripper(store, hand)


def part_grips(store: Store, part: dict, obj: ObjectModel | None = None) -> tuple[dict[str, np.ndarray], ObjectModel]:
    """A stored part's tabletop grips (the placements contract) and its object (read back unless given)."""
    grips = load_tabletop_grips(store, part["idobject"], part["idtabletop"])
    if obj is None:
        _, obj = get_object(store, part["part"])
    return grips, obj


def ik_run(store: Store, robot: Robot, scene: Scene, opts: IKOptions, handx: float, worldz: float, worlda: float) -> dict:
    """The robot, scene and ikret rows of an IK run (created if new): idrobot, idscene, idikret, scene_params."""
    params = scene_params(robot, scene, opts)
    # the robot row carries its allowed self-collision pairs, as `workbench ik` stores them: `plan`'s validator needs them
    rid, sid, kid = prepare_run(store, robot, params, handx, worldz, worlda, allowed_pairs(robot).to_json())
    return {"idrobot": rid, "idscene": sid, "idikret": kid, "scene_params": params}


def stored_ik(store: Store, run: dict, idtabletop: int) -> np.ndarray:
    """The tabletop grips of a part (its tabletop parameter set) that already have `ik` rows for the run."""
    return sql.stored_part_grips(store, run["idrobot"], run["idscene"], run["idikret"], idtabletop)


def merge_runs(store: Store, runs: list[dict], units: list[list[tuple[dict, Path]]]) -> int:
    """The shard files of complete (part, robot) IK runs (Section IV's `ik` rows; a run's `offset` moves its grips
    to the store's ids) and their units' catalog_unit rows, in the caller's transaction: the runs of parts this build
    merged in one insert per robot kind, those of parts the store held by their own (keeping the rows `workbench ik`
    stored). Returns the rows inserted."""
    fresh = [{**r, "paths": [p for _, p in u]} for r, u in zip(runs, units) if not len(r["stored"])]
    with store.transaction():
        n = sql.merge_ik_runs(store, fresh)
        for run, u in zip(runs, units):
            if len(run["stored"]):
                n += sql.merge_ik_shards(store, run["idrobot"], run["idscene"], run["idikret"], run["nq"],
                                         [str(p) for _, p in u], run.get("offset", 0), run["part"], run["robot"])
        sql.put_units(store, [unit for u in units for unit, _ in u])
    return n


def graph_inputs(store: Store, run: dict) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The tabletop grips of a part and their IK flags for a run (Section V's inputs, joints left out)."""
    rows = roadmap_rows(store, run["idtabletop"], run["idrobot"], run["idscene"], run["idikret"], 0, joints=False)
    feasible = rows.pop("feasible")
    return rows, feasible


def graph_unit_files(folder: str, shards: list[str], robot: str) -> pa.Table:
    """The worker's task for a (part, robot) run whose IK units are all on disk: the regrasp graph's sizes (Section V)
    from the part folder's tabletop grips, placements and angles and the run's shards (`robot` names the run)."""
    t0, c0 = time.perf_counter(), time.thread_time()
    g = pq.read_table(f"{folder}/tabletopgrips.parquet").sort_by("idtabletopgrips")
    p = pq.read_table(f"{folder}/tabletopplacements.parquet").sort_by("idtabletopplacements")
    a = pq.read_table(f"{folder}/angle.parquet").sort_by("idangle")
    rows = {c: _arrow_numpy(g.column(c)) for c in ("idtabletopgrips", "idtabletopplacements", "idfreeairgrip", "rotmat",
                                                    "jawwidth")}
    n = len(rows["idtabletopgrips"])
    at = np.searchsorted(_arrow_numpy(p.column("idtabletopplacements")), rows["idtabletopplacements"])
    for src, dst in (("rotmat", "placement_rotmat"), ("idfreetabletopplacement", "idfreetabletopplacement"),
                     ("tabletopposition", "tabletopposition")):
        rows[dst] = _arrow_numpy(p.column(src))[at]
    angle = _arrow_numpy(p.column("idangle"))[at]
    rows["angle"] = _arrow_numpy(a.column("value"))[np.searchsorted(_arrow_numpy(a.column("idangle")), angle)]
    rows["rotmat"], rows["placement_rotmat"] = rows["rotmat"].reshape(n, 4, 4), rows["placement_rotmat"].reshape(n, 4, 4)
    rows["tabletopposition"] = rows["tabletopposition"].reshape(n, 3)
    feasible = np.zeros((n, 5), dtype=bool)
    for shard in shards:
        t = table_arrays(pq.read_table(shard, columns=["idtabletopgrips", "feasible"]))
        feasible[np.searchsorted(rows["idtabletopgrips"], t["idtabletopgrips"])] = t["feasible"]
    table = graph_unit(rows, feasible)
    return stamp(table.replace_schema_metadata({}), t0, c0, robot=robot)


def _arrow_numpy(col: pa.ChunkedArray) -> np.ndarray:
    """An Arrow column as numpy; fixed-size and variable lists of numbers as (N, k) rows."""
    arr = col.combine_chunks()
    if pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type) or pa.types.is_large_list(arr.type):
        flat = arr.flatten().to_numpy(zero_copy_only=False)
        return flat.reshape(len(arr), -1) if len(arr) else flat.reshape(0, 0)
    return arr.to_numpy(zero_copy_only=False)


def put_units(store: Store, units: list[dict]) -> None:
    """Finished units' catalog_unit rows (graph units: their sizes, Section V, in `counts`), in one insert."""
    sql.put_units(store, units)


def part_unit_files(path: str, name: str, scale: float | None, units: str | None, gparams: GraspParams,
                    pparams: PlacementParams, tparams: TabletopParams, folder: str, ik_chunk: int,
                    hand: Gripper | None = None) -> pa.Table:
    """The worker's task for one part: its stages (Sections III-IV, `part_stages`) written by the stage writers into a
    scratch store (ids from 1, renumbered by the merge), left as Parquet files in `folder` (created whole: written under a
    temporary name, then renamed); returns the unit's record (ids, counts, tabletop grips) as a one-row table.
    `hand`: the catalogue's gripper (default the Franka hand, built once per worker)."""
    t0, c0 = time.perf_counter(), time.thread_time()
    obj = load_object(path, scale=scale, units=units, name=name)
    hand = hand or worker_state().hand()
    res = part_stages(obj, gparams, pparams, tparams, hand)
    res.seconds["load"] = time.perf_counter() - t0 - sum(res.seconds.values())
    unit: dict = {"digest": "", "kind": "part", "part": name, "fresh": True}
    with Store.scratch(sql.CATALOG_TABLES) as scratch:
        write_part(scratch, unit, res, hand, gparams, pparams, tparams)
        grips = load_tabletop_grips(scratch, unit["idobject"], unit["idtabletop"])
        tables = sql.export_tables(scratch)
    record = {k: unit[k] for k in ("idobject", "idgrasps", "idplacements", "idtabletop", "counts", "nrows")}
    record.update(grips=len(grips["idtabletopgrips"]), rows={t: tables[t].num_rows for t in sql.RENUMBERED})
    write_unit_folder(Path(folder), tables, grips, record, ik_chunk)
    return stamp(pa.table({"record": [json.dumps(record, default=float)]}), t0, c0)


def write_unit_folder(folder: Path, tables: dict[str, pa.Table], grips: dict[str, np.ndarray], record: dict,
                      ik_chunk: int) -> None:
    """A unit's folder: its tables, its grips in IK order and its record, whole or absent (a temporary folder renamed
    into place; a unit computed twice, after a worker was lost, keeps the first)."""
    tmp = folder.with_name(f"{folder.name}.{os.getpid()}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for name, table in tables.items():
        pq.write_table(table, tmp / f"{name}.parquet", compression="zstd")
    order = neighbour_order(grips)
    ik = arrays_table({"idtabletopgrips": np.asarray(grips["idtabletopgrips"], dtype=np.int64)[order],
                       "rotmat": grips["rotmat"][order], "placement_rotmat": grips["placement_rotmat"][order]})
    pq.write_table(ik, tmp / IK_GRIPS, row_group_size=max(1, ik_chunk), compression="none")
    (tmp / RECORD).write_text(json.dumps(record, default=float))
    try:
        os.replace(tmp, folder)
    except OSError:  # the folder is there already (the same unit, finished by another worker)
        shutil.rmtree(tmp, ignore_errors=True)


def read_record(folder: Path) -> dict | None:
    """The record of a unit folder left by an earlier run (None when absent or unreadable: computed again)."""
    try:
        return json.loads((folder / RECORD).read_text())
    except (OSError, ValueError):
        return None


def stored_part_folder(store: Store, part: dict, folder: Path, ik_chunk: int) -> int:
    """For a part already in the store: a folder holding only its grips in IK order (what its IK units read) and its
    object; returns the number of grips. The grips are named as the part unit's shards name them (its ids before
    the merge, `counts.offset` below the store's), so shards of an earlier run and new ones merge alike."""
    grips, obj = part_grips(store, part)
    grips["idtabletopgrips"] = np.asarray(grips["idtabletopgrips"], dtype=np.int64) - int(part["counts"].get("offset", 0))
    tables = {"object": pa.table({"digest": [obj.digest],
                                  "vertices": [np.asarray(obj.mesh.vertices, dtype=np.float64).tolist()],
                                  "faces": [np.asarray(obj.mesh.faces, dtype=np.int64).tolist()]})}
    shutil.rmtree(folder, ignore_errors=True)
    write_unit_folder(folder, tables, grips, {"grips": len(grips["idtabletopgrips"])}, ik_chunk)
    return len(grips["idtabletopgrips"])


def merge_units(store: Store, parts: list[tuple[dict, Path]]) -> int:
    """Part units' folders and their catalog_unit rows, in the caller's transaction; the units' ids become the
    store's (the offset of their tabletop grips, which their IK units' shards name, is kept in `counts`), their
    grasps name their unit's `idgripper`. Returns the rows inserted."""
    with store.transaction():
        offsets = sql.merge_part_files(store, [str(f) for _, f in parts], [u["rows"] for u, _ in parts],
                                       [u["idgripper"] for u, _ in parts], [u["part"] for u, _ in parts])
        for (unit, _), o in zip(parts, offsets):
            unit["idobject"] += o["object"]
            for k in ("idgrasps", "idplacements", "idtabletop"):
                unit[k] += o["paramset"]
            unit["counts"] = {**unit["counts"], "offset": o["tabletopgrips"]}
        sql.put_units(store, [u for u, _ in parts])
    return sum(sum(u["rows"].values()) for u, _ in parts)
