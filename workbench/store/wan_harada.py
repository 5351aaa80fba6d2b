"""SQL of the regrasp roadmap's inputs and of the `plan` and `planstep` tables (Wan & Harada, Section V).

Reads: the tabletop grips of a tabletop parameter set joined with their `ik` rows for one robot, scene and
retraction set (the roadmap's nodes and joint vectors) and the IK runs available for an object and robot; the
robot, scene and ikret rows come from `store.robots`. Writes: plans and their steps, each plan in one transaction.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pyarrow.compute as pc

from workbench.errors import StoreError
from workbench.store import Store, from_arrow
from workbench.store.robots import FEASIBILITY, JOINTS, feasibility_arrays


def ik_fingerprint(store: Store, idtabletop: int, idrobot: int, idscene: int, idikret: int) -> tuple[int, int]:
    """(rows, max idik) of one IK run: changes whenever its rows change (cache key of the roadmap)."""
    row = store.one(
        "SELECT count(*), coalesce(max(k.idik), 0) FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) "
        "JOIN tabletopplacements p USING (idtabletopplacements) "
        "WHERE p.idparamset = ? AND k.idrobot = ? AND k.idscene = ? AND k.idikret = ?", [idtabletop, idrobot, idscene, idikret])
    return int(row[0]), int(row[1])


def roadmap_rows(store: Store, idtabletop: int, idrobot: int, idscene: int, idikret: int, nq: int,
                 joints: bool = True) -> dict[str, np.ndarray]:
    """Every tabletop grip of a tabletop parameter set with its placement, angle and IK row (Section V's inputs):
    idtabletopgrips, idtabletopplacements, idfreeairgrip, rotmat (N, 4, 4), jawwidth, placement_rotmat (N, 4, 4),
    idfreetabletopplacement, tabletopposition (N, 3), angle (rad), feasible (N, 5) (False where no IK row) and
    joints (N, 5, nq) for the five poses of `robots.ik.KINDS` (NaN where infeasible; left out, and not read, when
    `joints` is False)."""
    cols = FEASIBILITY + JOINTS if joints else FEASIBILITY
    table = store.arrow(
        "SELECT g.idtabletopgrips, g.idtabletopplacements, g.idfreeairgrip, g.rotmat, g.jawwidth, "
        "p.rotmat AS placement_rotmat, p.idfreetabletopplacement, p.tabletopposition, a.value AS angle, "
        + ", ".join(f"k.{c}" for c in cols) + " "
        "FROM tabletopgrips g JOIN tabletopplacements p USING (idtabletopplacements) JOIN angle a USING (idangle) "
        "LEFT JOIN ik k ON k.idtabletopgrips = g.idtabletopgrips AND k.idrobot = $robot AND k.idscene = $scene AND k.idikret = $ikret "
        "WHERE p.idparamset = $tabletop ORDER BY g.idtabletopgrips",
        {"robot": idrobot, "scene": idscene, "ikret": idikret, "tabletop": idtabletop})

    out = {name: from_arrow(table.column(name)) for name in
           ("idtabletopgrips", "idtabletopplacements", "idfreeairgrip", "rotmat", "jawwidth", "placement_rotmat",
            "idfreetabletopplacement", "tabletopposition", "angle")}
    n = len(out["idtabletopgrips"])
    out["rotmat"] = np.asarray(out["rotmat"], dtype=np.float64).reshape(n, 4, 4)
    out["placement_rotmat"] = np.asarray(out["placement_rotmat"], dtype=np.float64).reshape(n, 4, 4)
    out["tabletopposition"] = np.asarray(out["tabletopposition"], dtype=np.float64).reshape(n, 3)
    if joints:
        out["feasible"], out["joints"] = feasibility_arrays(table, n, nq)
    else:
        out["feasible"] = np.stack([np.asarray(table.column(c).fill_null(False).to_numpy(zero_copy_only=False), dtype=bool)
                                    for c in FEASIBILITY], axis=1).reshape(n, len(FEASIBILITY))
    return out


def placements_of_tabletop(store: Store, idtabletop: int) -> int:
    """The placement parameter set a tabletop parameter set was built from."""
    row = store.one("SELECT params FROM paramset WHERE idparamset = ? AND stage = 'tabletop'", [idtabletop])
    if row is not None:
        params = json.loads(row[0])
        if "placements" in params:
            return int(params["placements"])
    row = store.one("SELECT max(f.idparamset) FROM tabletopplacements p JOIN freetabletopplacement f USING (idfreetabletopplacement) "
                    "WHERE p.idparamset = ?", [idtabletop])
    if row is None or row[0] is None:
        raise StoreError(f"store {store.path}: tabletop parameter set {idtabletop} has no placements; run `workbench placements`")
    return int(row[0])



# ----------------------------------------------------------------------------------------------------------------
# Plans.


QUERY_COLUMNS = ("idobject", "idrobot", "idscene", "idikret", "idtabletop", "start_placement", "goal_placement", "rank")


def find_plan(store: Store, plan: dict[str, Any], segments: dict[str, Any] | None = None) -> int | None:
    """The id of a stored plan answering the same query (object, robot, scene, retractions, tabletop set, start and
    goal placements and poses to 1e-9, rank, and a task's held ends, insertion and obstacles), or None. With its
    `segments`, only a plan with the same motions counts: the same acceleration limits, speed, duration and number of
    knots (another --acc or --speed, or a trajectory timed otherwise by another version, is a new plan)."""
    where = " AND ".join(f"{c} = ?" for c in QUERY_COLUMNS)
    args = [*(plan[c] for c in QUERY_COLUMNS), list(plan["start_xyyaw"]), list(plan["goal_xyyaw"])]
    same = (" AND coalesce(start_held, false) = ? AND coalesce(end_held, false) = ? AND obstacles IS NOT DISTINCT FROM ?"
            " AND insertion IS NOT DISTINCT FROM ?::DOUBLE[3] AND insertion_depth IS NOT DISTINCT FROM ?")
    args += [bool(plan.get("start_held", False)), bool(plan.get("end_held", False)), plan.get("obstacles"),
             plan.get("insertion"), plan.get("insertion_depth")]
    if segments is not None:
        knots = pc.sum(pc.list_value_length(segments["t"])).as_py() or 0
        same += (" AND acc IS NOT DISTINCT FROM ?::DOUBLE[] AND coalesce(speed, 1.0) = ?"
                " AND duration IS NOT DISTINCT FROM ?"
                " AND (SELECT coalesce(sum(len(s.t)), 0) FROM plansegment s WHERE s.idplan = plan.idplan) = ?")
        args += [plan.get("acc"), float(plan.get("speed") or 1.0), plan.get("duration"), int(knots)]
    row = store.one(f"SELECT min(idplan) FROM plan WHERE {where} AND list_distance(start_xyyaw, ?::DOUBLE[3]) < 1e-9 "
                    f"AND list_distance(goal_xyyaw, ?::DOUBLE[3]) < 1e-9{same}", args)
    return None if row is None or row[0] is None else int(row[0])


def save_plan(store: Store, plan: dict[str, Any], steps: dict[str, np.ndarray], segments: dict[str, np.ndarray] | None = None,
              obstacles: dict[str, Any] | None = None) -> int:
    """Store one plan (columns of `plan`), its steps (columns of `planstep`, arrays), its timed motions (columns
    of `plansegment`) and its task's obstacles (columns of `planobstacle`) in one transaction; returns idplan. A
    plan answering a query already stored, with the same motions, is not stored again: the stored plan's id is
    returned."""
    with store.transaction():
        found = find_plan(store, plan, segments)
        if found is not None:
            return found
        pid = store.next_id("plan", "idplan")
        cols = ["idplan", *plan.keys()]
        store.run(f"INSERT INTO plan ({', '.join(cols)}) VALUES ({', '.join('?' for _ in cols)})", [pid, *plan.values()])
        n = len(steps["seq"])
        store.insert("planstep", {"idplanstep": store.new_ids("planstep", n),
                                  "idplan": np.full(n, pid, dtype=np.int64), **steps})
        m = len(segments["seq"]) if segments else 0
        if m:
            store.insert("plansegment", {"idplansegment": store.new_ids("plansegment", m),
                                         "idplan": np.full(m, pid, dtype=np.int64), **segments})
        k = len(obstacles["seq"]) if obstacles else 0
        if k:
            store.insert("planobstacle", {"idplanobstacle": store.new_ids("planobstacle", k),
                                          "idplan": np.full(k, pid, dtype=np.int64), **obstacles})
    return pid


def load_plan_rows(store: Store, idplan: int) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """A stored plan row (as a dict) and its steps (arrays, in order)."""
    table = store.arrow("SELECT * FROM plan WHERE idplan = ?", [idplan])
    if table.num_rows == 0:
        raise StoreError(f"store {store.path} has no plan {idplan}")
    plan = {k: v[0] for k, v in table.to_pydict().items()}
    steps = store.arrow("SELECT * FROM planstep WHERE idplan = ? ORDER BY seq", [idplan])
    return plan, steps


def load_plan_obstacles(store: Store, idplan: int) -> list[dict[str, Any]]:
    """A stored plan's obstacles in order: dicts of name, end ('pickup' or 'destination'), vertices (V, 3), faces
    (F, 3) and pose (4, 4)."""
    rows = store.run("SELECT name, task_end, vertices, faces, pose FROM planobstacle WHERE idplan = ? ORDER BY seq", [idplan])
    return [{"name": n, "end": e, "vertices": np.asarray(v, dtype=np.float64).reshape(-1, 3),
             "faces": np.asarray(f, dtype=np.int64).reshape(-1, 3), "pose": np.asarray(p, dtype=np.float64).reshape(4, 4)}
            for n, e, v, f, p in rows]


def load_plan_segments(store: Store, idplan: int):
    """A stored plan's timed motions (`plansegment` rows in order, an Arrow table; q and qd row-major K x n)."""
    return store.arrow("SELECT * FROM plansegment WHERE idplan = ? ORDER BY seq", [idplan])
