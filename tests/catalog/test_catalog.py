"""`workbench catalog` on a real Dask LocalCluster and a real DuckDB file (issue 15): the rows equal a serial build's,
a worker killed by PID or a driver killed mid-run loses and duplicates nothing, a broken part is reported."""

from __future__ import annotations

import contextlib
import io
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import duckdb
import numpy as np
import pytest
import trimesh

from workbench.catalog.cluster import cluster_client
from workbench.catalog.driver import CatalogParams, build_catalog
from workbench.cli.main import main
from workbench.geometry.objects import load_object
from workbench.planners.wan_harada.stages import (
    ensure_grasps,
    ensure_placements,
    run_ik,
)
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.resources import bundled_objects
from workbench.robots.gripper import franka_hand
from workbench.robots.ik import IKOptions
from workbench.catalog.robots import parse_robots
from workbench.resources import erd_robots
from workbench.robots.model import get_robot, pose_xyz_yaw
from workbench.store import Store
from workbench.store import catalog as sql
from workbench.store.catalog import ik_vectors

UR5 = erd_robots() / "ur_description" / "urdf" / "ur5_robot.urdf"
ROBOTS = ("panda", "ur5_robot")  # a built-in robot and a user's URDF robot (the Franka hand on its flange)
ROBOT_ARGS = ["--robots", f"panda,ur5_robot={UR5}", "--tip", "tool0", "--mount", "0,0,0.1034,0,0,0"]
MOUNT = pose_xyz_yaw(0.0, 0.0, 0.1034, 0.0)
PARAMS = CatalogParams(tabletop=TabletopParams(x_min=0.4, x_max=0.6, nx=2, y_min=0.0, y_max=0.0, ny=1, angles=2,
                                               max_grasps=10),
                       ik=IKOptions(library=2048, seeds=2, self_collide=True), ik_chunk=32)
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def parts(tmp_path_factory) -> list[Path]:
    b = bundled_objects()
    broken = tmp_path_factory.mktemp("parts") / "broken.stl"
    broken.write_text("solid broken\nendsolid broken\n")
    return [b["planebody"], b["bracket"], b["tube"], broken]


def _rows(db: Path) -> dict:
    """Per part: counts of grasps, placements, tabletop grips; per (part, robot): the (N, 3) feasibility ordered by
    tabletop grip, and the number of ik rows (to catch duplicates)."""
    out = {}
    with Store(db, read_only=True) as s:
        for name, oid in s.run("SELECT name, idobject FROM object ORDER BY name"):
            g = s.one("SELECT count(*) FROM freeairgrip WHERE idobject = ?", [oid])[0]
            p = s.one("SELECT count(*) FROM freetabletopplacement WHERE idobject = ?", [oid])[0]
            tt, tg = s.one("SELECT max(p.idparamset), count(*) FROM tabletopgrips g JOIN tabletopplacements p "
                           "USING (idtabletopplacements) JOIN freetabletopplacement f USING (idfreetabletopplacement) "
                           "WHERE f.idobject = ?", [oid])
            out[name] = (g, p, tg)
            for rid, robot in s.run("SELECT idrobot, name FROM robot ORDER BY name"):
                for sid, kid in s.run("SELECT DISTINCT idscene, idikret FROM ik WHERE idrobot = ?", [rid]):
                    out[name, robot] = ik_vectors(s, tt, rid, sid, kid)
        out["ik rows"] = s.one("SELECT count(*), count(DISTINCT (idrobot, idtabletopgrips, idscene, idikret)) FROM ik")
    return out


PAPER_TABLES = ("object", "robot", "freeairgrip", "freetabletopplacement", "freetabletopgrip", "angle", "tabletopplacements",
                "tabletopgrips", "ikret", "ik", "gripper", "scene")


def _content(db: Path, ids: bool = False) -> dict[str, list]:
    """Every row of the paper's tables (and the gripper and scene) without its timestamps and IK joint vectors
    (compared to 1e-12 by `_joints`; BLAS sums in another order), sorted: what two builds of the same inputs share
    whatever order they wrote in; with `ids`, their ids too (the same when both wrote in the same order), but for
    the `ik` rows' own (a build numbers them as its IK solver finishes its chunks)."""
    out = {}
    with Store(db, read_only=True) as s:
        for t in PAPER_TABLES:
            cols = [c for c, kind in s.run("SELECT column_name, data_type FROM information_schema.columns WHERE "
                                           "table_name = ? ORDER BY ordinal_position", [t])
                    if (ids and c != "idik" or not c.startswith("id")) and not c.startswith("jnt_")
                    and "TIMESTAMP" not in kind
                    and c not in ("used", "created")]
            cols = list(dict.fromkeys(cols))  # a Parquet catalogue's view and the table beneath it list them twice
            out[t] = sorted(map(repr, s.run(f"SELECT {', '.join(cols)} FROM {t}")))
    return out


@pytest.fixture(scope="module")
def serial_db(parts, tmp_path_factory) -> Path:
    """A serial build through the stage runners `workbench build` uses, one part and robot at a time."""
    db = tmp_path_factory.mktemp("serial") / "serial.duckdb"
    hand = franka_hand()
    p = PARAMS
    with Store(db) as store:
        for path in parts[:-1]:
            obj = load_object(path)
            g = ensure_grasps(store, obj, hand, p.grasps)
            pl = ensure_placements(store, g.idobject, obj, g.idparamset, hand, p.placements, p.tabletop)
            for robot in (get_robot("panda"), get_robot(str(UR5), tip_frame="tool0", mount=MOUNT)):
                run_ik(store, obj.name, robot, None, p.handx, p.worldz, p.ik,
                       workers=1, progress=False, idtabletop=pl.idtabletop)
    return db


@pytest.fixture(scope="module")
def serial(serial_db) -> dict:
    return _rows(serial_db)


@pytest.fixture(scope="module")
def robots() -> dict:
    """The catalogue's columns, as `--robots panda,ur5_robot=UR5 --tip tool0 --mount ...` gives them."""
    return parse_robots(f"panda,ur5_robot={UR5}", tip="tool0", mount=MOUNT)


@pytest.fixture(scope="module")
def client():
    with cluster_client(workers=2) as c:
        yield c


def _same(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for k in a:
        if isinstance(a[k], np.ndarray):
            assert a[k].shape == b[k].shape and a[k].shape[0] > 0, k
            assert np.array_equal(a[k], b[k]), f"feasibility of {k} differs in {int((a[k] != b[k]).sum())} entries"
        else:
            assert a[k] == b[k], k


def test_cluster_build_equals_serial_and_reports_broken_part(parts, robots, serial, serial_db, client, tmp_path):
    db = tmp_path / "catalog.duckdb"
    res = build_catalog(parts, robots, db, client, PARAMS, progress=False)
    assert res.workers == 2 and res.dashboard.startswith("http://127.0.0.1:")
    rows = _rows(db)
    _same(rows, serial)
    assert rows["ik rows"][0] == rows["ik rows"][1] == sum(len(v) for k, v in rows.items() if isinstance(k, tuple))
    # every table, row for row, ids included: the catalogue writes in the listed order whichever unit finishes first
    mine, theirs = _content(db, ids=True), _content(serial_db, ids=True)
    for t in PAPER_TABLES:
        assert mine[t] == theirs[t] and mine[t], t
    with Store(db, read_only=True) as s:  # the ik rows' ids follow the parts, then the robots, then the grips
        rows = s.run("SELECT k.idik, f.idobject, r.name, k.idtabletopgrips FROM ik k JOIN robot r USING (idrobot) "
                     "JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
                     "JOIN freetabletopplacement f USING (idfreetabletopplacement) ORDER BY k.idik")
    assert [r[0] for r in rows] == list(range(1, len(rows) + 1))
    assert [r[1:] for r in rows] == sorted((r[1:] for r in rows), key=lambda r: (r[0], ROBOTS.index(r[1]), r[2]))
    assert [(f["part"], f["kind"]) for f in res.failures] == [("broken", "part")]
    assert "holds no triangle mesh" in res.failures[0]["error"] and "\n" not in res.failures[0]["error"]
    assert {(r["part"], r["robot"]) for r in res.rows} == {(p.stem, r) for p in parts[:-1] for r in ROBOTS}
    for r in res.rows:  # the summary comes from the stage tables; every grip has its IK row
        assert r["ik_rows"] == r["tabletop_grips"] == serial[r["part"]][2] > 0
        assert r["ik_feasible"] == int(serial[r["part"], r["robot"]].all(axis=1).sum())
        assert r["graph"]["components"] >= 1 and r["graph"]["grips"] == r["tabletop_grips"]
    again = build_catalog(parts, robots, db, client, PARAMS, progress=False)
    assert sum(again.computed.values()) == 0 and again.skipped == sum(res.computed.values())
    _same(_rows(db), serial)


@pytest.mark.parametrize("during", ["part", "ik"])
def test_worker_killed_mid_run_loses_nothing(parts, robots, serial, client, tmp_path, during):
    """A worker killed by PID while it runs a part unit (or an IK unit): Dask runs the unit again elsewhere, and the
    rows equal a serial build's; every unit file is merged and deleted."""
    pids = list(client.run(os.getpid).values())
    killed = []

    def kill_busy(prefix: str) -> None:
        busy = client.processing()  # kill a worker that is running a unit of this kind right now
        addr = next((a for a, keys in busy.items() if any(str(k).startswith(prefix) for k in keys)), None)
        if addr is not None and not killed:
            pid = client.run(os.getpid, workers=[addr])[addr]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    stop = threading.Event()

    def watch_parts() -> None:
        while not stop.is_set() and not killed:
            kill_busy("part-")
            time.sleep(0.05)

    watcher = threading.Thread(target=watch_parts, daemon=True)
    if during == "part":
        watcher.start()
    try:
        res = build_catalog(parts[:-1], robots, tmp_path / "c.duckdb", client, PARAMS, progress=False,
                            on_unit=(lambda kind, unit: kind == "ik" and kill_busy("ik-")) if during == "ik" else None,
                            shards=tmp_path / "units")
    finally:
        stop.set()
    assert killed and killed[0] in pids
    assert res.failures == []
    _same(_rows(tmp_path / "c.duckdb"), serial)
    assert not list((tmp_path / "units").iterdir())  # every file merged and deleted
    client.wait_for_workers(2, timeout=60)  # the nanny restarted it
    assert killed[0] not in client.run(os.getpid).values()


def test_unit_that_kills_its_worker_is_reported_and_rerun_finishes(parts, robots, serial, tmp_path):
    """With no retries allowed, the IK units on a killed worker fail (Dask's KilledWorker): each is reported with its
    part, robot and one-line reason while its run's other chunks are stored; that run gets no graph; a re-run
    computes the failed chunks and the graph only, and the rows equal a serial build's."""
    import dask

    db = tmp_path / "k.duckdb"
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}), cluster_client(workers=2) as client:
        killed = []

        def kill_one(kind: str, unit: dict) -> None:
            running = client.processing()
            if kind == "ik" and not killed:
                # a worker running only IK units, so the units that die with it are all IK units
                addr = next((a for a, keys in running.items()
                             if keys and all(str(k).startswith("ik-") for k in keys)), None)
                if addr is not None:
                    pid = client.run(os.getpid, workers=[addr])[addr]
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)

        res = build_catalog(parts[:-1], robots, db, client, PARAMS, progress=False, on_unit=kill_one)
        assert killed
        failed = {(f["part"], f["robot"]) for f in res.failures}
        # the worker dies with the IK units it runs and any graph unit already queued on it
        assert failed and all(f["kind"] in ("ik", "graph") and f["error"].startswith("KilledWorker")
                              and "\n" not in f["error"] for f in res.failures)
        assert any(f["kind"] == "ik" for f in res.failures)
        with Store(db, read_only=True) as s:
            graphs = set(s.run("SELECT part, robot FROM catalog_unit WHERE kind = 'graph' AND status = 'done'"))
            chunks = s.one("SELECT count(*) FROM catalog_unit WHERE kind = 'ik' AND status = 'done'")[0]
        assert graphs == {(p.stem, r) for p in parts[:-1] for r in ROBOTS} - failed
        client.wait_for_workers(2, timeout=60)
        again = build_catalog(parts[:-1], robots, db, client, PARAMS, progress=False)
    # the runs the kill left whole stored every chunk; a broken run's finished chunks wait as shards for the re-run
    # (which of the runs the worker held depends on the scheduling)
    with Store(db, read_only=True) as s:
        per_run = s.run("SELECT part, robot, count(*) FROM catalog_unit WHERE kind = 'ik' AND status = 'done' "
                        "GROUP BY part, robot")
    assert chunks == sum(n for part, robot, n in per_run if (part, robot) not in failed)
    assert again.failures == [] and again.computed["part"] == 0
    assert again.computed["ik"] == sum(f["kind"] == "ik" for f in res.failures)
    assert again.computed["graph"] == len(failed)
    _same(_rows(db), serial)


def _rerun(cmd: list[str], client, capsys) -> str:
    """The killed build's command again, in this process on the module's cluster (its stdout)."""
    args = cmd[cmd.index("catalog"):]
    at = args.index("--workers")
    capsys.readouterr()
    assert main([*args[:at], "--scheduler", client.scheduler.address, *args[at + 2:]]) == 0
    return capsys.readouterr().out


def test_driver_killed_during_a_merge_then_rerun_finishes(parts, serial, client, tmp_path, capsys):
    """The driver killed (SIGKILL) inside its first merge transaction, with 2 workers: the store holds no part, the
    units' files wait on disk; the re-run (the same command, on the module's cluster) merges them without computing a
    part again and the rows equal a serial build's; `catalog report` prints them."""
    db = tmp_path / "d.duckdb"
    cmd = [sys.executable, "-m", "workbench.cli", "catalog", "build", *map(str, parts[:-1]), *ROBOT_ARGS,
           "--db", str(db), "--workers", "2", "--x", "0.4,0.6,2", "--y", "0,0,1", "--angles", "2", "--max-grasps", "10",
           "--ik-library", "2048", "--ik-seeds", "2", "--ik-chunk", "32", "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**env, "WORKBENCH_FAULT": "tabletopgrips:1:SIGKILL"})
    try:
        assert proc.wait(timeout=600) == -signal.SIGKILL
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # the cluster it started
    with Store(db, read_only=True) as s:
        assert s.one("SELECT count(*) FROM object")[0] == 0  # the merge's transaction was rolled back whole
    waiting = [f for f in (tmp_path / "d.duckdb.units").glob("part-*") if f.is_dir()]
    assert waiting
    out = _rerun(cmd, client, capsys)
    computed = int(out.split("units computed (")[1].split(" part")[0])
    assert computed == len(parts[:-1]) - len(waiting)  # the parts on disk are merged, not computed again
    _same(_rows(db), serial)
    page = tmp_path / "catalogue.html"
    assert main(["catalog", "report", "--db", str(db), "--html", str(page)]) == 0
    report = capsys.readouterr().out
    text = page.read_text()  # a thumbnail per part, a column pair per robot
    assert text.count('<img src="data:image/png;base64,') == len(parts[:-1])
    assert all(f"{r} reachable" in text and f"{r} connected" in text for r in ROBOTS)
    lines = [line.split() for line in report.splitlines()]
    shown = {(w[0], w[1]): w for w in lines if len(w) == 9 and w[1] in ROBOTS}
    assert set(shown) == {(p.stem, r) for p in parts[:-1] for r in ROBOTS}
    for (part, robot), w in shown.items():  # tabletop grips and the feasible share, as stored
        feas = serial[part, robot]
        assert w[2] == "franka_hand" and int(w[5].replace(",", "")) == len(feas)
        assert w[6] == f"{feas.all(axis=1).mean():.1%}"


def _joints(db: Path) -> dict:
    """Per (part, robot): every ik row's joint vectors at the five poses, in tabletop grip order (None: infeasible)."""
    out = {}
    with Store(db, read_only=True) as s:
        rows = s.run("SELECT o.name, r.name, k.jnt_grasp, k.jnt_handx, k.jnt_handxworldz, k.jnt_worlda, k.jnt_worldaworldz "
                     "FROM ik k JOIN robot r USING (idrobot) JOIN tabletopgrips g USING (idtabletopgrips) "
                     "JOIN tabletopplacements p USING (idtabletopplacements) JOIN freetabletopplacement f "
                     "USING (idfreetabletopplacement) JOIN object o ON o.idobject = f.idobject ORDER BY k.idtabletopgrips")
    for part, robot, *joints in rows:
        out.setdefault((part, robot), []).append(joints)
    return out


def test_sharded_build_equals_serial_and_resumes(parts, robots, serial, serial_db, client, tmp_path):
    """IK workers write Parquet shards that the driver merges per (part, robot): the rows (and joint vectors) equal
    the serial build's. A driver stopped with shards on disk, not merged yet, leaves them to the re-run, which
    merges them without computing them again; stale files are cleaned; nothing is duplicated."""
    db, shards = tmp_path / "s.duckdb", tmp_path / "shards"

    def stop(kind: str, unit: dict) -> None:
        if kind == "ik" and list(shards.glob("*.parquet")):
            raise KeyboardInterrupt  # the driver stops with shards on disk, not merged yet

    with pytest.raises(KeyboardInterrupt):
        build_catalog(parts[:-1], robots, db, client, PARAMS, progress=False, shards=shards, on_unit=stop)
    waiting = sorted(p.name for p in shards.glob("*.parquet"))
    assert waiting, "no shard waits for its merge"
    (shards / f"{waiting[0]}.999.tmp").write_bytes(b"half a file")  # a worker killed while writing
    (shards / "part-0123.999.tmp").mkdir()  # a part unit's folder half written
    res = build_catalog(parts[:-1], robots, db, client, PARAMS, progress=False, shards=shards)
    assert res.failures == [] and res.merges > 0
    assert res.skipped >= len(waiting)  # the shards on disk are merged, not computed again
    assert not list(shards.iterdir())  # merged and deleted, the temporary file too
    rows = _rows(db)
    _same(rows, serial)
    assert rows["ik rows"][0] == rows["ik rows"][1]
    mine, theirs = _joints(db), _joints(serial_db)
    assert mine.keys() == theirs.keys()
    for key in mine:  # equal to the last bits of floating-point rounding (BLAS sums in another order)
        a, b = mine[key], theirs[key]
        assert [[j is None for j in r] for r in a] == [[j is None for j in r] for r in b], key
        assert all(np.allclose(x, y, rtol=0, atol=1e-12) for ra, rb in zip(a, b) for x, y in zip(ra, rb) if x is not None), key
    assert all(r["ik_rows"] == r["tabletop_grips"] > 0 and r["graph"]["grips"] == r["tabletop_grips"] for r in res.rows)


@pytest.mark.parametrize("args, message", [
    (["--robots", "nosuchrobot"], "nosuchrobot"),
    (["--robots", "panda", "--ik-chunk", "0"], "tabletop grips per IK unit must be an integer"),
    (["--robots", "panda", "--workers", "0"], "--workers: 0 is out of range"),
    (["--robots", "panda", "--scale", "-1"], "--scale: -1 is out of range"),
    (["--robots", "arm=arm.urdf"], "give its tip frame with --tip"),
    (["--robots", "panda,panda"], "listed twice"),
    (["--robots", "robots.yaml"], "robots file robots.yaml does not exist"),
    (["--robots", "panda", "--grippers", "franka,robotiq-2f85,franka"], "gripper franka_hand is listed twice"),
    (["--robots", "panda", "--grippers", "franka,nosuch.yaml"], "nosuch.yaml"),
])
def test_bad_input_is_one_line_and_status_2(parts, tmp_path, args, message):
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["catalog", "build", str(parts[0]), "--db", str(tmp_path / "x.duckdb"), *args])
    assert code == 2 and message in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1, err.getvalue()


def test_missing_part_file_is_refused_before_a_cluster_starts(tmp_path, monkeypatch):
    import workbench.cli.catalog as cli

    monkeypatch.setattr(cli, "cluster_client", None)  # calling it would raise: the check must come first
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["catalog", "build", str(tmp_path / "nosuch.stl"), "--robots", "panda", "--db", str(tmp_path / "x.duckdb")])
    assert code == 2 and "no such part file or folder" in err.getvalue() and len(err.getvalue().strip().splitlines()) == 1
    assert not (tmp_path / "x.duckdb").exists()


def test_report_of_a_store_without_catalogue(tmp_path):
    Store(tmp_path / "plain.duckdb").close()
    assert main(["catalog", "report", "--db", str(tmp_path / "plain.duckdb")]) == 2


def test_part_without_grasps_is_stored_with_zero_counts(client, tmp_path):
    """A 0.3 m cube is wider than the Franka hand's 80 mm jaw: zero grasps, stable placements, no grips, no error."""
    path = tmp_path / "bigcube.stl"
    trimesh.creation.box((0.3, 0.3, 0.3)).export(path)
    res = build_catalog([path], "panda", tmp_path / "z.duckdb", client, PARAMS, progress=False)
    assert res.failures == []
    (row,) = res.rows
    assert (row["part"], row["robot"], row["grasps"], row["tabletop_grips"], row["ik_rows"]) == ("bigcube", "panda", 0, 0, 0)
    assert row["placements"] == 6 and row["graph"]["nodes"] == 0
    assert row["reason"].startswith("pads_width: every contact pair is wider than the gripper's 80 mm opening")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        assert main(["catalog", "report", "--db", str(tmp_path / "z.duckdb")]) == 0
    assert "warning: bigcube has no free-air grasps; stage pads_width: every contact pair is wider" in err.getvalue()


def test_catalog_over_a_serial_store_duplicates_nothing(parts, robots, serial, serial_db, client, tmp_path):
    """Parts and IK rows stored by `workbench build` are reused: the catalogue adds its unit rows and no stage row."""
    db = tmp_path / "both.duckdb"
    shutil.copy(serial_db, db)
    res = build_catalog(parts[:-1], robots, db, client, PARAMS, progress=False)
    assert res.failures == [] and res.computed["part"] == 3 and res.computed["ik"] > 0
    assert res.rows_written == 0  # every stage row and IK row was there already
    _same(_rows(db), serial)
    assert all(r["ik_rows"] == r["tabletop_grips"] > 0 for r in res.rows)


def test_unit_rows_replace_a_recorded_failure_and_are_never_duplicated(tmp_path):
    """A failed unit's row is replaced when the unit later succeeds; a unit the writer knows is new is inserted (and a
    second insert of the same digest is refused by the key, never duplicated)."""
    with Store(tmp_path / "units.duckdb") as store:
        sql.ensure_catalog_tables(store)
        unit = {"digest": "d1", "kind": "part", "part": "p", "counts": {}, "nrows": 0}
        sql.record_failure(store, {**unit, "fresh": True}, "broken mesh")
        assert sql.unit_digests(store) == {"d1"} and sql.done_units(store) == {}
        with sql.unit_transaction(store, {**unit, "nrows": 3}):
            pass  # not fresh: the failure row is replaced
        rows = store.run("SELECT status, nrows FROM catalog_unit")
        assert rows == [("done", 3)]
        with sql.unit_transaction(store, {**unit, "digest": "d2", "fresh": True}):
            pass
        with pytest.raises(duckdb.ConstraintException):
            with sql.unit_transaction(store, {**unit, "digest": "d2", "fresh": True}):
                pass
        assert store.one("SELECT count(*) FROM catalog_unit WHERE digest = 'd2'")[0] == 1


def test_two_grippers_parquet_catalogue_survives_a_driver_killed_in_its_merge_and_plans(client, tmp_path, capsys):
    """Two parts x two grippers (the Franka hand, the bundled Robotiq-like spec, listed in the robots file) x one robot
    in the Parquet form on one worker, the driver killed (SIGKILL) after its first merge wrote some partition files: readers do not
    see them, the re-run deletes them and merges the units on disk without computing them again. Every table then
    equals the stage runners' build of each (gripper, part) in order, object rows are not duplicated, `catalog
    report` has a (robot, gripper) column pair per gripper, and `plan --gripper` answers with the Robotiq's grasps."""
    from workbench.grasping.grasps import GraspParams
    from workbench.robots.gripper import load_gripper

    b = bundled_objects()
    parts = [b["tube"], b["wheel"]]
    hands = [franka_hand(), load_gripper("robotiq-2f85")]
    robots = tmp_path / "robots.yaml"
    robots.write_text("robots: [panda]\ngrippers: [franka, robotiq-2f85]\n")
    db = tmp_path / "grippers"
    cmd = [sys.executable, "-m", "workbench.cli", "catalog", "build", *map(str, parts), "--robots", str(robots),
           "--db", str(db), "--form", "parquet", "--workers", "1", "--x", "0.4,0.6,2", "--y", "0,0,1", "--angles", "2",
           "--max-grasps", "10", "--rotations", "4", "--ik-library", "2048", "--ik-seeds", "2", "--ik-chunk", "32",
           "--no-progress"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
                            env={**env, "WORKBENCH_FAULT": "_wb_stage_tabletopgrips:1:SIGKILL"})  # before its COPY
    try:
        assert proc.wait(timeout=600) == -signal.SIGKILL
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)  # the cluster it started
    assert list(db.glob("*/part=*/b*.parquet"))  # written by the killed merge, never committed
    with Store(db, read_only=True) as s:
        assert s.one("SELECT count(*) FROM object")[0] == s.one("SELECT count(*) FROM freeairgrip")[0] == 0
    waiting = [f for f in Path(f"{db}.units").glob("part-*") if f.is_dir()]
    assert waiting

    p = replace(PARAMS, grasps=GraspParams(rotations=4))
    serial = tmp_path / "serial.duckdb"  # meanwhile, the build of each gripper and part in order
    with Store(serial) as store:
        for hand in hands:
            robot = get_robot("panda", gripper=hand)
            for path in parts:
                obj = load_object(path)
                g = ensure_grasps(store, obj, hand, p.grasps)
                pl = ensure_placements(store, g.idobject, obj, g.idparamset, hand, p.placements, p.tabletop)
                run_ik(store, obj.name, robot, None, p.handx, p.worldz, p.ik, workers=1, progress=False,
                       idtabletop=pl.idtabletop)

    out = _rerun(cmd, client, capsys)
    computed = int(out.split("units computed (")[1].split(" part")[0])
    assert computed == len(parts) * len(hands) - len(waiting)  # the part units on disk are merged, not computed again
    with Store(db, read_only=True) as s:  # every file left is a committed merge's (the killed batch's were deleted)
        batches = {r[0] for r in s.run("SELECT batch FROM catalog_batch")}
    assert {int(f.name[1:].split("_")[0]) for f in db.glob("*/part=*/**/b*.parquet")} <= batches
    mine, theirs = _content(db), _content(serial)
    for t in PAPER_TABLES:
        assert mine[t] == theirs[t] and mine[t], t
    assert len(mine["object"]) == 2 and len(mine["gripper"]) == 2 and len(mine["robot"]) == 2
    with Store(db, read_only=True) as s:
        assert s.one("SELECT count(*), count(DISTINCT (idrobot, idtabletopgrips, idscene, idikret)) FROM ik") == \
            (len(theirs["ik"]), len(theirs["ik"]))
    assert main(["catalog", "report", "--db", str(db)]) == 0
    text = capsys.readouterr().out
    assert all(f"panda + {h.name} reachable" in text and f"{h.name} grasps" in text for h in hands), text
    code = main(["plan", "--db", str(db), "--object", "wheel", "--robot", "panda", "--gripper", "robotiq-2f85", "--start",
                 "1,0.45,0.1,0", "--goal", "3,0.55,-0.1,90", "--alternatives", "0", "--json", str(tmp_path / "plan.json")])
    text = capsys.readouterr().out
    assert code == 0 and "validation: every listed plan passes" in text, text
    plan = json.loads((tmp_path / "plan.json").read_text())["plan"]
    with Store(db, read_only=True) as s:  # the plan's grasps are the Robotiq-like gripper's
        grip = {r[0] for r in s.run("SELECT g.name FROM freeairgrip f JOIN gripper g USING (idgripper) WHERE "
                                    "list_contains(?, f.idfreeairgrip)", [[st["idfreeairgrip"] for st in plan["steps"]]])}
    assert grip == {"robotiq-2f85"}
