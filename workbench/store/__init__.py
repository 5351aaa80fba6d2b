"""The DuckDB store: the only place with SQL (CONVENTIONS.md, Store).

`Store` owns the connection, the schema and the transaction discipline: each stage writes inside one
`store.transaction()`, so an interrupted run leaves the file as it was. Bulk rows go in as Arrow tables
(`insert`), and reads come back as numpy arrays. Domain modules (`grasps`, `placements`, `robots`,
`fingers`, `plans`) hold the SQL of each stage and take a `Store`. Use `store.run` / `store.one` rather than
`con.execute(...).fetchone()`: DuckDB refuses new work while a result is unfinished.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import signal
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import duckdb
import numpy as np
import pyarrow as pa

from workbench.errors import StoreError
from workbench.store.dataset import DATASET_FILE, DATASET_TABLES, dataset_views, without_references
from workbench.params import WAIT_ENV
from workbench.store.identity import (
    APPLICATION,
    META_TABLES,
    SCHEMA_VERSION,
    check_path,
    check_size,
    inspect,
    is_disk_full,
    is_interrupt,
    is_lock_error,
    open_error,
    read_error,
    upgrade,
)
from workbench.store.schema import ALL_TABLES, MIGRATIONS

CONNECT_CONFIG = {"autoinstall_known_extensions": False}
FAULT_ENV = "WORKBENCH_FAULT"  # tests only: "TABLE:N:SIGNAL" sends SIGNAL to this process after the N-th insert into TABLE
REACQUIRE_SECONDS = 60.0  # a run that released the store to compute waits at least this long to write its results
_INSERT = re.compile(r"\s*INSERT\s+(?:OR\s+\w+\s+)?INTO\s+(\w+)", re.IGNORECASE)


class Store:
    """An open DuckDB store file (created with the full schema when new)."""

    @classmethod
    def scratch(cls, extra_tables: tuple[str, ...] = ()) -> "Store":
        """An in-memory store with the full schema (and `extra_tables`' DDL): a catalogue worker writes a unit's rows
        in it with the stage writers, then exports them as Parquet files."""
        self = cls.__new__(cls)
        self.path, self._depth, self.read_only, self._fault, self._released = Path(":memory:"), 0, False, None, 0
        self._wait, self._con, self._closed = 0.0, None, False
        self.dataset = None
        self.con = duckdb.connect(":memory:", config=CONNECT_CONFIG)
        self.con.execute("SET threads = 1")
        with self.transaction():
            for ddl in ALL_TABLES + MIGRATIONS + extra_tables:
                self.run(ddl)
        return self

    def __init__(self, path: str | Path, read_only: bool = False, create: bool = True, wait: float | None = None):
        """Open (or, unless `create` is False, create) the store at `path`: its identity, version and length are
        checked before anything is written (workbench.store.identity). A file another process holds is waited for
        up to `wait` seconds (default: WORKBENCH_WAIT, else 0), then refused as busy."""
        self.path = Path(path)
        self.dataset: Path | None = None  # a Parquet catalogue folder: its partitioned tables are read as views
        if self.path.is_dir() and (self.path / DATASET_FILE).is_file():
            self.dataset, self.path = self.path, self.path / DATASET_FILE
        self._wait = _wait_seconds() if wait is None else max(0.0, float(wait))
        self._deadline = time.monotonic() + self._wait
        self._depth = 0  # open transaction() levels
        self._released = 0  # open released() levels: each outermost transaction gives the file back when it ends
        self._con: duckdb.DuckDBPyConnection | None = None
        self._closed = False
        self.read_only = read_only
        check_path(self.path, read_only or not create)
        if self.path.exists():
            self.con = self._open_checked(read_only)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.con = self._connect(read_only=False)
            self.identity = inspect(self.con, self.path, ALL_TABLES + META_TABLES + MIGRATIONS)
        self._fault = _parse_fault(os.environ.get(FAULT_ENV, ""))
        if not read_only:  # idempotent: tables added since this file was created appear
            try:
                self._create()
            except (StoreError, duckdb.Error) as exc:
                self.con.close()
                if isinstance(exc, duckdb.Error):
                    raise self._open_error(exc) from None
                raise
        if self.dataset is not None:
            dataset_views(self)

    @property
    def con(self) -> duckdb.DuckDBPyConnection:
        """The DuckDB connection; opened again here after `released` gave the file back (waiting for its lock)."""
        if self._con is None:
            if self._closed:
                raise StoreError(f"store {self.path} was closed; open it again")
            self._deadline = time.monotonic() + max(self._wait, REACQUIRE_SECONDS)
            self._con = self._connect(self.read_only)
            if self.dataset is not None:
                dataset_views(self)  # the views live on the connection
        return self._con

    @con.setter
    def con(self, value: duckdb.DuckDBPyConnection | None) -> None:
        self._con = value

    @contextmanager
    def released(self) -> Iterator["Store"]:
        """Computation that other processes may write beside: the file's lock is given back now and after each
        outermost transaction inside the block, and taken again (waiting up to --wait, at least REACQUIRE_SECONDS)
        at the next read or write. Inside a transaction, or on an in-memory store, nothing is released."""
        if self._depth or str(self.path) == ":memory:":
            yield self
            return
        self._released += 1
        self._give_back()
        try:
            yield self
        finally:
            self._released -= 1

    def _give_back(self) -> None:
        if self._con is not None:
            self._con.close()
            self._con = None

    def _open_checked(self, read_only: bool) -> duckdb.DuckDBPyConnection:
        """A connection to an existing file whose identity and version were checked first, on a read-only connection
        (a foreign or newer file is left untouched); when this process already holds the file read-write, on that
        configuration, still before anything is written."""
        checked_read_only = True
        try:
            con = self._connect(read_only=True, translate=False)
        except duckdb.Error as exc:
            if "different configuration" not in str(exc):
                raise self._open_error(exc) from None
            con, checked_read_only = self._connect(read_only), read_only
        try:
            self.identity = inspect(con, self.path, ALL_TABLES + META_TABLES + MIGRATIONS)
            check_size(con, self.path)
        except BaseException as exc:
            con.close()
            if isinstance(exc, duckdb.Error):
                raise self._open_error(exc) from None
            raise
        if checked_read_only != read_only:
            con.close()
            con = self._connect(read_only)
        return con

    def _connect(self, read_only: bool, translate: bool = True) -> duckdb.DuckDBPyConnection:
        """A connection, retried while another process holds the file's lock and the wait lasts."""
        while True:
            try:
                # never reach for the network: replaying a WAL that holds our DDL otherwise tries to install core_functions
                return duckdb.connect(str(self.path), read_only=read_only, config=CONNECT_CONFIG)
            except (duckdb.Error, OSError) as exc:
                if is_lock_error(exc) and time.monotonic() < self._deadline:
                    time.sleep(0.1)
                    continue
                if not translate and isinstance(exc, duckdb.Error):
                    raise
                raise self._open_error(exc) from None

    def _create(self) -> None:
        """The schema and metadata of a new store, or the upgrade of an older one, in one transaction."""
        current = self.identity.kind == "current"
        with self.transaction():
            for ddl in ALL_TABLES + META_TABLES + MIGRATIONS:
                self.run(ddl)  # IF NOT EXISTS: tables added to this schema version since the file was made
            if not current:
                self.run("INSERT OR REPLACE INTO workbench_meta VALUES ('application', ?), ('schema_version', ?)",
                         [APPLICATION, str(SCHEMA_VERSION)])
            if self.identity.kind == "older":
                upgrade(self, self.identity.version)
        if not current:
            self.con.execute("CHECKPOINT")  # the schema in the file itself, not only in the WAL

    def close(self) -> None:
        self._give_back()
        self._closed = True

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def transaction(self) -> Iterator[duckdb.DuckDBPyConnection]:
        """One stage's writes: committed together or not at all. A write the disk refuses (full, damaged) becomes
        a one-line StoreError; the store keeps what was committed before.

        The convention: every function that writes opens `transaction()`; one opened inside another joins the
        outermost, so a stage that calls several writers (an object, a gripper, its rows) still commits once,
        and an error anywhere rolls the whole stage back."""
        if self._depth:
            self._depth += 1
            try:
                yield self.con
            finally:
                self._depth -= 1
            return
        self.run("BEGIN TRANSACTION")
        self._depth = 1
        try:
            yield self.con
        except BaseException as exc:
            self._depth = 0
            self._rollback()
            if isinstance(exc, duckdb.Error):
                raise self._write_error(exc) from None
            raise
        else:
            self._depth = 0
            try:
                self.con.execute("COMMIT")
            except (duckdb.Error, RuntimeError) as exc:  # DuckDB reports a Ctrl-C during COMMIT as RuntimeError
                self._rollback()
                if is_interrupt(exc):
                    raise KeyboardInterrupt from None
                if not isinstance(exc, duckdb.Error):
                    raise
                raise self._write_error(exc) from None
        finally:
            if self._released and not self._depth:
                self._give_back()

    def _rollback(self) -> None:
        try:
            self.con.execute("ROLLBACK")
        except (duckdb.Error, RuntimeError):
            pass  # the failed statement (or COMMIT) already ended the transaction

    def _write_error(self, exc: BaseException) -> BaseException:
        if is_disk_full(exc) or isinstance(exc, (duckdb.IOException, duckdb.FatalException)):
            return self._open_error(exc)
        return exc

    def _open_error(self, exc: BaseException) -> StoreError:
        """`identity.open_error` for this store, naming how long it waited for a busy file."""
        return open_error(self.path, exc, self._wait)

    def run(self, sql: str, params: list[Any] | tuple[Any, ...] = ()) -> list[tuple]:
        """Execute one statement with bound parameters and return all its rows (DuckDB needs results finished).
        A damaged block or a missing stage's table is a one-line StoreError (`identity.read_error`)."""
        if self.dataset is not None and sql.lstrip().startswith("CREATE TABLE"):
            sql = without_references(sql)  # a Parquet catalogue's rows named by a foreign key are in its partitions
        try:
            rows = self.con.execute(sql, list(params)).fetchall()
        except (duckdb.Error, RuntimeError) as exc:
            raise read_error(self.path, exc) from None
        if self._fault:
            m = _INSERT.match(sql)
            if m:
                self._after_insert(m.group(1).lower())
        return rows

    def arrow(self, sql: str, params: list[Any] | tuple[Any, ...] | dict[str, Any] = ()) -> pa.Table:
        """Run a SELECT and return its rows as an Arrow table (named `$parameters` from a dict; errors as `run`)."""
        try:
            return self.con.sql(sql, params=params if isinstance(params, dict) else list(params)).to_arrow_table()
        except (duckdb.Error, RuntimeError) as exc:
            raise read_error(self.path, exc) from None

    def one(self, sql: str, params: list[Any] | tuple[Any, ...] = ()) -> tuple | None:
        """The first row of a query, or None (the result is always fully consumed)."""
        rows = self.run(sql, params)
        return rows[0] if rows else None

    def next_id(self, table: str, column: str) -> int:
        """The next free id of `table` (inside a transaction, so concurrent writers cannot collide)."""
        _check_name(table)
        _check_name(column)
        return int(self.one(f"SELECT coalesce(max({column}), 0) + 1 FROM {table}")[0])

    def new_ids(self, table: str, n: int) -> np.ndarray:
        """`n` fresh ids for `table` (its `id<table>` column), allocated inside the caller's transaction."""
        first = self.next_id(table, f"id{table}")
        return np.arange(first, first + n, dtype=np.int64)

    def insert(self, table: str, columns: dict[str, Any]) -> int:
        """Bulk-insert columns (numpy arrays; (N, k) float arrays become DOUBLE[k]) through Arrow; returns the row count."""
        _check_name(table)
        lengths = {len(v) for v in columns.values()}
        if len(lengths) > 1:
            raise StoreError(f"rows for table {table} have columns of different lengths {sorted(lengths)}")
        if not columns or lengths == {0}:
            return 0  # zero rows: nothing to write (and nothing to reshape)
        arrow = pa.table({name: to_arrow(v) for name, v in columns.items()})
        names = ", ".join(_check_name(c) for c in arrow.column_names)
        target = table if self.dataset is None else f"{DATASET_TABLES}.{table}"  # the view of a Parquet catalogue reads it too
        self.con.register("_wb_rows", arrow)
        try:
            self.run(f"INSERT INTO {target} ({names}) SELECT {names} FROM _wb_rows")
        finally:
            try:
                self.con.unregister("_wb_rows")
            except duckdb.Error:
                pass  # the insert failed or was interrupted: its own error is the one to report
        return arrow.num_rows

    def _after_insert(self, table: str) -> None:
        """Fault injection for the test suite (WORKBENCH_FAULT): a signal after the N-th INSERT into a table, inside
        its stage's transaction (every INSERT through `run`, whichever module writes it)."""
        if self._fault and self._fault[0] == table:
            self._fault[1] -= 1
            if self._fault[1] == 0:
                os.kill(os.getpid(), self._fault[2])

    def mark_complete(self, stage: str, runkey: str, rows: int) -> None:
        """Record that a stage written in several transactions (IK chunks) has all its rows."""
        with self.transaction():
            self.run("INSERT OR REPLACE INTO stagedone (stage, runkey, rows) VALUES (?, ?, ?)", [stage, runkey, int(rows)])

    def is_complete(self, stage: str, runkey: str) -> bool:
        """Whether `mark_complete` recorded this run (stores opened read-only before their upgrade: never)."""
        if self.identity.kind == "older":
            return False
        return self.one("SELECT 1 FROM stagedone WHERE stage = ? AND runkey = ?", [stage, runkey]) is not None

    def query_arrays(self, sql: str, params: list[Any] | tuple[Any, ...] = ()) -> dict[str, np.ndarray]:
        """Run a SELECT and return each column as a numpy array; fixed-size list columns become (N, k) arrays."""
        table = self.arrow(sql, params)
        return {name: from_arrow(table.column(name)) for name in table.column_names}

    def paramset(self, stage: str, params: dict[str, Any], idobject: int | None) -> tuple[int, bool]:
        """The id of the parameter set of `stage` (created if new) and whether it already existed.

        Call inside the stage's transaction; the digest covers the stage, the object and the parameters.
        """
        found = self.find_paramset(stage, params, idobject)
        if found is not None:
            self.mark_used(found)
            return found, True
        text = json.dumps(params, sort_keys=True, default=_json_default)
        digest = _digest(stage, params, idobject)
        pid = self.next_id("paramset", "idparamset")
        self.run("INSERT INTO paramset (idparamset, stage, digest, params, idobject) VALUES (?, ?, ?, ?, ?)",
                         [pid, stage, digest, text, idobject])
        self.mark_used(pid)
        return pid, False

    def mark_used(self, idparamset: int) -> None:
        """Record that a stage has just produced or reused this parameter set: consumers that are given none take
        the most recently used one (`last_used_paramset`), never the highest id."""
        self.run("UPDATE paramset SET used = (SELECT coalesce(max(used), 0) + 1 FROM paramset) WHERE idparamset = ?",
                 [int(idparamset)])

    def last_used_paramset(self, stage: str, idobject: int) -> int | None:
        """The parameter set of `stage` for an object that was produced or reused last. Each stage's parameters
        name the parameter set it consumed (`grasps`, `placements`), so following them from here is the chain."""
        row = self.one("SELECT idparamset FROM paramset WHERE stage = ? AND idobject = ? ORDER BY used DESC, "
                       "idparamset DESC LIMIT 1", [stage, idobject])
        return None if row is None else int(row[0])

    def require_last_used(self, stage: str, idobject: int, what: str, command: str) -> int:
        """`last_used_paramset`, or a StoreError naming what is missing and the command that makes it."""
        pid = self.last_used_paramset(stage, idobject)
        if pid is None:
            raise StoreError(f"store {self.path} has no {what} for object id {idobject}; run `workbench {command}` first")
        return pid

    def params_of(self, idparamset: int) -> dict[str, Any]:
        """The parameters stored with a parameter set (as JSON: lengths in metres, angles in radians); {} if unknown."""
        row = self.one("SELECT params FROM paramset WHERE idparamset = ?", [int(idparamset)])
        return {} if row is None else json.loads(row[0])

    def find_paramset(self, stage: str, params: dict[str, Any], idobject: int | None) -> int | None:
        """The id of a stored parameter set of `stage` for these parameters and object, or None."""
        row = self.one("SELECT idparamset FROM paramset WHERE digest = ?", [_digest(stage, params, idobject)])
        return None if row is None else int(row[0])


def open_reader(path: str | Path, wait: float | None = None) -> Store:
    """An existing store opened for reading only, so that other processes may read it at the same time (DuckDB lets
    any number of readers, or one writer, hold a file); a store of an older schema is opened read-write once, to be
    upgraded."""
    store = Store(path, read_only=True, create=False, wait=wait)
    if store.identity.kind == "current":
        return store
    store.close()
    return Store(path, create=False, wait=wait)


def _wait_seconds() -> float:
    text = os.environ.get(WAIT_ENV, "")
    try:
        return max(0.0, float(text)) if text else 0.0
    except ValueError:
        return 0.0


def _parse_fault(text: str) -> list | None:
    if not text:
        return None
    table, count, name = text.split(":")
    return [table, int(count), getattr(signal, name)]


def _digest(stage: str, params: dict[str, Any], idobject: int | None) -> str:
    text = json.dumps(params, sort_keys=True, default=_json_default)
    return hashlib.sha256(f"{stage}|{idobject}|{text}".encode()).hexdigest()[:24]


def _check_name(name: str) -> str:
    if not name.replace("_", "").isalnum():
        raise StoreError(f"invalid SQL identifier {name!r}")
    return name


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"cannot store parameter of type {type(value).__name__}")


def to_arrow(value: Any) -> pa.Array:
    """numpy to Arrow: (N,) plain, (N, k) fixed-size lists, (N, a, b) fixed-size lists of a*b (row-major poses)."""
    if isinstance(value, (pa.Array, pa.ChunkedArray)):
        return value
    arr = np.asarray(value)
    if arr.ndim == 1 or arr.dtype == object:
        return pa.array(arr if arr.dtype != object else list(arr))
    width = int(np.prod(arr.shape[1:]))
    flat = np.ascontiguousarray(arr.reshape(len(arr), width))
    return pa.FixedSizeListArray.from_arrays(pa.array(flat.ravel(), type=pa.float64() if arr.dtype.kind == "f" else None), width)


def from_arrow(column: pa.ChunkedArray) -> np.ndarray:
    """Arrow to numpy: fixed-size lists to (N, k); variable lists of equal length to (N, k); else an object array."""
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if pa.types.is_fixed_size_list(arr.type) and arr.null_count == 0:
        k = arr.type.list_size
        return arr.flatten().to_numpy(zero_copy_only=False).reshape(len(arr), k)
    if pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        return np.array([None if v is None else np.asarray(v) for v in arr.to_pylist()], dtype=object)
    return arr.to_numpy(zero_copy_only=False)
