"""SQL of the `freeairgrip` table (Wan & Harada, Section IV)."""

from __future__ import annotations

import numpy as np

from workbench.grasping.grasps import GraspParams, GraspSet
from workbench.robots.gripper import Gripper
from workbench.errors import StoreError
from workbench.store import Store
from workbench.store.objects import put_gripper

STAGE = "grasps"


def grasp_param_dict(params: GraspParams, gripper: Gripper) -> dict:
    """The grasp stage's parameter set as stored: the parameters (a friction left to the gripper set,
    `GraspParams.for_gripper`) and the gripper's digest."""
    return {**params.for_gripper(gripper).as_dict(), "gripper": gripper.digest}


def find_grasps(store: Store, idobject: int, gripper: Gripper, params: GraspParams) -> int | None:
    """The parameter set id of stored grasps for this object, gripper and parameters, if any."""
    return store.find_paramset(STAGE, grasp_param_dict(params, gripper), idobject)


def save_grasps(store: Store, idobject: int, gripper: Gripper, params: GraspParams, grasps: GraspSet) -> tuple[int, bool]:
    """Store the free-air grasps in one transaction; returns (idparamset, reused) and reuses an identical run."""
    with store.transaction():
        pid, existed = store.paramset(STAGE, grasp_param_dict(params, gripper), idobject)
        if existed:
            return pid, True
        gid = put_gripper(store, gripper)
        n = len(grasps)
        store.insert("freeairgrip", {
            "idfreeairgrip": store.new_ids("freeairgrip", n),
            "idobject": np.full(n, idobject, dtype=np.int64),
            "idparamset": np.full(n, pid, dtype=np.int64),
            "idgripper": np.full(n, gid, dtype=np.int64),
            "contactpoint0": grasps.contact0, "contactpoint1": grasps.contact1,
            "contactnormal0": grasps.normal0, "contactnormal1": grasps.normal1,
            "rotmat": grasps.poses, "jawwidth": grasps.jawwidth,
            "idfacet0": grasps.facet0.astype(np.int64), "idfacet1": grasps.facet1.astype(np.int64),
            "idcontactpair": grasps.pair.astype(np.int64), "rotation": grasps.rotation,
            "padoffset0": grasps.offset0, "padoffset1": grasps.offset1, "robustness": grasps.robustness,
        })
    return pid, False


def latest_grasp_paramset(store: Store, idobject: int) -> int:
    """The grasp parameter set of an object produced or reused last (not the highest id)."""
    return store.require_last_used(STAGE, idobject, "grasps", "grasps")


def load_grasps(store: Store, idobject: int, idparamset: int | None = None) -> dict[str, np.ndarray]:
    """Free-air grasps as arrays: idfreeairgrip, contactpoint0/1, contactnormal0/1 (N, 3), rotmat (N, 4, 4), jawwidth,
    robustness (NaN in stores written before it)."""
    pid = latest_grasp_paramset(store, idobject) if idparamset is None else idparamset
    out = store.query_arrays(
        "SELECT idfreeairgrip, contactpoint0, contactpoint1, contactnormal0, contactnormal1, rotmat, jawwidth, idgripper, "
        "coalesce(robustness, 'NaN'::DOUBLE) AS robustness "
        "FROM freeairgrip WHERE idobject = ? AND idparamset = ? ORDER BY idfreeairgrip", [idobject, pid])
    out["rotmat"] = out["rotmat"].reshape(-1, 4, 4)
    out["idparamset"] = pid
    return out


def paramset_gripper(store: Store, idparamset: int) -> str | None:
    """The digest of the gripper a parameter set depends on, following the chain tabletop -> placements -> grasps."""
    params = store.params_of(idparamset)
    for _ in range(4):
        if "gripper" in params:
            return params["gripper"]
        upstream = params.get("placements", params.get("grasps"))
        if not isinstance(upstream, int):
            return None
        params = store.params_of(upstream)
    return None


def latest_paramset_for(store: Store, stage: str, idobject: int, gripper: Gripper | str, command: str) -> int:
    """The parameter set of `stage` (grasps, placements, tabletop) for an object and a gripper (or its digest)
    produced or reused last: a store holding grasps of two grippers keeps both chains apart."""
    digest, name = (gripper, gripper) if isinstance(gripper, str) else (gripper.digest, gripper.name)
    rows = store.run("SELECT idparamset FROM paramset WHERE stage = ? AND idobject = ? ORDER BY used DESC, idparamset DESC",
                     [stage, idobject])
    for (pid,) in rows:
        if paramset_gripper(store, int(pid)) == digest:
            return int(pid)
    raise StoreError(f"store {store.path} has no {stage} of object id {idobject} for gripper {name!r}; run "
                     f"`workbench {command} --gripper ...` with that gripper first")
