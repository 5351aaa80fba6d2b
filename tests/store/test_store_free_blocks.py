"""A sound store whose last blocks are free (a table dropped, then checkpointed) is shorter than its header's block
count: the door's truncation check takes the free blocks into account, and a store cut short is still refused."""

from __future__ import annotations

import duckdb
import pytest

from workbench.errors import StoreError
from workbench.store import Store


def _store_with_a_free_tail(path) -> None:
    with Store(path):  # a new workbench store: its schema
        pass
    con = duckdb.connect(str(path))
    con.execute("CREATE TABLE scratch AS SELECT range AS y FROM range(300000)")
    con.execute("CHECKPOINT")
    con.execute("DROP TABLE scratch")
    con.execute("CHECKPOINT")
    con.close()


def test_a_store_with_free_blocks_at_its_end_opens(tmp_path):
    path = tmp_path / "s.duckdb"
    _store_with_a_free_tail(path)
    con = duckdb.connect(str(path), read_only=True)
    size, total, free = con.execute("SELECT block_size, total_blocks, free_blocks FROM pragma_database_size()").fetchone()
    assert con.execute("SELECT count(*) FROM workbench_meta").fetchone()[0] >= 1  # DuckDB itself reads it
    con.close()
    assert free >= 1 and path.stat().st_size < 3 * 4096 + size * total  # shorter than the header's count
    with Store(path) as store:
        assert store is not None
    data = path.read_bytes()
    path.write_bytes(data[:-4096])  # cut short: refused
    with pytest.raises(StoreError, match="truncated"):
        with Store(path):
            pass


def test_a_store_opened_read_only_answers_queries(tmp_path):
    """The door's checks leave no unfinished result on the connection a read-only store keeps."""
    path = tmp_path / "r.duckdb"
    with Store(path) as store:
        store.run("CREATE TABLE t AS SELECT range AS x FROM range(5)")
    with Store(path, read_only=True) as store:
        assert store.arrow("SELECT x FROM t WHERE x > ?", [1]).column("x").to_pylist() == [2, 3, 4]
        assert store.one("SELECT count(*) FROM t")[0] == 5
