"""The Franka hand model against pinocchio's own FK; store failure modes; the command line's one-line errors."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from workbench.cli.main import main
from workbench.errors import GripperError, StoreError
from workbench.resources import erd_robots, erd_share
from workbench.robots.gripper import gripper_from_urdf, parametric_gripper
from workbench.store import Store


def test_franka_tcp_and_pads_match_the_urdf(hand):
    """Pads at opening w sit at y = +/- w/2 around the TCP, as pinocchio's FK of panda.urdf says."""
    urdf = str(erd_robots() / "panda_description" / "urdf" / "panda.urdf")
    model = pin.buildModelFromUrdf(urdf)
    geom = pin.buildGeomFromUrdf(model, urdf, pin.COLLISION, package_dirs=[str(erd_share())])
    data, gdata = model.createData(), geom.createData()
    q = pin.neutral(model)
    q[model.joints[model.getJointId("panda_finger_joint1")].idx_q] = 0.03
    q[model.joints[model.getJointId("panda_finger_joint2")].idx_q] = 0.03
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    pin.updateGeometryPlacements(model, data, geom, gdata)
    tcp = data.oMf[model.getFrameId("panda_hand_tcp")]
    hand_frame = data.oMf[model.getFrameId("panda_hand")]
    assert np.allclose(hand_frame.actInv(tcp.translation), [0, 0, 0.1034])
    tips = [k for k, g in enumerate(geom.geometryObjects) if g.name in ("panda_leftfinger_3", "panda_rightfinger_3")]
    inner = []
    for k in tips:
        centre = tcp.actInv(gdata.oMg[k].translation)
        half = geom.geometryObjects[k].geometry.halfSide
        inner.append(centre[1] - np.sign(centre[1]) * half[1])
        assert abs(centre[2]) < 1e-3  # pad centres at the TCP's height
    width = inner[0] - inner[1]
    assert abs(width - 0.06) < 1e-4
    # our model: with the pads `width` apart, the left pad's inner face is at +width/2
    left = [(e, p) for e, p in hand.finger_poses(width)][2 * hand.pad]
    assert np.isclose(left[1][1, 3] - left[0][1] / 2, width / 2, atol=1e-9)
    assert np.isclose(hand.jaw_max, 0.08, atol=1e-4) and hand.jaw_min == 0.0


def test_hand_body_is_behind_the_tcp(hand):
    assert hand.body.bounds[1, 2] < -0.03  # the palm is more than 3 cm behind the fingertips' centre
    mesh = hand.collision_mesh(0.04)
    assert mesh.bounds[1, 2] > 0.005  # fingertips reach past the TCP


def test_bad_gripper_inputs(tmp_path):
    with pytest.raises(GripperError, match="does not exist"):
        gripper_from_urdf(tmp_path / "none.urdf", "hand", "tcp", ("a", "b"))
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/>")
    with pytest.raises(GripperError):
        gripper_from_urdf(bad, "a", "tcp", ("j1", "j2"))
    urdf = erd_robots() / "panda_description" / "urdf" / "panda.urdf"
    with pytest.raises(GripperError, match="no TCP frame"):
        gripper_from_urdf(urdf, "panda_hand", "not_a_frame", ("panda_finger_joint1", "panda_finger_joint2"))
    with pytest.raises(GripperError, match="moves the hand link"):
        gripper_from_urdf(urdf, "panda_hand", "panda_hand_tcp", ("panda_joint7", "panda_finger_joint2"))
    with pytest.raises(GripperError):
        parametric_gripper(jaw_range=(0.05, 0.01))


def test_store_refuses_damaged_and_folder(tmp_path):
    damaged = tmp_path / "damaged.duckdb"
    damaged.write_bytes(b"this is not a database" * 100)
    with pytest.raises(StoreError, match="not a DuckDB database"):
        Store(damaged)
    assert damaged.read_bytes() == b"this is not a database" * 100  # untouched
    with pytest.raises(StoreError, match="folder"):
        Store(tmp_path)
    with pytest.raises(StoreError, match="does not exist"):
        Store(tmp_path / "missing.duckdb", read_only=True)


def test_store_refuses_when_locked_by_another_process(tmp_path):
    db = tmp_path / "locked.duckdb"
    Store(db).close()
    holder = subprocess.Popen([sys.executable, "-c", f"import duckdb, sys, time; c = duckdb.connect({str(db)!r}); "
                               "print('ready', flush=True); time.sleep(30)"], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "ready"
        with pytest.raises(StoreError, match="locked"):
            Store(db)
    finally:
        holder.kill()
        holder.wait()
    Store(db).close()  # usable again once released


def test_transaction_rolls_back_on_error(tmp_path):
    with Store(tmp_path / "t.duckdb") as store:
        with pytest.raises(RuntimeError):
            with store.transaction():
                store.run("INSERT INTO angle (idangle, value) VALUES (1, 0.5)")
                raise RuntimeError("interrupted")
        assert store.one("SELECT count(*) FROM angle")[0] == 0


def test_cli_bad_input_is_one_line_and_status_2(tmp_path, capsys):
    empty = tmp_path / "empty.stl"
    empty.write_bytes(b"")
    assert main(["grasps", str(empty), "--db", str(tmp_path / "x.duckdb")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "empty" in err[0]
    big = tmp_path / "big.stl"
    trimesh.creation.box((60.0, 40.0, 30.0)).export(big)
    assert main(["grasps", str(big), "--db", str(tmp_path / "x.duckdb")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--units mm (60 mm across)" in err[0]
    assert main(["placements", "--db", str(tmp_path / "x.duckdb"), "--object", "nothing"]) == 2
    assert "does not exist" in capsys.readouterr().err  # refused meshes never created the store; reading creates none
    assert not (tmp_path / "x.duckdb").exists()
    Store(tmp_path / "x.duckdb").close()
    assert main(["placements", "--db", str(tmp_path / "x.duckdb"), "--object", "nothing"]) == 2
    assert "no object 'nothing'" in capsys.readouterr().err
    assert main(["grasps", str(big), "--db", str(tmp_path / "x.duckdb"), "--rotations", "many"]) == 2
    assert "--rotations" in capsys.readouterr().err


def test_cli_grasps_then_placements(tmp_path, capsys):
    mesh = tmp_path / "block.stl"
    trimesh.creation.box((0.05, 0.04, 0.03)).export(mesh)
    db = str(tmp_path / "c.duckdb")
    assert main(["grasps", str(mesh), "--db", db]) == 0
    first = capsys.readouterr().out
    assert "stored" in first
    assert main(["grasps", str(mesh), "--db", db]) == 0
    assert "reused" in capsys.readouterr().out
    assert main(["placements", "--db", db, "--object", "block", "--x", "0.4,0.5,2", "--y", "0,0,1", "--angles", "2"]) == 0
    out = capsys.readouterr().out
    assert "6 stable placements" in out and "24 tabletop placements" in out


def test_consumers_take_the_parameter_set_used_last_not_the_highest_id(tmp_path, box, hand):
    """grasps A, then B, then A again (reused): the next stage consumes A, and so do its consumers."""
    from workbench.grasping.grasps import GraspParams
    from workbench.planners.wan_harada.stages import ensure_grasps
    from workbench.store.grasps import latest_grasp_paramset

    db = tmp_path / "chain.duckdb"
    a, b = GraspParams(rotations=4), GraspParams(rotations=6)
    ra = ensure_grasps(db, box, hand, a)
    rb = ensure_grasps(db, box, hand, b)
    again = ensure_grasps(db, box, hand, a)
    assert again.reused and again.idparamset == ra.idparamset and rb.idparamset > ra.idparamset
    with Store(db) as store:
        assert latest_grasp_paramset(store, ra.idobject) == ra.idparamset


def test_transactions_nest_by_joining_the_outermost(tmp_path):
    """A writer called inside another's transaction joins it: one commit, and an error anywhere rolls back all."""
    with Store(tmp_path / "nest.duckdb") as store:
        with store.transaction():
            store.run("INSERT INTO angle (idangle, value) VALUES (1, 0.5)")
            with store.transaction():  # e.g. put_gripper inside save_grasps
                store.run("INSERT INTO angle (idangle, value) VALUES (2, 1.0)")
        assert store.one("SELECT count(*) FROM angle")[0] == 2
        with pytest.raises(RuntimeError):
            with store.transaction():
                store.run("INSERT INTO angle (idangle, value) VALUES (3, 1.5)")
                with store.transaction():
                    store.run("INSERT INTO angle (idangle, value) VALUES (4, 2.0)")
                    raise RuntimeError("stage failed")
        assert store.one("SELECT count(*) FROM angle")[0] == 2
        with store.transaction():  # the store is usable again
            store.run("INSERT INTO angle (idangle, value) VALUES (5, 2.5)")
        assert store.one("SELECT count(*) FROM angle")[0] == 3
