"""A catalogue store is planned on, in both forms (a DuckDB file, a folder of Hive-partitioned Parquet files): `plan`
(Wan & Harada) and `gptable` + `gpplan` (Tournassoud) answer on a catalogue written by `workbench catalog build`,
their plans pass the validators rebuilt from the store's rows, and the two forms hold the same rows and give the
same plan."""

from __future__ import annotations

import json
from pathlib import Path

import duckdb
import numpy as np
import pytest

from workbench.cli.main import main
from workbench.planners.tournassoud.shapes import l_part
from workbench.errors import StoreError
from workbench.store import Store
from workbench.store.catalog import PARTITIONED

COARSE = ["--x", "0.4,0.6,2", "--y", "-0.1,0.1,2", "--angles", "4", "--max-grasps", "10", "--ik-library", "2048",
          "--ik-seeds", "2", "--ik-chunk", "64"]
PLAN = ["--object", "L", "--robot", "panda", "--start", "1,0.45,0.1,0", "--goal", "3,0.55,-0.1,90", "--alternatives", "0"]
SHARED = ("paramset", "angle", "robot", "gripper", "scene", "ikret")  # in both forms tables of the DuckDB file


@pytest.fixture(scope="module")
def catalogues(tmp_path_factory) -> dict[str, str]:
    tmp = tmp_path_factory.mktemp("forms")
    mesh = tmp / "L.stl"
    l_part().mesh.export(mesh)
    out = {"mesh": str(mesh)}
    for form, db in (("duckdb", tmp / "catalogue.duckdb"), ("parquet", tmp / "catalogue")):
        assert main(["catalog", "build", str(mesh), "--robots", "panda", "--db", str(db), "--form", form, "--workers", "1",
                     "--no-progress", *COARSE]) == 0
        out[form] = str(db)
    return out


def _table(store: Store, table: str) -> list[tuple]:
    cols = [c for c, in store.run("SELECT column_name FROM duckdb_columns() WHERE table_name = ? AND schema_name = 'main' "
                                  "AND database_name = current_database() ORDER BY column_index", [table])
            if c not in ("created", "used")]
    return sorted(map(repr, store.run(f"SELECT {', '.join(cols)} FROM {table}")))


def test_parquet_and_duckdb_catalogues_hold_the_same_rows_and_give_the_same_plan(catalogues, tmp_path, capsys):
    folder = catalogues["parquet"]
    files = {t: sorted(p.relative_to(folder).as_posix() for p in Path(folder).glob(f"{t}/**/*.parquet"))
             for t in PARTITIONED}
    assert files["ik"] == ["ik/part=L/robot=panda/" + f.split("/")[-1] for f in files["ik"]] and files["ik"]
    assert all(f.startswith(f"{t}/part=L/") for t in PARTITIONED for f in files[t]) and all(files.values())
    # DuckDB alone reads the partitions, with the paper's column names and the Hive keys
    con = duckdb.connect()
    (n, parts, robots), = con.execute(f"SELECT count(*), count(DISTINCT part), min(robot) FROM read_parquet("
                                      f"'{folder}/ik/*/*/*.parquet', hive_partitioning = true)").fetchall()
    cols = [r[0] for r in con.execute(f"DESCRIBE SELECT * FROM read_parquet('{folder}/ik/*/*/*.parquet')").fetchall()]
    con.close()
    assert parts == 1 and robots == "panda" and cols[:3] == ["idik", "idrobot", "idtabletopgrips"]
    with Store(catalogues["duckdb"], read_only=True) as a, Store(folder, read_only=True) as b:
        assert b.dataset is not None and a.dataset is None
        for t in (*PARTITIONED, *SHARED):  # row for row, ids included
            mine, theirs = _table(b, t), _table(a, t)
            assert mine == theirs and mine, t
        assert n == a.one("SELECT count(*) FROM ik")[0] > 0
    plans = {}
    for form in ("duckdb", "parquet"):
        out = tmp_path / f"{form}.json"
        assert main(["plan", "--db", catalogues[form], *PLAN, "--no-save", "--json", str(out)]) == 0
        assert "validation: every listed plan passes" in capsys.readouterr().out
        plans[form] = {k: v for k, v in json.loads(out.read_text())["plan"].items() if k != "timings"}
    assert plans["parquet"] == plans["duckdb"] and plans["duckdb"]["steps"]


@pytest.mark.parametrize("form", ["duckdb", "parquet"])
def test_plan_and_gpplan_answer_on_a_catalogue_store(catalogues, tmp_path, capsys, form):
    db = catalogues[form]
    with Store(db, read_only=True) as s:
        (allowed,), = s.run("SELECT allowed_pairs FROM robot WHERE name = 'panda'")
        (body_faces,), = s.run("SELECT body_faces FROM gripper")
    assert json.loads(allowed)["allowed"] and body_faces > 0  # what the trajectory validator rebuilds the hand from

    out_json = tmp_path / "plan.json"
    assert main(["plan", "--db", db, *PLAN, "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "validation: every listed plan passes" in out and "stored plan ids [1]" in out
    plan = json.loads(out_json.read_text())
    assert plan["plan"]["robot"] == "panda" and plan["plan"]["steps"] and plan["plan"]["motion"]

    assert main(["gptable", catalogues["mesh"], "--db", db, "--theta-step", "10", "--phi-step", "10", "--table-point",
                 "0.45,0.1", "--base", "0,0,-0.3,0"]) == 0
    assert main(["gpplan", "--db", db, "--object", "L", "--from", f"1,{np.degrees(0.3):.6f}",
                 "--to", f"3,{np.degrees(1.0):.6f}", "--table", "0.15,-0.8,1.0,0.8", "--max-removed", "3"]) == 0
    out = capsys.readouterr().out
    assert "1 regrasp(s)" in out and "validator: ok" in out
    with Store(db, read_only=True) as s:
        planners = [r[0] for r in s.run("SELECT planner FROM plan ORDER BY idplan")]
        objects = s.one("SELECT count(*) FROM object")[0]
    assert planners[-1] == "tournassoud" and len(planners) == 2 and objects == 1  # the catalogue's part, reused


def test_files_of_a_merge_that_never_committed_are_swept_and_the_rows_stay(catalogues, tmp_path):
    """A driver killed inside a merge of a Parquet catalogue leaves files of a batch `catalog_batch` does not hold
    (one half written): readers do not see the whole ones, the next build's opening deletes them, and the catalogue
    reads the rows it held before."""
    import shutil

    from workbench.catalog.stages import open_store

    folder = tmp_path / "copy"
    shutil.copytree(catalogues["parquet"], folder)
    with Store(folder, read_only=True) as s:
        before = {t: _table(s, t) for t in PARTITIONED}
        batch = s.one("SELECT max(batch) FROM catalog_batch")[0]
    ik = next((folder / "ik").glob("*/*/*.parquet"))
    stray = [ik.with_name(f"b{batch + 1}_1_0.parquet"), folder / "object" / "part=M" / f"b{batch + 1}_2_0.parquet"]
    shutil.copy(ik, stray[0])  # a whole file of the uncommitted batch: its rows would be duplicates
    with Store(folder, read_only=True) as s:  # ... which a reader does not see
        assert {t: _table(s, t) for t in PARTITIONED} == before
    stray[1].parent.mkdir()
    stray[1].write_bytes(ik.read_bytes()[:100])  # a half-written one
    with pytest.raises(StoreError):
        with Store(folder, read_only=True) as s:
            s.run("SELECT count(*) FROM object")  # the half-written file cannot be read
    open_store(folder).close()
    assert not any(p.exists() for p in stray) and ik.exists()
    with Store(folder, read_only=True) as s:
        assert {t: _table(s, t) for t in PARTITIONED} == before


def test_notebook_07_reads_a_parquet_catalogue(catalogues, monkeypatch):
    """Notebook 07's cells after its build (the summary from SQL, its check against the build's summary, the plot of
    shares and stage times, the explorer loading the best part's graph) on a Parquet catalogue, which nbmake's run
    of the notebook (a DuckDB file) does not cover."""
    from types import SimpleNamespace

    import matplotlib

    from workbench.catalog.driver import report

    matplotlib.use("Agg")
    monkeypatch.chdir(Path(__file__).resolve().parents[2] / "notebooks")
    nb = json.loads(Path("07_catalogue.ipynb").read_text())
    cells = {c["id"]: "".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code"}
    first = list(cells)[0]
    assert 'form = "duckdb"' in cells[first] and "form=form" in cells[first]  # the user's choice of form
    db = catalogues["parquet"]
    ns = {"db": Path(db), "parts": {"L": catalogues["mesh"]}, "result": SimpleNamespace(rows=report(db)[0])}
    for cid in list(cells)[1:]:
        exec(compile(cells[cid], f"07_catalogue.ipynb cell {cid}", "exec"), ns)
    assert [r[:2] for r in ns["rows"]] == [("L", "panda")] and ns["pick_part"] == "L"
    assert ns["planner"].roadmap.n_components == ns["best"][ns["names"].index("components")]
    import matplotlib.pyplot as plt

    plt.close("all")
