"""The task's pick-up and destination (Tournassoud et al. 1987, Section 5.1, Fig. 1): obstacles and the insertion
turn into the first and last grasps' legal angles; checked against coal, independently of the planner's fcl."""

from __future__ import annotations

import coal
import numpy as np
import pytest

from workbench.errors import WorkbenchError
from workbench.grasping.placements import stable_placements
from workbench.planners.tournassoud.classes import grasp_classes
from workbench.planners.tournassoud.table import TableParams, build_table
from workbench.planners.tournassoud.task import TaskEnd, end_mask, task_query, walls_around
from workbench.planners.tournassoud.shapes import l_part

STANDING = next(j for j, p in enumerate(stable_placements(l_part()).poses)
                if np.allclose(p[:3, :3] @ [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], atol=1e-6))
"""The L part's placement standing on one leg with its other leg upright (the pick-up of Fig. 1)."""


@pytest.fixture(scope="module")
def setup(lpart, hand, puma560):
    classes = grasp_classes(lpart, hand)
    table = build_table(classes, stable_placements(lpart).poses, puma560, hand, TableParams(table_point=(0.45, 0.1)),
                        progress=False)
    return classes, table


_BVH: dict = {}


def _coal(mesh) -> coal.BVHModelOBBRSS:
    key = (id(mesh), len(mesh.vertices), float(np.asarray(mesh.vertices).sum()))
    if key in _BVH:
        return _BVH[key][1]
    m = coal.BVHModelOBBRSS()
    m.beginModel(len(mesh.faces), len(mesh.vertices))
    m.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    m.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    m.endModel()
    _BVH[key] = (mesh, m)  # the mesh kept alive so that its id is not reused
    return m


def _hits(hand_mesh, poses: np.ndarray, obstacles) -> bool:
    """coal: whether the hand mesh at any of the world poses touches any obstacle (a check sharing no code with the
    planner's python-fcl test)."""
    hand = _coal(hand_mesh)
    req = coal.CollisionRequest()
    for o in obstacles:
        obs = _coal(o.mesh)
        to = coal.Transform3s(o.pose[:3, :3], o.pose[:3, 3])
        for p in poses:
            res = coal.CollisionResult()
            if coal.collide(hand, coal.Transform3s(p[:3, :3], p[:3, 3]), obs, to, req, res):
                return True
    return False


_HANDS: dict = {}


def _hand_at(hand, width: float):
    """The hand's collision mesh with the fingers `width` apart (one mesh per width, for the coal cache)."""
    key = round(float(width), 12)
    if key not in _HANDS:
        _HANDS[key] = hand.collision_mesh(min(float(width), hand.jaw_max))
    return _HANDS[key]


def _end_hits(hand, cls, tcp: np.ndarray, end) -> bool:
    """coal: the hand at the class's pre-grasp opening (its opening plus 10 mm, CONVENTIONS.md, capped at the stroke)
    at the grasp and along the approach, or at the grasp's opening along the insertion, touches an obstacle."""
    if _hits(_hand_at(hand, cls.opening + 0.010), _path(tcp, end.approach), end.obstacles):
        return True
    return end.insertion is not None and _hits(_hand_at(hand, cls.opening), _path(tcp, 0.0, end.insertion, end.depth),
                                               end.obstacles)


def _path(tcp: np.ndarray, approach: float, insertion=None, depth: float = 0.0) -> np.ndarray:
    """The test's own sweep: the grasp backed off along its -z every 5 mm, and back along the insertion every 2 mm."""
    out = []
    for s in np.linspace(0, approach, int(np.ceil(approach / 0.005)) + 1):
        p = tcp.copy()
        p[:3, 3] -= s * tcp[:3, 2]
        out.append(p)
    if insertion is not None:
        for s in np.linspace(0, depth, int(np.ceil(depth / 0.002)) + 1):
            p = tcp.copy()
            p[:3, 3] -= s * np.asarray(insertion)
            out.append(p)
    return np.array(out)


def test_pickup_obstacles_refuse_the_grasps_that_hit_them(setup, lpart, hand, puma560):
    """The L part standing in a pocket (walls on two sides, 20 mm away): the grasps whose hand hits a wall at the grasp or
    on its approach are refused, exactly those by coal; the chosen first grasp of a task query clears them."""
    classes, table = setup
    bare = TaskEnd(STANDING, 0.45, -0.12, np.radians(30))
    pocket = TaskEnd(STANDING, 0.45, -0.12, np.radians(30))
    pocket.obstacles = walls_around(lpart.mesh, pocket.object_pose(table), gap=0.02, sides="y")
    free, _ = end_mask(table, classes, bare, puma560, hand)
    legal, counts = end_mask(table, classes, pocket, puma560, hand)
    refused = free & ~legal
    assert legal.any() and refused.any() and not (legal & ~free).any()
    assert counts["obstacles"] == int(refused.sum())
    obj = pocket.object_pose(table)
    for (c, t), expect in [((c, t), True) for c, t in np.argwhere(refused)] + [((c, t), False) for c, t in np.argwhere(legal)]:
        tcp = obj @ classes[c].pose(table.theta[t])
        assert _end_hits(hand, classes[c], tcp, pocket) == expect, (c, t)
    dest = TaskEnd(0, 0.45, 0.32, 0.0)
    seq = task_query(table, legal, end_mask(table, classes, dest, puma560, hand)[0], pocket, dest)
    c, t = seq.grasps[0]
    assert legal[c, t] and not _end_hits(hand, classes[c], obj @ classes[c].pose(table.theta[t]), pocket)
    assert np.allclose(seq.extra["start_pose"], obj) and seq.placements[0][0] == STANDING


def test_a_tight_pocket_is_entered_at_the_pregrasp_opening(setup, lpart, hand, puma560):
    """Walls 10 mm from the standing part: the hand fully open (80 mm) fits no grasp between them, the hand at each
    class's pre-grasp opening (its opening plus 10 mm) fits some; each grasp is legal exactly when coal finds the hand
    at that opening clear of the walls along the approach."""
    classes, table = setup
    pocket = TaskEnd(STANDING, 0.45, -0.12, np.radians(30))
    pocket.obstacles = walls_around(lpart.mesh, pocket.object_pose(table), gap=0.01, sides="y")
    legal, _ = end_mask(table, classes, pocket, puma560, hand)
    wide, _ = end_mask(table, classes, pocket, puma560, hand, pregrasp_margin=None)
    free, _ = end_mask(table, classes, TaskEnd(STANDING, 0.45, -0.12, np.radians(30)), puma560, hand)
    assert not wide.any() and legal.any() and not (legal & ~free).any()
    obj = pocket.object_pose(table)
    for c, t in np.argwhere(free):
        assert _end_hits(hand, classes[c], obj @ classes[c].pose(table.theta[t]), pocket) == (not legal[c, t]), (c, t)


def test_insertion_keeps_the_last_hand_clear_of_the_fixture(setup, lpart, hand, puma560):
    """The L part lying in a slot (walls 10 mm either side along x, 20 mm taller than the part), inserted straight down
    over 30 mm: every grasp refused at the destination hits the fixture by coal somewhere along the insertion or the
    retract, every accepted one clears it all along, and the query's last grasp is an accepted one."""
    classes, table = setup
    dest = TaskEnd(0, 0.45, 0.32, 0.0, insertion=np.array([0.0, 0.0, -2.0]), depth=0.03)
    assert np.allclose(dest.insertion, [0, 0, -1])
    obj = dest.object_pose(table)
    height = float(lpart.mesh.copy().apply_transform(obj).bounds[1, 2])
    dest.obstacles = walls_around(lpart.mesh, obj, gap=0.01, height=height + 0.02, sides="x")
    bare = TaskEnd(0, 0.45, 0.32, 0.0)
    free, _ = end_mask(table, classes, bare, puma560, hand)
    legal, _ = end_mask(table, classes, dest, puma560, hand)
    assert legal.any() and (free & ~legal).any() and not (legal & ~free).any()
    for (c, t) in np.argwhere(free):
        tcp = obj @ classes[c].pose(table.theta[t])
        assert _end_hits(hand, classes[c], tcp, dest) == (not legal[c, t]), (c, t)
    pick = TaskEnd(STANDING, 0.45, -0.12, np.radians(30))
    seq = task_query(table, end_mask(table, classes, pick, puma560, hand)[0], legal, pick, dest)
    c, t = seq.grasps[-1]
    assert legal[c, t] and seq.placements[-1][0] == 0 and np.allclose(seq.extra["goal_pose"], obj)
    with pytest.raises(WorkbenchError, match="insertion direction"):
        TaskEnd(0, 0.45, 0.32, insertion=np.zeros(3))
    with pytest.raises(WorkbenchError, match="placement 9 does not exist"):
        TaskEnd(9, 0.45, 0.32).object_pose(table)


def test_cli_task_plan_clears_the_obstacles(tmp_path, lpart, hand, capsys):
    """`gpplan --pickup ... --destination ... --insert` with obstacle files: Fig. 1's task (the L part standing in a
    pocket, laid into a slot) gives an executable plan, stored and passed by the validators (trajectory checked against
    the obstacles too); it starts by taking the part at the pick-up and ends by putting it at the destination; every
    knot of its motions keeps the hand and the held part clear of the obstacles, by coal on the robot's FK."""
    import json

    import trimesh

    from workbench.cli.main import main
    from workbench.robots.model import get_robot

    mesh = tmp_path / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp_path / "task.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--table-point", "0.45,0.1"]) == 0
    from workbench.planners.tournassoud.stages import load_planner

    run = load_planner(db, "L")
    pick, dest = TaskEnd(STANDING, 0.55, -0.05, np.radians(30)), TaskEnd(0, 0.35, 0.25, 0.0)
    args, obstacles = [], []
    for flag, end, gap, sides in (("--pickup-obstacle", pick, 0.02, "y"), ("--destination-obstacle", dest, 0.01, "x")):
        for k, o in enumerate(walls_around(lpart.mesh, end.object_pose(run.table), gap=gap, sides=sides)):
            f = tmp_path / f"{flag[2:6]}{k}.stl"
            o.mesh.export(f)
            args += [flag, f"{f}@{o.pose[0, 3]:.6f},{o.pose[1, 3]:.6f},{o.pose[2, 3]:.6f}"]
            obstacles.append(o)
    js = tmp_path / "task.json"
    assert main(["gpplan", "--db", db, "--object", "L", "--pickup", f"{STANDING},0.55,-0.05,30", "--destination", "0,0.35,0.25,0",
                 "--insert", "0,0,-1,0.02", *args, "--json", str(js)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    plan = doc["plan"]
    assert plan is not None and "validator: ok" in out and "the pick-up" in out and "the destination" in out, out
    assert plan["steps"][0]["kind"] == "pick" and plan["steps"][-1]["kind"] == "place"
    assert np.allclose(np.reshape(plan["steps"][0]["object_pose"], (4, 4)), pick.object_pose(run.table), atol=1e-9)
    assert np.allclose(np.reshape(plan["steps"][-1]["object_pose"], (4, 4)), dest.object_pose(run.table), atol=1e-9)
    robot = get_robot("puma560")
    held = trimesh.Trimesh(lpart.mesh.vertices, lpart.mesh.faces, process=False)
    knots = 0
    for seg in plan["motion"]["segments"]:
        step = plan["steps"][seg["step"]]
        body = _hand_at(hand, seg["jaw"])  # the fingers at the segment's opening
        for q in seg["q"]:
            tcp = robot.tcp_pose(np.asarray(q))
            assert not _hits(body, tcp[None], obstacles), (seg["kind"], seg["caption"])
            if seg["holding"]:
                assert not _hits(held, (tcp @ np.linalg.inv(np.reshape(step["grasp"], (4, 4))))[None], obstacles)
            knots += 1
    assert knots > 100
    assert doc["task"]["destination"]["insertion"] == [0.0, 0.0, -1.0] and len(doc["task"]["pickup"]["obstacles"]) == 2
    # not stored: the same validators check the plan and its trajectory against the obstacles given
    assert main(["gpplan", "--db", db, "--object", "L", "--pickup", f"{STANDING},0.55,-0.05,30", "--destination",
                 "0,0.35,0.25,0", "--insert", "0,0,-1,0.02", *args, "--no-save"]) == 0
    out = capsys.readouterr().out
    assert "validator: ok" in out and "stored plan id" not in out, out
    # bad task input: one line each, exit 2, nothing planned
    base = ["gpplan", "--db", db, "--object", "L", "--no-motion", "--no-save"]
    ends = ["--pickup", f"{STANDING},0.55,-0.05,30", "--destination", "0,0.35,0.25,0"]
    for bad in (["--pickup", f"{STANDING},0.55,-0.05,30"], ["--pickup", f"{STANDING},x,0,0", "--destination", "0,0.35,0.25,0"],
                ends + ["--insert", "0,0,0"], ends + ["--insert", "0,0,-1,-0.1"],
                ends + ["--pickup-obstacle", str(tmp_path / "missing.stl") + "@0,0,0"],
                ends + ["--pickup-obstacle", "nopose.stl"], ends + ["--from", "0,0", "--to", "1,0"],
                ["--from", "0,0", "--to", "1,0", "--insert", "0,0,-1"], ["--from", "0,0", "--to", "1,0", "--end-held"], ends[:2] + ["--destination", "9,0.35,0.25,0"]):
        assert main(base + bad) == 2, bad
    err = capsys.readouterr().err
    assert "Traceback" not in err


def _pin_fk(robot):
    """The test's own forward kinematics: pinocchio on the robot's URDF, TCP = base @ oMf(tip) @ mount."""
    import pinocchio as pin

    model = pin.buildModelFromXML(robot.spec.urdf)
    data = model.createData()
    tip = model.getFrameId(robot.spec.tip_frame)
    idx = [model.joints[model.getJointId(j)].idx_q for j in robot.joint_names]

    def fk(q: np.ndarray) -> np.ndarray:
        full = pin.neutral(model)
        full[idx] = q
        pin.framesForwardKinematics(model, data, full)
        return robot.base @ np.asarray(data.oMf[tip].homogeneous) @ robot.mount
    return fk


@pytest.fixture(scope="module")
def slot(tmp_path_factory, lpart):
    """A store with the L part's table, and obstacle files: a pocket at the pick-up (the part standing, walls along y)
    and a slot open along x at the destination (the part lying, walls along y), with their `--*-obstacle` flags."""
    from workbench.cli.main import main
    from workbench.planners.tournassoud.stages import load_planner

    tmp = tmp_path_factory.mktemp("slot")
    mesh = tmp / "L.stl"
    lpart.mesh.export(mesh)
    db = str(tmp / "slot.duckdb")
    assert main(["gptable", str(mesh), "--db", db, "--table-point", "0.45,0.1"]) == 0
    run = load_planner(db, "L")
    ends = {"pickup": TaskEnd(STANDING, 0.55, -0.05, np.radians(30)), "destination": TaskEnd(0, 0.35, 0.25, 0.0)}
    walls, flags = {}, {}
    for name, gap in (("pickup", 0.02), ("destination", 0.01)):
        walls[name] = walls_around(lpart.mesh, ends[name].object_pose(run.table), gap=gap, sides="y")
        flags[name] = []
        for k, o in enumerate(walls[name]):
            f = tmp / f"{name}{k}.stl"
            o.mesh.export(f)
            flags[name] += [f"--{name}-obstacle", f"{f}@{o.pose[0, 3]:.6f},{o.pose[1, 3]:.6f},{o.pose[2, 3]:.6f}"]
    return db, run, walls, flags, tmp


def _stored_segments(db: str, idplan: int) -> list[dict]:
    from workbench.store import Store
    from workbench.store.wan_harada import load_plan_segments

    with Store(db) as store:
        return load_plan_segments(store, idplan).to_pylist()


def _clear_everywhere(segs, steps, fk, nq, hand, lpart, walls) -> None:
    """coal: at every stored knot (pinocchio FK), the hand and, while held, the part clear every wall."""
    import trimesh

    grasps = [np.linalg.inv(np.reshape(x["grasp"], (4, 4))) for x in steps]
    held = trimesh.Trimesh(lpart.mesh.vertices, lpart.mesh.faces, process=False)
    for s in segs:
        body = _hand_at(hand, s["jaw"])  # the fingers at the segment's opening
        for x in np.reshape(s["q"], (-1, nq)):
            p = fk(x)
            assert not _hits(body, p[None], walls), (s["kind"], s["caption"])
            if s["holding"]:
                assert not _hits(held, (p @ grasps[s["step"]])[None], walls), (s["kind"], s["caption"])


def test_slanted_insertion_is_the_plans_last_straight_line(slot, lpart, hand, capsys):
    """`gpplan --insert 1,0,-1,0.03` into a slot open along x (walls either side along y): the stored plan's last
    motion with the part in the hand is a straight TCP line of 30 mm along the insertion direction ending at the
    destination (pinocchio FK of the stored knots, not the planner's), every knot of which keeps the hand and the
    held part clear of the slot's walls (coal); the plan passes the validators."""
    import json

    from workbench.cli.main import main
    from workbench.robots.model import get_robot

    db, run, walls, flags, tmp = slot
    capsys.readouterr()
    js = tmp / "slant.json"
    assert main(["gpplan", "--db", db, "--object", "L", "--pickup", f"{STANDING},0.55,-0.05,30", "--destination", "0,0.35,0.25,0",
                 "--insert", "1,0,-1,0.03", *flags["destination"], "--json", str(js)]) == 0
    out = capsys.readouterr().out
    assert "validator: ok" in out, out
    idplan = int(out.split("stored plan id ")[1].split()[0])
    segs = _stored_segments(db, idplan)
    robot = get_robot("puma560")
    fk = _pin_fk(robot)
    last = [s for s in segs if s["kind"] == "lower"][-1]
    tcp = np.array([fk(x) for x in np.reshape(last["q"], (-1, robot.nq))])
    d = np.array([1.0, 0.0, -1.0]) / np.sqrt(2)
    move = tcp[-1, :3, 3] - tcp[0, :3, 3]
    assert np.allclose(move, 0.03 * d, atol=1e-3), move
    rel = tcp[:, :3, 3] - tcp[0, :3, 3]
    off_line = np.linalg.norm(rel - np.outer(rel @ d, d), axis=1)
    assert off_line.max() < 1e-3 and np.all(np.diff(rel @ d) > -1e-6), off_line.max()
    assert np.allclose(tcp[:, :3, :3], tcp[0, :3, :3], atol=1e-3)  # the hand translates along the line
    after = segs[segs.index(last) + 1]
    assert after["kind"] == "gripper" and not after["holding"]  # the part is released in place
    steps = json.loads(js.read_text())["plan"]["steps"]
    assert last["step"] == len(steps) - 1 and np.allclose(tcp[-1], np.reshape(steps[-1]["tcp"], (4, 4)), atol=1e-3)
    _clear_everywhere(segs, steps, fk, robot.nq, hand, lpart, walls["destination"])


@pytest.fixture(scope="module")
def held(slot, capsys_module):
    """`gpplan` of the task with obstacles at both ends, the part held at the start and at the end, and a slanted
    insertion: (idplan, its JSON plan, the output)."""
    import json

    from workbench.cli.main import main

    db, run, walls, flags, tmp = slot
    js = tmp / "held.json"
    out = capsys_module(lambda: main(["gpplan", "--db", db, "--object", "L", "--pickup", f"{STANDING},0.55,-0.05,30",
                                      "--destination", "0,0.35,0.25,0", "--insert", "1,0,-1,0.03", *flags["pickup"],
                                      *flags["destination"], "--start-held", "--end-held", "--json", str(js)]))
    idplan = int(out.split("stored plan id ")[1].split()[0])
    return idplan, json.loads(js.read_text())["plan"], out


@pytest.fixture(scope="module")
def capsys_module():
    """Run a callable that must return 0 and give its standard output (module-scoped fixtures cannot use capsys)."""
    import contextlib
    import io

    def run(fn) -> str:
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            assert fn() == 0
        return buf.getvalue()
    return run


def test_plan_starts_and_ends_in_the_hand(slot, held, lpart, hand):
    """`--start-held --end-held` (Fig. 1 (a) and (d)): the stored trajectory begins with the part held at the first
    grasp at the pick-up, lifting it out of the pocket, and ends with it still held at the last grasp at the
    destination after the insertion (pinocchio FK of the stored knots); hand and part clear both ends' walls (coal);
    the validators rebuilt from the store accept it because the plan says so, and refuse the same trajectory when
    the plan claims to release the part at the end or to start with an empty hand."""
    from workbench.planners.tournassoud.stages import validate_stored
    from workbench.planners.wan_harada.plans import Plan
    from workbench.robots.model import get_robot

    db, run, walls, flags, tmp = slot
    idplan, doc, out = held
    assert "validator: ok" in out and "starts with the part in the hand" in out and "still in the hand" in out, out
    assert doc["start_held"] and doc["end_held"]
    steps = doc["steps"]
    segs = _stored_segments(db, idplan)
    robot = get_robot("puma560")
    fk = _pin_fk(robot)
    first, last = segs[0], segs[-1]
    assert first["kind"] == "lift" and first["holding"] and last["kind"] == "lower" and last["holding"]
    q0, q1 = np.reshape(first["q"], (-1, robot.nq))[0], np.reshape(last["q"], (-1, robot.nq))[-1]
    assert np.allclose(fk(q0), np.reshape(steps[0]["tcp"], (4, 4)), atol=1e-3)
    assert np.allclose(fk(q1), np.reshape(steps[-1]["tcp"], (4, 4)), atol=1e-3)
    # the jaw acts only at the regrasps in between: once to release, once to take, per regrasp on the table
    assert sum(s["kind"] == "gripper" for s in segs) == 2 * doc["regrasps"]
    assert not any(s["kind"] in ("approach", "retract") and s["step"] in (0, len(steps) - 1) for s in segs)
    _clear_everywhere(segs, steps, fk, robot.nq, hand, lpart, walls["pickup"] + walls["destination"])
    obstacles = [(o.mesh, o.pose) for o in walls["pickup"] + walls["destination"]]
    plan = Plan.from_dict(doc)
    plan.obstacles = []  # the obstacles given, not the plan's
    assert validate_stored(db, run, idplan, plan, require_motion=True, obstacles=obstacles).ok
    plan.end_held = False
    report = validate_stored(db, run, idplan, plan, require_motion=True, obstacles=obstacles)
    assert not report.ok and any("still in the hand" in e for e in report.errors), report.errors
    plan.end_held, plan.start_held = True, False
    report = validate_stored(db, run, idplan, plan, require_motion=True, obstacles=obstacles)
    assert not report.ok and any("held" in e for e in report.errors), report.errors


def test_reloaded_plan_keeps_its_task(slot, held, tmp_path, capsys):
    """The held plan with obstacles and an insertion, reloaded from the store in a fresh process (`gpplan --plan`):
    the same steps with their lifts, the same timed motions, both held ends, the insertion and every obstacle (the
    walls' own meshes and poses, compared with the files given); the validators rebuilt from the store accept it
    again, checking the trajectory against the stored obstacles; its exports name them."""
    import json
    import os
    import subprocess
    import sys

    db, run, walls, flags, tmp = slot
    idplan, doc, _ = held
    js, traj, page = tmp_path / "reloaded.json", tmp_path / "plan.yaml", tmp_path / "plan.html"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(__import__("pathlib").Path(__file__).parents[3])] +
                                                       os.environ.get("PYTHONPATH", "").split(os.pathsep))}
    res = subprocess.run([sys.executable, "-m", "workbench", "gpplan", "--db", db, "--plan", str(idplan), "--json", str(js),
                          "--trajectory", str(traj), "--plan-html", str(page)], capture_output=True, text=True, env=env,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert "validator: ok" in out and "starts with the part in the hand" in out and "still in the hand" in out, out
    assert "insertion of 30 mm" in out and "obstacles: 2 at the pick-up, 2 at the destination" in out, out
    back = json.loads(js.read_text())
    assert back["validator"]["ok"], back["validator"]
    plan = back["plan"]
    assert plan["start_held"] and plan["end_held"]
    assert np.allclose(plan["insertion"], np.array([1.0, 0.0, -1.0]) / np.sqrt(2)) and plan["insertion_depth"] == 0.03
    assert len(plan["steps"]) == len(doc["steps"])
    for a, b in zip(plan["steps"], doc["steps"]):
        assert a["kind"] == b["kind"]
        for k in ("object_pose", "tcp", "q_grasp", "q_approach", "q_retract", "q_worlda", "q_worldaworldz"):
            assert np.allclose(a[k], b[k], atol=1e-12), k
        assert (a.get("lift") is None) == (b.get("lift") is None)
        if b.get("lift") is not None:
            assert np.allclose(a["lift"], b["lift"], atol=1e-12)
    assert np.allclose(plan["steps"][-1]["lift"], -0.03 * np.array([1.0, 0.0, -1.0]) / np.sqrt(2), atol=1e-12)
    sa, sb = plan["motion"]["segments"], doc["motion"]["segments"]
    assert [(x["kind"], x["holding"], x["step"]) for x in sa] == [(x["kind"], x["holding"], x["step"]) for x in sb]
    for x, y in zip(sa, sb):
        assert np.allclose(x["t"], y["t"]) and np.allclose(x["q"], y["q"]) and np.allclose(x["qd"], y["qd"])
    given = [(e, o) for e in ("pickup", "destination") for o in walls[e]]
    assert [o["end"] for o in plan["obstacles"]] == [e for e, _ in given]
    for o, (_, w) in zip(plan["obstacles"], given):
        assert np.allclose(np.reshape(o["pose"], (4, 4)), w.pose, atol=1e-6)
        assert np.allclose(np.sort(np.reshape(o["vertices"], (-1, 3)), axis=0), np.sort(w.mesh.vertices, axis=0), atol=1e-6)
    assert "joint_names" in traj.read_text() and "planobstacle" not in traj.read_text()
    assert page.stat().st_size > 10_000 and "wb-caption" in page.read_text()
    # the store answers the same query with this plan only among the same obstacles and held ends
    from workbench.planners.wan_harada.plans import Plan, plan_rows
    from workbench.store import Store
    from workbench.store.wan_harada import find_plan

    same = Plan.from_dict(doc)
    moved = Plan.from_dict(doc)
    moved.obstacles[0].pose[0, 3] += 0.01
    released = Plan.from_dict(doc)
    released.end_held = False
    found = []
    with Store(db, read_only=True) as store:
        for p in (same, moved, released):
            row, _, segments = plan_rows(p)
            found.append(find_plan(store, row, segments))
    assert found == [idplan, None, None], found
    # a plan that is not there, or a query beside --plan: one line, status 2
    from workbench.cli.main import main

    assert main(["gpplan", "--db", db, "--plan", "9999"]) == 2
    assert main(["gpplan", "--db", db, "--plan", str(idplan), "--initial", "0,10"]) == 2
    assert main(["gpplan", "--db", db, "--initial", "0,10", "--goal", "3,0:90"]) == 2  # no --object
    err = capsys.readouterr().err
    assert "Traceback" not in err and "has no plan 9999" in err and "--plan ID reloads" in err and "--object NAME" in err
