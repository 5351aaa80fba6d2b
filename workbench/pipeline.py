"""Runs planner stages against a store: reuse what is stored for the same inputs and parameters, else compute
and write each stage in one transaction (CONVENTIONS.md, Store)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .grasps import GraspParams, GraspPlan, plan_grasps
from .placements import PlacementParams
from .tabletop import TabletopParams
from .gripper import Gripper
from .objects import ObjectModel
from .store import Store
from .store.grasps import find_grasps, load_grasps, save_grasps
from .store.objects import put_object


@dataclass
class GraspsResult:
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
            plan = plan_grasps(obj, gripper, params)
            pid, _ = save_grasps(store, oid, gripper, params, plan.grasps)
        rows = load_grasps(store, oid, pid)
        return GraspsResult(idobject=oid, idparamset=pid, reused=plan is None, count=len(rows["jawwidth"]),
                            poses=rows["rotmat"], widths=rows["jawwidth"], plan=plan)
    finally:
        if not isinstance(db, Store):
            store.close()


@dataclass
class PlacementsResult:
    idplacements: int
    idtabletop: int
    reused: bool
    placements: dict
    n_free_grips: np.ndarray
    n_tabletop_placements: int
    n_tabletop_grips: int
    timings: dict


def ensure_placements(db: str | Path | Store, idobject: int, obj: ObjectModel, grasp_pid: int, gripper: Gripper,
                      pparams: PlacementParams, tparams: TabletopParams) -> PlacementsResult:
    """Free placements, free tabletop grips, tabletop placements and grips of a stored grasp set (Section IV)."""
    import time

    from .placements import free_tabletop_grips, stable_placements
    from .store.placements import (find_placements, find_tabletop, load_free_tabletop_grips, load_placements,
                                   save_placements, save_tabletop, tabletop_counts)
    from .tabletop import select_grasps, tabletop

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
            grasp_ids = np.unique(ftg["idfreeairgrip"])
            usable = np.zeros((len(stored["stability"]), len(grasp_ids)), dtype=bool)
            usable[fp_index, np.searchsorted(grasp_ids, ftg["idfreeairgrip"])] = True
            grasps = load_grasps(store, idobject, grasp_pid) if grasps is None else grasps
            poses = grasps["rotmat"][np.searchsorted(grasps["idfreeairgrip"], grasp_ids)]
            chosen = grasp_ids[select_grasps(poses, usable, tparams.max_grasps)]
            keep = np.isin(ftg["idfreeairgrip"], chosen)
            tt = tabletop(stored["rotmat"], fp_index, ftg["rotmat"], keep, tparams)
            timings["tabletop"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            tt_pid = save_tabletop(store, idobject, pl_pid, tparams, tt, ftg, stored["idfreetabletopplacement"])
            timings["write_tabletop"] = time.perf_counter() - t0
        n_tp, n_tg = tabletop_counts(store, tt_pid)
        return PlacementsResult(idplacements=pl_pid, idtabletop=tt_pid, reused=reused, placements=stored,
                                n_free_grips=np.bincount(fp_index, minlength=len(stored["stability"])),
                                n_tabletop_placements=int(n_tp), n_tabletop_grips=int(n_tg), timings=timings)
    finally:
        if not isinstance(db, Store):
            store.close()
