"""A catalogue store is planned on: `plan` (Wan & Harada) and `gptable` + `gpplan` (Tournassoud) answer on a store
written by `workbench catalog build`, and their plans pass the validators rebuilt from the store's rows."""

from __future__ import annotations

import json

import duckdb
import numpy as np

from workbench.cli.main import main
from workbench.planners.tournassoud.shapes import l_part

COARSE = ["--x", "0.4,0.6,2", "--y", "-0.1,0.1,2", "--angles", "4", "--max-grasps", "10", "--ik-library", "2048",
          "--ik-seeds", "2", "--ik-chunk", "64"]


def test_plan_and_gpplan_answer_on_a_catalogue_store(tmp_path, capsys):
    mesh = tmp_path / "L.stl"
    l_part().mesh.export(mesh)
    db = str(tmp_path / "catalogue.duckdb")
    assert main(["catalog", "build", str(mesh), "--robots", "panda", "--db", db, "--workers", "1", "--no-progress",
                 *COARSE]) == 0
    capsys.readouterr()
    con = duckdb.connect(db, read_only=True)
    (allowed,), = con.execute("SELECT allowed_pairs FROM robot WHERE name = 'panda'").fetchall()
    (body_faces,), = con.execute("SELECT body_faces FROM gripper").fetchall()
    con.close()
    assert json.loads(allowed)["allowed"] and body_faces > 0  # what the trajectory validator rebuilds the hand from

    out_json = tmp_path / "plan.json"
    assert main(["plan", "--db", db, "--object", "L", "--robot", "panda", "--start", "1,0.45,0.1,0",
                 "--goal", "3,0.55,-0.1,90", "--alternatives", "0", "--json", str(out_json)]) == 0
    out = capsys.readouterr().out
    assert "validation: every listed plan passes" in out and "stored plan ids [1]" in out
    plan = json.loads(out_json.read_text())
    assert plan["plan"]["robot"] == "panda" and plan["plan"]["steps"] and plan["plan"]["motion"]

    assert main(["gptable", str(mesh), "--db", db, "--theta-step", "10", "--phi-step", "10", "--table-point", "0.45,0.1",
                 "--base", "0,0,-0.3,0"]) == 0
    assert main(["gpplan", "--db", db, "--object", "L", "--from", f"1,{np.degrees(0.3):.6f}",
                 "--to", f"3,{np.degrees(1.0):.6f}", "--table", "0.15,-0.8,1.0,0.8", "--max-removed", "3"]) == 0
    out = capsys.readouterr().out
    assert "1 regrasp(s)" in out and "validator: ok" in out
    con = duckdb.connect(db, read_only=True)
    planners = [r[0] for r in con.execute("SELECT planner FROM plan ORDER BY idplan").fetchall()]
    objects = con.execute("SELECT count(*) FROM object").fetchone()[0]
    con.close()
    assert planners[-1] == "tournassoud" and len(planners) == 2 and objects == 1  # the catalogue's part, reused
