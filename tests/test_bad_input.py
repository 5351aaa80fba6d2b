"""Bad inputs and faults against every command, run as a user would: a subprocess (issue 11).

Refusals: exit status 2, at most three lines on stderr, no traceback, a message naming the input and what to
do, and the store unchanged (every table's row count and content checksum, read with DuckDB directly).
Faults: SIGKILL and Ctrl-C (SIGINT) inside each stage's transaction, two writers at once, a full disk and a store
left by an older version: the store stays consistent and a re-run ends with the same rows as an uninterrupted
run. One small store is built once per session and copied per test.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import duckdb
import numpy as np
import pytest
import trimesh

from workbench.store import Store
from workbench.store.identity import SCHEMA_VERSION

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "workbench.cli"]
GRID = ["--x", "0.4,0.6,2", "--y=-0.1,0.1,2", "--angles", "2", "--max-grasps", "10"]
BUILD = ["--robot", "panda", "--workers", "1", *GRID]
QUERY = ["--start", "1,0.4,-0.1,0", "--goal", "3,0.6,0.1,1.57"]
FINGERS = ["--faces", "120", "--clusters", "8", "--samples", "40", "--picks", "3", "--queries", "2"]
# clocks, and paramset.used (bumped whenever a stage reuses a set): they differ between runs that store the same rows
VOLATILE = {"created", "finished", "used", "seconds", "seconds_clustering", "seconds_roadmap", "t_connect", "t_search",
            "seconds_hand_object", "seconds_hand_table", "seconds_ik"}


def cli(*args, cwd: Path, env: dict | None = None, fsize: int | None = None) -> subprocess.CompletedProcess:
    """Run `workbench ARGS` as a user would: its own process (forked from the session's command server), exit
    status, stdout and stderr."""
    return _SERVER[0].run([str(a) for a in args], cwd, {k: str(v) for k, v in (env or {}).items()}, fsize)


_SERVER: list = []


@pytest.fixture(scope="session", autouse=True)
def fork_server(cli_server):
    _SERVER.append(cli_server)
    yield cli_server
    _SERVER.clear()


def spawn(*args, cwd: Path) -> subprocess.Popen:
    """`workbench ARGS` in a fresh interpreter, running concurrently."""
    return subprocess.Popen([*CLI, *map(str, args)], cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def state(db: Path) -> dict | None:
    """{table: (rows, checksum)} of every table, read with DuckDB directly (not our code); None when absent."""
    if not db.exists():
        return None
    con = duckdb.connect(str(db), read_only=True, config={"autoinstall_known_extensions": False})
    try:
        out = {}
        for (table,) in con.execute("SELECT table_name FROM information_schema.tables ORDER BY table_name").fetchall():
            cols = [c for (c,) in con.execute("SELECT column_name FROM information_schema.columns WHERE table_name = ? "
                                              "ORDER BY ordinal_position", [table]).fetchall() if c not in VOLATILE]
            rows = con.execute(f'SELECT count(*) FROM "{table}"').fetchone()[0]
            row = ", ".join(f'"{c}"' for c in cols)
            text = con.execute(f'SELECT string_agg(r, chr(10) ORDER BY r) FROM '
                               f'(SELECT CAST(ROW({row}) AS VARCHAR) AS r FROM "{table}")').fetchone()[0]
            out[table] = (rows, hashlib.sha256((text or "").encode()).hexdigest()[:16])
        return out
    finally:
        con.close()


def file_digest(path: Path) -> str | None:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def assert_refused(res: subprocess.CompletedProcess, *words: str) -> str:
    """Exit 2, one to three lines on stderr, no traceback, the message contains every word (case-insensitive)."""
    err = res.stderr.strip()
    assert res.returncode == 2, f"exit {res.returncode}\nstdout: {res.stdout[-2000:]}\nstderr: {res.stderr[-3000:]}"
    assert "Traceback" not in err, err
    lines = err.splitlines()
    assert 1 <= len(lines) <= 3, err
    for w in words:
        assert w.lower() in err.lower(), f"{w!r} not in {err!r}"
    return err


def assert_clean(res: subprocess.CompletedProcess) -> None:
    """Any exit but a crash: no traceback, at most three lines of messages (progress bars aside)."""
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    assert res.returncode in (0, 2), f"exit {res.returncode}: {res.stderr[-2000:]}"
    lines = [ln for ln in res.stderr.replace("\r", "\n").splitlines() if ln.strip() and "it/s]" not in ln and "/s]" not in ln]
    assert len(lines) <= 3, res.stderr[-2000:]


# ---------------------------------------------------------------------------------------------------------------
# Session fixtures: meshes and one built store.


@pytest.fixture(scope="session")
def work(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("badinput")
    trimesh.creation.box((0.05, 0.04, 0.03)).export(d / "box.stl")
    a = trimesh.creation.box((0.03, 0.03, 0.03))
    b = a.copy()
    b.apply_translation((0.12, 0, 0))
    trimesh.util.concatenate([a, b]).export(d / "two.stl")
    trimesh.Trimesh([[0, 0, 0], [0.03, 0, 0], [0, 0.03, 0]], [[0, 1, 2]]).export(d / "triangle.stl")
    trimesh.creation.box((1000.0, 60.0, 60.0)).export(d / "bar_mm.stl")  # a 1 m part, in millimetres
    trimesh.creation.box((0.0001, 0.0001, 0.0001)).export(d / "speck.stl")  # a 0.1 mm part, in metres
    trimesh.creation.icosphere(subdivisions=3, radius=0.03).export(d / "ball.stl")
    (d / "broken.urdf").write_text("<robot name='broken'><link name='a'/>")
    (d / "afile").write_text("not a folder\n")
    (d / "folder.csv").mkdir()
    return d


@pytest.fixture(scope="session")
def built(work) -> Path:
    """box: grasps, placements, tabletop grips and IK for panda, built once."""
    db = work / "built.duckdb"
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-3000:]
    return db


@pytest.fixture(scope="session")
def reference(built) -> dict:
    return state(built)


@pytest.fixture
def db(built, tmp_path) -> Path:
    out = tmp_path / "store.duckdb"
    shutil.copy(built, out)
    return out


# ---------------------------------------------------------------------------------------------------------------
# Kind 1: zero rows never crash the store writer.


def test_insert_of_zero_rows_writes_nothing(tmp_path):
    from workbench.store import Store

    with Store(tmp_path / "s.duckdb") as store:
        with store.transaction():
            n = store.insert("freetabletopplacement", {
                "idfreetabletopplacement": np.zeros(0, dtype=np.int64), "idobject": np.zeros(0, dtype=np.int64),
                "idparamset": np.zeros(0, dtype=np.int64), "rotmat": np.zeros((0, 4, 4)), "stability": np.zeros(0),
                "support": np.array([], dtype=object)})
        assert n == 0
        assert store.one("SELECT count(*) FROM freetabletopplacement")[0] == 0


@pytest.mark.parametrize("mesh, extra", [
    ("two.stl", []),  # two disjoint bodies
    ("triangle.stl", []),  # a single triangle: an open sheet, no volume
    ("bar_mm.stl", ["--units", "mm"]),  # a 1 m part given in mm: too wide for the jaw everywhere
])
def test_zero_results_never_crash(work, tmp_path, mesh, extra):
    res = cli("build", work / mesh, *extra, "--db", tmp_path / "s.duckdb", *BUILD, cwd=work)
    assert_clean(res)


@pytest.mark.parametrize("option", [["--min-stability", "1e9"], ["--min-stability", "50"]])
def test_placements_with_zero_results_never_crash(work, db, option):
    res = cli("placements", "--db", db, "--object", "box", *GRID, *option, cwd=work)
    assert_clean(res)


# ---------------------------------------------------------------------------------------------------------------
# Kind 2: parameters out of range are refused before any work, naming the option and its range.

BAD_PARAMETERS = [
    ("grasps", ["--neighbour-radius", "0"], "--neighbour-radius"),
    ("grasps", ["--neighbour-radius", "-0.01"], "--neighbour-radius"),
    ("grasps", ["--seed", "-1"], "--seed"),
    ("grasps", ["--density", "1e30"], "--density"),
    ("grasps", ["--density", "0"], "--density"),
    ("grasps", ["--density", "1e9"], "memory budget"),  # in range, but its neighbour filter would need terabytes
    ("grasps", ["--rotations", "1000000"], "--rotations"),
    ("grasps", ["--rotations", "0"], "--rotations"),
    ("grasps", ["--tau-deg", "95"], "--tau-deg"),
    ("grasps", ["--tau-deg", "nan"], "--tau-deg"),
    ("grasps", ["--parallel-deg", "inf"], "--parallel-deg"),
    ("grasps", ["--com-max", "-1"], "--com-max"),
    ("grasps", ["--dist-min", "0.05", "--dist-max", "0.01"], "--dist-min"),
    ("grasps", ["--scale", "0"], "--scale"),
    ("grasps", ["--scale", "nan"], "--scale"),
    ("fingers", ["--seed", "-1"], "--seed"),
    ("fingers", ["--pyramid", "100000"], "--pyramid"),
    ("fingers", ["--pyramid", "2"], "--pyramid"),
    ("fingers", ["--friction", "0"], "--friction"),
    ("fingers", ["--clusters", "0"], "--clusters"),
    ("fingers", ["--samples", "-1"], "--samples"),
    ("fingers", ["--queries", "-3"], "--queries"),
    ("fingers", ["--faces", "2"], "--faces"),
    ("placements", ["--angles", "1000000"], "--angles"),
    ("placements", ["--angles", "0"], "--angles"),
    ("placements", ["--x", "0.3,0.6,100000"], "--x"),
    ("placements", ["--x", "0.6,0.3,3"], "--x"),
    ("placements", ["--y", "a,b,c"], "--y"),
    ("placements", ["--min-stability", "-1"], "--min-stability"),
    ("placements", ["--clearance", "nan"], "--clearance"),
    ("placements", ["--max-grasps", "-5"], "--max-grasps"),
    ("ik", ["--handx", "-1"], "--handx"),
    ("ik", ["--workers", "0"], "--workers"),
    ("ik", ["--table-thickness", "0"], "--table-thickness"),
    ("ik", ["--base", "0,0,0,90"], "--base yaw 90 is in radians"),  # a yaw typed in degrees
    ("ik", ["--mount", "0,0,0.1034,0,0,-45"], "--mount yaw -45 is in radians"),
    ("plan", ["--alternatives", "-1"], "--alternatives"),
    ("plan", ["--start", "one,two"], "--start"),
    ("build", ["--handx", "nan"], "--handx"),
    ("build", ["--rotations", "1000000"], "--rotations"),
    ("demo", ["--seed", "-1"], "--seed"),
    ("demo", ["--workers", "0"], "--workers"),
    ("gptable", ["--edge-angle", "nan"], "--edge-angle"),
    ("gptable", ["--edge-angle=-10"], "[0, 180] deg"),
    ("gptable", ["--min-face-area", "nan"], "--min-face-area"),
    ("gptable", ["--min-contact-area", "nan"], "--min-contact-area"),
    ("gptable", ["--min-range", "400"], "[0, 360] deg"),
    ("gptable", ["--points", "0"], "--points"),
    ("gptable", ["--theta-step", "0"], "--theta-step"),
    ("gptable", ["--table-point", "0.4,nan"], "--table-point"),
    ("gpplan", ["--initial", "0,nan", "--goal", "1,0:90"], "--initial"),
    ("gpplan", ["--from", "0,0", "--to", "1,inf"], "--to"),
    ("gpplan", ["--from", "0,0", "--to", "1,90", "--handx", "nan"], "--handx"),
    ("gpplan", ["--from", "0,0", "--to", "1,90", "--acc", "-1"], "--acc"),
    ("catalog", ["--workers", "1000"], "memory budget"),
    ("catalog", ["--workers", "0"], "--workers"),
    ("catalog", ["--ik-chunk", "0"], "--ik-chunk"),
    ("catalog", ["--worlda", "nan"], "--worlda"),
    ("catalog", ["--shards", "box.stl"], "not a folder"),
    ("ik", ["--workers", "1000"], "memory budget"),
    ("plan", ["--budget", "nan"], "--budget"),
    ("plan", ["--json", "afile/plan.json"], "afile is a file"),
    ("plan", ["--html", "."], "is a folder"),
    ("plan", ["--trajectory", "."], "must end in"),
    ("plan", ["--trajectory", "folder.csv"], "is a folder"),
    ("grasps", ["--html", "."], "is a folder"),
    ("fingers", ["--json", "afile/q.json"], "--json"),
    # /proc takes no new file, even from root (whom a read-only mode does not stop)
    ("plan", ["--json", "/proc/plan.json"], "folder /proc is not writable"),
    ("gpplan", ["--from", "0,0", "--to", "1,90", "--json", "/proc/q.json"], "folder /proc is not writable"),
    ("gpplan", ["--from", "0,0", "--to", "1,90", "--html", "."], "is a folder"),
    ("gpplan", ["--from", "0,0", "--to", "1,90", "--html", "afile/t.html"], "afile is a file"),
    ("catalog", ["--shards", "/proc/units"], "folder /proc is not writable"),
]


def _command(cmd: str, work: Path, db: Path, extra: list[str]) -> list:
    if cmd in ("grasps", "fingers"):
        return [cmd, work / "box.stl", "--db", db, *extra]
    if cmd == "build":
        return [cmd, work / "box.stl", "--db", db, *BUILD, *extra]
    if cmd == "placements":
        return [cmd, "--db", db, "--object", "box", *extra]
    if cmd == "demo":
        return [cmd, "--out", db.parent / "demo", *extra]
    if cmd == "ik":
        return [cmd, "--db", db, "--object", "box", "--robot", "panda", *extra]
    if cmd == "gptable":
        return [cmd, work / "box.stl", "--db", db, *extra]
    if cmd == "gpplan":
        return [cmd, "--db", db, "--object", "box", *extra]
    if cmd == "catalog":
        return [cmd, "build", work / "box.stl", "--robots", "panda", "--db", db, *extra]
    return [cmd, "--db", db, "--object", "box", "--robot", "panda", *QUERY, *extra]


@pytest.mark.parametrize("cmd, extra, flag", BAD_PARAMETERS, ids=[f"{c}{''.join(e)}" for c, e, _ in BAD_PARAMETERS])
def test_bad_parameter_is_refused_before_any_work(work, db, reference, cmd, extra, flag):
    before = file_digest(db)
    res = cli(*_command(cmd, work, db, extra), cwd=work)
    assert_refused(res, flag)
    assert state(db) == reference
    assert file_digest(db) == before  # refused before the store was even opened


def test_memory_estimate_refuses_above_the_budget(work, db, reference):
    """A grid that fits the ranges but not the budget is refused before the work starts, naming the budget."""
    res = cli("placements", "--db", db, "--object", "box", "--x", "0.3,0.6,1000", "--y=-0.3,0.3,1000", "--angles", "360",
              "--max-grasps", "0", cwd=work, env={"WORKBENCH_MEMORY_BUDGET": "64MiB"})
    assert_refused(res, "memory budget", "64.0 MiB")
    assert state(db) == reference


# ---------------------------------------------------------------------------------------------------------------
# Kind 3: stores that are not ours, damaged, or in impossible places.


def test_foreign_store_is_refused_with_nothing_written(work, tmp_path):
    path = tmp_path / "foreign.duckdb"
    con = duckdb.connect(str(path))
    con.execute("CREATE TABLE object (id INTEGER, stuff VARCHAR)")
    con.execute("INSERT INTO object VALUES (1, 'theirs')")
    con.close()
    before = state(path)
    res = cli("grasps", work / "box.stl", "--db", path, cwd=work)
    assert_refused(res, str(path.name), "not a workbench store")
    assert state(path) == before


def test_newer_store_is_refused_with_nothing_written(work, db, reference):
    con = duckdb.connect(str(db))
    con.execute("UPDATE workbench_meta SET value = '999' WHERE key = 'schema_version'")
    con.close()
    before = state(db)
    for args in (["grasps", work / "box.stl", "--db", db], ["plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY]):
        res = cli(*args, cwd=work)
        assert_refused(res, "newer", "999")
        assert state(db) == before


@pytest.mark.parametrize("damage", ["truncate", "garbage"])
def test_damaged_store_is_reported_in_one_line(work, db, damage):
    data = db.read_bytes()
    db.write_bytes(data[:20000] if damage == "truncate" else b"\x00garbage" * 5000)
    before = file_digest(db)
    res = cli("placements", "--db", db, "--object", "box", cwd=work)
    assert_refused(res, str(db), "damaged")
    assert "move it aside" in res.stderr or "backup" in res.stderr
    assert file_digest(db) == before


def test_store_path_under_a_regular_file(work):
    res = cli("grasps", work / "box.stl", "--db", work / "afile" / "s.duckdb", cwd=work)
    assert_refused(res, "afile", "not a folder")


def test_demo_out_under_a_regular_file(work):
    assert_refused(cli("demo", "--out", work / "afile" / "demo", cwd=work), "afile", "--out")


def test_store_path_is_a_folder(work, tmp_path):
    res = cli("grasps", work / "box.stl", "--db", tmp_path, cwd=work)
    assert_refused(res, "folder")


def test_reading_commands_do_not_create_a_store(work, tmp_path):
    for args in (["placements", "--db", tmp_path / "none.duckdb", "--object", "box"],
                 ["plan", "--db", tmp_path / "none.duckdb", "--object", "box", "--robot", "panda", *QUERY]):
        assert_refused(cli(*args, cwd=work), "does not exist")
        assert not (tmp_path / "none.duckdb").exists()


READERS = {  # every command that opens an existing store, on the store `db`
    "plan": ["plan", "--db", "{db}", "--object", "box", "--robot", "panda", *QUERY],
    "ik": ["ik", "--db", "{db}", "--object", "box", "--robot", "panda", "--workers", "1"],
    "build": ["build", "box.stl", "--db", "{db}", *BUILD],
    "gpplan": ["gpplan", "--db", "{db}", "--object", "box", "--from", "0,0", "--to", "1,90"],
    "catalog report": ["catalog", "report", "--db", "{db}"],
}


def _reader(name: str, db: Path) -> list[str]:
    return [str(db) if a == "{db}" else a for a in READERS[name]]


@pytest.mark.parametrize("cut", ["half", "last block"])
def test_truncated_store_is_one_line_for_every_command(work, db, cut):
    """A copy cut short past its header (DuckDB opens it, then fails on the first missing block) is refused at the
    store's door, whichever command opens it; the file is left as it was."""
    data = db.read_bytes()
    db.write_bytes(data[: len(data) // 2] if cut == "half" else data[:-4096])
    before = file_digest(db)
    for name in READERS:
        res = cli(*_reader(name, db), cwd=work)
        assert_refused(res, str(db.name), "damaged", "truncated")
        assert file_digest(db) == before, name


def test_corrupt_block_is_one_line(work, db):
    """A block whose checksum fails (the file changed outside DuckDB): one line naming the damage, file untouched."""
    con = duckdb.connect(str(db), read_only=True)
    block, blocks = con.execute("SELECT block_size, total_blocks FROM pragma_database_size()").fetchone()
    con.close()
    damaged = []
    for k in range(blocks):  # the blocks a plan reads lie somewhere: spoil every block, each read fails its checksum
        damaged.append((3 * 4096 + k * block + 64, b"\x55" * 256))
    with open(db, "r+b") as fh:
        for at, junk in damaged:
            fh.seek(at)
            fh.write(junk)
    before = file_digest(db)
    res = cli(*_reader("plan", db), cwd=work)
    assert_refused(res, str(db.name), "damaged")
    assert file_digest(db) == before


def test_gpplan_on_a_store_without_a_table_names_gptable(work, db, reference):
    res = cli(*_reader("gpplan", db), cwd=work)
    assert_refused(res, "tgptable", "workbench gptable")
    assert state(db) == reference


def _hold(db: Path, seconds: float) -> subprocess.Popen:
    """Another process holding the store read-write for `seconds` (its lock taken when it prints)."""
    code = (f"import duckdb, sys, time; c = duckdb.connect({str(db)!r}); print('held', flush=True); "
            f"time.sleep({seconds}); c.close()")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_busy_store_is_one_line_or_waited_for(work, db, reference):
    """A store another process writes: each command says so in one line (naming --wait), or waits with --wait."""
    holder = _hold(db, 60)
    try:
        for name in ("plan", "ik", "catalog report"):
            res = cli(*_reader(name, db), cwd=work)
            assert_refused(res, "busy", f"process {holder.pid}", "--wait")
            # --wait after a subcommand too (catalog report); a wait that ends says how long it waited
            res = cli(*_reader(name, db), "--wait", "0.5", cwd=work)
            assert_refused(res, "still busy after waiting 0.5 s", f"process {holder.pid}", "longer --wait")
    finally:
        holder.kill()
        holder.wait()
    assert state(db) == reference
    holder = _hold(db, 1.5)
    try:
        res = cli(*_reader("plan", db), "--no-save", "--wait", "60", cwd=work)
    finally:
        holder.wait()
    assert res.returncode == 0, res.stderr[-2000:]
    assert state(db) == reference


def test_four_plans_at_once(work, db):
    """Four plans of one query at once: planning only reads (readers share the store), each stores briefly; with
    --wait every one succeeds and the plans are stored once; without, each succeeds or says the store is busy."""
    for wait in (["--wait", "120"], []):
        for res in _SERVER[0].run_many([[*_reader("plan", db), *wait]] * 4, work):
            if wait or res.returncode == 0:
                assert res.returncode == 0, res.stderr[-2000:]
            else:
                assert_refused(res, "busy", "--wait")
        con = duckdb.connect(str(db), read_only=True)
        stored = con.execute("SELECT count(*), count(DISTINCT rank) FROM plan").fetchone()
        con.close()
        assert stored[0] == stored[1] >= 1  # the best plan and its alternatives, each once


def test_a_reader_beside_a_reader(work, db, reference):
    """plan --no-save needs no writer's lock: it runs while another process reads the store."""
    code = (f"import duckdb, time; c = duckdb.connect({str(db)!r}, read_only=True); print('held', flush=True); "
            f"time.sleep(60)")
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        res = cli(*_reader("plan", db), "--no-save", cwd=work)
        assert res.returncode == 0, res.stderr[-2000:]
        assert "stored plan" not in res.stdout
    finally:
        holder.kill()
        holder.wait()
    assert state(db) == reference


URDF_FAULTS = {  # a change to UR5's URDF -> words of its one-line refusal
    "loop": (lambda t: t.replace("</robot>", '<joint name="loop" type="revolute"><parent link="wrist_3_link"/>'
                                             '<child link="shoulder_link"/><axis xyz="0 0 1"/><limit lower="-1" '
                                             'upper="1" effort="1" velocity="1"/></joint></robot>'),
             ["not a tree", "shoulder_link", "loop"]),
    "nan": (lambda t: re.sub(r'(<joint name="elbow_joint".*?lower=")[^"]*"', r'\1nan"', t, count=1, flags=re.S),
            ["elbow_joint", "not finite"]),
    "inverted": (lambda t: re.sub(r'(<joint name="elbow_joint".*?lower=")[^"]*"', r'\g<1>4"', t, count=1, flags=re.S),
                 ["elbow_joint", "inverted"]),
    "empty": (lambda t: re.sub(r'(lower|upper)="[^"]*"', r'\1="0.5"', t), ["empty range"]),
    "roots": (lambda t: t.replace("</robot>", '<link name="stray"/></robot>'), ["not a tree", "stray"]),
}


@pytest.mark.parametrize("fault", [*URDF_FAULTS, "tip is a joint"])
def test_urdf_faults_are_named_before_pinocchio(work, db, reference, tmp_path, fault):
    from workbench.resources import erd_robots

    text = (erd_robots() / "ur_description" / "urdf" / "ur5_robot.urdf").read_text()
    change, words = URDF_FAULTS.get(fault, (lambda t: t, ["elbow_joint", "is a joint, not a link", "forearm_link"]))
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(change(text))
    tip = "elbow_joint" if fault == "tip is a joint" else "tool0"
    res = cli("ik", "--db", db, "--object", "box", "--robot", urdf, "--tip", tip, "--workers", "1", cwd=work)
    assert_refused(res, "arm.urdf", *words)
    assert state(db) == reference


# ---------------------------------------------------------------------------------------------------------------
# Kind 4: no silent wrong answers.


def test_unknown_tabletop_parameter_set_is_an_error(work, db, reference):
    res = cli("ik", "--db", db, "--object", "box", "--robot", "panda", "--tabletop", "999", cwd=work)
    assert_refused(res, "999", "tabletop")
    assert state(db) == reference


def _kill_ik_part_way(db: Path, keep: int = 120) -> None:
    """The store an IK run killed after its first chunks leaves: some committed `ik` rows, no completion record."""
    con = duckdb.connect(str(db))
    con.execute("DELETE FROM ik WHERE idik > ?", [keep])
    con.execute("DELETE FROM stagedone WHERE stage = 'ik'")
    con.close()


def test_plan_refuses_an_incomplete_ik_stage_unless_allowed(work, db, reference):
    """IK killed part-way leaves its finished chunks; plan refuses them, or plans with a loud warning when asked;
    a re-run of ik resumes and completes with the rows of an uninterrupted run."""
    _kill_ik_part_way(db)
    before = state(db)
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert_refused(res, "incomplete", f"120 of {reference['tabletopgrips'][0]}", "--allow-partial", "workbench ik")
    assert state(db) == before
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, "--allow-partial", cwd=work)
    assert_clean(res)
    assert "warning" in res.stderr and "incomplete" in res.stderr
    assert state(db)["plan"] == before["plan"]  # a plan on a partial graph is not stored
    res = cli("ik", "--db", db, "--object", "box", "--robot", "panda", "--workers", "1", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    after = state(db)
    assert {k: v for k, v in after.items() if k != "stagedone"} == {k: v for k, v in reference.items() if k != "stagedone"}
    assert after["stagedone"][0] == 1
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, "--no-save", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]


def test_the_resume_command_of_an_incomplete_ik_run_carries_its_retractions(work, db):
    """An IK run with its own --handx killed part-way: plan's message names the command that resumes that run (with
    its --handx, not the default run's), and running it completes the run, so the plan is made."""
    res = cli("ik", "--db", db, "--object", "box", "--robot", "panda", "--handx", "0.08", "--workers", "1", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    con = duckdb.connect(str(db))
    run = con.execute("SELECT idikret FROM ikret WHERE abs(handx - 0.08) < 1e-9").fetchall()[0][0]
    first = con.execute("SELECT min(idik) FROM ik WHERE idikret = ?", [run]).fetchall()[0][0]
    con.execute("DELETE FROM ik WHERE idikret = ? AND idik > ?", [run, first + 100])
    con.execute("DELETE FROM stagedone WHERE stage = 'ik' AND runkey LIKE ?", [f"%ikret={run}"])
    con.close()
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", "--handx", "0.08", *QUERY, cwd=work)
    err = assert_refused(res, "incomplete", "workbench ik")
    command = re.search(r"`workbench (ik [^`]*)`", err).group(1).split()
    assert command[command.index("--handx") + 1] == "0.08"
    res = cli(*command, "--workers", "1", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", "--handx", "0.08", *QUERY, "--no-save", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]


def test_plan_rerun_answers_from_the_store_without_a_duplicate(work, db):
    first = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert first.returncode == 0, first.stderr[-2000:]
    after_first = state(db)
    second = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert second.returncode == 0, second.stderr[-2000:]
    assert state(db) == after_first
    assert "from the store" in second.stdout
    # other motion settings are another plan, stored beside the first (the stored one is not passed off as it)
    third = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, "--acc", "2", cwd=work)
    assert third.returncode == 0 and "from the store" not in third.stdout, third.stdout + third.stderr[-2000:]
    con = duckdb.connect(str(db), read_only=True)
    accs = {tuple(r[0]) for r in con.execute("SELECT acc FROM plan").fetchall()}
    con.close()
    assert {a[0] for a in accs} >= {2.0, 3.0}


def test_a_start_that_is_the_goal_needs_no_plan(work, db):
    """The same placement, position and yaw (a full turn apart): nothing is moved, nothing is stored, exit 0."""
    before = state(db)
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", "--start", "1,0.4,-0.1,0", "--goal",
              "1,0.4,-0.1,360", cwd=work)
    assert_clean(res)
    assert "already in place" in res.stdout
    assert state(db) == before


# ---------------------------------------------------------------------------------------------------------------
# Kind 5: messages that lead to the fix.


def test_speck_names_its_size_and_a_scale(work, tmp_path):
    res = cli("grasps", work / "speck.stl", "--units", "mm", "--db", tmp_path / "s.duckdb", cwd=work)
    err = assert_refused(res, "speck.stl", "1e-07 m", "--scale")
    assert "degenerate" not in err
    assert not (tmp_path / "s.duckdb").exists()


def test_a_part_read_in_metres_that_is_not_hand_sized(work, tmp_path):
    """A 1.65 m part given without units is refused, naming the units that make it hand-sized; --accept-size keeps
    it in metres (a result: the hand spans nothing), --units cm reads it as a 16.5 mm part."""
    big = tmp_path / "duck.stl"
    trimesh.creation.box((1.65, 0.8, 1.0)).export(big)
    db = tmp_path / "s.duckdb"
    for extra in (["grasps"], ["gptable"], ["build", "--robot", "panda"]):
        res = cli(extra[0], big, "--db", db, *extra[1:], cwd=work)
        assert_refused(res, "duck.stl", "1.65 m across", "--units cm", "--accept-size")
        assert not db.exists()
    res = cli("grasps", big, "--db", db, "--accept-size", cwd=work)
    assert res.returncode == 0 and "0 free-air grasps" in res.stdout, res.stderr[-2000:]
    assert "80 mm opening" in res.stderr  # the zero names the size that causes it
    res = cli("grasps", big, "--db", tmp_path / "cm.duckdb", "--units", "cm", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]


def test_build_with_a_broken_urdf_is_refused_before_any_work(work, tmp_path):
    res = cli("build", work / "box.stl", "--db", tmp_path / "s.duckdb", "--robot", work / "broken.urdf", cwd=work)
    assert_refused(res, "broken.urdf", "--tip")
    res = cli("build", work / "box.stl", "--db", tmp_path / "s.duckdb", "--robot", work / "broken.urdf", "--tip", "a",
              cwd=work)
    assert_refused(res, "broken.urdf", "not well-formed")
    assert not (tmp_path / "s.duckdb").exists()


@pytest.mark.parametrize("form", [["--y", "-0.1,0.1,2"], ["--y=-0.1,0.1,2"]])
def test_negative_ranges_parse(work, db, form):
    res = cli("placements", "--db", db, "--object", "box", "--x", "0.4,0.6,2", *form, "--angles", "2", "--max-grasps", "10",
              cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert "reused" in res.stdout


def test_help_documents_ranges(work):
    res = cli("grasps", "--help", cwd=work)
    assert res.returncode == 0
    assert "[1, 360]" in " ".join(res.stdout.split())  # --rotations


# ---------------------------------------------------------------------------------------------------------------
# Faults: each keeps the store consistent; a re-run ends with the rows of an uninterrupted run.

STAGES = ["freeairgrip", "freetabletopgrip", "tabletopgrips", "ik"]


@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT"])
@pytest.mark.parametrize("table", STAGES)
def test_signal_inside_each_stage(work, tmp_path, reference, table, sig):
    db = tmp_path / "s.duckdb"
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work, env={"WORKBENCH_FAULT": f"{table}:1:{sig}"})
    if sig == "SIGKILL":
        assert res.returncode == -signal.SIGKILL
    else:
        assert res.returncode == 130 and "Traceback" not in res.stderr, res.stderr[-2000:]
        assert "interrupted" in res.stderr
    partial = state(db)
    if partial is not None:
        assert partial[table][0] == 0  # the stage's transaction was rolled back
        for t, (rows, _) in partial.items():
            assert rows <= reference.get(t, (rows,))[0]
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert state(db) == reference


@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT"])
def test_signal_while_storing_a_plan(work, db, sig):
    before = state(db)
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work,
              env={"WORKBENCH_FAULT": f"planstep:1:{sig}"})
    assert res.returncode in (-signal.SIGKILL, 130) and "Traceback" not in res.stderr
    assert state(db) == before
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]


def test_signal_inside_finger_stages(work, tmp_path):
    clean = tmp_path / "clean.duckdb"
    assert cli("fingers", work / "ball.stl", "--db", clean, *FINGERS, cwd=work).returncode == 0
    for table in ("fingercontact", "fingergrasp", "fingerquery"):
        db = tmp_path / f"{table}.duckdb"
        res = cli("fingers", work / "ball.stl", "--db", db, *FINGERS, cwd=work, env={"WORKBENCH_FAULT": f"{table}:1:SIGKILL"})
        assert res.returncode == -signal.SIGKILL
        assert state(db)[table][0] == 0
        res = cli("fingers", work / "ball.stl", "--db", db, *FINGERS, cwd=work)
        assert res.returncode == 0, res.stderr[-2000:]
        assert state(db) == state(clean)


def test_two_writers_at_once(work, tmp_path, reference):
    db = tmp_path / "s.duckdb"
    first = spawn("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    deadline = time.monotonic() + 120
    while not db.exists() and first.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    second = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    out, err = first.communicate(timeout=600)
    codes = sorted([first.returncode, second.returncode])
    assert codes in ([0, 2], [0, 0]), (first.returncode, err[-1500:], second.returncode, second.stderr[-1500:])
    if codes == [0, 2]:
        loser = second if second.returncode == 2 else subprocess.CompletedProcess([], 2, out, err)
        assert_refused(loser, "locked")
    assert state(db) == reference


def _mount_tmpfs(path: Path, size: str) -> bool:
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True,
                          check=False).returncode == 0


def test_full_disk(work, tmp_path, reference):
    """A store on a small tmpfs (when root may mount one) or under a file-size limit (RLIMIT_FSIZE: writes past it
    fail as on a full disk): refused in one line naming the store; the file is consistent and completes elsewhere."""
    mnt = tmp_path / "small"
    mounted = _mount_tmpfs(mnt, "256k")
    db = mnt / "s.duckdb"
    try:
        res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work, fsize=None if mounted else 256 << 10)
        err = assert_refused(res, "s.duckdb", "disk is full")
        moved = tmp_path / "moved"
        moved.mkdir()
        for f in mnt.glob("s.duckdb*"):
            shutil.copy(f, moved / f.name)
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(mnt)], capture_output=True, check=False)
    assert "Traceback" not in err
    res = cli("build", work / "box.stl", "--db", moved / "s.duckdb", *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert state(moved / "s.duckdb") == reference


def test_schema_2_plans_move_to_plan_time(work, tmp_path):
    """Schema 2 stored knot times from each segment's start: opening such a store moves them to plan time (from the
    plan's start, CONVENTIONS.md), once."""
    db = tmp_path / "p.duckdb"
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    con = duckdb.connect(str(db))
    now = con.execute("SELECT idplansegment, t0, t FROM plansegment ORDER BY idplan, seq").fetchall()
    assert len(now) > 3 and all(abs(t[0] - t0) < 1e-9 for _, t0, t in now)
    con.executemany("UPDATE plansegment SET t = ? WHERE idplansegment = ?",  # as schema 2 wrote them
                    [[[x - t0 for x in t], i] for i, t0, t in now])
    con.execute("UPDATE workbench_meta SET value = '2' WHERE key = 'schema_version'")
    con.close()
    for _ in range(2):  # upgraded once: a second opening changes nothing
        Store(db).close()
    con = duckdb.connect(str(db), read_only=True)
    back = con.execute("SELECT idplansegment, t0, t FROM plansegment ORDER BY idplan, seq").fetchall()
    version = con.execute("SELECT value FROM workbench_meta WHERE key = 'schema_version'").fetchall()[0][0]
    con.close()
    assert version == str(SCHEMA_VERSION) and all(np.allclose(a[2], b[2]) for a, b in zip(now, back))


def test_a_schema_3_store_is_upgraded_when_plan_reads_it(work, tmp_path):
    """Schema 3 had no plan.speed, which the lookup of a stored plan reads: `plan`, which opens a current store for
    reading only, opens a schema-3 store read-write once, so that the column is added before it is read, and
    answers with no traceback."""
    db = tmp_path / "p.duckdb"
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    con = duckdb.connect(str(db))
    con.execute("UPDATE workbench_meta SET value = '3' WHERE key = 'schema_version'")
    con.close()
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, cwd=work)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr[-2000:]
    con = duckdb.connect(str(db), read_only=True)
    version = con.execute("SELECT value FROM workbench_meta WHERE key = 'schema_version'").fetchall()[0][0]
    speeds = con.execute("SELECT speed FROM plan").fetchall()
    con.close()
    assert version == str(SCHEMA_VERSION) and speeds and all(v == 1.0 for (v,) in speeds)


def test_store_left_by_an_older_version(work, db, reference):
    """Schema 1 stores had no metadata and no completion records: opened, upgraded, and every stage reused."""
    con = duckdb.connect(str(db))
    con.execute("DROP TABLE workbench_meta")
    con.execute("DROP TABLE stagedone")
    con.close()
    res = cli("build", work / "box.stl", "--db", db, *BUILD, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.count("reused") >= 2
    assert state(db) == reference
    res = cli("plan", "--db", db, "--object", "box", "--robot", "panda", *QUERY, "--no-save", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]


# ---------------------------------------------------------------------------------------------------------------
# Ctrl-C as a terminal sends it: SIGINT to the whole process group while the workers run.


def interrupt_when(args: list, marker: str, cwd: Path, delay: float = 0.0, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `workbench ARGS` in its own process group and send SIGINT to the group once `marker` shows on its stderr
    (then after `delay` seconds), as a terminal's Ctrl-C reaches a command and every worker it started."""
    proc = subprocess.Popen([*CLI, *map(str, args)], cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT)},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    seen, deadline = b"", time.monotonic() + timeout
    os.set_blocking(proc.stderr.fileno(), False)
    while marker.encode() not in seen and proc.poll() is None and time.monotonic() < deadline:
        seen += proc.stderr.read() or b""
        time.sleep(0.02)
    time.sleep(delay)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)
    os.set_blocking(proc.stderr.fileno(), True)
    out, err = proc.communicate(timeout=timeout)
    return subprocess.CompletedProcess(args, proc.returncode, out.decode(), (seen + err).decode())


def assert_interrupted(res: subprocess.CompletedProcess, command: str) -> None:
    """Exit 130 and one line from the driver; no traceback or KeyboardInterrupt from any process."""
    assert "Traceback" not in res.stderr and "KeyboardInterrupt" not in res.stderr, res.stderr[-3000:]
    lines = [ln for ln in res.stderr.replace("\r", "\n").splitlines() if ln.strip() and "/s]" not in ln
             and "it/s" not in ln and not ln.startswith("dask:")]
    # 130, or death by the SIGINT itself (-2), which a shell also reports as status 130 (a worker process's end)
    assert res.returncode in (130, -signal.SIGINT), (res.returncode, res.stderr[-2000:])
    assert lines == [f"workbench {command}: interrupted; the store keeps only completed stages"], lines


def test_ctrl_c_during_ik_workers(work, db, tmp_path):
    """ik with two worker processes, interrupted while they start and solve: one line; the re-run resumes and ends
    with the rows of an uninterrupted run."""
    clean = tmp_path / "clean.duckdb"
    shutil.copy(db, clean)
    # the numerical solver, so the closed form's speed does not end the run before the interrupt reaches it
    args = ["ik", "--object", "box", "--robot", "ur5", "--workers", "2", "--ik", "numerical"]
    assert cli(*args[:1], "--db", clean, *args[1:], cwd=work).returncode == 0
    res = interrupt_when([*args[:1], "--db", db, *args[1:]], "ik ur5", cwd=work, delay=0.0)
    assert_interrupted(res, "ik")
    res = cli(*args[:1], "--db", db, *args[1:], cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert state(db) == state(clean)


def test_ctrl_c_during_build(work, tmp_path, reference):
    db = tmp_path / "s.duckdb"
    args = ["build", work / "box.stl", "--db", db, "--robot", "panda", "--workers", "2", *GRID]
    assert_interrupted(interrupt_when(args, "ik panda", cwd=work, delay=0.3), "build")
    res = cli(*args, cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert state(db) == reference


def test_ctrl_c_during_gptable(work, tmp_path):
    db = tmp_path / "g.duckdb"
    # the bundled tube's 94 grasp classes, so the run outlasts the delay on a fast machine; a Ctrl-C while it still
    # loads is the same line
    tube = ROOT / "workbench" / "assets" / "objects" / "tube.stl"
    res = interrupt_when(["gptable", tube, "--db", db, "--theta-step", "2", "--phi-step", "2"], "", cwd=work, delay=1.5)
    assert_interrupted(res, "gptable")


@pytest.mark.parametrize("delay", [0.1, 0.3, 0.6])
def test_ctrl_c_while_modules_load(work, tmp_path, delay):
    """A Ctrl-C in the first second, while the command imports scipy and the planners (a library that catches
    everything there would swallow it): the command still stops, with one line and exit 130."""
    res = interrupt_when(["gptable", work / "box.stl", "--db", tmp_path / "g.duckdb"], "", cwd=work, delay=delay)
    assert_interrupted(res, "gptable")


def test_ctrl_c_during_catalog_build(work, tmp_path):
    """The Dask workers never see the Ctrl-C; the driver stops with one line and records no unit as failed."""
    db = tmp_path / "c.duckdb"
    args = ["catalog", "build", work / "box.stl", "--robots", "panda", "--db", db, "--workers", "1", "--no-progress",
            *GRID[:-2]]
    assert_interrupted(interrupt_when(args, "dask:", cwd=work, delay=1.0), "catalog")
    con = duckdb.connect(str(db), read_only=True)
    tables = {t for (t,) in con.execute("SELECT table_name FROM information_schema.tables").fetchall()}
    failed = con.execute("SELECT count(*) FROM catalog_unit WHERE error IS NOT NULL").fetchone()[0] \
        if "catalog_unit" in tables else 0
    con.close()
    assert failed == 0


def test_catalog_of_only_broken_parts_is_a_failure(work, tmp_path):
    """Every part broken: each named with its reason, and the build exits 2 (it built nothing)."""
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "a.stl").write_text("solid nothing\n")
    (parts / "b.stl").write_bytes((work / "box.stl").read_bytes()[:300])
    res = cli("catalog", "build", parts, "--robots", "panda", "--db", tmp_path / "c.duckdb", "--workers", "1",
              "--no-progress", cwd=work)
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr[-2000:]
    assert res.stdout.count("failed: ") == 2 and "no part of" in res.stderr


# ---------------------------------------------------------------------------------------------------------------
# Another program's store, and meshes whose headers claim more than a store holds.


def _foreign_with_core_tables(path: Path, keyed: bool) -> None:
    """Another program's file with tables named `object` and `paramset`: its own, with a few columns named as ours, or
    all of our core columns but no primary key (a copy of our rows made with CREATE TABLE AS)."""
    con = duckdb.connect(str(path))
    if keyed:
        con.execute("CREATE TABLE object (idobject BIGINT PRIMARY KEY, name VARCHAR)")
        con.execute("CREATE TABLE paramset (idparamset BIGINT PRIMARY KEY, stage VARCHAR)")
    else:
        con.execute("CREATE TABLE object (idobject BIGINT, name VARCHAR, digest VARCHAR, scale DOUBLE, com DOUBLE[3], "
                    "vertices DOUBLE[3][], faces INTEGER[3][])")
        con.execute("CREATE TABLE paramset (idparamset BIGINT, stage VARCHAR, digest VARCHAR, params VARCHAR, "
                    "idobject BIGINT)")
    con.execute("INSERT INTO object (idobject, name) VALUES (1, 'theirs')")
    con.close()


@pytest.mark.parametrize("kind", ["own columns", "no primary key"])
def test_another_programs_object_and_paramset_tables_are_refused(work, tmp_path, kind):
    path = tmp_path / "theirs.duckdb"
    _foreign_with_core_tables(path, keyed=kind == "own columns")
    before = file_digest(path)
    words = ["without our columns"] if kind == "own columns" else ["not a primary key"]
    for args in (["grasps", work / "box.stl", "--db", path], ["build", work / "box.stl", "--db", path, *BUILD],
                 _reader("plan", path), _reader("catalog report", path)):
        res = cli(*args, cwd=work)
        assert_refused(res, "theirs.duckdb", "not a workbench store", "object", *words)
        assert file_digest(path) == before, args[0]
    assert not list(tmp_path.glob("theirs.duckdb.wal"))


def _binary_stl_header(path: Path, triangles: int, body: int = 10, header: bytes = b"") -> Path:
    path.write_bytes(header.ljust(80, b"\0") + int(triangles).to_bytes(4, "little") + b"\0" * 50 * body)
    return path


def test_a_mesh_header_claiming_more_triangles_than_a_store_holds(work, tmp_path):
    """Binary STL headers (one beginning with "solid", as some exporters write) and a PLY header that declare
    2^31 or more triangles: refused in one line naming the count and the limit, before the mesh is read; a header
    claiming more triangles than the file holds is named truncated. Nothing is stored."""
    from workbench.errors import MeshError
    from workbench.geometry.objects import MAX_TRIANGLES, check_triangle_count

    assert MAX_TRIANGLES == 2**31 - 1  # object.faces keeps 32-bit indices
    check_triangle_count(2**31 - 1, "mesh")
    with pytest.raises(MeshError, match="2,147,483,648 triangles, more than the 2,147,483,647"):
        check_triangle_count(2**31, "mesh")
    with pytest.raises(MeshError, match="vertices"):
        check_triangle_count(10, "mesh", vertices=2**32)
    ply = tmp_path / "scan.ply"
    ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                    b"property float z\nelement face 3000000000\nproperty list uchar int vertex_indices\nend_header\n"
                    + b"\0" * 100)
    db = tmp_path / "s.duckdb"
    cases = [(_binary_stl_header(tmp_path / "huge.stl", 2**31 + 5), ["2,147,483,653 triangles", "2,147,483,647"]),
             (_binary_stl_header(tmp_path / "solid.stl", 2**32 - 1, header=b"solid exported"), ["4,294,967,295 triangles"]),
             (ply, ["3,000,000,000 triangles", "PLY header"]),
             (_binary_stl_header(tmp_path / "short.stl", 1000), ["declares 1,000 triangles", "truncated"])]
    for path, words in cases:
        for cmd in (["grasps", path, "--db", db], ["gptable", path, "--db", db]):
            err = assert_refused(cli(*cmd, cwd=work), path.name, *words)
            assert "assimp" not in err and "no triangle mesh" not in err
        assert not db.exists()
    # a real binary STL passes the header check unchanged
    assert cli("grasps", work / "box.stl", "--db", db, "--rotations", "2", cwd=work).returncode == 0


# ---------------------------------------------------------------------------------------------------------------
# The grasp-placement table: unknown ids, and SIGKILL anywhere.

GPTABLE = ["--theta-step", "15", "--phi-step", "15"]


@pytest.fixture(scope="session")
def gp_built(work) -> Path:
    db = work / "gp.duckdb"
    res = cli("gptable", work / "box.stl", "--db", db, *GPTABLE, cwd=work)
    assert res.returncode == 0, res.stderr[-3000:]
    return db


@pytest.mark.parametrize("query, words", [
    (["--initial", "0,0", "--goal", "3,0:90"], ["goal grasp class 3", "classes 0..2"]),
    (["--from", "6,0", "--to", "0,90"], ["start placement 6", "placements 0..5"]),
    (["--pickup", "9,0.45,0,0", "--destination", "0,0.45,0.1,0"], ["placement 9", "0..5"]),
    (["--pickup", "0,0.45,0,0", "--destination", "1,0.45,0.1,0", "--initial", "5,0"], ["grasp class 5", "0..2"]),
])
def test_gpplan_with_unknown_ids_names_the_valid_range(work, gp_built, tmp_path, query, words):
    """The box's table has 3 grasp classes and 6 placement classes: an id beyond them is one line naming the
    range, exit 2, and the store is unchanged (nothing planned, nothing stored)."""
    db = tmp_path / "gp.duckdb"
    shutil.copy(gp_built, db)
    before = state(db)
    res = cli("gpplan", "--db", db, "--object", "box", "--no-motion", *query, cwd=work)
    assert_refused(res, *words)
    assert state(db) == before


def test_gpplan_writes_its_json_into_a_folder_it_creates(work, gp_built, tmp_path):
    """--json and --html into folders that do not exist yet: created, the files written whole; the store keeps
    its rows (a plan stored only without --no-save)."""
    db = tmp_path / "gp.duckdb"
    shutil.copy(gp_built, db)
    before = state(db)
    out = tmp_path / "new" / "deeper"
    res = cli("gpplan", "--db", db, "--object", "box", "--from", "0,0", "--to", "1,90", "--no-motion", "--no-save",
              "--json", out / "q.json", "--html", out / "t.html", cwd=work)
    assert res.returncode == 0, res.stderr[-2000:]
    assert json.loads((out / "q.json").read_text())["sequence"] is not None
    assert (out / "t.html").read_text().lstrip().lower().startswith("<")
    assert state(db) == before


def test_gptable_face_area_hint_names_a_threshold_that_keeps_classes(work, tmp_path):
    """--min-face-area above every face of the box: 0 classes, and the warning names the two largest faces and a
    --min-face-area within its declared range that keeps them, which then gives classes (not a curved surface)."""
    from workbench.params import bounds
    from workbench.planners.tournassoud.classes import ClassParams

    db = tmp_path / "g.duckdb"
    res = cli("gptable", work / "box.stl", "--db", db, *GPTABLE, "--min-face-area", "1", cwd=work)
    assert res.returncode == 0 and "0 grasp classes" in res.stdout, res.stderr[-2000:]
    assert "curved" not in res.stderr and bounds(ClassParams)["min_face_area"][0].describe(True) in res.stderr
    keep = re.search(r"its two largest are 2000 and 2000 mm\^2: --min-face-area ([0-9.e-]+) keeps them", res.stderr)
    assert keep, res.stderr
    res = cli("gptable", work / "box.stl", "--db", db, *GPTABLE, "--min-face-area", keep.group(1), cwd=work)
    assert res.returncode == 0 and re.search(r"box: [1-9]\d* grasp classes", res.stdout), res.stdout + res.stderr[-2000:]


GP_FAULTS = ["object", "tgraspclass", "robot", "tplacementclass", "tgpcell"]  # each stage, and between them


def test_gptable_killed_anywhere_resumes_to_the_same_rows(work, gp_built, tmp_path):
    """SIGKILL after the first insert into each table gptable writes (inside the stage's transaction, and so at
    each stage boundary: the classes committed, the table not): the store keeps the completed stages only, and the
    same command then finishes with the rows of an uninterrupted run."""
    clean = state(gp_built)
    for table in GP_FAULTS:
        db = tmp_path / f"{table}.duckdb"
        res = cli("gptable", work / "box.stl", "--db", db, *GPTABLE, cwd=work, env={"WORKBENCH_FAULT": f"{table}:1:SIGKILL"})
        assert res.returncode == -signal.SIGKILL, (table, res.returncode, res.stderr[-1500:])
        partial = state(db) or {}
        assert partial.get(table, (0,))[0] == 0, table  # its transaction rolled back
        for t, (rows, _) in partial.items():
            assert rows <= clean[t][0], (table, t)
        res = cli("gptable", work / "box.stl", "--db", db, *GPTABLE, cwd=work)
        assert res.returncode == 0, (table, res.stderr[-2000:])
        assert state(db) == clean, table


CATALOG = ["--robots", "panda", "--workers", "1", "--no-progress", "--x", "0.4,0.6,2", "--y=-0.1,0.1,2", "--angles", "2",
           "--max-grasps", "10", "--ik-library", "2048", "--ik-seeds", "2", "--ik-chunk", "64"]


def _catalog_build(work: Path, db: Path, fault: str | None = None, kill_at: str | None = None) -> subprocess.CompletedProcess:
    """`catalog build` of the box in its own process group (the cluster it starts ends with it); with `kill_at`, the
    group is killed (SIGKILL) once a file matching that pattern shows in the units' folder beside the store."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    if fault:
        env["WORKBENCH_FAULT"] = fault
    proc = subprocess.Popen([*CLI, "catalog", "build", str(work / "box.stl"), "--db", str(db), *CATALOG], cwd=work,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        if kill_at:
            deadline = time.monotonic() + 300
            while proc.poll() is None and not list(db.parent.glob(f"{db.name}.units/{kill_at}")) \
                    and time.monotonic() < deadline:
                time.sleep(0.02)
            os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate(timeout=600)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # a killed driver leaves its scheduler and worker behind
    return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)


def test_catalog_build_killed_anywhere_resumes_to_the_same_rows(work, tmp_path):
    """The driver killed (SIGKILL) while its units compute (an IK shard on disk, nothing merged), then the re-run
    killed inside its merge, after its ik rows, writing the units' records: each kill leaves the store without a
    row of the part, and the last re-run ends with the rows of an uninterrupted build (the units' records by kind
    and failures; their seconds and workers differ)."""
    clean = tmp_path / "clean.duckdb"
    assert _catalog_build(work, clean).returncode == 0
    db = tmp_path / "c.duckdb"
    for fault, kill_at in ((None, "ik-*.parquet"), ("catalog_unit:1:SIGKILL", None)):
        res = _catalog_build(work, db, fault, kill_at)
        assert res.returncode == -signal.SIGKILL, (fault, res.returncode, res.stderr[-2000:])
        killed = state(db) or {}
        assert killed.get("object", (0,))[0] == killed.get("ik", (0,))[0] == killed.get("catalog_unit", (0,))[0] == 0
    res = _catalog_build(work, db)
    assert res.returncode == 0, res.stderr[-2000:]
    skip = {"catalog_unit"}
    assert {t: v for t, v in state(db).items() if t not in skip} == {t: v for t, v in state(clean).items() if t not in skip}
    units = "SELECT kind, count(*), count(error) FROM catalog_unit GROUP BY kind ORDER BY kind"
    with duckdb.connect(str(db), read_only=True) as a, duckdb.connect(str(clean), read_only=True) as b:
        assert a.execute(units).fetchall() == b.execute(units).fetchall()


# ---------------------------------------------------------------------------------------------------------------
# Two builds of different parts into one store, side by side.


def _part_rows(db: Path, name: str) -> dict:
    """One part's rows in a store, without ids (which depend on what else the store holds): grasps, placements,
    tabletop grips and IK rows, each as a sorted list of values, hashed."""
    con = duckdb.connect(str(db), read_only=True)
    queries = {
        "freeairgrip": "SELECT g.rotmat, round(g.jawwidth, 12) FROM freeairgrip g JOIN object o USING (idobject) WHERE o.name = ?",
        "freetabletopplacement": "SELECT p.rotmat FROM freetabletopplacement p JOIN object o USING (idobject) WHERE o.name = ?",
        "tabletopgrips": "SELECT g.rotmat FROM tabletopgrips g JOIN tabletopplacements t USING (idtabletopplacements) "
                         "JOIN freetabletopplacement f USING (idfreetabletopplacement) JOIN object o ON o.idobject = f.idobject "
                         "WHERE o.name = ?",
        "ik": "SELECT g.rotmat, k.feasibility, k.feasibility_handx, k.feasibility_handxworldz, k.jnt_grasp FROM ik k "
              "JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements t USING (idtabletopplacements) "
              "JOIN freetabletopplacement f USING (idfreetabletopplacement) JOIN object o ON o.idobject = f.idobject "
              "WHERE o.name = ?",
    }
    try:
        out = {}
        for table, sql in queries.items():
            rows = sorted(str(r) for r in con.execute(sql, [name]).fetchall())
            out[table] = (len(rows), hashlib.sha256("\n".join(rows).encode()).hexdigest()[:16])
        out["ik complete"] = con.execute("SELECT count(*) FROM stagedone WHERE stage = 'ik'").fetchone()[0]
        return out
    finally:
        con.close()


def _wait_for(proc: subprocess.Popen, marker: str, timeout: float = 300) -> bytes:
    """Read `proc`'s stderr until `marker` shows (or it ends); returns what was read."""
    seen, deadline = b"", time.monotonic() + timeout
    os.set_blocking(proc.stderr.fileno(), False)
    while marker.encode() not in seen and proc.poll() is None and time.monotonic() < deadline:
        seen += proc.stderr.read() or b""
        time.sleep(0.02)
    os.set_blocking(proc.stderr.fileno(), True)
    return seen


def test_two_builds_of_different_parts_run_side_by_side(work, built, tmp_path):
    """A build of the box holds the store only while it writes: frozen (SIGSTOP) in the middle of its IK stage, a
    build of the ball into the same store runs from start to end beside it, and the box's build then finishes.
    Each part's rows equal those of a build of it alone (the box's IK here by the numerical solver, so that it
    lasts: one row per tabletop grip, the run recorded complete)."""
    alone = tmp_path / "ball.duckdb"
    assert cli("build", work / "ball.stl", "--db", alone, *BUILD, cwd=work).returncode == 0
    db = tmp_path / "both.duckdb"
    first = subprocess.Popen([*CLI, "build", str(work / "box.stl"), "--db", str(db), *BUILD, "--ik", "numerical",
                              "--wait", "300"], cwd=work, env={**os.environ, "PYTHONPATH": str(ROOT)},
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = _wait_for(first, "ik panda")
    try:
        for _ in range(5):  # frozen at a moment it holds no lock, which is nearly always: a chunk's write is brief
            os.kill(first.pid, signal.SIGSTOP)
            second = cli("build", work / "ball.stl", "--db", db, *BUILD, "--wait", "5", cwd=work)
            os.kill(first.pid, signal.SIGCONT)
            if second.returncode == 0:
                break
            assert_refused(second, "busy")
            time.sleep(0.3)
    finally:
        os.kill(first.pid, signal.SIGCONT)
        out, err = first.communicate(timeout=600)
    assert second.returncode == 0, second.stderr[-2000:]
    assert first.returncode == 0 and "Traceback" not in err.decode(), (seen + err.decode().encode())[-2000:]
    box, ball = _part_rows(db, "box"), _part_rows(db, "ball")
    assert box["ik complete"] == ball["ik complete"] == 2
    assert {k: v for k, v in ball.items() if k != "ik complete"} == \
        {k: v for k, v in _part_rows(alone, "ball").items() if k != "ik complete"}
    reference = _part_rows(built, "box")
    assert {k: v for k, v in box.items() if k not in ("ik", "ik complete")} == \
        {k: v for k, v in reference.items() if k not in ("ik", "ik complete")}
    assert box["ik"][0] == box["tabletopgrips"][0]


def test_ctrl_c_inside_a_finaliser_is_noted_not_reported(capsys):
    """A Ctrl-C that lands in a finaliser (llvmlite's, while numba loads a kernel) cannot propagate: the command notes
    it, to stop with its one line, and Python does not print it as an ignored exception with a traceback."""
    from workbench.cli.main import _CtrlC

    class Finalised:
        def __del__(self):
            raise KeyboardInterrupt

    hook = sys.unraisablehook
    with _CtrlC() as ctrl_c:
        ctrl_c.loaded()
        Finalised()  # dropped at once: its finaliser raises where Python cannot pass the exception on
    err = capsys.readouterr().err
    assert ctrl_c.seen and "KeyboardInterrupt" not in err and "Traceback" not in err
    assert sys.unraisablehook is hook  # outside the command, the reports are Python's (here pytest's) again
