"""IK feasibility of tabletop grips (Wan & Harada Section IV: robot, ikret, ik) on a real DuckDB store.

The stored rows are checked with pinocchio directly on the stored URDF text, joint names, tip frame, mount and
base (not through workbench.robots). Grips are a small synthetic box set written through the library.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from workbench.benchmarks.ik import synthetic_grips, synthetic_store
from workbench.cli import main as cli
from workbench.errors import RobotError, StoreError
from workbench.planners.wan_harada import stages
from workbench.planners.wan_harada.stages import HANDX, WORLDZ, run_ik
from workbench.resources import erd_robots
from workbench.robots.chain import forward
from workbench.robots.collider import Scene, default_scene
from workbench.robots.ik import IKOptions, diagnose_unreachable, ik_feasibility
from workbench.robots.model import get_robot, pose_xyz_yaw, robot_from_urdf
from workbench.store import Store
from workbench.store import robots as sql

SMALL = dict(xs=np.array([0.4, 0.55]), ys=np.array([-0.15, 0.15]), angles=4, approaches=4, offsets=1)
OPTS = IKOptions(chunk=32, library=4096, solver="numerical")


@pytest.fixture(scope="module")
def panda():
    return get_robot("panda")


@pytest.fixture(scope="module")
def stored(tmp_path_factory, panda):
    """A store with the small box grips and the panda's ik rows (computed once in this process)."""
    db = tmp_path_factory.mktemp("ik") / "ik.duckdb"
    with Store(db) as store:
        oid, pid = synthetic_store(store, "box", **SMALL)
        run = run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
    return db, run


def _stored_check(store: Store, idrobot: int, idscene: int, idikret: int) -> tuple[float, float, int]:
    """Max position (m) and rotation (rad) error of the stored joint vectors against the stored TCP targets, using
    pinocchio on the stored robot row only; and the number of checked vectors."""
    row = sql.robot_row(store, idrobot)
    ret = sql.ikret_row(store, idikret)
    handx, worldz, worlda = ret["handx"], ret["worldz"], ret["worlda"]
    rows = sql.load_ik(store, idrobot, idscene, idikret)
    model = pin.buildModelFromXML(row["urdf"])
    data = model.createData()
    fid = model.getFrameId(row["tip_frame"])
    idx = [model.joints[model.getJointId(n)].idx_q for n in row["joint_names"]]
    lo, hi = model.lowerPositionLimit[idx], model.upperPositionLimit[idx]
    worst_p = worst_r = 0.0
    count = 0
    for i in range(len(rows["idik"])):
        grasp = rows["rotmat"][i]
        targets = [grasp.copy() for _ in range(5)]
        targets[1][:3, 3] -= handx * grasp[:3, 2]
        targets[2][:3, 3] = targets[1][:3, 3] + np.array([0.0, 0.0, worldz])
        targets[3][2, 3] += worlda                  # the held object lifted straight up
        targets[4][2, 3] += worlda + worldz
        for k in range(5):
            if not rows["feasible"][i, k]:
                assert np.isnan(rows["joints"][i, k]).all()
                continue
            qv = rows["joints"][i, k]
            assert (qv >= lo - 1e-9).all() and (qv <= hi + 1e-9).all()
            q = pin.neutral(model)
            for name, value in row["locked"].items():  # joints outside the arm, e.g. a humanoid's other arm
                q[model.joints[model.getJointId(name)].idx_q] = value
            q[idx] = qv
            pin.framesForwardKinematics(model, data, q)
            tcp = row["base"] @ np.asarray(data.oMf[fid].homogeneous) @ row["mount"]
            worst_p = max(worst_p, float(np.linalg.norm(tcp[:3, 3] - targets[k][:3, 3])))
            cos = (np.trace(tcp[:3, :3].T @ targets[k][:3, :3]) - 1) / 2
            worst_r = max(worst_r, float(np.arccos(np.clip(cos, -1, 1))))
            count += 1
    return worst_p, worst_r, count


def test_stored_joints_reproduce_tcp_and_respect_limits(stored):
    db, run = stored
    assert run.computed == run.grips > 50
    assert 0 < run.feasible_all <= run.feasible < run.grips  # some far or awkward grips are infeasible
    with Store(db, read_only=True) as store:
        dp, dr, count = _stored_check(store, run.idrobot, run.idscene, run.idikret)
        names = sql.robot_row(store, run.idrobot)["joint_names"]
    assert count > 100
    assert dp < 1e-3 and dr < np.radians(0.5)
    assert names == [f"panda_joint{i}" for i in range(1, 8)]


def test_humanoid_rows_rebuild_from_the_robot_row(tmp_path):
    """Talos's stored row alone (URDF text, joint names incl. the waist, locked joints, base, mount) reproduces
    every stored TCP pose."""
    talos = get_robot("talos")
    with Store(tmp_path / "talos.duckdb") as store:
        oid, pid = synthetic_store(store, "box", **SMALL)
        run = run_ik(store, "box", talos, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
        row = sql.robot_row(store, run.idrobot)
        assert row["joint_names"][:2] == ["torso_1_joint", "torso_2_joint"]
        assert row["locked"] and set(row["locked"]).isdisjoint(row["joint_names"])
        assert row["drop_geometry"]
        dp, dr, count = _stored_check(store, run.idrobot, run.idscene, run.idikret)
    assert count > 20 and dp < 1e-3 and dr < np.radians(0.5)


def test_rerun_reuses_and_interrupted_run_resumes(stored, tmp_path, panda, monkeypatch):
    db, run = stored
    with Store(db) as store:
        again = run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=run.idtabletop)
        reference = sql.load_ik(store, run.idrobot, run.idscene, run.idikret)
    assert again.reused and again.computed == 0 and again.feasible == run.feasible
    # a new revision of a solver these rows do not use changes nothing; of the one they use, they are computed again
    from workbench.robots import solvers

    for kind, reused in (("three parallel axes", True), ("numerical", False)):
        monkeypatch.setitem(solvers.REVISIONS, kind, solvers.REVISIONS[kind] + 1)
        with Store(db) as store:
            bumped = run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False,
                            idtabletop=run.idtabletop)
        assert bumped.reused == reused and bumped.computed == (0 if reused else run.grips)
        assert (bumped.idscene == run.idscene) == reused and bumped.feasible == run.feasible
    monkeypatch.undo()

    # interrupt after the first chunk is written, then resume: the same rows as the uninterrupted run
    db2 = tmp_path / "resume.duckdb"
    calls = {"n": 0}
    real = sql.insert_ik

    def flaky(*args, **kwargs):
        if calls["n"] == 1:
            raise KeyboardInterrupt
        calls["n"] += 1
        return real(*args, **kwargs)

    with Store(db2) as store:
        _, pid = synthetic_store(store, "box", **SMALL)
        monkeypatch.setattr(sql, "insert_ik", flaky)
        monkeypatch.setattr(stages, "IK_WRITE_SECONDS", 0.0)  # every chunk written as it comes
        with pytest.raises(KeyboardInterrupt):
            run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
        monkeypatch.setattr(sql, "insert_ik", real)
        runs = sql.ik_runs(store)
        assert len(runs) == 1 and runs[0]["rows"] == OPTS.chunk  # the first chunk survived the interruption
        resumed = run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
        rows = sql.load_ik(store, resumed.idrobot, resumed.idscene, resumed.idikret)
    assert resumed.computed == run.grips - OPTS.chunk
    np.testing.assert_array_equal(rows["idtabletopgrips"], reference["idtabletopgrips"])
    np.testing.assert_array_equal(rows["feasible"], reference["feasible"])
    np.testing.assert_array_equal(rows["joints"], reference["joints"])


def _single(pose: np.ndarray) -> dict[str, np.ndarray]:
    place = np.eye(4)
    place[:3, 3] = pose[:3, 3] - np.array([0, 0, 0.02])
    return {"idtabletopgrips": np.array([1]), "idfreeairgrip": np.array([1]), "rotmat": pose[None],
            "placement_rotmat": place[None], "tabletopposition": place[None, :3, 3].copy(), "jawwidth": np.array([0.04])}


def test_pose_far_outside_the_workspace_is_infeasible(panda):
    far = np.eye(4)
    far[:3, 3] = (3.0, 0.0, 0.3)
    res = ik_feasibility(panda, _single(far), default_scene("panda"), HANDX, WORLDZ, None, OPTS, workers=1, progress=False)
    assert not res.feasible.any()
    assert np.isnan(res.joints).all()


def test_grip_that_puts_the_arm_through_the_table_is_infeasible(panda):
    # TCP 5 cm above the table, approaching straight up from below: the hand and wrist are under the table top
    up = np.eye(4)  # the TCP's z (approach) along world +z
    up[:3, 3] = (0.45, 0.0, 0.05)
    grips = _single(up)
    free = ik_feasibility(panda, grips, default_scene("panda"), 0.0, 0.0, None, IKOptions(collide=False, library=4096),
                          workers=1, progress=False)
    assert free.feasible[0, 0], "the pose is kinematically reachable, only the table forbids it"
    # pinocchio (not the library) confirms the arm itself, not only the hand, is below the table top there
    model = panda.model
    data = model.createData()
    pin.framesForwardKinematics(model, data, free.joints[0, 0])
    z7 = (panda.base @ np.asarray(data.oMf[model.getFrameId("panda_link7")].homogeneous))[2, 3]
    assert z7 < 0
    res = ik_feasibility(panda, grips, default_scene("panda"), 0.0, 0.0, None, IKOptions(library=4096), workers=1, progress=False)
    assert not res.feasible[0, 0]


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_compiled_broad_phase_answers_as_fcl_alone(name):
    """The collider's compiled broad phase (hull vertices settle most pairs) gives, configuration by configuration,
    fcl's answer on every candidate pair: random in-limit configurations against the table, and the box held near
    the TCP for half of them against the arm."""
    from workbench.robots.collider import Collider

    robot = get_robot(name)
    _, mesh, _ = synthetic_grips(**SMALL)
    collider = Collider(robot, default_scene(name), mesh)
    rng = np.random.default_rng(7)
    q = rng.uniform(robot.lower, robot.upper, (3000, robot.nq))
    rot, pos, _, tcp = forward(robot, q)
    places = np.tile(np.eye(4), (len(q), 1, 1))
    r = np.linalg.qr(rng.normal(size=(len(q), 3, 3)))[0]
    r[:, :, 2] *= np.sign(np.linalg.det(r))[:, None]  # proper rotations
    places[:, :3, :3] = r
    places[:, :3, 3] = tcp + rng.normal(0, 0.08, (len(q), 3))
    for pl in (places, None):
        fast = collider.collides_q(q, pl)
        ref = collider.collides(rot, pos, pl)
        assert 0.05 * len(q) < ref.sum() < 0.95 * len(q)
        assert (fast == ref).all()


def test_batched_forward_kinematics_matches_pinocchio():
    for name in ("ur5", "talos"):
        robot = get_robot(name)
        q = np.random.default_rng(3).uniform(robot.lower, robot.upper, size=(6, robot.nq))
        _, _, rot, pos = forward(robot, q)
        model = pin.buildModelFromXML(robot.spec.urdf)
        data = model.createData()
        fid = model.getFrameId(robot.spec.tip_frame)
        for i in range(len(q)):
            full = pin.neutral(model)
            for jn, v in zip(robot.joint_names, q[i]):
                full[model.joints[model.getJointId(jn)].idx_q] = v
            for jn, v in robot.spec.locked:
                full[model.joints[model.getJointId(jn)].idx_q] = v
            pin.framesForwardKinematics(model, data, full)
            tcp = robot.base @ np.asarray(data.oMf[fid].homogeneous) @ robot.mount
            np.testing.assert_allclose(rot[i], tcp[:3, :3], atol=1e-12)
            np.testing.assert_allclose(pos[i], tcp[:3, 3], atol=1e-12)


def test_humanoid_arm_includes_the_waist():
    talos = get_robot("talos")
    assert talos.joint_names[:2] == ("torso_1_joint", "torso_2_joint") and talos.nq == 9
    grips, mesh, _ = synthetic_grips(xs=np.array([0.45]), ys=np.array([0.1]), angles=1, approaches=4, offsets=1)
    res = ik_feasibility(talos, grips, default_scene("talos"), HANDX, WORLDZ, mesh, IKOptions(library=4096),
                         workers=1, progress=False)
    assert res.feasible[:, 0].any()


def test_bad_robot_inputs_name_the_input(tmp_path):
    with pytest.raises(RobotError, match="does not exist"):
        robot_from_urdf(tmp_path / "missing.urdf", "tool0")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><joint name='j' type='revolute'></robot>")
    with pytest.raises(RobotError, match="could not be loaded"):
        robot_from_urdf(bad, "a")
    with pytest.raises(RobotError, match="no link 'nowhere' for --tip"):
        robot_from_urdf(erd_robots() / "ur_description" / "urdf" / "ur5_robot.urdf", "nowhere")
    with pytest.raises(RobotError, match="NaN"):
        get_robot("panda", base=np.full((4, 4), np.nan))
    nan = np.eye(4)
    nan[0, 3] = np.nan
    with pytest.raises(RobotError, match="TCP pose 0"):
        ik_feasibility(get_robot("panda"), _single(nan), Scene(), HANDX, WORLDZ, None, OPTS, workers=1, progress=False)


def test_cli_runs_reuses_and_reports_bad_input_in_one_line(stored, capsys, tmp_path):
    db, run = stored
    assert cli.main(["ik", "--db", str(db), "--object", "box", "--robot", "panda", "--no-progress", "--workers", "1",
                     "--tabletop", str(run.idtabletop)]) == 0
    out = capsys.readouterr().out
    assert "ik panda:" in out
    assert cli.main(["ik", "--db", str(db), "--object", "box", "--robot", str(tmp_path / "nope.urdf"), "--tip", "x"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not exist" in err[0]
    assert cli.main(["ik", "--db", str(db), "--object", "nothing", "--robot", "panda"]) == 2
    assert "no object 'nothing'" in capsys.readouterr().err
    with Store(db) as holder:  # a locked store is a one-line error, not a traceback
        import subprocess
        import sys
        from pathlib import Path

        proc = subprocess.run([sys.executable, "-m", "workbench.cli", "ik", "--db", str(db), "--object", "box", "--robot", "panda"],
                              capture_output=True, text=True, timeout=120, cwd=Path(__file__).resolve().parents[2])
        assert holder is not None
    assert proc.returncode == 2 and "locked" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    with pytest.raises(StoreError):
        Store(tmp_path / "missing.duckdb", read_only=True)


def test_the_gripper_enters_the_robot_digest_the_workers_and_the_ik_rows(tmp_path, panda):
    """A robot carrying another gripper is another robot: its digest differs, a worker process rebuilds it with that
    gripper (from the pickled spec), and its IK run writes its own robot row and `ik` rows."""
    import pickle

    from workbench.robots.gripper import parametric_gripper
    from workbench.robots.model import robot_from_spec

    small = parametric_gripper(pad_size=(0.015, 0.015), jaw_range=(0.0, 0.05))
    other = get_robot("panda", gripper=small)
    assert other.spec.digest != panda.spec.digest
    rebuilt = robot_from_spec(pickle.loads(pickle.dumps(other.spec)))  # what an IKPool worker does
    assert rebuilt.gripper.digest == small.digest != panda.gripper.digest
    db = tmp_path / "grippers.duckdb"
    with Store(db) as store:
        _, pid = synthetic_store(store, "box", **SMALL)
        a = run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
        b = run_ik(store, "box", other, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid)
        assert a.idrobot != b.idrobot and b.computed == b.grips > 0
        assert sql.robot_row(store, b.idrobot)["digest"] == other.spec.digest


def test_a_stored_urdf_robot_is_rebuilt_from_its_row_with_every_field(tmp_path):
    """A URDF robot with dropped hand geometry is rebuilt from its `robot` row alone (drop_geometry, mesh folders,
    digest check); a row whose digest does not match is refused in one line."""
    from workbench.errors import PlanningError
    from workbench.planners.wan_harada.stages import _robot_from_row

    urdf = erd_robots() / "panda_description" / "urdf" / "panda.urdf"
    robot = robot_from_urdf(urdf, "panda_hand_tcp", name="mypanda",
                            drop_geometry=("panda_hand", "panda_leftfinger", "panda_rightfinger"))
    with Store(tmp_path / "urdf.duckdb") as store:
        with store.transaction():
            rid = sql.put_robot(store, robot)
        row = sql.robot_row(store, rid)
    rebuilt = _robot_from_row(row)
    assert rebuilt.spec.digest == robot.spec.digest
    assert rebuilt.spec.drop_geometry == robot.spec.drop_geometry
    assert str(urdf.parent) in rebuilt.spec.package_dirs
    with pytest.raises(PlanningError, match="other kinematics"):
        _robot_from_row({**row, "digest": "0" * 24})


def test_the_stored_urdf_names_the_tcp_frame_even_where_the_robots_own_urdf_lacks_it(tmp_path):
    """A UR5 with the Franka hand mounted on its flange: its URDF has no TCP link, so the stored URDF text gains one,
    fixed to the tip at the mount. Pinocchio on that text alone (no library) finds the TCP by the stored name, and
    base @ oMf(TCP) is the library's TCP at random joint vectors; the library rebuilds the robot from the row as
    before (same digest). The Panda's URDF has its TCP and is stored as given."""
    import duckdb

    from workbench.planners.wan_harada.stages import _robot_from_row

    ur5 = get_robot("ur5")
    with Store(tmp_path / "tcp.duckdb") as store:
        with store.transaction():
            rids = [sql.put_robot(store, r) for r in (ur5, get_robot("panda"))]
        rows = [sql.robot_row(store, rid) for rid in rids]
    assert _robot_from_row(rows[0]).spec.digest == ur5.spec.digest
    with duckdb.connect(str(tmp_path / "tcp.duckdb"), read_only=True) as con:
        stored = con.execute("SELECT urdf, tcp_frame, base, joint_names FROM robot ORDER BY idrobot").fetchall()
    assert stored[0][0] != ur5.spec.urdf and stored[1][0] == get_robot("panda").spec.urdf
    text, tcp, base, names = stored[0]
    assert f'<link name="{tcp}"/>' not in ur5.spec.urdf and f'<link name="{tcp}"/>' in text
    model = pin.buildModelFromXML(text)
    data = model.createData()
    fid = model.getFrameId(tcp)
    assert fid < model.nframes
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, len(names))
        full = pin.neutral(model)
        for name, v in zip(names, q):
            full[model.joints[model.getJointId(name)].idx_q] = v
        pin.framesForwardKinematics(model, data, full)
        tcp_pose = np.asarray(base).reshape(4, 4) @ data.oMf[fid].homogeneous
        assert np.allclose(tcp_pose, ur5.tcp_pose(q), atol=1e-9)


def test_no_feasible_grip_names_its_cause(tmp_path):
    """Zero feasible grips is a result that names its cause (issue 10): a UR5 loaded from its URDF with the Franka
    hand at the flange (no mount) reaches into the part with its wrist, and the diagnosis says to give the mount;
    with the mount the same grips are feasible; with the base 2.5 m away they are out of reach."""
    grips, mesh, _ = synthetic_grips(xs=np.array([0.45]), ys=np.array([0.1]), angles=2, approaches=4, offsets=1)
    urdf = erd_robots() / "ur_description" / "urdf" / "ur5_robot.urdf"
    scene = default_scene("ur5")
    bare = robot_from_urdf(urdf, "tool0", name="ur5_flange")
    res = ik_feasibility(bare, grips, scene, HANDX, WORLDZ, mesh, OPTS, workers=1, progress=False)
    assert not res.feasible[:, 0].any()
    why = diagnose_unreachable(bare, grips, scene, mesh, OPTS)
    assert "wrist" in why and "hits the object" in why and "--mount 0,0,0.1034" in why
    mount = np.eye(4)
    mount[2, 3] = 0.1034
    mounted = robot_from_urdf(urdf, "tool0", mount=mount, name="ur5_mounted")
    res = ik_feasibility(mounted, grips, scene, HANDX, WORLDZ, mesh, OPTS, workers=1, progress=False)
    assert res.feasible[:, 0].any()
    far = robot_from_urdf(urdf, "tool0", mount=mount, base=pose_xyz_yaw(2.5, 0.0, 0.0, 0.0), name="ur5_far")
    assert "out of reach" in diagnose_unreachable(far, grips, scene, mesh, OPTS)


def test_load_ik_of_one_tabletop_grid_when_the_store_holds_two(tmp_path, panda):
    """Two tabletop grids of one object, IK for both: each run's rows are exactly its grid's grips (counted with
    DuckDB directly), and without the grid filter the object's rows are both runs'."""
    with Store(tmp_path / "two.duckdb") as store:
        runs = []
        for xs in (np.array([0.45]), np.array([0.5, 0.6])):
            oid, pid = synthetic_store(store, "box", **{**SMALL, "xs": xs})
            runs.append(run_ik(store, "box", panda, None, HANDX, WORLDZ, OPTS, workers=1, progress=False, idtabletop=pid))
        assert runs[0].idrobot == runs[1].idrobot and runs[0].idtabletop != runs[1].idtabletop
        for run in runs:
            rows = sql.load_ik(store, run.idrobot, run.idscene, run.idikret, oid, run.idtabletop)
            n = store.con.execute("SELECT count(*) FROM tabletopgrips JOIN tabletopplacements USING (idtabletopplacements) "
                                  "WHERE idparamset = ?", [run.idtabletop]).fetchone()[0]
            assert len(rows["idik"]) == run.grips == n > 0
        both = sql.load_ik(store, runs[0].idrobot, runs[0].idscene, runs[0].idikret, oid)
        assert len(both["idik"]) == runs[0].grips + runs[1].grips


def test_rows_depend_on_the_grip_alone_not_on_chunks_workers_or_order(panda):
    """The numerical solver's rows are the same, bit for bit, whatever the chunk size, the number of worker processes
    (forkserver workers building the solver once) or the order of the grips: each grip is solved from its own seeds
    (the library poses nearest to it, restarts hashed from its pose)."""
    grips, mesh, _ = synthetic_grips(**{**SMALL, "angles": 2})
    scene = default_scene("panda")
    base = ik_feasibility(panda, grips, scene, HANDX, WORLDZ, mesh, OPTS, workers=1, progress=False)
    assert base.feasible.any() and not base.feasible.all()
    flip = {k: v[::-1] for k, v in grips.items()}
    for opts, workers, g in ((replace(OPTS, chunk=7), 2, grips), (replace(OPTS, chunk=10_000), 1, flip)):
        res = ik_feasibility(panda, g, scene, HANDX, WORLDZ, mesh, opts, workers=workers, progress=False)
        feas, joints = (res.feasible[::-1], res.joints[::-1]) if g is flip else (res.feasible, res.joints)
        assert np.array_equal(feas, base.feasible)
        assert np.array_equal(joints, base.joints, equal_nan=True)
    assert OPTS.as_dict() == replace(OPTS, chunk=7).as_dict()  # the chunk is not part of the rows' parameters


def test_closed_form_stores_the_free_branch_nearest_home_and_finds_what_the_numerical_solver_finds():
    """The UR5 by default gets its closed form: each stored grasp configuration is the branch nearest the robot's
    home among the collision-free ones (every nearer branch collides, by the same collider), the other branches stay
    available (the solver returns the one nearest any seed), and it finds every grip the numerical solver finds."""
    from workbench.robots.ik import IKSolver
    from workbench.robots.solvers import closed_form

    ur5 = get_robot("ur5")
    grips, mesh, _ = synthetic_grips(**{**SMALL, "angles": 2})
    scene = default_scene("ur5")
    closed = ik_feasibility(ur5, grips, scene, HANDX, WORLDZ, mesh, IKOptions(chunk=32), workers=1, progress=False)
    numeric = ik_feasibility(ur5, grips, scene, HANDX, WORLDZ, mesh, OPTS, workers=1, progress=False)
    assert closed.feasible[:, 0].sum() > 10
    assert not (numeric.feasible & ~closed.feasible).any()
    rows = np.flatnonzero(closed.feasible[:, 0])
    stored = closed.joints[rows, 0]
    joints, valid = closed_form(ur5).solve(grips["rotmat"][rows])
    home = ur5.home()
    turns = 2 * np.pi * np.round((home - joints) / (2 * np.pi))
    joints = np.where((joints + turns >= ur5.lower) & (joints + turns <= ur5.upper), joints + turns, joints)
    dist = np.where(valid, np.abs(np.nan_to_num(joints - home)).sum(axis=2), np.inf)
    mine = np.abs(stored - home).sum(axis=1)
    assert (dist.min(axis=1) <= mine + 1e-9).all()
    solver = IKSolver(ur5, scene, IKOptions(), mesh)
    nearer = np.argwhere(dist < mine[:, None] - 1e-9)
    # the branches nearer home (often none) were rejected by a collision
    hit = solver.collider.collides_q(joints[nearer[:, 0], nearer[:, 1]], grips["placement_rotmat"][rows[nearer[:, 0]]])
    assert hit.all()
    other = np.argwhere(valid & (dist > mine[:, None] + 1e-6))
    free = ~solver.collider.collides_q(joints[other[:, 0], other[:, 1]], grips["placement_rotmat"][rows[other[:, 0]]])
    assert free.any()  # another collision-free branch exists: query-time IK seeded near it gets it, not the stored one
    r, b = other[np.argmax(free)]
    q, ok = solver.solve(grips["rotmat"][rows[r]][None], grips["placement_rotmat"][rows[r]][None], joints[r, b][None], 1)
    assert ok[0] and np.allclose(q[0], joints[r, b]) and not np.allclose(q[0], stored[r])


def _nearest_turn(q: np.ndarray, ref: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Whether each joint of `q` (M, n) is, among its whole-turn equivalents within the limits, the one nearest `ref`."""
    cand = q[..., None] + 2 * np.pi * np.arange(-3, 4)
    inside = (cand >= lower[:, None]) & (cand <= upper[:, None])
    best = np.where(inside, np.abs(cand - np.asarray(ref)[..., None]), np.inf).min(axis=-1)
    return np.abs(q - ref) <= best + 1e-9


def test_numerical_solutions_take_the_whole_turns_nearest_home_and_their_neighbours():
    """A joint spanning more than a turn (the UR5's, +-2 pi) reaches each pose at angles a turn apart. Solved
    numerically from seeds far from home, the stored grasp takes the equivalent nearest the robot's home on every
    joint, and every retraction and lift the one nearest its neighbour's on the way, so that no motion swings a joint
    round a whole turn; the poses are unchanged (pinocchio forward kinematics of the stored joints)."""
    ur5 = get_robot("ur5")
    grips, mesh, _ = synthetic_grips(**{**SMALL, "angles": 2})
    res = ik_feasibility(ur5, grips, default_scene("ur5"), HANDX, WORLDZ, mesh, OPTS, workers=1, progress=False)
    rows = np.flatnonzero(res.feasible.all(axis=1))
    assert len(rows) > 10
    q = res.joints[rows]
    assert _nearest_turn(q[:, 0], ur5.home(), ur5.lower, ur5.upper).all()
    for k, prev in ((1, 0), (2, 1), (3, 0), (4, 3)):
        assert _nearest_turn(q[:, k], q[:, prev], ur5.lower, ur5.upper).all()
    # the same TCP poses as asked: the stored grasp joints through pinocchio against the grips' world TCP poses
    model, data = ur5.model, ur5.model.createData()
    for r, qq in zip(rows[:20], q[:20, 0]):
        pin.framesForwardKinematics(model, data, qq)
        tcp = ur5.base @ data.oMf[ur5.tcp_id].homogeneous
        assert np.allclose(tcp, grips["rotmat"][r], atol=2e-4)
