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
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator

import duckdb
import numpy as np
import pyarrow as pa

from workbench.errors import StoreError
from workbench.store.schema import ALL_TABLES, MIGRATIONS


class Store:
    """An open DuckDB store file (created with the full schema when new)."""

    def __init__(self, path: str | Path, read_only: bool = False):
        self.path = Path(path)
        self._depth = 0  # open transaction() levels
        if read_only and not self.path.exists():
            raise StoreError(f"store {self.path} does not exist; build it first (workbench build / grasps)")
        if self.path.exists() and self.path.is_dir():
            raise StoreError(f"store path {self.path} is a folder; give a file path such as {self.path / 'regrasp.duckdb'}")
        if not read_only:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self.con = duckdb.connect(str(self.path), read_only=read_only)
        except duckdb.IOException as exc:
            msg = str(exc)
            if "lock" in msg.lower():
                raise StoreError(f"store {self.path} is locked by another process; close it (or its notebook kernel) and retry") from None
            if "not a valid DuckDB" in msg:
                raise StoreError(f"store {self.path} is not a DuckDB database (damaged or another format); move it aside and rebuild") from None
            raise StoreError(f"store {self.path} could not be opened: {msg.splitlines()[0]}") from None
        except duckdb.Error as exc:
            raise StoreError(f"store {self.path} could not be opened: {str(exc).splitlines()[0]}") from None
        self.read_only = read_only
        if not read_only:
            try:
                with self.transaction():
                    for ddl in ALL_TABLES + MIGRATIONS:
                        self.run(ddl)
            except duckdb.Error as exc:
                self.con.close()
                raise StoreError(f"store {self.path} has an incompatible schema ({str(exc).splitlines()[0]}); use a new file") from None

    def close(self) -> None:
        self.con.close()

    def __enter__(self) -> "Store":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @contextmanager
    def transaction(self) -> Iterator[duckdb.DuckDBPyConnection]:
        """One stage's writes: committed together or not at all.

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
        except BaseException:
            self._depth = 0
            self.run("ROLLBACK")
            raise
        else:
            self._depth = 0
            self.run("COMMIT")

    def run(self, sql: str, params: list[Any] | tuple[Any, ...] = ()) -> list[tuple]:
        """Execute one statement with bound parameters and return all its rows (DuckDB needs results finished)."""
        return self.con.execute(sql, list(params)).fetchall()

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
        arrow = pa.table({name: to_arrow(v) for name, v in columns.items()})
        if arrow.num_rows == 0:
            return 0
        names = ", ".join(_check_name(c) for c in arrow.column_names)
        self.con.register("_wb_rows", arrow)
        try:
            self.run(f"INSERT INTO {table} ({names}) SELECT {names} FROM _wb_rows")
        finally:
            self.con.unregister("_wb_rows")
        return arrow.num_rows

    def query_arrays(self, sql: str, params: list[Any] | tuple[Any, ...] = ()) -> dict[str, np.ndarray]:
        """Run a SELECT and return each column as a numpy array; fixed-size list columns become (N, k) arrays."""
        table = self.con.sql(sql, params=list(params)).to_arrow_table()
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

    def find_paramset(self, stage: str, params: dict[str, Any], idobject: int | None) -> int | None:
        """The id of a stored parameter set of `stage` for these parameters and object, or None."""
        row = self.one("SELECT idparamset FROM paramset WHERE digest = ?", [_digest(stage, params, idobject)])
        return None if row is None else int(row[0])


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
    flat = np.ascontiguousarray(arr.reshape(len(arr), int(np.prod(arr.shape[1:]))))  # also for zero rows
    return pa.FixedSizeListArray.from_arrays(pa.array(flat.ravel()), flat.shape[1])


def from_arrow(column: pa.ChunkedArray) -> np.ndarray:
    """Arrow to numpy: fixed-size lists to (N, k); variable lists of equal length to (N, k); else an object array."""
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if pa.types.is_fixed_size_list(arr.type) and arr.null_count == 0:
        k = arr.type.list_size
        return arr.flatten().to_numpy(zero_copy_only=False).reshape(len(arr), k)
    if pa.types.is_list(arr.type) or pa.types.is_fixed_size_list(arr.type):
        return np.array([None if v is None else np.asarray(v) for v in arr.to_pylist()], dtype=object)
    return arr.to_numpy(zero_copy_only=False)
