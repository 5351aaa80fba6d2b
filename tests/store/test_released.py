"""A store released while its process computes: another process writes meanwhile, and the first one's next read
sees that write; a read takes the file again until the next transaction ends; nothing is released inside a
transaction; a closed store is not opened again behind its back."""

from __future__ import annotations

import subprocess
import sys

import pytest

from workbench.errors import StoreError
from workbench.store import Store

WRITE = ("import duckdb, sys; c = duckdb.connect(sys.argv[1], config={'autoinstall_known_extensions': False}); "
         "c.execute('INSERT INTO workbench_meta VALUES (?, ?)', [sys.argv[2], 'from another process']); c.close()")


def _other_process_writes(path, key: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", WRITE, str(path), key], capture_output=True, text=True, timeout=120)


def _locked(res: subprocess.CompletedProcess) -> bool:
    return res.returncode != 0 and "lock" in res.stderr.lower()


def test_another_process_writes_while_the_store_is_released(tmp_path):
    db = tmp_path / "s.duckdb"
    with Store(db) as store:
        assert _locked(_other_process_writes(db, "a"))  # an open store holds the file
        with store.released():
            wrote = _other_process_writes(db, "b")
            assert wrote.returncode == 0, wrote.stderr
            assert store.one("SELECT value FROM workbench_meta WHERE key = 'b'") == ("from another process",)
            assert _locked(_other_process_writes(db, "c"))  # the read took the file again ...
            with store.transaction():
                store.run("INSERT INTO workbench_meta VALUES ('mine', 'x')")
            wrote = _other_process_writes(db, "d")  # ... until the transaction after it committed
            assert wrote.returncode == 0, wrote.stderr
        with store.transaction():
            with store.released():  # inside a transaction nothing is given back
                assert _locked(_other_process_writes(db, "e"))
    with Store(db, read_only=True) as store:
        keys = {k for (k,) in store.run("SELECT key FROM workbench_meta")}
        assert {"b", "d", "mine"} <= keys and not {"a", "c", "e"} & keys
    with pytest.raises(StoreError, match="closed"):
        store.one("SELECT 1")
