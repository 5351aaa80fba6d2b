"""SQL of the `simulation` and `simulationstep` tables (CONVENTIONS.md, Simulation; columns in store.schema) and of
what a replay reads besides the plan: the object's name and the grasp friction the plan's grasps were planned with."""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from workbench.errors import StoreError
from workbench.grasping.grasps import DEFAULT_FRICTION
from workbench.store import Store

STEP_COLUMNS = ("seq", "step", "kind", "caption", "t", "planned", "simulated", "error", "angle", "slip", "slip_angle",
                "settle", "touching", "ok")


def plan_inputs(store: Store, idplan: int) -> dict[str, Any]:
    """The object name, robot id, scene id and grasp friction coefficient (`grasp_friction` of the first grasp) of a
    stored plan."""
    row = store.one("SELECT o.name, p.idrobot, p.idscene FROM plan p JOIN object o USING (idobject) WHERE p.idplan = ?", [idplan])
    if row is None:
        raise StoreError(f"store {store.path} has no plan {idplan}; `workbench plan` stores plans and prints their ids")
    first = store.one("SELECT idfreeairgrip FROM planstep WHERE idplan = ? ORDER BY seq LIMIT 1", [idplan])
    return {"object": row[0], "idrobot": int(row[1]), "idscene": int(row[2]),
            "friction": grasp_friction(store, int(first[0])) if first else DEFAULT_FRICTION}


def grasp_friction(store: Store, idfreeairgrip: int) -> float:
    """The friction coefficient a grasp was planned with (its parameter set's `friction`; 0.3 when it names none)."""
    row = store.one("SELECT s.params FROM freeairgrip g JOIN paramset s ON s.idparamset = g.idparamset "
                    "WHERE g.idfreeairgrip = ?", [idfreeairgrip])
    return float(json.loads(row[0]).get("friction", DEFAULT_FRICTION)) if row else DEFAULT_FRICTION


def find_simulation(store: Store, idplan: int, digest: str) -> int | None:
    """The id of the simulation of plan `idplan` with these parameters (their digest), or None."""
    row = store.one("SELECT idsimulation FROM simulation WHERE idplan = ? AND digest = ?", [idplan, digest])
    return None if row is None else int(row[0])


def save_simulation(store: Store, row: dict[str, Any], steps: dict[str, np.ndarray]) -> int:
    """Store one simulation row and its per-waypoint rows in one transaction; returns idsimulation (the stored one's
    when the same plan and parameters were simulated before)."""
    with store.transaction():
        found = find_simulation(store, row["idplan"], row["digest"])
        if found is not None:
            return found
        sid = store.next_id("simulation", "idsimulation")
        cols = ["idsimulation", *row.keys()]
        store.run(f"INSERT INTO simulation ({', '.join(cols)}) VALUES ({', '.join('?' for _ in cols)})", [sid, *row.values()])
        n = len(steps["seq"])
        store.insert("simulationstep", {"idsimulationstep": store.new_ids("simulationstep", n),
                                        "idsimulation": np.full(n, sid, dtype=np.int64), **steps})
    return sid


def load_simulation(store: Store, idsimulation: int) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """A stored simulation row (a dict) and its waypoint rows (arrays in order; planned and simulated (N, 4, 4))."""
    table = store.con.sql("SELECT * FROM simulation WHERE idsimulation = ?", params=[idsimulation]).to_arrow_table()
    if table.num_rows == 0:
        raise StoreError(f"store {store.path} has no simulation {idsimulation}")
    row = {k: v[0] for k, v in table.to_pydict().items()}
    steps = store.con.sql(f"SELECT {', '.join(STEP_COLUMNS)} FROM simulationstep WHERE idsimulation = ? ORDER BY seq",
                          params=[idsimulation]).to_arrow_table().to_pydict()
    out = {k: np.asarray(v, dtype=object if k in ("kind", "caption") else None) for k, v in steps.items()}
    for k in ("planned", "simulated"):
        out[k] = np.asarray(steps[k], dtype=np.float64).reshape(-1, 4, 4)
    for k in ("error", "angle", "slip", "slip_angle", "settle", "t"):
        out[k] = np.array([np.nan if x is None else x for x in steps[k]], dtype=np.float64)
    return row, out


def simulations_of_plan(store: Store, idplan: int) -> list[int]:
    """The ids of every stored simulation of a plan, newest first."""
    return [int(r[0]) for r in store.run("SELECT idsimulation FROM simulation WHERE idplan = ? ORDER BY idsimulation DESC", [idplan])]
