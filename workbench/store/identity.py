"""Is this file our store, of which version, and is it readable? (stores that are not ours).

Every store written by this version holds `workbench_meta` (application, schema_version), written in the same
transaction as the schema at creation. Before anything is written, `inspect` reads the file read-only and
classifies it: new (no tables), ours at this version, ours at an older version (upgraded in one transaction),
ours at a newer version, or another program's file (refused: nothing written). Stores of schema 1 predate the
metadata table; they are recognised by their tables and columns. `open_error` turns DuckDB's open failures
(lock, damage, truncation, permissions, a full disk) into one line naming the path and what to do.
"""

from __future__ import annotations

import errno
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import duckdb

from workbench.errors import StoreError

if TYPE_CHECKING:
    from workbench.store import Store

APPLICATION = "regrasp-workbench"
SCHEMA_VERSION = 4  # 1: no metadata, no completion records; 2: workbench_meta and stagedone; 3: plansegment.t in
# plan time (s from the plan's start, CONVENTIONS.md), it was from the segment's start; 4: plan.speed, which the
# lookup of a stored plan reads (a schema-3 store is opened read-write once, to add it)

META_TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS workbench_meta (
        key VARCHAR PRIMARY KEY,
        value VARCHAR NOT NULL
    )""",
    # Completion of stages written in several transactions (the IK stage, chunk by chunk): one row when the
    # last chunk is stored. Stages written in one transaction are complete when their paramset row exists.
    """CREATE TABLE IF NOT EXISTS stagedone (
        stage VARCHAR NOT NULL,
        runkey VARCHAR NOT NULL,
        rows BIGINT NOT NULL,
        finished TIMESTAMP DEFAULT current_timestamp,
        PRIMARY KEY (stage, runkey)
    )""",
)


IK_STAGE = "ik"


def ik_runkey(idtabletop: int, idrobot: int, idscene: int, idikret: int) -> str:
    """The completion key of one IK run: its tabletop parameter set, robot, scene and retractions."""
    return f"tabletop={int(idtabletop)}:robot={int(idrobot)}:scene={int(idscene)}:ikret={int(idikret)}"


@dataclass(frozen=True)
class Identity:
    """What a file holds: `kind` is new, current, older or newer; `version` its schema version."""

    kind: str
    version: int


def check_path(path: Path, must_exist: bool) -> None:
    """Refuse paths no store can live at: a folder, a missing file to read, a folder that is a regular file."""
    if path.is_dir():
        raise StoreError(f"store path {path} is a folder; give a file path such as {path / 'regrasp.duckdb'}")
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise StoreError(f"store path {path}: {parent} is a file, not a folder; choose a store path inside a folder")
            break
    if must_exist and not path.exists():
        raise StoreError(f"store {path} does not exist; build it first (workbench build, or workbench grasps MESH --db {path})")
    if path.exists() and not path.is_file():
        raise StoreError(f"store path {path} is not a regular file; give a file path")


def open_error(path: Path, exc: BaseException, waited: float = 0.0) -> StoreError:
    """One line for a file DuckDB cannot open or write: what happened and what to do (`waited`: the seconds a busy
    store was waited for)."""
    msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    low = msg.lower()
    if is_lock_error(exc):
        held = re.search(r"\(PID (\d+)\)", msg)
        who = f"process {held.group(1)}" if held else "another process"
        if waited > 0:
            return StoreError(f"store {path} is still busy after waiting {waited:g} s: locked by {who} that is writing "
                              f"it (or a notebook kernel holding it); retry when it is done, or give a longer --wait")
        return StoreError(f"store {path} is busy: locked by {who} that is writing it (or a notebook kernel holding it); "
                          f"retry when it is done, or give --wait SECONDS to wait for it")
    if "different configuration" in low:
        return StoreError(f"store {path} is already open in this process in another mode (read-only or read-write); "
                          f"use the open Store, or close it first")
    if is_disk_full(exc):
        return StoreError(f"store {path}: the disk is full ({msg}); free space or use a store on another disk, then re-run "
                          f"(completed stages are kept)")
    if "permission" in low or isinstance(exc, PermissionError):
        return StoreError(f"store {path} cannot be written (permission denied); use a store path you can write")
    if "not a valid duckdb" in low:
        return StoreError(f"store {path} is damaged or not a DuckDB database; restore it from a backup, or move it aside "
                          f"and rebuild it with `workbench build`")
    if "could not read enough bytes" in low:
        return StoreError(f"store {path} is damaged (truncated: shorter than its own header says); restore it from a "
                          f"backup, or move it aside and rebuild it with `workbench build`")
    if "checksum" in low:
        return StoreError(f"store {path} is damaged (a block fails its checksum: the file was changed outside DuckDB); "
                          f"restore it from a backup, or move it aside and rebuild it with `workbench build`")
    if any(w in low for w in ("not a valid duckdb", "could not read enough bytes", "checksum", "corrupt", "serializ",
                              "invalid", "unexpected", "magic", "failed to read", "truncat", "malformed")):
        return StoreError(f"store {path} is damaged (truncated or corrupt: {msg[:120]}); restore it from a backup, or move "
                          f"it aside and rebuild it with `workbench build`")
    return StoreError(f"store {path} could not be opened ({msg[:160]}); move it aside and rebuild it, or give another path")


def is_interrupt(exc: BaseException) -> bool:
    """Whether DuckDB stopped a statement for a Ctrl-C (an InterruptException, or a RuntimeError 'Query interrupted')."""
    return isinstance(exc, duckdb.InterruptException) or (isinstance(exc, RuntimeError) and "interrupted" in str(exc).lower())


def is_lock_error(exc: BaseException) -> bool:
    """Whether DuckDB refused the file because another process holds its lock (worth waiting for)."""
    return "could not set lock" in str(exc).lower() or "conflicting lock" in str(exc).lower()


HEADER_BYTES = 3 * 4096  # DuckDB's file header and its two database headers, before the first block


def check_size(con: duckdb.DuckDBPyConnection, path: Path) -> None:
    """Refuse a file shorter than the blocks its own header counts (a truncated copy or an interrupted transfer):
    DuckDB would open it and fail on the first read of a missing block, deep inside a command."""
    rows = con.execute("SELECT block_size, total_blocks, free_blocks FROM pragma_database_size() "
                       "WHERE database_name = current_database()").fetchall()  # fetched whole: DuckDB refuses new
    if not rows:                                                                # work while a result is unfinished
        return
    row = rows[0]
    # free blocks at the end of the file are counted but never written: a sound file may be that much shorter
    expected = HEADER_BYTES + int(row[0]) * (int(row[1]) - int(row[2]))
    size = path.stat().st_size
    if size < expected:
        raise StoreError(f"store {path} is damaged (truncated: {size:,} of its {expected:,} bytes); restore it from a "
                         f"backup, or move it aside and rebuild it with `workbench build`")


# the command that makes each table created on first use (a store built by `workbench build` has none of them)
TABLE_MAKERS = {"tgraspclass": "gptable", "tgptable": "gptable", "tplacementclass": "gptable", "tgpcell": "gptable",
                "catalog_unit": "catalog build"}


def read_error(path: Path, exc: BaseException) -> BaseException:
    """One line for a query the file cannot answer: a damaged or truncated block (I/O, checksum, fatal), or a
    table of a stage this store never ran; a query interrupted by Ctrl-C is a KeyboardInterrupt. Other errors (our
    own bugs, constraint violations) pass unchanged."""
    if is_interrupt(exc):
        return KeyboardInterrupt()  # Ctrl-C inside a query: the command stops as for any other interrupt
    if not isinstance(exc, duckdb.Error):
        return exc
    if isinstance(exc, duckdb.CatalogException):
        m = re.search(r"Table with name (\w+) does not exist", str(exc))
        if m:
            table = m.group(1)
            maker = TABLE_MAKERS.get(table)
            hint = f"`workbench {maker}` makes it; run that first" if maker else "it was built by another command or version"
            return StoreError(f"store {path} has no {table} table: {hint}")
        return exc
    if isinstance(exc, (duckdb.IOException, duckdb.FatalException, duckdb.InternalException, duckdb.SerializationException)) \
            or any(w in str(exc).lower() for w in ("corrupt", "checksum", "no magic bytes")):  # a damaged Parquet file too
        return open_error(path, exc)
    return exc


def is_disk_full(exc: BaseException) -> bool:
    """Whether an exception from a write means the disk or the file size limit is full."""
    if isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        return True
    low = str(exc).lower()
    return "no space left" in low or "file too large" in low or "disk quota" in low


def _columns(con: duckdb.DuckDBPyConnection) -> dict[str, set[str]]:
    rows = con.execute("SELECT table_name, column_name FROM information_schema.columns "
                       "WHERE table_schema = 'main' ORDER BY table_name").fetchall()
    out: dict[str, set[str]] = {}
    for table, column in rows:
        out.setdefault(table, set()).add(column)
    return out


def reference_columns(ddl: tuple[str, ...]) -> dict[str, set[str]]:
    """Our tables and columns, from the schema's own statements run on an in-memory database."""
    con = duckdb.connect(":memory:")
    try:
        for stmt in ddl:
            con.execute(stmt)
        return _columns(con)
    finally:
        con.close()


def inspect(con: duckdb.DuckDBPyConnection, path: Path, ddl: tuple[str, ...]) -> Identity:
    """Classify an open file (read-only use: nothing is written); raise StoreError for foreign or newer stores."""
    have = _columns(con)
    if not have:
        return Identity("new", SCHEMA_VERSION)
    if "workbench_meta" in have:
        meta = dict(con.execute("SELECT key, value FROM workbench_meta").fetchall())
        if meta.get("application") != APPLICATION:
            raise StoreError(f"store {path} is not a workbench store (its workbench_meta names {meta.get('application')!r}); "
                             f"give a new file for --db")
        try:
            version = int(meta.get("schema_version", "0"))
        except ValueError:
            version = -1
        if version > SCHEMA_VERSION:
            raise StoreError(f"store {path} was written by a newer workbench (schema {meta.get('schema_version')}, this one "
                             f"reads up to {SCHEMA_VERSION}); upgrade the workbench or give another file")
        if version < 1:
            raise StoreError(f"store {path} has an unknown schema version {meta.get('schema_version')!r}; give a new file")
        return Identity("current" if version == SCHEMA_VERSION else "older", version)
    ours = reference_columns(ddl)
    # a schema-1 store: our core tables with our columns (extra tables, e.g. a catalogue's, are allowed)
    core = [t for t in ("object", "paramset") if t in have]
    clash = sorted(t for t, cols in have.items() if t in ours and not cols <= ours[t])
    lacking = {t: sorted(CORE_COLUMNS[t] - have[t]) for t in core if not CORE_COLUMNS[t] <= have[t]}
    keyless = [t for t in core if t not in lacking and f"id{t}" not in _primary_keys(con, t)]
    if clash or lacking or keyless or len(core) < 2:
        foreign = sorted(t for t in have if t not in ours)
        what = (f"table {clash[0]} with columns {', '.join(sorted(have[clash[0]])[:4])}" if clash else
                f"its own table {next(iter(lacking))}, without our columns {', '.join(next(iter(lacking.values()))[:4])}"
                if lacking else f"its own table {keyless[0]}, whose id{keyless[0]} is not a primary key" if keyless else
                f"tables {', '.join(foreign[:3])}" if foreign else "none of our core tables")
        raise StoreError(f"store {path} is not a workbench store (it holds {what}); give a new file for --db")
    return Identity("older", 1)


# the columns every workbench store has had in its two core tables since the first schema
CORE_COLUMNS = {"object": {"idobject", "name", "digest", "scale", "com", "vertices", "faces"},
                "paramset": {"idparamset", "stage", "digest", "params", "idobject"}}


def _primary_keys(con: duckdb.DuckDBPyConnection, table: str) -> set[str]:
    rows = con.execute("SELECT constraint_column_names FROM duckdb_constraints() WHERE table_name = ? "
                       "AND constraint_type = 'PRIMARY KEY'", [table]).fetchall()
    return {c for (cols,) in rows for c in cols}


def table_names(ddl: tuple[str, ...]) -> list[str]:
    """The table names created by a tuple of CREATE TABLE statements."""
    return [m.group(1) for stmt in ddl for m in [re.search(r"CREATE TABLE IF NOT EXISTS (\w+)", stmt)] if m]


def upgrade(store: Store, version: int) -> None:
    """Bring a store of schema `version` to the current one (inside `Store`'s opening transaction).

    Schema 1 (no `workbench_meta`, no `stagedone`): every stage but IK wrote in one transaction, so its rows are
    complete when its paramset exists; an IK run (written chunk by chunk) is recorded complete when it has a row for
    every tabletop grip of its tabletop parameter set, and left unrecorded (incomplete) otherwise. Schema 2: the knot
    times of `plansegment.t` counted from the segment's start (`t0`); they are moved to plan time."""
    if version < 2:
        rows = store.run(
            "WITH runs AS (SELECT p.idparamset AS tt, k.idrobot, k.idscene, k.idikret, count(*) AS n "
            "FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
            "GROUP BY ALL), grips AS (SELECT p.idparamset AS tt, count(*) AS n FROM tabletopgrips g "
            "JOIN tabletopplacements p USING (idtabletopplacements) GROUP BY ALL) "
            "SELECT r.tt, r.idrobot, r.idscene, r.idikret, r.n FROM runs r JOIN grips USING (tt) WHERE r.n = grips.n")
        for tt, robot, scene, ikret, n in rows:
            store.run("INSERT OR REPLACE INTO stagedone (stage, runkey, rows) VALUES (?, ?, ?)",
                      [IK_STAGE, ik_runkey(tt, robot, scene, ikret), int(n)])
    if version < 3:  # knot times from the segment's start -> from the plan's start, every knot at once
        import numpy as np
        import pyarrow as pa
        import pyarrow.compute as pc

        seg = store.con.sql("SELECT idplansegment AS id, t0, t FROM plansegment").to_arrow_table()
        if seg.num_rows:
            t = seg["t"].combine_chunks()
            n = pc.list_value_length(t).to_numpy(zero_copy_only=False)
            shifted = pc.list_flatten(t).to_numpy(zero_copy_only=False) + np.repeat(seg["t0"].to_numpy(), n)
            fix = pa.table({"id": seg["id"], "t": pa.ListArray.from_arrays(np.r_[0, np.cumsum(n)].astype(np.int32), shifted)})
            store.con.register("plansegment_plan_time", fix)
            store.run("UPDATE plansegment SET t = f.t FROM plansegment_plan_time f WHERE plansegment.idplansegment = f.id")
            store.con.unregister("plansegment_plan_time")
