"""SQL of `freetabletopplacement`, `freetabletopgrip`, `angle`, `tabletopplacements` and `tabletopgrips`
(Wan & Harada, Section IV, Fig. 5)."""

from __future__ import annotations

import numpy as np

from workbench.errors import StoreError
from workbench.grasping.placements import PlacementParams, Placements
from workbench.planners.wan_harada.tabletop import Tabletop, TabletopParams
from workbench.store import Store

PLACEMENT_STAGE = "placements"
TABLETOP_STAGE = "tabletop"


def _apply(poses: np.ndarray, points: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", poses[:, :3, :3], points) + poses[:, :3, 3]


def _rotate(poses: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", poses[:, :3, :3], vectors)


def find_placements(store: Store, idobject: int, grasp_pid: int, params: PlacementParams) -> int | None:
    """The parameter set id of stored placements for these grasps and parameters, if any."""
    return store.find_paramset(PLACEMENT_STAGE, {**params.as_dict(), "grasps": grasp_pid}, idobject)


def save_placements(store: Store, idobject: int, grasp_pid: int, params: PlacementParams, placements: Placements,
                    grasps: dict[str, np.ndarray], ftg: tuple[np.ndarray, np.ndarray, np.ndarray]) -> int:
    """Store free placements and free tabletop grips in one transaction; returns the parameter set id.

    grasps: the stored free-air grasps (load_grasps); ftg: (placement index, grasp index, TCP pose in the table frame).
    """
    with store.transaction():
        pid, existed = store.paramset(PLACEMENT_STAGE, {**params.as_dict(), "grasps": grasp_pid}, idobject)
        if existed:
            return pid
        n = len(placements)
        fp_ids = store.new_ids("freetabletopplacement", n)
        store.insert("freetabletopplacement", {
            "idfreetabletopplacement": fp_ids, "idobject": np.full(n, idobject, dtype=np.int64),
            "idparamset": np.full(n, pid, dtype=np.int64), "rotmat": placements.poses, "stability": placements.stability,
            "probability": placements.probability, "rocking": placements.rocking,
            "support": np.array([s.tolist() for s in placements.supports] + [None], dtype=object)[:n],
        })
        p_idx, g_idx, poses = ftg
        place = placements.poses[p_idx]
        store.insert("freetabletopgrip", {
            "idfreetabletopgrip": store.new_ids("freetabletopgrip", len(p_idx)),
            "idfreetabletopplacement": fp_ids[p_idx], "idfreeairgrip": grasps["idfreeairgrip"][g_idx],
            "contactpoint0": _apply(place, grasps["contactpoint0"][g_idx]),
            "contactpoint1": _apply(place, grasps["contactpoint1"][g_idx]),
            "contactnormal0": _rotate(place, grasps["contactnormal0"][g_idx]),
            "contactnormal1": _rotate(place, grasps["contactnormal1"][g_idx]),
            "rotmat": poses, "jawwidth": grasps["jawwidth"][g_idx],
        })
    return pid


def load_placements(store: Store, idplacements: int) -> dict[str, np.ndarray]:
    """Free placements of a parameter set: idfreetabletopplacement, rotmat (P, 4, 4), stability, support (objects),
    probability and rocking (1.0 when a small tilt rolls the part on, 0.0 when not; both NaN where a store written
    before them has none)."""
    out = store.query_arrays("SELECT idfreetabletopplacement, rotmat, stability, support, "
                             "coalesce(probability, 'NaN'::DOUBLE) AS probability, "
                             "coalesce(rocking::DOUBLE, 'NaN'::DOUBLE) AS rocking FROM freetabletopplacement "
                             "WHERE idparamset = ? ORDER BY idfreetabletopplacement", [idplacements])
    out["rotmat"] = out["rotmat"].reshape(-1, 4, 4)
    return out


def load_free_tabletop_grips(store: Store, idplacements: int) -> dict[str, np.ndarray]:
    """Free tabletop grips of a placement parameter set, with their placement and free-air grasp ids and the free-air
    grasp's contact robustness (NaN where not stored)."""
    out = store.query_arrays(
        "SELECT g.idfreetabletopgrip, g.idfreetabletopplacement, g.idfreeairgrip, g.rotmat, g.jawwidth, "
        "g.contactpoint0, g.contactpoint1, g.contactnormal0, g.contactnormal1, "
        "coalesce(a.robustness, 'NaN'::DOUBLE) AS robustness "
        "FROM freetabletopgrip g JOIN freetabletopplacement p USING (idfreetabletopplacement) "
        "LEFT JOIN freeairgrip a ON a.idfreeairgrip = g.idfreeairgrip "
        "WHERE p.idparamset = ? ORDER BY g.idfreetabletopgrip", [idplacements])
    out["rotmat"] = out["rotmat"].reshape(-1, 4, 4)
    return out


def find_tabletop(store: Store, idobject: int, idplacements: int, params: TabletopParams) -> int | None:
    """The parameter set id of stored tabletop placements and grips for these placements and grid, if any."""
    return store.find_paramset(TABLETOP_STAGE, {**params.as_dict(), "placements": idplacements}, idobject)


def angle_ids(store: Store, values: np.ndarray) -> np.ndarray:
    """Ids of the `angle` rows of these values (radians), created when missing; call inside a transaction."""
    out = np.zeros(len(values), dtype=np.int64)
    for k, v in enumerate(np.round(values, 12)):
        row = store.one("SELECT idangle FROM angle WHERE abs(value - ?) < 1e-9", [float(v)])
        if row is None:
            aid = store.next_id("angle", "idangle")
            store.run("INSERT INTO angle (idangle, value) VALUES (?, ?)", [aid, float(v)])
            row = (aid,)
        out[k] = row[0]
    return out


def save_tabletop(store: Store, idobject: int, idplacements: int, params: TabletopParams, tt: Tabletop,
                  ftg: dict[str, np.ndarray], fp_ids: np.ndarray) -> int:
    """Store tabletop placements and grips in one transaction; returns the parameter set id.

    ftg: the stored free tabletop grips (load_free_tabletop_grips); fp_ids: free placement ids by index.
    """
    with store.transaction():
        pid, existed = store.paramset(TABLETOP_STAGE, {**params.as_dict(), "placements": idplacements}, idobject)
        if existed:
            return pid
        aids = angle_ids(store, params.angle_values())
        tp_ids = store.new_ids("tabletopplacements", len(tt.placement))
        store.insert("tabletopplacements", {
            "idtabletopplacements": tp_ids, "idfreetabletopplacement": fp_ids[tt.placement], "idangle": aids[tt.angle],
            "idparamset": np.full(len(tp_ids), pid, dtype=np.int64), "tabletopposition": tt.position, "rotmat": tt.poses,
        })
        # contacts in the world: the free tabletop grip's (table-frame) contacts moved with the placement
        m = tt.moves[tt.grip_tp]
        g = tt.grip_ftg
        store.insert("tabletopgrips", {
            "idtabletopgrips": store.new_ids("tabletopgrips", len(g)), "idtabletopplacements": tp_ids[tt.grip_tp],
            "idfreeairgrip": ftg["idfreeairgrip"][g], "idfreetabletopgrip": ftg["idfreetabletopgrip"][g],
            "contactpoint0": _apply(m, ftg["contactpoint0"][g]), "contactpoint1": _apply(m, ftg["contactpoint1"][g]),
            "contactnormal0": _rotate(m, ftg["contactnormal0"][g]), "contactnormal1": _rotate(m, ftg["contactnormal1"][g]),
            "rotmat": tt.grip_poses, "jawwidth": ftg["jawwidth"][g],
        })
    return pid


def latest_tabletop_paramset(store: Store, idobject: int) -> int:
    """The tabletop parameter set of an object produced or reused last (not the highest id)."""
    return store.require_last_used(TABLETOP_STAGE, idobject, "tabletop placements", "placements")


def load_tabletop_grips(store: Store, idobject: int, idparamset: int | None = None) -> dict[str, np.ndarray]:
    """Tabletop grips of a tabletop parameter set as arrays (Fig. 5): idtabletopgrips, idtabletopplacements,
    idfreeairgrip, rotmat (N, 4, 4) TCP in the world, jawwidth, placement_rotmat (N, 4, 4) object in the world,
    idangle, idfreetabletopplacement, tabletopposition (N, 3)."""
    pid = latest_tabletop_paramset(store, idobject) if idparamset is None else int(idparamset)
    if idparamset is not None and store.one("SELECT 1 FROM paramset WHERE idparamset = ? AND stage = ? AND idobject = ?",
                                            [pid, TABLETOP_STAGE, idobject]) is None:
        have = [r[0] for r in store.run("SELECT idparamset FROM paramset WHERE stage = ? AND idobject = ? ORDER BY 1",
                                        [TABLETOP_STAGE, idobject])]
        raise StoreError(f"store {store.path} has no tabletop parameter set {pid} for object id {idobject} (it has: "
                         f"{', '.join(map(str, have)) or 'none'}); give one of those to --tabletop, or leave it out for the latest")
    out = store.query_arrays(
        "SELECT g.idtabletopgrips, g.idtabletopplacements, g.idfreeairgrip, g.rotmat, g.jawwidth, "
        "p.rotmat AS placement_rotmat, p.idangle, p.idfreetabletopplacement, p.tabletopposition "
        "FROM tabletopgrips g JOIN tabletopplacements p USING (idtabletopplacements) "
        "WHERE p.idparamset = ? ORDER BY g.idtabletopgrips", [pid])
    out["rotmat"] = out["rotmat"].reshape(-1, 4, 4)
    out["placement_rotmat"] = out["placement_rotmat"].reshape(-1, 4, 4)
    out["idparamset"] = pid
    return out



def tabletop_grasp_count(store: Store, idtabletop: int) -> int:
    """Distinct free-air grasps among the tabletop grips of a tabletop parameter set (the roadmap's grasps)."""
    return int(store.one("SELECT count(DISTINCT g.idfreeairgrip) FROM tabletopgrips g JOIN tabletopplacements p "
                         "USING (idtabletopplacements) WHERE p.idparamset = ?", [idtabletop])[0])


def tabletop_counts(store: Store, idtabletop: int) -> tuple[int, int]:
    """(tabletop placements, tabletop grips) of a tabletop parameter set."""
    n_tp, n_tg = store.one(
        "SELECT count(DISTINCT p.idtabletopplacements), count(g.idtabletopgrips) FROM tabletopplacements p "
        "LEFT JOIN tabletopgrips g USING (idtabletopplacements) WHERE p.idparamset = ?", [idtabletop])
    return int(n_tp), int(n_tg)
