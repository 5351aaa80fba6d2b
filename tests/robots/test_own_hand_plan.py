"""A robot's own hand end to end: Tiago Pro built with `--gripper own`, planned with `plan --gripper own` (the hand
rebuilt from the stored robot's URDF text), and the URDF form naming the same hand finds the same rows and plan."""

from __future__ import annotations

import contextlib
import io
import json

import duckdb
import pytest

from workbench.cli.main import main
from workbench.resources import bundled_objects, erd_robots
from workbench.robots.gripper import load_gripper

TIAGO = erd_robots() / "tiago_pro_description" / "robots" / "tiago_pro.urdf"
TIP = "arm_left_tool_link"
FINGERS = "gripper_left_inner_finger_left_joint,gripper_left_inner_finger_right_joint"
QUERY = ["--start", "2,0.45,-0.1,0", "--goal", "2,0.55,0.1,90", "--alternatives", "0"]


def _run(argv: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(argv)
    return code, buf.getvalue()


@pytest.fixture(scope="module")
def tiago(tmp_path_factory):
    db = str(tmp_path_factory.mktemp("own") / "tiago.duckdb")
    code, out = _run(["build", str(bundled_objects()["tube"]), "--db", db, "--robot", str(TIAGO), "--tip", TIP,
                      "--gripper", "own", "--gripper-fingers", FINGERS, "--x=0.45,0.55,2", "--y=-0.1,0.1,2",
                      "--angles", "2", "--rotations", "4", "--max-grasps", "60", "--workers", "1"])
    assert code == 0, out
    return db


def test_plan_with_the_robots_own_hand_and_its_urdf_form_share_rows(tiago, tmp_path, capsys):
    hand = load_gripper("own", robot_urdf=TIAGO, tip=TIP, finger_joints=tuple(FINGERS.split(",")))  # from the file
    con = duckdb.connect(tiago, read_only=True)
    assert con.execute("SELECT g.digest FROM robot r JOIN gripper g USING (idgripper)").fetchall() == [(hand.digest,)]
    con.close()
    js = tmp_path / "own.json"
    code, out = _run(["plan", "--db", tiago, "--object", "tube", "--robot", "tiago_pro", "--gripper", "own",
                      "--gripper-fingers", FINGERS, *QUERY, "--json", str(js)])
    assert code == 0 and "validation: every listed plan passes" in out and "stored plan ids" in out, out
    ids = out.split("stored plan ids ")[1].split(" in ")[0]
    plan = json.loads(js.read_text())["plan"]
    jaws = [s["jaw"] for s in plan["motion"]["segments"]] + [s["jawwidth"] for s in plan["steps"]]
    assert jaws and all(hand.jaw_min - 1e-6 <= w <= hand.jaw_max + 1e-6 for w in jaws)
    # the same hand named by its URDF: the same robot row, so the same stored plan
    code, out = _run(["plan", "--db", tiago, "--object", "tube", "--robot", "tiago_pro", "--gripper", str(TIAGO),
                      "--gripper-hand", TIP, "--gripper-fingers", FINGERS, *QUERY])
    assert code == 0 and f"answered from the store: plan ids {ids}" in out, out
    # another gripper on the same robot: not in the store, refused in one line
    capsys.readouterr()
    code, _ = _run(["plan", "--db", tiago, "--object", "tube", "--robot", "tiago_pro", "--gripper", "robotiq-2f85",
                    *QUERY, "--no-save"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "tiago_pro-hand" in err[0], err


@pytest.mark.parametrize("extra,words", [
    ([], "--gripper-fingers"),
    (["--gripper-fingers", "gripper_left_inner_finger_left_joint,no_such_joint"], "no finger joint 'no_such_joint'"),
    (["--gripper-fingers", FINGERS, "--gripper-hand", "arm_left_7_link"], "not its own hand at arm_left_7_link"),
])
def test_own_hand_the_store_cannot_rebuild_is_refused_in_one_line(tiago, capsys, extra, words):
    con = duckdb.connect(tiago, read_only=True)
    before = con.execute("SELECT count(*) FROM plan").fetchone()
    con.close()
    capsys.readouterr()
    code, _ = _run(["plan", "--db", tiago, "--object", "tube", "--robot", "tiago_pro", "--gripper", "own", *extra, *QUERY])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0], err
    con = duckdb.connect(tiago, read_only=True)
    assert con.execute("SELECT count(*) FROM plan").fetchone() == before
    con.close()
