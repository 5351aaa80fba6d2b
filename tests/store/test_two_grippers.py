"""One part with two grippers in one store, on a UR10 loaded from example-robot-data's URDF: the Robotiq-like spec
and the Franka hand each keep their grasp chain and robot row, `plan --gripper` picks the right rows, and each plan
passes the validator with its gripper's geometry. The stored grasps clear the part by a coal check built here from
the spec file's own numbers."""

from __future__ import annotations

import contextlib
import io
import json
import shutil

import coal
import duckdb
import numpy as np
import pytest
import trimesh
import yaml
from scipy.spatial.transform import Rotation

from workbench.cli.main import main
from workbench.resources import bundled_objects, erd_robots
from workbench.robots.gripper import BUNDLED, franka_hand

UR10 = erd_robots() / "ur_description" / "urdf" / "ur10_robot.urdf"
GRID = ["--x=0.45,0.55,2", "--y=-0.1,0.1,2", "--angles", "4", "--workers", "1"]
SPEC = yaml.safe_load(BUNDLED["robotiq-2f85"].read_text())


def _ids(out: str) -> list[int]:
    return [int(v) for v in out.split("(PLACEMENT,X,Y,YAW): ")[1].split(" (")[0].split("\n")[0].split(", ")]


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    work = tmp_path_factory.mktemp("grippers")
    db = str(work / "two.duckdb")
    mesh = str(bundled_objects()["bracket"])
    out = {}
    flange = ",".join(f"{v:g}" for v in franka_hand().tcp_in_hand[:3, 3]) + ",0,0,0"
    for gripper, extra in (("robotiq-2f85", []), ("franka", ["--mount", flange])):
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            code = main(["build", mesh, "--db", db, "--robot", str(UR10), "--tip", "tool0", "--gripper", gripper, *extra,
                         *GRID])
        assert code == 0, buf.getvalue()
        out[gripper] = buf.getvalue()
        if gripper == "robotiq-2f85":  # a store of one gripper, for the commands' default
            shutil.copy(db, work / "robotiq.duckdb")
    return work, db, out


def test_each_gripper_keeps_its_grasps_within_its_stroke(store):
    _, db, _ = store
    con = duckdb.connect(db, read_only=True)
    rows = con.execute("SELECT g.name, g.jaw_min, g.jaw_max, min(f.jawwidth), max(f.jawwidth), count(*) FROM freeairgrip f "
                       "JOIN gripper g USING (idgripper) GROUP BY ALL ORDER BY g.name").fetchall()
    assert [r[0] for r in rows] == ["franka_hand", "robotiq-2f85"]
    for name, lo, hi, wmin, wmax, n in rows:
        assert n > 20 and lo - 1e-9 <= wmin and wmax <= hi + 1e-9
    assert rows[1][2] == pytest.approx(SPEC["stroke"][1])
    # two robot rows, one per gripper, each with its own grasp chain's IK
    robots = con.execute("SELECT r.name, g.name FROM robot r JOIN gripper g USING (idgripper) ORDER BY r.idrobot").fetchall()
    assert [g for _, g in robots] == ["robotiq-2f85", "franka_hand"]


def _spec_boxes(width: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """(size, pose in the TCP frame) of the palm, pads and fingers, from the spec file's numbers alone."""
    tcp = np.eye(4)
    tcp[:3, :3] = Rotation.from_euler("xyz", SPEC.get("rpy", [0, 0, 0])).as_matrix()
    tcp[:3, 3] = SPEC["tcp"]
    palm = np.eye(4)
    palm[:3, 3] = SPEC["palm"]["offset"]
    out = [(np.array(SPEC["palm"]["size"]), np.linalg.inv(tcp) @ palm)]
    (px, pz), t, f = SPEC["pad"]["size"], SPEC["pad"]["thickness"], SPEC["finger"]["size"]
    for side in (1, -1):
        for size, y, z in (((px, t, pz), width / 2 + t / 2, 0.0), (f, width / 2 + f[1] / 2, pz / 2 - f[2] / 2)):
            m = np.eye(4)
            m[:3, 3] = (0.0, side * y, z)
            out.append((np.array(size, dtype=float), m))
    return out


def test_robotiq_grasps_clear_the_part_by_an_independent_coal_check(store):
    """No palm, pad or finger box, shrunk by the 0.5 mm tolerance, meets the part's surface or sits inside it, at the
    grasp's opening and at full opening."""
    _, db, _ = store
    con = duckdb.connect(db, read_only=True)
    rows = con.execute("SELECT f.rotmat, f.jawwidth FROM freeairgrip f JOIN gripper g USING (idgripper) "
                       "WHERE g.name = 'robotiq-2f85' ORDER BY idfreeairgrip").fetchall()
    part = trimesh.load(bundled_objects()["bracket"], force="mesh")
    bvh = coal.BVHModelOBBRSS()
    bvh.beginModel(len(part.faces), len(part.vertices))
    bvh.addVertices(np.asarray(part.vertices, dtype=np.float64))
    bvh.addTriangles(np.asarray(part.faces, dtype=np.int64))
    bvh.endModel()
    tol = 5e-4 + 1e-6
    pick = np.linspace(0, len(rows) - 1, min(40, len(rows))).astype(int)
    hits = 0
    for i in pick:
        pose, width = np.asarray(rows[i][0]).reshape(4, 4), float(rows[i][1])
        for w in (width, SPEC["stroke"][1]):
            for size, local in _spec_boxes(w):
                m = pose @ local
                res = coal.CollisionResult()
                box = coal.Box(*np.maximum(size - 2 * tol, 1e-6))
                hit = coal.collide(bvh, coal.Transform3s(), box, coal.Transform3s(m[:3, :3], m[:3, 3]),
                                   coal.CollisionRequest(), res)
                hits += bool(hit) or bool(part.contains(m[None, :3, 3])[0])
    assert hits == 0


@pytest.mark.parametrize("gripper", ["robotiq-2f85", "franka"])
def test_plan_with_each_gripper_uses_its_rows_and_validates(store, gripper, capsys, tmp_path):
    work, db, out = store
    pid = _ids(out[gripper])[0]
    js = tmp_path / "plan.json"
    code = main(["plan", "--db", db, "--object", "bracket", "--robot", "ur10_robot", "--gripper", gripper,
                 "--start", f"{pid},0.45,0.1,0", "--goal", f"{pid},0.55,-0.1,90", "--alternatives", "0", "--json", str(js)])
    text = capsys.readouterr().out
    assert code == 0 and "validation: every listed plan passes" in text, text
    plan = json.loads(js.read_text())["plan"]
    con = duckdb.connect(db, read_only=True)
    name, lo, hi = con.execute("SELECT g.name, g.jaw_min, g.jaw_max FROM robot r JOIN gripper g USING (idgripper) "
                               "WHERE r.name = ?", [plan["robot"]]).fetchone()
    assert name == ("robotiq-2f85" if gripper != "franka" else "franka_hand")
    widths = [s["jawwidth"] for s in plan["steps"]]
    assert all(lo - 1e-6 <= w <= hi + 1e-6 for w in widths)
    stored = con.execute("SELECT f.jawwidth FROM freeairgrip f JOIN gripper g USING (idgripper) WHERE g.name = ? AND "
                         "f.idfreeairgrip = ?", [name, plan["steps"][0]["idfreeairgrip"]]).fetchone()
    assert stored is not None and stored[0] == pytest.approx(widths[0])


@pytest.mark.parametrize("only", [True, False])
def test_without_gripper_a_plan_takes_the_stores_one_gripper_else_the_franka_hand(store, only, tmp_path):
    work, db, out = store
    db = str(work / "robotiq.duckdb") if only else db
    pid = _ids(out["robotiq-2f85" if only else "franka"])[0]
    js = tmp_path / "plan.json"
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["plan", "--db", db, "--object", "bracket", "--robot", "ur10_robot", "--start", f"{pid},0.45,0.1,0",
                     "--goal", f"{pid},0.55,-0.1,90", "--alternatives", "0", "--no-save", "--json", str(js)])
    assert code == 0
    robot = json.loads(js.read_text())["plan"]["robot"]
    con = duckdb.connect(db, read_only=True)
    name = con.execute("SELECT g.name FROM robot r JOIN gripper g USING (idgripper) WHERE r.name = ?", [robot]).fetchone()
    assert name == ("robotiq-2f85" if only else "franka_hand",)


def test_plan_with_a_gripper_the_store_lacks_is_refused_in_one_line(store, capsys):
    _, db, out = store
    pid = _ids(out["franka"])[0]
    code = main(["plan", "--db", db, "--object", "bracket", "--robot", "ur10_robot", "--gripper", "parallel60",
                 "--start", f"{pid},0.45,0.1,0", "--goal", f"{pid},0.55,-0.1,90", "--alternatives", "0", "--no-save"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "not 'parallel60'" in err[0] and "robotiq-2f85" in err[0], err
