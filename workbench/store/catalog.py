"""SQL of a parts x robots catalogue built on a cluster (`workbench catalog`).

- catalog_unit: one row per finished (or failed) unit of work, keyed by the unit's digest (the mesh file's bytes,
  its scale and name, every stage's parameters, the robot's kinematics, the scene, the retractions and the IK
  chunk). kind is `part` (grasps, placements, tabletop grips), `ik` (one chunk of a part's tabletop grips for a
  robot) or `graph` (the regrasp graph's size for a part and robot). The row is written in the same transaction as
  the unit's rows, so a unit is either stored with all its rows or not at all, and a re-run skips the stored ones.
  status is `done` or `failed` (error holds the one-line reason; failed units are tried again on a re-run).
  seconds: worker compute time; write_seconds: the driver's write transaction; counts: JSON of the unit's sizes.
  idgripper: the unit's gripper row (a catalogue of several grippers has a part unit per part and gripper, and an
  IK run per part, gripper and robot).

Units are written by one process (the driver); workers never open the store.

A catalogue takes one of two forms. A DuckDB file holds every table. A Parquet catalogue is a folder: the rows of
each part (`object`, `freeairgrip`, `freetabletopplacement`, `freetabletopgrip`, `tabletopplacements`,
`tabletopgrips`) are Hive partitions `TABLE/part=NAME/*.parquet`, the IK rows `ik/part=NAME/robot=NAME/*.parquet`,
and the small shared tables (paramset, angle, robot, gripper, scene, ikret, catalog_unit, plans) sit beside them in
`catalog.duckdb`. Opening the folder as a store (`Store(FOLDER)`) reads the partitions through DuckDB views with the
paper's table and column names and types, nothing imported. Each merge writes its files named after its batch,
recorded in `catalog_batch` in the merge's transaction; files of a batch that never committed (a driver killed
during a merge) are deleted when the next build opens the folder.
"""

from __future__ import annotations

import json
import os
import time
from contextlib import contextmanager
from typing import Any, Iterator

import duckdb
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from workbench.errors import StoreError
from pathlib import Path

from workbench.store import CONNECT_CONFIG, Store, _digest
from workbench.store.dataset import (
    DATASET_FILE,
    DATASET_TABLES,
    PARTITIONED,
    dataset_files,
    dataset_views,
    without_references,
)
from workbench.store.identity import APPLICATION, META_TABLES, SCHEMA_VERSION
from workbench.store.schema import ALL_TABLES, MIGRATIONS
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
        created TIMESTAMP DEFAULT current_timestamp,
        idgripper BIGINT
    )""",
    """CREATE TABLE IF NOT EXISTS catalog_batch (
        batch BIGINT PRIMARY KEY,
        created TIMESTAMP DEFAULT current_timestamp
    )""",
)


UNIT_COLUMNS = ("digest", "kind", "part", "source", "robot", "chunk", "idobject", "idgrasps", "idplacements", "idtabletop",
                "idrobot", "idscene", "idikret", "status", "error", "nrows", "counts", "seconds", "write_seconds", "worker",
                "idgripper")


def create_dataset(folder: Path) -> None:
    """A new Parquet catalogue at `folder` (created with its `catalog.duckdb`); an existing one is left as it is."""
    if folder.exists() and not folder.is_dir():
        raise StoreError(f"catalogue path {folder} is a file; a Parquet catalogue is a folder (or give --form duckdb)")
    if (folder / DATASET_FILE).is_file():
        return
    if folder.is_dir() and any(folder.iterdir()):
        raise StoreError(f"folder {folder} is not empty and holds no catalogue; give a new or empty folder")
    folder.mkdir(parents=True, exist_ok=True)
    # the shared tables without foreign keys: the rows they name are in the partitions, not in this file
    tmp = folder / f"{DATASET_FILE}.{os.getpid()}.tmp"
    tmp.unlink(missing_ok=True)
    con = duckdb.connect(str(tmp), config=CONNECT_CONFIG)
    try:
        for ddl in ALL_TABLES + META_TABLES + MIGRATIONS + CATALOG_TABLES:
            con.execute(without_references(ddl))
        con.execute("INSERT INTO workbench_meta VALUES ('application', ?), ('schema_version', ?)",
                    [APPLICATION, str(SCHEMA_VERSION)])
        con.execute("CHECKPOINT")
    finally:
        con.close()
    os.replace(tmp, folder / DATASET_FILE)


def sweep_dataset(store: Store) -> int:
    """Delete a Parquet catalogue's files of batches that never committed (a driver killed during a merge); returns
    how many."""
    batches = {r[0] for r in store.run("SELECT batch FROM catalog_batch")}
    gone = 0
    for table in PARTITIONED:
        for f in store.dataset.glob(f"{table}/{'/'.join('*' for _ in PARTITIONED[table])}/b*_*.parquet"):
            if int(f.name[1:].split("_", 1)[0]) not in batches:
                f.unlink(missing_ok=True)
                gone += 1
    return gone


@contextmanager
def merge_batch(store: Store) -> Iterator[None]:
    """One merge's transaction; in a Parquet catalogue the batch that names its files, recorded when it commits."""
    with store.transaction():
        if store.dataset is None:
            yield
            return
        store._batch = int(store.one("SELECT coalesce(max(batch), 0) + 1 FROM catalog_batch")[0])
        store.run("INSERT INTO catalog_batch (batch) VALUES (?)", [store._batch])
        store._copies = 0
        try:
            yield
        finally:
            del store._batch, store._copies


def _put(store: Store, table: str, columns: str, source: str, args: list, keys: dict[str, str]) -> int:
    """The rows `SELECT columns source` into `table` (by column name), inside the caller's transaction; in a Parquet
    catalogue as the batch's files of the table's partitions (`keys`: the SQL of each Hive key in the select's
    scope). Returns the rows written."""
    if store.dataset is None:
        return _count(store.run(f"INSERT INTO {table} BY NAME SELECT {columns} {source}", args))
    names = PARTITIONED[table]
    stage = f"_wb_stage_{table}"
    store.run(f"CREATE OR REPLACE TEMP TABLE {stage} AS SELECT *, {', '.join(f'NULL::VARCHAR AS {k}' for k in names)} "
              f"FROM {DATASET_TABLES}.{table} LIMIT 0")
    keyed = ", ".join(f"{keys[k]} AS {k}" for k in names)  # a failed statement rolls the temporary table back too
    n = _count(store.run(f"INSERT INTO {stage} BY NAME SELECT {columns}, {keyed} {source}", args))
    if n:
        store._copies += 1  # a file name of its own for every write of the batch
        store.run(f"COPY {stage} TO '{store.dataset}/{table}' (FORMAT parquet, COMPRESSION zstd, PARTITION_BY "
                  f"({', '.join(names)}), FILENAME_PATTERN 'b{store._batch}_{store._copies}_{{i}}', OVERWRITE_OR_IGNORE true)")
    store.run(f"DROP TABLE {stage}")
    if n:
        dataset_views(store, (table,))
    return n


def ensure_catalog_tables(store: Store) -> None:
    """Create the catalogue's tables when missing, and the columns a catalogue written by an earlier version lacks
    (idempotent)."""
    with store.transaction():
        for ddl in CATALOG_TABLES:
            store.run(ddl)
        store.run("ALTER TABLE catalog_unit ADD COLUMN IF NOT EXISTS idgripper BIGINT")


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


def put_units(store: Store, units: list[dict[str, Any]]) -> None:
    """The catalog_unit rows of many finished units (status `done`), replacing earlier rows of their digests (a
    recorded failure), in one insert inside the caller's transaction."""
    if not units:
        return
    rows = {k: [_plain(u.get(k)) for u in units] for k in UNIT_COLUMNS}
    rows["status"] = ["done"] * len(units)
    rows["counts"] = [json.dumps(c or {}, sort_keys=True, default=_plain) for c in rows["counts"]]
    rows["nrows"] = [int(n or 0) for n in rows["nrows"]]
    types = {"chunk": pa.int32(), "nrows": pa.int64(), "seconds": pa.float64(), "write_seconds": pa.float64(),
             **{k: pa.int64() for k in UNIT_COLUMNS if k.startswith("id")}}
    table = pa.table({k: pa.array(v, type=types.get(k, pa.string())) for k, v in rows.items()})
    with store.transaction():
        store.con.register("_wb_units", table)
        try:
            if not all(u.get("fresh") for u in units):
                store.run("DELETE FROM catalog_unit WHERE digest IN (SELECT digest FROM _wb_units)")
            store.run(f"INSERT INTO catalog_unit ({', '.join(UNIT_COLUMNS)}) SELECT {', '.join(UNIT_COLUMNS)} FROM _wb_units")
        finally:
            store.con.unregister("_wb_units")


def merge_ik_runs(store: Store, runs: list[dict[str, Any]]) -> int:
    """The `ik` rows of many IK runs' shard files whose grips have no row yet (`paths`, `idrobot`, `idscene`,
    `idikret`, `nq`, `offset` per run; see `merge_ik_shards`), in one insert per joint count inside the caller's
    transaction; ids follow the runs' order (whatever their joint counts), then the grips'. Returns the rows
    inserted."""
    n = 0
    # each run's first id: the runs before it take as many as their shards hold rows (the footers say)
    sizes = [sum(pq.ParquetFile(str(p)).metadata.num_rows for p in r["paths"]) for r in runs]
    bases = store.next_id("ik", "idik") + np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    for nq in sorted({r["nq"] for r in runs}):
        group = [(k, r) for k, r in enumerate(runs) if r["nq"] == nq and r["paths"]]
        if not group:
            continue
        files = [(str(p), k, r) for k, r in group for p in r["paths"]]
        table = pa.table({"file": [f for f, _, _ in files], "ord": [k for _, k, _ in files],
                          "base": [int(bases[k]) for _, k, _ in files],
                          **{c: [int(r[c]) for _, _, r in files] for c in ("idrobot", "idscene", "idikret", "offset")},
                          **{c: [str(r[c]) for _, _, r in files] for c in ("part", "robot")}})
        with store.transaction():
            store.con.register("_wb_runs", table)
            try:
                n += _put(store, "ik",
                          "r.base - 1 + row_number() OVER (PARTITION BY r.ord ORDER BY s.idtabletopgrips + r.offset) "
                          "AS idik, r.idrobot, "
                          f"s.idtabletopgrips + r.offset AS idtabletopgrips, r.idikret, r.idscene, {_ik_columns(nq)}",
                          "FROM (SELECT filename, idtabletopgrips, feasible::BOOLEAN[] AS f, joints::DOUBLE[] AS j "
                          "FROM read_parquet(?, filename = true)) s JOIN _wb_runs r ON r.file = s.filename",
                          [[f for f, _, _ in files]], {"part": "r.part", "robot": "r.robot"})
            except duckdb.IOException as exc:
                raise StoreError(f"a shard of an IK run cannot be read ({str(exc).splitlines()[0]})") from None
            finally:
                _unregister(store, "_wb_runs")
    return n


def _ik_columns(nq: int) -> str:
    """The `ik` table's feasibility and joint columns from a shard's feasible (`f`, 5) and joints (`j`, 5 x nq)."""
    feas = ", ".join(f"f[{k + 1}] AS {c}" for k, c in enumerate(FEASIBILITY))
    jnts = ", ".join(f"CASE WHEN f[{k + 1}] THEN j[{k * nq + 1}:{(k + 1) * nq}] END AS {c}" for k, c in enumerate(JOINTS))
    return f"{feas}, {jnts}"


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


def merge_ik_shards(store: Store, idrobot: int, idscene: int, idikret: int, nq: int, paths: list[str],
                    offset: int = 0, part: str = "", robot: str = "") -> int:
    """The `ik` rows of one IK run's shard files (Parquet, one per unit: idtabletopgrips, feasible (5) and joints
    (5 x nq, NaN where infeasible), as `workbench.catalog.units.ik_unit` writes them) in one transaction; grips that
    already have a row for the run (stored by `workbench ik`) are left as they are. Returns the rows inserted. The
    shards of a part unit merged from its folder name its tabletop grips by their ids in the unit's range: `offset`
    moves them to the store's ids. `part` and `robot` name the run's partition in a Parquet catalogue. A shard that
    cannot be read is a StoreError naming it."""
    if not paths:
        return 0
    with store.transaction():
        first = store.next_id("ik", "idik")
        try:
            return _put(store, "ik",
                        "? - 1 + row_number() OVER (ORDER BY idtabletopgrips) AS idik, ?::BIGINT AS idrobot, idtabletopgrips, "
                        f"?::BIGINT AS idikret, ?::BIGINT AS idscene, {_ik_columns(nq)}",
                        "FROM (SELECT idtabletopgrips + ? AS idtabletopgrips, feasible::BOOLEAN[] AS f, joints::DOUBLE[] AS j "
                        "FROM read_parquet(?)) s WHERE idtabletopgrips NOT IN "
                        "(SELECT idtabletopgrips FROM ik WHERE idrobot = ? AND idscene = ? AND idikret = ?)",
                        [first, idrobot, idikret, idscene, int(offset), list(paths), idrobot, idscene, idikret],
                        {"part": _literal(part), "robot": _literal(robot)})
        except duckdb.IOException as exc:
            raise StoreError(f"a shard of this IK run cannot be read ({str(exc).splitlines()[0]})") from None


UNIT_TABLES = ("object", "paramset", "freeairgrip", "freetabletopplacement", "freetabletopgrip", "angle",
               "tabletopplacements", "tabletopgrips")  # a part unit's rows, in the order their foreign keys need


def export_tables(store: Store, tables: tuple[str, ...] = UNIT_TABLES) -> dict[str, pa.Table]:
    """Every row of `tables` as Arrow tables (a scratch store's unit, to be written as Parquet files)."""
    return {t: store.con.sql(f"SELECT * FROM {t} ORDER BY 1").to_arrow_table() for t in tables}


# a part unit's rows, numbered from 1 in its scratch store, are renumbered at the merge into the store's sequences;
# the columns naming them
RENUMBERED: dict[str, tuple[str, ...]] = {
    "object": ("idobject",),
    "paramset": ("idparamset", "idobject"),
    "freeairgrip": ("idfreeairgrip", "idobject", "idparamset"),
    "freetabletopplacement": ("idfreetabletopplacement", "idobject", "idparamset"),
    "freetabletopgrip": ("idfreetabletopgrip", "idfreetabletopplacement", "idfreeairgrip"),
    "tabletopplacements": ("idtabletopplacements", "idfreetabletopplacement", "idparamset"),
    "tabletopgrips": ("idtabletopgrips", "idtabletopplacements", "idfreeairgrip", "idfreetabletopgrip"),
}
PARAMSET_REFS = ("grasps", "placements")  # keys of a stage's parameters naming the parameter set it consumed


def merge_part_files(store: Store, folders: list[str], counts: list[dict[str, int]], idgripper: list[int],
                     names: list[str]) -> list[dict[str, int]]:
    """The rows of part units left as Parquet folders (`<folder>/<table>.parquet` for `UNIT_TABLES`, each table's
    ids counting from 1, `counts` rows per table) in the caller's transaction. Ids are renumbered into the store's
    sequences (each unit's ids move by one offset per table, returned per unit), the parameter sets' digests are
    computed again with their new ids, the free-air grasps take their unit's gripper row (`idgripper`, one per
    folder), and angles already stored are reused by value. A part stored already (by another gripper's unit) keeps
    its object row, which the unit's rows then name; one of the same name with other geometry is a StoreError.
    `names`: the parts' names (their partitions in a Parquet catalogue). An unreadable file is a StoreError naming
    the problem."""
    if not folders:
        return []
    files = {t: [f"{d}/{t}.parquet" for d in folders] for t in UNIT_TABLES}
    nxt = {t: store.next_id(t, f"id{t}") for t in RENUMBERED}
    stored = {n: (int(i), dg) for n, i, dg in store.run("SELECT name, idobject, digest FROM object WHERE list_contains(?, name)",
                                                       [sorted(set(names))])}
    offsets, new_object = [], []
    for c, name, digest in zip(counts, names, _object_digests(folders)):
        o = {t: nxt[t] - 1 for t in RENUMBERED}
        new_object.append(name not in stored)
        if name in stored:  # the unit's one object (id 1) is the stored row
            if stored[name][1] != digest:
                raise StoreError(f"the catalogue holds part {name!r} built from another file or scale; build this one "
                                 f"into a new catalogue or rename its file")
            o["object"] = stored[name][0] - 1
        else:
            stored[name] = (nxt["object"], digest)
        offsets.append(o)
        for t in RENUMBERED:
            if t != "object" or new_object[-1]:
                nxt[t] += int(c.get(t, 0))
    rows = [(f"{d}/{t}.parquet", name, gid, new, *(o[r] for r in RENUMBERED))
            for d, name, gid, new, o in zip(folders, names, idgripper, new_object, offsets) for t in UNIT_TABLES]
    table = pa.table({"file": [r[0] for r in rows], "part": [r[1] for r in rows],
                      "idgripper": pa.array([r[2] for r in rows], type=pa.int64()), "new_object": [r[3] for r in rows],
                      **{f"d_{t}": [r[k + 4] for r in rows] for k, t in enumerate(RENUMBERED)}})
    try:
        with store.transaction():
            store.con.register("_wb_offsets", table)
            try:
                for t in ("object", "freeairgrip", "freetabletopplacement", "freetabletopgrip", "tabletopplacements",
                          "tabletopgrips"):
                    if t == "freeairgrip":
                        _insert_renumbered(store, "paramset", folders, offsets)
                    if t == "tabletopplacements":
                        _insert_angles(store, files["angle"])
                    swap = [f"x.{c} + o.d_{c[2:]} AS {c}" for c in RENUMBERED[t]]
                    angle, args = "WHERE o.new_object" if t == "object" else "", [files[t]]
                    if t == "freeairgrip":
                        swap.append("o.idgripper AS idgripper")
                    if t == "tabletopplacements":  # the unit's angle ids -> the store's, by value
                        swap.append("a.idangle AS idangle")
                        angle = ("JOIN read_parquet(?, filename = true) u ON u.idangle = x.idangle AND "
                                 "replace(u.filename, '/angle.parquet', '') = replace(x.filename, '/tabletopplacements.parquet', '') "
                                 "JOIN (SELECT value, min(idangle) AS idangle FROM angle GROUP BY value) a "
                                 "ON abs(a.value - u.value) < 1e-9 ")
                        args.append(files["angle"])
                    _put(store, t, f"x.* EXCLUDE (filename) REPLACE ({', '.join(swap)})",
                         f"FROM read_parquet(?, filename = true) x JOIN _wb_offsets o ON o.file = x.filename {angle}", args,
                         {"part": "o.part"})
            finally:
                _unregister(store, "_wb_offsets")
    except duckdb.IOException as exc:
        raise StoreError(f"a part unit's file cannot be read ({str(exc).splitlines()[0]})") from None
    return offsets


def _object_digests(folders: list[str]) -> list[str]:
    """The digest of each part unit folder's object."""
    out = []
    for d in folders:
        try:
            out.append(pq.read_table(f"{d}/object.parquet", columns=["digest"]).column("digest")[0].as_py())
        except (OSError, pa.ArrowException, IndexError, KeyError) as exc:
            raise StoreError(f"a part unit's file cannot be read ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})") from None
    return out


def _insert_renumbered(store: Store, table: str, folders: list[str], offsets: list[dict[str, int]]) -> None:
    """The units' parameter sets with their ids renumbered and their digests computed again (a stage's parameters
    name the parameter set it consumed, and the digest covers them and the object)."""
    rows, unit = [], []
    for k, d in enumerate(folders):
        part = pq.read_table(f"{d}/{table}.parquet").to_pylist()
        rows += part
        unit += [offsets[k]] * len(part)
    out: dict[str, list] = {"idparamset": [], "stage": [], "digest": [], "params": [], "idobject": [], "created": []}
    for r, o in zip(rows, unit):
        params = json.loads(r["params"])
        for key in PARAMSET_REFS:
            if isinstance(params.get(key), int):
                params[key] += o["paramset"]
        oid = None if r["idobject"] is None else int(r["idobject"]) + o["object"]
        out["idparamset"].append(int(r["idparamset"]) + o["paramset"])
        out["stage"].append(r["stage"])
        out["digest"].append(_digest(r["stage"], params, oid))
        out["params"].append(json.dumps(params, sort_keys=True))
        out["idobject"].append(oid)
        out["created"].append(r["created"])
    extra = [k for k in rows[0] if k not in out] if rows else []
    for k in extra:  # columns added by later schema versions (the stage's use counter), as written
        out[k] = [r[k] for r in rows]
    arrow = pa.table(out)
    store.con.register("_wb_rows", arrow)
    try:
        store.run(f"INSERT INTO {table} BY NAME SELECT * FROM _wb_rows")
    finally:
        _unregister(store, "_wb_rows")


def _insert_angles(store: Store, files: list[str]) -> None:
    """Angle values not stored yet, with new ids."""
    first = store.next_id("angle", "idangle")
    store.run("INSERT INTO angle (idangle, value) SELECT ? - 1 + row_number() OVER (ORDER BY value), value FROM "
              "(SELECT DISTINCT value FROM read_parquet(?) u WHERE NOT EXISTS "
              "(SELECT 1 FROM angle a WHERE abs(a.value - u.value) < 1e-9))", [first, files])


def _unregister(store: Store, name: str) -> None:
    """Drop a registered Arrow table; after a failed statement the connection refuses it, and that error is the one
    to report."""
    try:
        store.con.unregister(name)
    except duckdb.Error:
        pass


def _literal(text: str) -> str:
    return "'" + str(text).replace("'", "''") + "'"


def _count(rows: list[tuple]) -> int:
    return int(rows[0][0]) if rows else 0


def checkpoint(store: Store) -> None:
    """CHECKPOINT: the write-ahead log folded into the file."""
    store.run("CHECKPOINT")


def object_names(store: Store) -> set[str]:
    """The names of the stored objects."""
    return {r[0] for r in store.run("SELECT name FROM object")}


def record_failure(store: Store, unit: dict[str, Any], error: str) -> None:
    """Store a failed unit with its one-line reason (it is tried again by the next run)."""
    with store.transaction():
        _put_unit(store, {**unit, "status": "failed", "error": error})


def _units(store: Store) -> str:
    """catalog_unit, with a NULL idgripper in a catalogue written before units named their gripper (opened read-only)."""
    has = store.one("SELECT count(*) FROM duckdb_columns() WHERE table_name = 'catalog_unit' AND column_name = 'idgripper' "
                    "AND database_name = current_database()")[0]
    return "catalog_unit" if has else "(SELECT *, NULL::BIGINT AS idgripper FROM catalog_unit)"


def failures(store: Store) -> list[dict[str, Any]]:
    """Failed units (no `done` row of the same part, gripper, kind, robot and IK chunk since): part, kind, robot,
    gripper (its name), source, error."""
    units = _units(store)
    rows = store.run(
        f"SELECT f.part, f.kind, f.robot, (SELECT name FROM gripper g WHERE g.idgripper = f.idgripper), f.source, f.error "
        f"FROM {units} f WHERE f.status = 'failed' AND NOT EXISTS "
        f"(SELECT 1 FROM {units} d WHERE d.status = 'done' AND d.part = f.part AND d.kind = f.kind "
        "AND d.robot IS NOT DISTINCT FROM f.robot AND d.chunk IS NOT DISTINCT FROM f.chunk "
        "AND d.idgripper IS NOT DISTINCT FROM f.idgripper AND d.created >= f.created) "
        "ORDER BY f.part, f.idgripper, f.kind, f.robot, f.chunk")
    return [dict(zip(("part", "kind", "robot", "gripper", "source", "error"), r)) for r in rows]


def summary(store: Store) -> list[dict[str, Any]]:
    """One row per stored (part, gripper, robot) of the catalogue (the newest build of each), from the stage tables themselves: free-air grasps, stable
    placements, tabletop grips, IK rows and how many are feasible at all five poses (grasp, retractions, lifts), graph components and nodes
    (from the graph unit), and seconds of worker time for the part's stages and the robot's IK and graph."""
    sql = f"""
    WITH part AS (  -- the newest part unit of each part and gripper (a store may hold builds with other parameters)
        SELECT part, idgripper, idobject, idgrasps, idplacements, idtabletop, seconds, counts FROM {_units(store)}
        WHERE kind = 'part' AND status = 'done'
        QUALIFY row_number() OVER (PARTITION BY part, idgripper ORDER BY created DESC) = 1),
    robot AS (  -- per part, tabletop set and robot: the newest IK run (robot, scene, retractions)
        SELECT part, robot, idtabletop, idrobot, idscene, idikret,
               sum(seconds) FILTER (WHERE kind = 'ik') AS ik_seconds,
               sum(seconds) FILTER (WHERE kind = 'graph') AS graph_seconds,
               max(counts) FILTER (WHERE kind = 'graph') AS graph
        FROM catalog_unit WHERE kind IN ('ik', 'graph') AND status = 'done'
        GROUP BY part, robot, idtabletop, idrobot, idscene, idikret
        QUALIFY row_number() OVER (PARTITION BY part, robot, idtabletop ORDER BY max(created) DESC) = 1)
    SELECT p.part, r.robot, (SELECT name FROM gripper g WHERE g.idgripper = p.idgripper) AS gripper,
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
    FROM part p LEFT JOIN robot r ON r.part = p.part AND r.idtabletop = p.idtabletop ORDER BY p.part, p.idgripper, r.robot"""
    keys = ("part", "robot", "gripper", "grasps", "placements", "tabletop_grips", "ik_rows", "ik_feasible", "graph",
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
