"""SQL of a parts x robots catalogue built on a cluster (`workbench catalog`).

- catalog_unit: one row per finished (or failed) unit of work, keyed by the unit's digest (the mesh file's bytes,
  its scale and name, every stage's parameters, the robot's kinematics, the scene, the retractions and the IK
  chunk). kind is `part` (grasps, placements, tabletop grips), `ik` (one chunk of a part's tabletop grips for a
  robot) or `graph` (the regrasp graph's size for a part and robot). The row is written in the same transaction as
  the unit's rows, so a unit is either stored with all its rows or not at all, and a re-run skips the stored ones.
  status is `done` or `failed` (error holds the one-line reason; failed units are tried again on a re-run).
  seconds: worker compute time; write_seconds: the driver's write transaction; counts: JSON of the unit's sizes.

Units are written by one process (the driver); workers never open the store.
"""

from __future__ import annotations

import json
import time
from contextlib import contextmanager
from typing import Any, Iterator

import duckdb
import numpy as np

from workbench.errors import StoreError
from workbench.store import Store
from workbench.store.robots import ALL_FEASIBLE, FEASIBILITY, JOINTS

CATALOG_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS catalog_unit (
        digest VARCHAR PRIMARY KEY,
        kind VARCHAR NOT NULL,
        part VARCHAR NOT NULL,
        source VARCHAR,
        robot VARCHAR,
        chunk INTEGER,
        idobject BIGINT,
        idgrasps BIGINT,
        idplacements BIGINT,
        idtabletop BIGINT,
        idrobot BIGINT,
        idscene BIGINT,
        idikret BIGINT,
        status VARCHAR NOT NULL,
        error VARCHAR,
        nrows BIGINT NOT NULL DEFAULT 0,
        counts VARCHAR NOT NULL DEFAULT '{}',
        seconds DOUBLE,
        write_seconds DOUBLE,
        worker VARCHAR,
        created TIMESTAMP DEFAULT current_timestamp
    )""",
)

UNIT_COLUMNS = ("digest", "kind", "part", "source", "robot", "chunk", "idobject", "idgrasps", "idplacements", "idtabletop",
                "idrobot", "idscene", "idikret", "status", "error", "nrows", "counts", "seconds", "write_seconds", "worker")


def ensure_catalog_tables(store: Store) -> None:
    """Create the catalogue's table when missing (idempotent)."""
    with store.transaction():
        for ddl in CATALOG_TABLES:
            store.run(ddl)


def single_thread(store: Store) -> None:
    """One DuckDB thread on this connection (the catalogue's driver leaves the cores to its workers)."""
    store.run("SET threads = 1")


def has_catalog(store: Store) -> bool:
    """Whether the store holds a catalogue (its catalog_unit table)."""
    return store.one("SELECT count(*) FROM information_schema.tables WHERE table_name = 'catalog_unit'")[0] > 0


def done_units(store: Store) -> dict[str, dict[str, Any]]:
    """Every stored unit with status `done`, by digest (all columns, counts parsed)."""
    rows = store.run(f"SELECT {', '.join(UNIT_COLUMNS)} FROM catalog_unit WHERE status = 'done'")
    out = {}
    for r in rows:
        d = dict(zip(UNIT_COLUMNS, r))
        d["counts"] = json.loads(d["counts"])
        out[d["digest"]] = d
    return out


def unit_digests(store: Store) -> set[str]:
    """The digests of every stored unit row, done or failed."""
    return {r[0] for r in store.run("SELECT digest FROM catalog_unit")}


def _put_unit(store: Store, unit: dict[str, Any]) -> None:
    """Replace the unit row of this digest (a failure recorded by an earlier run) inside the caller's transaction; a
    unit marked `fresh` (the caller knows no row has its digest) is inserted, three times cheaper."""
    row = {k: unit.get(k) for k in UNIT_COLUMNS}
    row["counts"] = json.dumps(row["counts"] or {}, sort_keys=True, default=_plain)
    row["nrows"] = int(row["nrows"] or 0)
    verb = "INSERT" if unit.get("fresh") else "INSERT OR REPLACE"
    store.run(f"{verb} INTO catalog_unit ({', '.join(UNIT_COLUMNS)}) VALUES ({', '.join('?' * len(UNIT_COLUMNS))})",
              [_plain(row[k]) for k in UNIT_COLUMNS])


@contextmanager
def unit_transaction(store: Store, unit: dict[str, Any]) -> Iterator[dict[str, Any]]:
    """One unit's writes and its catalog_unit row in one transaction. The body fills `unit` (ids, nrows, counts)
    and the row is written with status `done` when it returns; on an exception nothing of the unit is stored."""
    t0 = time.perf_counter()
    with store.transaction():
        yield unit
        unit["status"] = "done"
        unit["write_seconds"] = time.perf_counter() - t0  # the commit itself is not included
        _put_unit(store, unit)


def merge_ik_shards(store: Store, idrobot: int, idscene: int, idikret: int, nq: int, units: list[dict[str, Any]],
                    paths: list[str], stored: bool = True) -> int:
    """The `ik` rows of one IK run's shard files (Parquet, one per unit: idtabletopgrips, feasible (5) and joints
    (5 x nq, NaN where infeasible), as `workbench.catalog.units.ik_unit` writes them) and the units' catalog_unit
    rows, in one transaction; grips that already have a row for the run are left as they are (`stored`: the run may
    have rows already; when False the anti-join is skipped, and the UNIQUE key still refuses a duplicate). Returns
    the rows inserted. A shard that cannot be read is a StoreError naming it."""
    if not paths:
        return 0
    feas = ", ".join(f"f[{k + 1}]" for k in range(len(FEASIBILITY)))
    jnts = ", ".join(f"CASE WHEN f[{k + 1}] THEN j[{k * nq + 1}:{(k + 1) * nq}] END" for k in range(len(JOINTS)))
    t0 = time.perf_counter()
    with store.transaction():
        first = store.next_id("ik", "idik")
        try:
            store.run(
                f"INSERT INTO ik (idik, idrobot, idtabletopgrips, idikret, idscene, {', '.join(FEASIBILITY)}, {', '.join(JOINTS)}) "
                f"SELECT ? - 1 + row_number() OVER (ORDER BY idtabletopgrips), ?, idtabletopgrips, ?, ?, {feas}, {jnts} "
                "FROM (SELECT idtabletopgrips, feasible::BOOLEAN[] AS f, joints::DOUBLE[] AS j FROM read_parquet(?)) s "
                + ("WHERE idtabletopgrips NOT IN (SELECT idtabletopgrips FROM ik WHERE idrobot = ? AND idscene = ? AND idikret = ?)"
                   if stored else ""),
                [first, idrobot, idikret, idscene, list(paths)] + ([idrobot, idscene, idikret] if stored else []))
        except duckdb.IOException as exc:
            raise StoreError(f"a shard of this IK run cannot be read ({str(exc).splitlines()[0]})") from None
        n = store.next_id("ik", "idik") - first
        seconds = (time.perf_counter() - t0) / len(units)
        for unit in units:
            _put_unit(store, {**unit, "status": "done", "write_seconds": seconds})
    return n


def record_failure(store: Store, unit: dict[str, Any], error: str) -> None:
    """Store a failed unit with its one-line reason (it is tried again by the next run)."""
    with store.transaction():
        _put_unit(store, {**unit, "status": "failed", "error": error})


def failures(store: Store) -> list[dict[str, Any]]:
    """Failed units (no `done` row of the same part, kind, robot and IK chunk since): part, kind, robot, source, error."""
    rows = store.run(
        "SELECT f.part, f.kind, f.robot, f.source, f.error FROM catalog_unit f WHERE f.status = 'failed' AND NOT EXISTS "
        "(SELECT 1 FROM catalog_unit d WHERE d.status = 'done' AND d.part = f.part AND d.kind = f.kind "
        "AND d.robot IS NOT DISTINCT FROM f.robot AND d.chunk IS NOT DISTINCT FROM f.chunk AND d.created >= f.created) "
        "ORDER BY f.part, f.kind, f.robot, f.chunk")
    return [dict(zip(("part", "kind", "robot", "source", "error"), r)) for r in rows]


def summary(store: Store) -> list[dict[str, Any]]:
    """One row per stored (part, robot) of the catalogue (the newest build of each), from the stage tables themselves: free-air grasps, stable
    placements, tabletop grips, IK rows and how many are feasible at all five poses (grasp, retractions, lifts), graph components and nodes
    (from the graph unit), and seconds of worker time for the part's stages and the robot's IK and graph."""
    sql = f"""
    WITH part AS (  -- the newest part unit of each part name (a store may hold builds with other parameters)
        SELECT part, idobject, idgrasps, idplacements, idtabletop, seconds, counts FROM catalog_unit
        WHERE kind = 'part' AND status = 'done' QUALIFY row_number() OVER (PARTITION BY part ORDER BY created DESC) = 1),
    robot AS (  -- per part, tabletop set and robot: the newest IK run (robot, scene, retractions)
        SELECT part, robot, idtabletop, idrobot, idscene, idikret,
               sum(seconds) FILTER (WHERE kind = 'ik') AS ik_seconds,
               sum(seconds) FILTER (WHERE kind = 'graph') AS graph_seconds,
               max(counts) FILTER (WHERE kind = 'graph') AS graph
        FROM catalog_unit WHERE kind IN ('ik', 'graph') AND status = 'done'
        GROUP BY part, robot, idtabletop, idrobot, idscene, idikret
        QUALIFY row_number() OVER (PARTITION BY part, robot, idtabletop ORDER BY max(created) DESC) = 1)
    SELECT p.part, r.robot,
        (SELECT count(*) FROM freeairgrip f WHERE f.idparamset = p.idgrasps) AS grasps,
        (SELECT count(*) FROM freetabletopplacement f WHERE f.idparamset = p.idplacements) AS placements,
        (SELECT count(*) FROM tabletopgrips g JOIN tabletopplacements t USING (idtabletopplacements)
            WHERE t.idparamset = p.idtabletop) AS tabletop_grips,
        (SELECT count(*) FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements t
            USING (idtabletopplacements) WHERE t.idparamset = p.idtabletop AND k.idrobot = r.idrobot
            AND k.idscene = r.idscene AND k.idikret = r.idikret) AS ik_rows,
        (SELECT count(*) FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements t
            USING (idtabletopplacements) WHERE t.idparamset = p.idtabletop AND k.idrobot = r.idrobot
            AND k.idscene = r.idscene AND k.idikret = r.idikret
            AND {ALL_FEASIBLE}) AS ik_feasible,
        r.graph, p.seconds AS part_seconds, r.ik_seconds, r.graph_seconds, p.counts AS part_counts
    FROM part p LEFT JOIN robot r ON r.part = p.part AND r.idtabletop = p.idtabletop ORDER BY p.part, r.robot"""
    keys = ("part", "robot", "grasps", "placements", "tabletop_grips", "ik_rows", "ik_feasible", "graph",
            "part_seconds", "ik_seconds", "graph_seconds", "part_counts")
    out = []
    for r in store.run(sql):
        d = dict(zip(keys, r))
        d["graph"] = json.loads(d["graph"]) if d["graph"] else {}
        d["reason"] = json.loads(d.pop("part_counts") or "{}").get("reason")  # why a stage kept nothing
        out.append(d)
    return out


def unit_times(store: Store) -> list[dict[str, Any]]:
    """Per stored unit: kind, part, robot, worker seconds, driver write seconds, rows written."""
    rows = store.run("SELECT kind, part, robot, seconds, write_seconds, nrows FROM catalog_unit WHERE status = 'done' "
                     "ORDER BY part, robot, kind, chunk")
    return [dict(zip(("kind", "part", "robot", "seconds", "write_seconds", "nrows"), r)) for r in rows]


def stored_part_grips(store: Store, idrobot: int, idscene: int, idikret: int, idtabletop: int) -> np.ndarray:
    """The idtabletopgrips of one tabletop parameter set that already have an `ik` row for this run (sorted)."""
    out = store.query_arrays(
        "SELECT k.idtabletopgrips FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements t "
        "USING (idtabletopplacements) WHERE t.idparamset = ? AND k.idrobot = ? AND k.idscene = ? AND k.idikret = ? "
        "ORDER BY k.idtabletopgrips", [idtabletop, idrobot, idscene, idikret])
    return np.asarray(out["idtabletopgrips"], dtype=np.int64)


def ik_vectors(store: Store, idtabletop: int, idrobot: int, idscene: int, idikret: int) -> np.ndarray:
    """The (N, 5) feasibility flags (`FEASIBILITY` order) of a run over a tabletop parameter set, by idtabletopgrips."""
    out = store.query_arrays(
        f"SELECT {', '.join('k.' + c for c in FEASIBILITY)} FROM ik k JOIN tabletopgrips g "
        "USING (idtabletopgrips) JOIN tabletopplacements t USING (idtabletopplacements) WHERE t.idparamset = ? "
        "AND k.idrobot = ? AND k.idscene = ? AND k.idikret = ? ORDER BY k.idtabletopgrips",
        [idtabletop, idrobot, idscene, idikret])
    return np.stack([np.asarray(out[c], dtype=bool) for c in FEASIBILITY], axis=1).reshape(-1, len(FEASIBILITY))


def _plain(value: Any) -> Any:
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return value.item()
    return value
