"""A Parquet catalogue's layout (see `workbench.store.catalog`): its partitioned tables and their Hive keys, the file
of its shared tables, and the views through which a `Store` opened on the folder reads the partitions."""

from __future__ import annotations

import re

DATASET_FILE = "catalog.duckdb"  # a Parquet catalogue folder's shared tables and bookkeeping
DATASET_TABLES = '"catalog".main'  # ... its own tables, past the views of the same names

# a Parquet catalogue's partitioned tables and their Hive keys
PARTITIONED: dict[str, tuple[str, ...]] = {
    "object": ("part",), "freeairgrip": ("part",), "freetabletopplacement": ("part",), "freetabletopgrip": ("part",),
    "tabletopplacements": ("part",), "tabletopgrips": ("part",), "ik": ("part", "robot"),
}


# a partition file's merge batch is named in its file name (b<batch>_...); a batch is committed with its row
COMMITTED = (f"coalesce(TRY_CAST(regexp_extract(filename, '/b([0-9]+)_[^/]*$', 1) AS BIGINT) IN "
             f"(SELECT batch FROM {DATASET_TABLES}.catalog_batch), true)")


def without_references(ddl: str) -> str:
    """A CREATE TABLE statement without its foreign keys (a Parquet catalogue's rows they name are in partitions)."""
    return re.sub(r"\s+REFERENCES\s+\w+\s*\([^)]*\)", "", ddl)


def dataset_files(store, table: str) -> str:
    """The glob of a partitioned table's files."""
    return f"{store.dataset}/{table}/{'/'.join('*' for _ in PARTITIONED[table])}/*.parquet"


def dataset_views(store, tables: tuple[str, ...] | None = None) -> None:
    """A Parquet catalogue's partitioned tables as views (temporary, on this connection) with the tables' own column
    names and types, over the files of its committed merges and the rows other commands (`gpplan`) added to the table of the same name in
    catalog.duckdb (`Store.insert` writes there); a table with no file yet is that table alone."""
    for table in tables or tuple(PARTITIONED):
        if next(iter(store.dataset.glob(f"{table}/{'/'.join('*' for _ in PARTITIONED[table])}/*.parquet")), None) is None:
            continue
        cols = store.run("SELECT column_name, data_type FROM duckdb_columns() WHERE table_name = ? AND schema_name = 'main' "
                         "AND database_name = current_database() ORDER BY column_index", [table])
        select = ", ".join(f"CAST({c} AS {t}) AS {c}" for c, t in cols)
        # only the files of committed merges: a driver killed during a merge leaves files the next build deletes
        store.run(f"CREATE OR REPLACE TEMP VIEW {table} AS SELECT {', '.join(c for c, _ in cols)} FROM {DATASET_TABLES}.{table} "
                  f"UNION ALL SELECT {select} FROM read_parquet('{dataset_files(store, table)}', hive_partitioning = true, "
                  f"filename = true) WHERE {COMMITTED}")
