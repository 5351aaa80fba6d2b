"""The grasp-placement planner against a real DuckDB store and through the command line (Tournassoud et al. 1987)."""

from __future__ import annotations

import json

import duckdb
import numpy as np
import trimesh
import yaml

from workbench.cli.main import main
from workbench.planners.tournassoud.stages import load_planner, table_stage_at
from workbench.planners.tournassoud.table import TableParams

PARAMS = TableParams(theta_step=np.radians(10), phi_step=np.radians(10), table_point=(0.45, 0.1))


def test_store_round_trip_and_reuse(tmp_path, lpart, puma560):
    db = str(tmp_path / "gp.duckdb")
    built = table_stage_at(db, lpart, puma560, params=PARAMS)
    again = table_stage_at(db, lpart, puma560, params=PARAMS)
    assert built.reused == (False, False) and again.reused == (True, True)
    loaded = load_planner(db, "L", "puma560")
    for run in (again, loaded):
        assert np.array_equal(run.table.q, built.table.q)
        assert np.array_equal(run.table.hand_table, built.table.hand_table)
        assert np.array_equal(run.table.hand_object, built.table.hand_object)
        assert np.allclose(run.table.placements, built.table.placements)
        assert [c.intervals for c in run.classes] == [c.intervals for c in built.classes]
    # the stored phi intervals, read with plain SQL, give back the table
    con = duckdb.connect(db, read_only=True)
    rows = con.execute("SELECT g.idx, p.idx, c.itheta, c.phi_lo, c.phi_hi FROM tgpcell c JOIN tgraspclass g USING (idtgraspclass) "
                       "JOIN tplacementclass p USING (idtplacementclass)").fetchall()
    con.close()
    step = 2 * np.pi / built.table.q.shape[3]
    q = np.zeros_like(built.table.q)
    for i, j, t, lo, hi in rows:
        for a, b in zip(lo, hi):
            q[i, j, t, int(round(a / step)):int(round(b / step)) + 1] = True
    assert np.array_equal(q, built.table.q) and q.any()
    # another resolution is another table
    other = table_stage_at(db, lpart, puma560, params=TableParams(theta_step=np.radians(15), phi_step=np.radians(10),
                                                                   table_point=(0.45, 0.1)))
    assert other.reused == (True, False) and other.table.q.shape[2] == 24


def test_cli_gptable_and_gpplan(tmp_path, lpart, capsys):
    mesh = tmp_path / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp_path / "cli.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--theta-step", "10", "--phi-step", "10", "--table-point", "0.45,0.1"]) == 0
    out = capsys.readouterr().out
    assert "5 grasp classes (5 face/face" in out and "5 placement classes" in out
    run = load_planner(db, "L")
    legal = np.flatnonzero(run.table.hand_object[0])
    theta0 = float(np.degrees(run.table.theta[legal[len(legal) // 2]]))
    js = tmp_path / "plan.json"
    html = tmp_path / "plan.html"
    assert theta0 == 130.0  # a query known to have an executable plan from the default pedestal
    code = main(["gpplan", "--db", db, "--object", "L", "--initial", f"0,{theta0:g}", "--goal", "3,0:360",
                 "--json", str(js), "--html", str(html)])
    assert code == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    assert doc["plan"] is not None and doc["sequence"] is not None, out
    assert "validator: ok" in out and "(planner tournassoud" in out
    assert doc["sequence"]["regrasps"] == doc["plan"]["regrasps"] >= 1 and doc["plan"]["planner"] == "tournassoud"
    assert doc["plan"]["motion"]["duration"] > 0
    assert doc["table_sequence"]["regrasps"] <= doc["sequence"]["regrasps"]
    assert html.read_text().startswith("<!doctype html>")
    # bad input: one line, status 2
    assert main(["gpplan", "--db", db, "--object", "L", "--initial", "0,abc", "--goal", "3,0:360"]) == 2
    assert main(["gpplan", "--db", db, "--object", "L", "--initial", "0,10", "--goal", "3,90:10"]) == 2
    assert main(["gpplan", "--db", db, "--object", "nope", "--initial", "0,10", "--goal", "3,0:90"]) == 2
    assert main(["gpplan", "--db", db, "--object", "L", "--initial", "42,10", "--goal", "3,0:90"]) == 2
    assert main(["gptable", str(mesh), "--db", db, "--table-point", "x"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len([ln for ln in err.splitlines() if ln.startswith("workbench")]) == 5


def test_zero_classes_is_a_warning(tmp_path, capsys):
    big = tmp_path / "slab.stl"
    trimesh.creation.box((0.3, 0.2, 0.15)).export(big)  # wider than the 80 mm jaw in every direction
    assert main(["gptable", str(big), "--db", str(tmp_path / "z.duckdb"), "--theta-step", "15", "--phi-step", "15"]) == 0
    cap = capsys.readouterr()
    assert "0 grasp classes" in cap.out and "warning: no grasp class" in cap.err and "spans no pair" in cap.err
    # a curved part has no planar face to pair: the warning says so and names the planner for it
    ball = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=0.025).export(ball)
    assert main(["gptable", str(ball), "--db", str(tmp_path / "z.duckdb"), "--theta-step", "15", "--phi-step", "15"]) == 0
    err = capsys.readouterr().err
    assert "0 planar face(s)" in err and "workbench build" in err


def test_plans_are_stored_like_the_roadmap_planners(tmp_path, lpart, make_puma):
    """A plan of this planner, with its timed motions, goes into the store's plan / planstep / plansegment tables,
    named, with foreign keys to real freeairgrip / freetabletopplacement rows whose poses agree with the steps, and
    passes the validators rebuilt from the store (waypoints and trajectory); the same query is not stored twice."""
    from workbench.errors import PlanningError
    from workbench.planners.tournassoud.plans import Realiser, plan_placement_query
    from workbench.planners.tournassoud.stages import save_plan, validate_stored
    from workbench.planners.wan_harada.motions import ExecOptions
    from workbench.robots.collider import Scene

    db = str(tmp_path / "plans.duckdb")
    puma = make_puma(base_z=-0.3)  # see test_table._setup: from the default pedestal few sequences are executable
    run = table_stage_at(db, lpart, puma, params=PARAMS)
    scene = Scene(table_min=(0.15, -0.8))
    realiser = Realiser(puma, scene, lpart.mesh)
    plan = None
    for a, b in [(1, 3), (1, 0), (3, 1)]:
        try:
            _, plan = plan_placement_query(run.table, run.classes, realiser, puma, "L", (a, 0.3), (b, 1.0),
                                           ExecOptions(max_removed=3))
        except PlanningError:
            continue
        if plan.regrasps >= 1:
            break
    assert plan is not None and plan.regrasps >= 1 and plan.segments
    pid, stored = save_plan(db, run, plan, scene, realiser.opts)
    report = validate_stored(db, run, pid, stored, require_motion=True)
    assert report.ok, report.errors
    assert save_plan(db, run, plan, scene, realiser.opts)[0] == pid
    con = duckdb.connect(db, read_only=True)
    assert con.execute("SELECT count(*), min(planner), min(regrasps) FROM plan").fetchone() == (1, "tournassoud", plan.regrasps)
    assert con.execute("SELECT count(*) FROM plansegment WHERE idplan = ?", [pid]).fetchone()[0] == len(plan.segments)
    rows = con.execute("SELECT s.kind, s.object, s.tcp, s.yaw, s.position, g.rotmat, g.jawwidth, f.rotmat FROM planstep s "
                       "JOIN freeairgrip g USING (idfreeairgrip) JOIN freetabletopplacement f USING (idfreetabletopplacement) "
                       "WHERE s.idplan = ? ORDER BY s.seq", [pid]).fetchall()
    con.close()
    assert [r[0] for r in rows] == [s.kind for s in plan.steps]
    for _, obj, tcp, yaw, pos, grip, jaw, free in rows:
        obj, tcp = np.reshape(obj, (4, 4)), np.reshape(tcp, (4, 4))
        assert np.allclose(obj @ np.reshape(grip, (4, 4)), tcp, atol=1e-9)           # TCP = object pose x stored grasp
        c, s = np.cos(yaw), np.sin(yaw)
        move = np.array([[c, -s, 0, pos[0]], [s, c, 0, pos[1]], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        assert np.allclose(move @ np.reshape(free, (4, 4)), obj, atol=1e-9)          # object = H Rz(phi) placement
        assert 0 < jaw <= 0.08


def test_cli_gpplan_stores_an_executable_plan(tmp_path, lpart, capsys):
    """`workbench gpplan` plans the motions, stores the plan in the plan tables (planner named) and checks it with the
    validators rebuilt from the store; a second run of the same query finds the stored plan."""
    mesh = tmp_path / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp_path / "cli.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--theta-step", "10", "--phi-step", "10", "--table-point", "0.45,0.1",
                 "--base", "0,0,-0.3,0"]) == 0
    query = ["gpplan", "--db", db, "--object", "L", "--from", f"1,{np.degrees(0.3):.6f}", "--to", f"3,{np.degrees(1.0):.6f}",
             "--table", "0.15,-0.8,1.0,0.8", "--max-removed", "3"]
    assert main(query) == 0
    out = capsys.readouterr().out
    assert "1 regrasp(s)" in out and "(planner tournassoud" in out and "validator: ok" in out
    con = duckdb.connect(db, read_only=True)
    (idplan, planner, regrasps, duration), = con.execute("SELECT idplan, planner, regrasps, duration FROM plan").fetchall()
    segments = con.execute("SELECT count(*) FROM plansegment WHERE idplan = ?", [idplan]).fetchone()[0]
    con.close()
    assert planner == "tournassoud" and regrasps == 1 and duration > 0 and segments > 0
    assert main(query) == 0
    assert f"stored plan id {idplan}" in capsys.readouterr().out
    assert main(["gptable", str(mesh), "--db", db, "--base", "0,0"]) == 2
    assert main(query[:-2] + ["--table", "1,0,0,1"]) == 2


def test_removal_learns_and_explains(tmp_path, box, capsys):
    """A placement query whose table answers the arm cannot execute next to the table: each failed conjunction
    removes every neighbouring sample that fails the same way, so the default limit of 10 suffices; the output and
    the JSON name every removed conjunction, why, at which step, and the table's own answer beside the executable
    one, which the validators rebuilt from the store accept with its motions."""
    mesh = tmp_path / "box.stl"
    box.mesh.export(mesh)
    db = str(tmp_path / "box.duckdb")
    assert main(["gptable", str(mesh), "--db", db]) == 0
    js = tmp_path / "box.json"
    assert main(["gpplan", "--db", db, "--object", "box", "--from", "5,75", "--to", "4,25", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    assert doc["plan"] is not None and "validator: ok" in out, out
    assert doc["plan"]["motion"]["removed"] == len(doc["removed"]) >= 1
    assert len(doc["removed"]) <= 10
    assert all(r["samples"] > 1 and r["reason"] and r["motion"] in ("ik", "lines", "transfer", "transit")
               for r in doc["removed"]), doc["removed"]
    assert out.count("  removed step ") == len(doc["removed"])
    own = doc["table_sequence"]
    assert own is not None and f"the table's shortest sequence has {own['regrasps']} regrasp(s)" in out
    assert f"the shortest executable one has {doc['sequence']['regrasps']}" in out
    # the executable sequence avoids every removed conjunction
    used = {(tuple(g), tuple(p)) for g, p in zip(doc["sequence"]["grasps"], doc["sequence"]["placements"][:-1])}
    used |= {(tuple(g), tuple(p)) for g, p in zip(doc["sequence"]["grasps"], doc["sequence"]["placements"][1:])}
    assert not used & {tuple(map(tuple, r["conjunction"])) for r in doc["removed"]}
    # a goal range keeps its lower end: 85:85 is the 85-degree sample, and 85:90 can end at 85
    for goal in ("1,85:85", "1,85:90"):
        assert main(["gpplan", "--db", db, "--object", "box", "--initial", "0,30", "--goal", goal, "--no-motion",
                     "--no-save", "--json", str(js)]) == 0
        last = json.loads(js.read_text())["sequence"]["theta"][-1]
        assert abs(np.degrees(last) - 85.0) < 1e-9, (goal, np.degrees(last))
    capsys.readouterr()


def test_narrow_classes_are_kept_or_dropped_with_their_count(tmp_path, lpart, hand, capsys):
    """--min-range 0 keeps every class; a width drops the narrower ones with a warning naming how many, on the first
    run and again when the classes are reused from the store; the dropped classes are exactly those narrower."""
    from workbench.planners.tournassoud.classes import ClassParams, grasp_classes

    mesh = tmp_path / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp_path / "n.duckdb")
    every = grasp_classes(lpart, hand, ClassParams(theta_step=np.radians(10), bisection=np.radians(0.1)))
    width = float(np.median([np.degrees(c.legal_range) for c in every]))
    narrower = sum(np.degrees(c.legal_range) < width for c in every)
    assert 0 < narrower < len(every)
    base = ["gptable", str(mesh), "--db", db, "--theta-step", "10", "--phi-step", "10"]
    assert main(base) == 0
    cap = capsys.readouterr()
    assert f"{len(every)} grasp classes" in cap.out and "dropped" not in cap.err
    for _ in range(2):
        assert main(base + ["--min-range", f"{width:g}"]) == 0
        cap = capsys.readouterr()
        assert f"{len(every) - narrower} grasp classes" in cap.out
        assert f"warning: {narrower} grasp class(es) dropped as narrower than --min-range" in cap.err



def test_notebook_query_names_its_removals_and_the_tables_answer(tmp_path, lpart, capsys):
    """Notebook 06's query (the PUMA 0.3 m low, class 0 at the middle of its legal range to class 2 at 60-120 degrees):
    the table's own answer has 2 regrasps, some of its conjunctions fail with the arm, and the output names each removed
    conjunction with its step and reason beside the executable answer, which exists and passes the validators."""
    mesh = tmp_path / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp_path / "nb.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--table-point", "0.45,0.1", "--base", "0,0,-0.3,0"]) == 0
    run = load_planner(db, "L")
    legal = np.flatnonzero(run.table.hand_object[0])
    theta0 = float(np.degrees(run.table.theta[legal[len(legal) // 2]]))
    js = tmp_path / "nb.json"
    assert main(["gpplan", "--db", db, "--object", "L", "--initial", f"0,{theta0:g}", "--goal", "2,60:120",
                 "--table", "0.15,-0.8,1,0.8", "--json", str(js)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    assert doc["table_sequence"]["regrasps"] == 2 and doc["removed"], out
    assert "the table's shortest sequence has 2 regrasp(s)" in out
    lines = [ln for ln in out.splitlines() if ln.startswith("  removed step ")]
    assert len(lines) == len(doc["removed"]) and all(" fails " in ln and "table sample(s) removed" in ln for ln in lines)
    assert doc["plan"] is not None and "validator: ok" in out
    assert f"the shortest executable one has {doc['sequence']['regrasps']}" in out
    # the last grasp is in the goal class and range, both ends kept
    c, t = doc["sequence"]["grasps"][-1]
    assert c == 2 and 60 - 1e-6 <= np.degrees(run.table.theta[t]) <= 120 + 1e-6


def test_gpplan_with_a_urdf_robots_own_hand(tmp_path, box, capsys):
    """The Panda from its URDF with the hand in that URDF (`--gripper own`): `gptable` stores the robot with that
    hand (the digest of the hand read from the file here), `gpplan --gripper own` rebuilds it from the stored row and
    plans, validates and stores an executable plan whose jaw widths are within that hand's range; another gripper on
    the same robot is refused in one line."""
    from workbench.resources import erd_robots
    from workbench.robots.gripper import load_gripper

    urdf = erd_robots() / "panda_description" / "urdf" / "panda.urdf"
    fingers = "panda_finger_joint1,panda_finger_joint2"
    own = ["--gripper", "own", "--gripper-hand", "panda_hand", "--gripper-tcp", "panda_hand_tcp", "--gripper-fingers", fingers]
    mesh = tmp_path / "box.stl"
    box.mesh.export(mesh)
    db = str(tmp_path / "own.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--robot", str(urdf), "--tip", "panda_hand_tcp", *own,
                 "--theta-step", "30", "--phi-step", "30", "--table-point", "0.45,0.1"]) == 0
    hand = load_gripper("own", robot_urdf=urdf, tip="panda_hand_tcp", hand_link="panda_hand", tcp_frame="panda_hand_tcp",
                        finger_joints=tuple(fingers.split(",")))
    con = duckdb.connect(db, read_only=True)
    assert con.execute("SELECT r.name, g.digest FROM robot r JOIN gripper g USING (idgripper)").fetchall() == [("panda", hand.digest)]
    con.close()
    js, traj = tmp_path / "own.json", tmp_path / "own.yaml"
    capsys.readouterr()
    assert main(["gpplan", "--db", db, "--object", "box", "--robot", "panda", *own, "--from", "0,0", "--to", "1,90",
                 "--json", str(js), "--trajectory", str(traj)]) == 0
    out = capsys.readouterr().out
    assert "validator: ok" in out and "stored plan id" in out and "own.gripper.yaml" in out, out
    plan = json.loads(js.read_text())["plan"]
    jaws = [s["jaw"] for s in plan["motion"]["segments"]] + [s["jawwidth"] for s in plan["steps"]]
    assert plan["regrasps"] >= 1 and all(hand.jaw_min - 1e-6 <= w <= hand.jaw_max + 1e-6 for w in jaws)
    # the ROS 2 export: the gripper's JointTrajectory beside the arm's, at the same times, with the stored jaw widths
    arm, grip = (yaml.safe_load(f.read_text()) for f in (traj, tmp_path / "own.gripper.yaml"))
    times = [[p["time_from_start"]["sec"] + 1e-9 * p["time_from_start"]["nanosec"] for p in m["points"]] for m in (arm, grip)]
    assert grip["joint_names"] == ["jaw_width"] and np.allclose(times[0], times[1], atol=1e-9)
    t, width = np.array(times[1]), np.array([p["positions"][0] for p in grip["points"]])
    con = duckdb.connect(db, read_only=True)
    idplan = con.execute("SELECT max(idplan) FROM plan").fetchone()[0]
    segs = con.execute("SELECT s.kind, s.holding, s.t0, s.duration, s.jaw, p.jawwidth FROM plansegment s JOIN planstep p "
                       "ON p.idplan = s.idplan AND p.seq = s.step WHERE s.idplan = ? ORDER BY s.seq", [idplan]).fetchall()
    con.close()
    closes = 0
    for k, (kind, holding, t0, duration, jaw, jawwidth) in enumerate(segs):
        inside = (t > t0 + 1e-6) & (t <= t0 + duration + 1e-6)
        assert inside.any(), k
        if kind == "gripper":  # the jaw moves from the previous segment's width to this one's while the arm rests
            assert np.isclose(width[inside][-1], jaw) and np.isclose(width[t <= t0 + 1e-6][-1], segs[k - 1][4])
            closes += holding and np.isclose(jaw, jawwidth)  # closed on the stored grasp's width
        else:
            assert np.allclose(width[inside], jaw), (k, kind)
    assert closes == plan["regrasps"] + 1
    assert main(["gpplan", "--db", db, "--object", "box", "--robot", "panda", "--gripper", "robotiq-2f85",
                 "--from", "0,0", "--to", "1,90", "--no-save"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "panda-hand" in err[0], err
