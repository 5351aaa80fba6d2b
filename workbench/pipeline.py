"""Runs planner stages against a store: reuse what is stored for the same inputs and parameters, else compute
and write each stage in one transaction (CONVENTIONS.md, Store)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .grasps import GraspParams, GraspPlan, plan_grasps
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
