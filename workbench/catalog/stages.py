"""The catalogue's store side: the only module of `workbench.catalog` that talks to the store.

The driver hands it finished units; each is written with the Wan & Harada stage writers of `workbench.store`
(object, free-air grasps, placements, free tabletop grips, tabletop placements and grips, `ik` rows) together with
its `catalog_unit` row in one transaction (`workbench.store.catalog`), so a unit is stored whole or not at all.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from workbench.catalog.units import PartResult
from workbench.errors import StoreError
from workbench.geometry.objects import ObjectModel
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import get_object, scene_params
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.collider import Scene
from workbench.robots.gripper import Gripper
from workbench.robots.ik import IKOptions
from workbench.robots.model import Robot
from workbench.robots.selfcollision import allowed_pairs
from workbench.store import Store
from workbench.store import catalog as sql
from workbench.store.grasps import load_grasps, save_grasps
from workbench.store.objects import put_object
from workbench.store.placements import (
    find_placements,
    find_tabletop,
    load_free_tabletop_grips,
    load_placements,
    load_tabletop_grips,
    save_placements,
    save_tabletop,
)
from workbench.store.robots import insert_ik, prepare_run
from workbench.store.wan_harada import roadmap_rows

done_units = sql.done_units
unit_digests = sql.unit_digests
record_failure = sql.record_failure
summary = sql.summary
failures = sql.failures
unit_times = sql.unit_times


def open_store(db: str | Path, read_only: bool = False) -> Store:
    """The catalogue's store (created with its `catalog_unit` table when new)."""
    store = Store(db, read_only=read_only)
    if not read_only:
        sql.ensure_catalog_tables(store)
        sql.single_thread(store)  # the driver shares the machine with the workers
    elif not sql.has_catalog(store):
        store.close()
        raise StoreError(f"store {db} holds no catalogue; build one with `workbench catalog build`")
    return store


@contextmanager
def batch(store: Store) -> Iterator[None]:
    """Several finished units in one transaction (each unit whole; they share the commit)."""
    with store.transaction():
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
        unit.update(idobject=oid, idgrasps=gid, idplacements=pid, idtabletop=tid, counts=counts, nrows=nrows,
                    new_tabletop=not had_tabletop)


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


def stored_ik(store: Store, run: dict, idtabletop: int, new: bool = False) -> np.ndarray:
    """The tabletop grips of a part (its tabletop parameter set) that already have `ik` rows for the run (none when
    the tabletop rows are `new`: written by this build's part unit)."""
    if new:
        return np.zeros(0, dtype=np.int64)
    return sql.stored_part_grips(store, run["idrobot"], run["idscene"], run["idikret"], idtabletop)


def write_ik(store: Store, units: list[dict], chunks: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
             stored: np.ndarray) -> None:
    """IK units of one part and robot: their `ik` rows (Section IV) in one insert and each unit's catalog_unit row,
    in one transaction; `chunks` holds each unit's (grip ids, feasibility (C, 5), joints (C, 5, nq)). Grips a
    `workbench ik` run already stored for the same run keep their rows (nothing is duplicated)."""
    todo = [~np.isin(ids, stored) for ids, _, _ in chunks]
    unit = units[0]
    with store.transaction():
        if any(t.any() for t in todo):
            insert_ik(store, unit["idrobot"], unit["idscene"], unit["idikret"],
                      *(np.concatenate([c[k][t] for c, t in zip(chunks, todo)]) for k in range(3)))
        for u, (ids, feasible, _), t in zip(units, chunks, todo):
            with sql.unit_transaction(store, u):
                u.update(nrows=int(t.sum()), counts={"grips": int(len(ids)), "feasible": int(feasible[:, 0].sum()),
                                                     "feasible_all": int(feasible.all(axis=1).sum())})


def merge_ik_shards(store: Store, run: dict, units: list[tuple[dict, Path]]) -> int:
    """The shard files of one (part, robot) IK run and their units' catalog_unit rows, in one transaction (rows of
    grips already stored for the run are kept, not duplicated); returns the rows inserted."""
    return sql.merge_ik_shards(store, run["idrobot"], run["idscene"], run["idikret"], run["nq"], [u for u, _ in units],
                               [str(p) for _, p in units], stored=len(run["stored"]) > 0)


def graph_inputs(store: Store, run: dict) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The tabletop grips of a part and their IK flags for a run (Section V's inputs, joints left out)."""
    rows = roadmap_rows(store, run["idtabletop"], run["idrobot"], run["idscene"], run["idikret"], 0, joints=False)
    feasible = rows.pop("feasible")
    return rows, feasible


def write_graph(store: Store, unit: dict, counts: dict) -> None:
    """A graph unit's sizes (Section V) as its catalog_unit row."""
    with sql.unit_transaction(store, unit):
        unit.update(counts=counts, nrows=0)
