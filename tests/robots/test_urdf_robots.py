"""A robot the user brings as a URDF: continuous joints, its own hand past the tip, a joint named like a link, meshes
in a ROS package, the same robot stored again with another mount; then `build` and `plan` on it end to end, checked
with pinocchio and coal on the stored robot row only."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import coal
import duckdb
import numpy as np
import pinocchio as pin
import pytest

from workbench.errors import RobotError
from workbench.resources import erd_robots
from workbench.robots.model import get_robot, prepare_urdf

KINOVA = erd_robots() / "kinova_description" / "robots" / "kinova.urdf"
KINOVA_TIP = "j2s6s200_end_effector"
FLANGE = "0,0,0.1034,0,0,0"  # the Franka hand's TCP 103.4 mm out along the flange's z


def _cli(*args, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=900)


def test_prepare_urdf_bounds_continuous_joints_drops_the_own_hand_and_renames_clashes():
    text = """<robot name="r">
      <link name="base"/><link name="a"/><link name="tool"/><link name="finger"/><link name="finger_tip"/>
      <joint name="j1" type="continuous"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/>
        <limit effort="10" velocity="1.5"/></joint>
      <joint name="tool" type="fixed"><parent link="a"/><child link="tool"/></joint>
      <joint name="f" type="prismatic"><parent link="tool"/><child link="finger"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>
      <joint name="ft" type="fixed"><parent link="finger"/><child link="finger_tip"/></joint>
    </robot>"""
    out, past, bounded, renamed = prepare_urdf(text, "tool")
    assert bounded == ("j1",)
    assert past == ("finger", "finger_tip")  # the whole subtree past the tip link
    assert renamed == {"tool": "tool_joint"}
    root = ElementTree.fromstring(out)
    j1 = root.find("joint[@name='j1']")
    assert j1.get("type") == "revolute"
    lim = j1.find("limit")
    assert float(lim.get("lower")) == pytest.approx(-2 * np.pi) and float(lim.get("upper")) == pytest.approx(2 * np.pi)
    assert float(lim.get("velocity")) == 1.5  # kept
    model = pin.buildModelFromXML(out)  # independent: one angle per joint, the bounds as written
    assert model.nq == model.nv == 2
    assert model.upperPositionLimit[0] == pytest.approx(2 * np.pi)
    # nothing to change: the text comes back as it was
    plain = "<robot name='p'><link name='a'/></robot>"
    assert prepare_urdf(plain, "a")[0] == plain


def test_a_continuous_joint_without_a_velocity_limit_is_refused_in_one_line(tmp_path):
    urdf = tmp_path / "spin.urdf"
    urdf.write_text("""<robot name="spin"><link name="base"/><link name="a"/>
      <joint name="j1" type="continuous"><parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint></robot>""")
    with pytest.raises(RobotError, match="j1 of robot 'spin' have no velocity limit"):
        get_robot(str(urdf), tip_frame="a")


def test_an_arm_joint_that_mimics_another_is_refused_and_a_mimic_finger_past_the_tip_is_not(tmp_path):
    """Pinocchio reads a <mimic> joint as a joint of its own: an arm with one on its chain to the tip would be planned
    at joint values the coupled arm cannot take, so it is refused in one line naming both joints; a hand's mimic
    finger past the tip (replaced by the planning gripper) loads."""
    def arm(mimic_on: str) -> str:
        joints = []
        for i, (parent, child) in enumerate((("base", "l1"), ("l1", "l2"), ("l2", "tool"), ("tool", "finger"))):
            kind = "prismatic" if child == "finger" else "revolute"
            mimic = '<mimic joint="j0" multiplier="1"/>' if f"j{i}" == mimic_on else ""
            joints.append(f'<joint name="j{i}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                          f'<origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>{mimic}'
                          f'<limit lower="-1" upper="1" effort="10" velocity="1"/></joint>')
        links = "".join(f'<link name="{n}"/>' for n in ("base", "l1", "l2", "tool", "finger"))
        return f'<robot name="m">{links}{"".join(joints)}</robot>'

    coupled = tmp_path / "coupled.urdf"
    coupled.write_text(arm("j2"))
    with pytest.raises(RobotError, match="arm joint 'j2' .*mimics joint 'j0'") as err:
        get_robot(str(coupled), tip_frame="tool")
    assert "\n" not in str(err.value)
    fingers = tmp_path / "fingers.urdf"
    fingers.write_text(arm("j3"))
    robot = get_robot(str(fingers), tip_frame="tool")
    assert robot.nq == 3 and tuple(robot.joint_names) == ("j0", "j1", "j2")


def test_a_urdf_in_a_ros_package_finds_its_meshes_and_the_row_lets_pinocchio_load_them(tmp_path):
    pkg = tmp_path / "ws" / "src" / "my_xarm"
    shutil.copytree(erd_robots() / "xarm_description", pkg)
    urdf = pkg / "urdf" / "xarm7.urdf"
    urdf.write_text(urdf.read_text().replace("package://example-robot-data/robots/xarm_description", "package://my_xarm"))
    robot = get_robot(str(urdf), tip_frame="link_eef")
    assert str(tmp_path / "ws" / "src") in robot.package_dirs
    # the folders the robot row will carry are enough for pinocchio alone
    model = pin.buildModelFromXML(robot.spec.urdf)
    geom = pin.buildGeomFromUrdfString(model, robot.spec.urdf, pin.COLLISION, package_dirs=robot.package_dirs)
    assert geom.ngeoms >= 8
    # outside the package nothing resolves package://my_xarm: a one-line error that says where to point
    alone = tmp_path / "xarm7.urdf"
    alone.write_text(urdf.read_text())
    with pytest.raises(RobotError, match="ROS_PACKAGE_PATH"):
        get_robot(str(alone), tip_frame="link_eef")


def test_a_link_and_a_joint_of_one_name_load_and_the_own_hand_is_found():
    # so100: link "gripper" and joint "gripper"; pinocchio's reduction failed with a traceback before
    so100 = str(erd_robots() / "so_arm_description" / "urdf" / "so100.urdf")
    robot = get_robot(so100, tip_frame="gripper")
    assert robot.joint_names == ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")
    assert robot.spec.drop_geometry == ("jaw",)
    # Panda's own URDF at its flange: the hand and fingers past link8 make way for the planning gripper
    panda = get_robot(str(erd_robots() / "panda_description" / "urdf" / "panda.urdf"), tip_frame="panda_link8")
    assert set(panda.spec.drop_geometry) >= {"panda_hand", "panda_leftfinger", "panda_rightfinger"}
    arm = {panda.model.frames[panda.geom.geometryObjects[k].parentFrame].name for k in panda.arm_geometry()}
    assert "panda_link7" in arm and not any(a.startswith(("panda_hand", "panda_leftfinger", "panda_rightfinger")) for a in arm)
    with pytest.raises(RobotError, match="--hand-links nope match no link"):
        get_robot(so100, tip_frame="gripper", hand_links=("nope",))


@pytest.fixture(scope="module")
def kinova_store(tmp_path_factory):
    """The bundled bracket built for a Kinova Jaco (continuous joints, its own three-finger hand past the tip)."""
    work = tmp_path_factory.mktemp("kinova")
    shutil.copy(Path(__file__).parents[2] / "workbench" / "assets" / "objects" / "bracket.stl", work)
    grid = ["--x=0.4,0.6,3", "--y=-0.15,0.15,3", "--angles", "4"]
    res = _cli("build", "bracket.stl", "--db", "k.duckdb", "--robot", KINOVA, "--tip", KINOVA_TIP, "--mount", FLANGE,
               "--hand-links", "j2s6s200_link_finger", "--workers", "2", *grid, cwd=work)
    assert res.returncode == 0, res.stderr[-3000:]
    return work, res


def test_build_and_plan_on_a_urdf_robot(kinova_store):
    work, res = kinova_store
    assert "continuous joints j2s6s200_joint_1, j2s6s200_joint_4, j2s6s200_joint_6" in res.stderr
    assert "replaces" not in res.stderr  # its fingers hang off the wrist by fixed joints: named with --hand-links
    assert "regrasp graph:" in res.stdout and "IK for kinova" in res.stdout
    ids = res.stdout.split("(PLACEMENT,X,Y,YAW): ")[1].split()[0].strip(",")
    plan = _cli("plan", "--db", "k.duckdb", "--object", "bracket", "--robot", "kinova", "--start", f"{ids},0.45,0.1,0",
                "--goal", f"{ids},0.55,-0.1,90", "--alternatives", "0", cwd=work)
    assert plan.returncode == 0, plan.stderr[-3000:]
    assert "validation: every listed plan passes" in plan.stdout, plan.stdout

    # independent check from the stored rows: pinocchio on the stored URDF with the stored mesh folders
    con = duckdb.connect(str(work / "k.duckdb"), read_only=True)
    urdf, tip, mount, base, names, dirs, drop = con.execute(
        "SELECT urdf, tip_frame, mount, base, joint_names, package_dirs, drop_geometry FROM robot WHERE name = 'kinova'").fetchone()
    model = pin.buildModelFromXML(urdf)
    geom = pin.buildGeomFromUrdfString(model, urdf, pin.COLLISION, package_dirs=list(dirs))
    assert list(drop) == ["j2s6s200_link_finger"]
    mount, base = np.array(mount).reshape(4, 4), np.array(base).reshape(4, 4)
    qi = [model.joints[model.getJointId(n)].idx_q for n in names]
    data = model.createData()
    tipf = model.getFrameId(tip, pin.FrameType.BODY)

    def tcp(q):
        full = pin.neutral(model)
        full[qi] = q
        pin.framesForwardKinematics(model, data, full)
        return base @ data.oMf[tipf].homogeneous @ mount, full

    steps = con.execute("SELECT tcp, jnt_grasp FROM planstep WHERE idplan = 1 ORDER BY seq").fetchall()
    for t, q in steps:
        got, _ = tcp(np.array(q))
        assert np.abs(got[:3, 3] - np.array(t).reshape(4, 4)[:3, 3]).max() < 1e-3

    # every knot: within [-2 pi, 2 pi] on the bounded joints, no arm link below the table top (coal, the stored scene)
    scene = json.loads(con.execute("SELECT params FROM scene s JOIN plan p USING (idscene) WHERE idplan = 1").fetchone()[0])
    lo, hi, th = np.array(scene["table_min"]), np.array(scene["table_max"]), scene["table_thickness"]
    table = coal.Box(hi[0] - lo[0], hi[1] - lo[1], th)
    t_table = coal.Transform3s(np.eye(3), np.array([*(0.5 * (lo + hi)), -th / 2]))
    moving = [k for k, g in enumerate(geom.geometryObjects) if g.parentJoint > 0
              and not any(model.frames[g.parentFrame].name.startswith(d) for d in drop)]
    gdata = geom.createData()
    knots = 0
    for q, in con.execute("SELECT q FROM plansegment WHERE idplan = 1 ORDER BY seq").fetchall():
        for row in np.array(q).reshape(-1, len(names)):
            assert np.abs(row).max() <= 2 * np.pi + 1e-9
            _, full = tcp(row)
            pin.updateGeometryPlacements(model, data, geom, gdata, full)
            for k in moving:
                m = gdata.oMg[k]
                placed = coal.Transform3s(base[:3, :3] @ m.rotation, base[:3, :3] @ m.translation + base[:3, 3])
                req, out = coal.CollisionRequest(), coal.CollisionResult()
                assert coal.collide(geom.geometryObjects[k].geometry, placed, table, t_table, req, out) == 0, \
                    geom.geometryObjects[k].name
            knots += 1
    assert knots > 100


def test_the_same_robot_with_another_mount_is_named_apart_and_plan_says_which_to_use(kinova_store):
    work, _ = kinova_store
    # the same arm and hand with its base 3 m away: nothing is in reach
    res = _cli("ik", "--db", "k.duckdb", "--object", "bracket", "--robot", KINOVA, "--tip", KINOVA_TIP, "--mount", FLANGE,
               "--hand-links", "j2s6s200_link_finger", "--base", "3,0,0,0", "--no-progress", cwd=work)
    assert res.returncode == 0, res.stderr[-3000:]
    stored = res.stdout.split("stored as robot '")[1].split("'")[0]
    assert stored.startswith("kinova-") and f"plan with --robot {stored}" in res.stdout
    plan = _cli("plan", "--db", "k.duckdb", "--object", "bracket", "--robot", stored, "--start", "2,0.45,0.1,0",
                "--goal", "3,0.55,-0.1,90", cwd=work)
    assert plan.returncode == 0, plan.stderr[-3000:]
    assert "plan with --robot kinova" in plan.stderr, plan.stderr


def test_the_motion_benchmark_loads_its_urdf_arms_as_a_user_would():
    from workbench.benchmarks.regrasp import bench_robot
    from workbench.errors import WorkbenchError

    assert bench_robot("panda") == "panda"  # a built-in stays a name
    kinova = bench_robot("kinova")
    assert kinova.spec.urdf_path.endswith("kinova.urdf") and kinova.spec.drop_geometry == ("j2s6s200_link_finger",)
    assert np.allclose(kinova.mount[:3, 3], [0, 0, 0.1034])
    assert 'type="continuous"' not in kinova.spec.urdf  # bounded, as `build` stores it
    with pytest.raises(WorkbenchError, match="unknown robot 'nope'"):
        bench_robot("nope")
