"""The store's tables as DuckDB creates them: the schema reference of the documentation (CONVENTIONS.md, Store)."""

from __future__ import annotations

import tempfile
from pathlib import Path

from workbench.store import Store


def table_columns() -> dict[str, list[tuple[str, str, bool]]]:
    """{table: [(column, DuckDB type, nullable), ...]} of a new, empty store, in creation order."""
    with tempfile.TemporaryDirectory() as tmp:
        store = Store(Path(tmp) / "reference.duckdb")
        try:
            rows = store.con.execute(
                "SELECT table_name, column_name, data_type, is_nullable FROM information_schema.columns "
                "WHERE table_schema = 'main' ORDER BY table_name, ordinal_position").fetchall()
        finally:
            store.close()
    out: dict[str, list[tuple[str, str, bool]]] = {}
    for table, column, dtype, nullable in rows:
        out.setdefault(table, []).append((column, dtype, nullable == "YES"))
    return out
