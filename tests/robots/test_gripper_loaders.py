"""Gripper loaders: spec files, URDF grippers (prismatic and a mimic linkage) and a robot's own hand, against
pinocchio's FK and the spec's own numbers; every bad spec refused in one line, exit 2, nothing written."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import yaml

from workbench.cli.main import main
from workbench.errors import GripperError
from workbench.resources import erd_robots, erd_share
from workbench.robots.gripper import BUNDLED, franka_hand, gripper_from_urdf, load_gripper

ROBOTIQ = BUNDLED["robotiq-2f85"]
TIAGO = erd_robots() / "tiago_pro_description" / "robots" / "tiago_pro.urdf"
TIAGO_FINGERS = ("gripper_left_inner_finger_left_joint", "gripper_left_inner_finger_right_joint")


def test_robotiq_spec_geometry_follows_its_fields():
    spec = yaml.safe_load(ROBOTIQ.read_text())
    g = load_gripper("robotiq-2f85")
    assert (g.jaw_min, g.jaw_max) == (0.0, 0.085)
    assert np.allclose(g.tcp_in_hand[:3, 3], spec["tcp"])
    ext, pose = g.finger_boxes[g.pad]
    assert np.allclose(ext, [spec["pad"]["size"][0], spec["pad"]["thickness"], spec["pad"]["size"][1]])
    for width in (0.0, 0.03, 0.085):  # pad inner faces at +/- width / 2 around the TCP, centred on its height
        (_, left), (_, right) = g.finger_poses(width)[2 * g.pad: 2 * g.pad + 2]
        assert np.isclose(left[1, 3] - ext[1] / 2, width / 2) and np.isclose(right[1, 3] + ext[1] / 2, -width / 2)
        assert np.isclose(left[2, 3], 0.0)
    palm_top = spec["palm"]["offset"][2] + spec["palm"]["size"][2] / 2
    assert np.isclose(g.body.bounds[1, 2], palm_top - spec["tcp"][2])  # the palm in the TCP frame
    # every field enters the digest: a spec differing only in mass is another gripper
    assert g.digest != franka_hand().digest


def test_spec_digest_covers_every_field(tmp_path):
    spec = yaml.safe_load(ROBOTIQ.read_text())
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(spec))
    b.write_text(json.dumps({**spec, "mass": 1.5}))
    assert load_gripper(str(a)).digest == load_gripper(str(ROBOTIQ)).digest
    assert load_gripper(str(b)).digest != load_gripper(str(a)).digest


def test_urdf_gripper_matches_pinocchio_fk():
    g = load_gripper("parallel60")
    urdf = str(BUNDLED["parallel60"])
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    q = pin.neutral(model)
    q[:] = 0.02  # both fingers 20 mm out: pads 2 * 20 mm apart (they touch at 0)
    pin.framesForwardKinematics(model, data, q)
    tcp = data.oMf[model.getFrameId("p60_tcp")]
    left = tcp.actInv(data.oMf[model.getFrameId("p60_left_finger")].translation)
    assert np.isclose(left[1], 0.02)  # the finger link's origin is its inner face
    assert (g.jaw_min, g.jaw_max) == pytest.approx((0.0, 0.06))
    assert np.allclose(g.tcp_in_hand[:3, 3], [0, 0, 0.1])


def test_tiago_own_hand_linkage_sampled_along_the_stroke():
    """Tiago Pro's gripper: revolute four-bar fingers driven by one joint; the fingertips stay parallel."""
    g = load_gripper("own", robot_urdf=TIAGO, tip="arm_left_tool_link", finger_joints=TIAGO_FINGERS)
    assert 0.0 <= g.jaw_min < 0.02 and 0.06 < g.jaw_max < 0.1
    # independent: the fingertip links' distance along the jaw axis at both ends of the driver's range
    model = pin.buildModelFromUrdf(str(TIAGO))
    data = model.createData()
    tips = []
    for s in (0.0, 0.8028514559173916):
        q = pin.neutral(model)
        for j in ("gripper_left_finger_joint", "gripper_left_inner_finger_left_joint", "gripper_left_inner_finger_right_joint",
                  "gripper_left_outer_finger_right_joint"):
            q[model.joints[model.getJointId(j)].idx_q] = s
        for j in ("gripper_left_fingertip_left_joint", "gripper_left_fingertip_right_joint"):
            q[model.joints[model.getJointId(j)].idx_q] = -s
        pin.framesForwardKinematics(model, data, q)
        a = data.oMf[model.getFrameId("gripper_left_fingertip_left_link")].translation
        b = data.oMf[model.getFrameId("gripper_left_fingertip_right_link")].translation
        tips.append(np.asarray(a - b))
    axis = tips[1] / np.linalg.norm(tips[1])  # the jaw axis at full opening
    assert abs(abs((tips[1] - tips[0]) @ axis) - (g.jaw_max - g.jaw_min)) < 2e-3


def test_fingers_that_turn_are_refused(tmp_path):
    """Break the linkage (the fingertip no longer counter-rotates): the pads turn, and the model says it cannot."""
    text = TIAGO.read_text().replace('<mimic joint="gripper_left_finger_joint" multiplier="-1" offset="0"/>',
                                     '<mimic joint="gripper_left_finger_joint" multiplier="0" offset="0"/>')
    broken = tmp_path / "tiago_broken.urdf"
    broken.write_text(text)
    with pytest.raises(GripperError, match="stay parallel"):
        gripper_from_urdf(broken, "arm_left_tool_link", None, TIAGO_FINGERS, package_dirs=[str(erd_robots().parent.parent)])


def _spec(tmp_path, name="bad.yaml", **change):
    spec = yaml.safe_load(ROBOTIQ.read_text())
    for key, value in change.items():
        cur = spec
        *head, last = key.split("__")
        for k in head:
            cur = cur[k]
        if value is None:
            del cur[last]
        else:
            cur[last] = value
    path = tmp_path / name
    path.write_text(yaml.safe_dump(spec))
    return path


BAD = [
    ({"stroke": [0.05, 0.05]}, "'stroke'"),
    ({"pad__thickness": None}, "missing field 'pad.thickness'"),
    ({"finger__size": [0.027, -0.014, 0.06]}, "'finger.size' must be positive"),
    ({"tcp": [0.0, 0.0, 0.05]}, "outside the hand"),
    ({"tcp": [0.2, 0.0, 0.15]}, "outside the hand"),
    # lengths written in millimetres
    ({"stroke": [0, 85]}, "'stroke' reaches 85 m, implausible for a gripper"),
    ({"pad__thickness": 5}, "divide millimetres by 1000"),
]


@pytest.mark.parametrize("change,words", BAD)
def test_bad_spec_exits_2_in_one_line_and_writes_nothing(tmp_path, capsys, change, words):
    bad = _spec(tmp_path, **change)
    db = tmp_path / "s.duckdb"
    mesh = str(BUNDLED["parallel60"].parents[1] / "objects" / "tube.stl")
    assert main(["grasps", mesh, "--db", str(db), "--gripper", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0] and str(bad) in err[0]
    assert not db.exists()


def test_bad_urdf_gripper_exits_2(tmp_path, capsys):
    mesh = str(BUNDLED["parallel60"].parents[1] / "objects" / "tube.stl")
    db = tmp_path / "u.duckdb"
    urdf = str(BUNDLED["parallel60"])
    cases = [(["--gripper-hand", "nope"], "no hand link 'nope'"),
             (["--gripper-fingers", "p60_left_joint,missing_joint"], "no finger joint 'missing_joint'"),
             (["--gripper-tcp", "nowhere"], "no TCP frame 'nowhere'")]
    for extra, words in cases:
        assert main(["grasps", mesh, "--db", str(db), "--gripper", urdf, *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0] and "parallel60.urdf" in err[0]
    # a TCP frame beyond the fingertips
    far = tmp_path / "far.urdf"
    far.write_text(BUNDLED["parallel60"].read_text().replace('<origin xyz="0 0 0.1"/>', '<origin xyz="0 0 0.3"/>'))
    assert main(["grasps", mesh, "--db", str(db), "--gripper", str(far), "--gripper-hand", "p60_hand",
                 "--gripper-fingers", "p60_left_joint,p60_right_joint", "--gripper-tcp", "p60_tcp"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "far.urdf" in err[0] and "outside the hand" in err[0]
    # the fingers closing along two different axes
    skew = tmp_path / "skew.urdf"
    skew.write_text(BUNDLED["parallel60"].read_text().replace('<axis xyz="0 -1 0"/>', '<axis xyz="0 -1 1"/>').replace(
        '<mimic joint="p60_left_joint"/>', ""))
    assert main(["grasps", mesh, "--db", str(db), "--gripper", str(skew), "--gripper-hand", "p60_hand",
                 "--gripper-fingers", "p60_left_joint,p60_right_joint", "--gripper-tcp", "p60_tcp"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "skew.urdf" in err[0]
    assert not db.exists()


def test_tiago_finger_boxes_hold_its_links_along_the_stroke():
    """At three openings, every vertex of the left finger's links (pinocchio FK of the URDF and its meshes) lies in
    the boxes `finger_poses` gives at that opening: the linkage's bars turn, and the boxes follow them."""
    import trimesh

    g = load_gripper("own", robot_urdf=TIAGO, tip="arm_left_tool_link", finger_joints=TIAGO_FINGERS)
    model = pin.buildModelFromUrdf(str(TIAGO))
    geom = pin.buildGeomFromUrdf(model, str(TIAGO), pin.COLLISION, package_dirs=[str(erd_robots().parent.parent)])
    data, gdata = model.createData(), geom.createData()
    upper = 0.8028514559173916
    links = ("gripper_left_inner_finger_left_link", "gripper_left_outer_finger_left_link", "gripper_left_fingertip_left_link")
    for i in (0, 20, 40):
        s = i / 40 * upper
        q = pin.neutral(model)
        for j in ("gripper_left_finger_joint", "gripper_left_inner_finger_left_joint", "gripper_left_inner_finger_right_joint",
                  "gripper_left_outer_finger_right_joint"):
            q[model.joints[model.getJointId(j)].idx_q] = s
        for j in ("gripper_left_fingertip_left_joint", "gripper_left_fingertip_right_joint"):
            q[model.joints[model.getJointId(j)].idx_q] = -s
        pin.framesForwardKinematics(model, data, q)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        tcp = np.asarray(data.oMf[model.getFrameId("arm_left_tool_link")].homogeneous) @ g.tcp_in_hand
        boxes = [(e, p) for e, p in g.finger_poses(float(g.stroke[0][i])) if p[1, 3] > 0]
        for k, go in enumerate(geom.geometryObjects):
            if model.frames[go.parentFrame].name not in links:
                continue
            v = np.asarray(trimesh.load(go.meshPath, force="mesh").vertices) * np.asarray(go.meshScale)
            world = v @ np.asarray(gdata.oMg[k].rotation).T + np.asarray(gdata.oMg[k].translation)
            local = (np.linalg.inv(tcp) @ np.c_[world, np.ones(len(world))].T).T[:, :3]
            inside = np.zeros(len(local), dtype=bool)
            for ext, pose in boxes:
                rel = (np.linalg.inv(pose) @ np.c_[local, np.ones(len(local))].T).T[:, :3]
                inside |= (np.abs(rel) <= ext / 2 + 1e-6).all(axis=1)
            assert inside.all(), (go.name, i, int((~inside).sum()))


@pytest.mark.parametrize("name", ["panda", "ur5", "puma560"])
def test_another_gripper_on_a_builtin_robot_sits_where_the_franka_hand_does(name):
    """The Robotiq-like spec's hand frame (its TCP less its offset) is the Franka hand's, at any joint vector."""
    from workbench.robots.model import get_robot

    robotiq = load_gripper("robotiq-2f85")
    a, b = get_robot(name), get_robot(name, gripper=robotiq)
    assert b.gripper.digest == robotiq.digest and a.spec.digest != b.spec.digest
    q = np.random.default_rng(0).uniform(a.lower, a.upper)
    hand_a = a.tcp_pose(q) @ np.linalg.inv(franka_hand().tcp_in_hand)
    hand_b = b.tcp_pose(q) @ np.linalg.inv(robotiq.tcp_in_hand)
    assert np.allclose(hand_a, hand_b, atol=1e-9)


def test_franka_hand_visuals_are_those_of_a_full_parse_without_the_arms_meshes():
    """The arm's visual meshes are not read; the hand's and fingers' visuals are pinocchio's full parse's, in order,
    at the same poses relative to the hand."""
    urdf = erd_robots() / "panda_description" / "urdf" / "panda.urdf"
    model = pin.buildModelFromUrdf(str(urdf))
    vis = pin.buildGeomFromUrdf(model, str(urdf), pin.VISUAL, package_dirs=[str(erd_share())])
    data, vdata = model.createData(), vis.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    pin.updateGeometryPlacements(model, data, vis, vdata)
    hand_frame = model.getFrameId("panda_hand")
    mine = [o for o in vis.geometryObjects if model.frames[o.parentFrame].name in
            ("panda_hand", "panda_leftfinger", "panda_rightfinger")]
    got = franka_hand().visuals
    assert [v.path for v in got] == [o.meshPath for o in mine] and len(got) == 3
    hand = data.oMf[hand_frame].homogeneous
    body = [k for k, o in enumerate(vis.geometryObjects) if model.frames[o.parentFrame].name == "panda_hand"][0]
    rel = np.linalg.inv(hand) @ vdata.oMg[body].homogeneous   # the body's visual in the hand frame, from pinocchio
    assert np.allclose(franka_hand().tcp_in_hand @ got[0].pose, rel, atol=1e-9)
