"""The plan validator (independent of the planner's kinematics and collision code) on `workbench demo`'s plan:
it accepts the plan and rejects corrupted joint vectors, swapped grasps, unstable placements and wrong goals."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.planners.wan_harada.plans import Plan
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.stages import load_planner


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    assert main(["demo", "--out", str(out), "--workers", "2"]) == 0
    return out


@pytest.fixture(scope="module")
def planner(demo):
    return load_planner(demo / "regrasp.duckdb", "tube", "panda")


@pytest.fixture(scope="module")
def plan(demo):
    return Plan.from_dict(json.loads((demo / "plan.json").read_text())["plan"])


def test_demo_writes_a_plan_with_a_regrasp_that_validates(demo, plan, planner):
    assert (demo / "plan.html").stat().st_size > 10_000
    assert "set_animation" in (demo / "plan.html").read_text()[:5_000_000]
    assert plan.regrasps >= 1 and plan.transfers == plan.regrasps + 1
    report = planner.validate(plan)
    assert report.ok, report.errors
    assert report.checks > 20
    # the alternatives written beside it validate too
    for alt in json.loads((demo / "plan.json").read_text())["alternatives"]:
        assert planner.validate(Plan.from_dict(alt)).ok


def _errors(plan, planner):
    report = planner.validate(plan)
    assert not report.ok
    return " | ".join(report.errors)


def test_rejects_a_corrupted_joint_vector(plan, planner):
    bad = copy.deepcopy(plan)
    bad.steps[1].q_grasp[3] += 0.3
    assert "grasp configuration reaches a TCP" in _errors(bad, planner)
    bad = copy.deepcopy(plan)
    bad.steps[0].q_retract[:] = np.nan
    assert "retract joint vector is missing" in _errors(bad, planner)
    bad = copy.deepcopy(plan)
    v = planner.validator
    bad.steps[-1].q_approach[0] = v.upper[0] + 0.2
    assert "outside their limits" in _errors(bad, planner)


def test_rejects_a_swapped_grasp(plan, planner):
    """The transfer step carries another grasp than the one picked (consistent joints, TCP and grasp of its own)."""
    bad = copy.deepcopy(plan)
    other = bad.steps[2]  # the regrasp: same placement, another grasp
    t = bad.steps[1]
    t.idfreeairgrip, t.grasp, t.tcp, t.jawwidth = other.idfreeairgrip, other.grasp.copy(), other.tcp.copy(), other.jawwidth
    t.q_approach, t.q_grasp, t.q_retract = other.q_approach.copy(), other.q_grasp.copy(), other.q_retract.copy()
    t.q_worlda, t.q_worldaworldz = other.q_worlda.copy(), other.q_worldaworldz.copy()
    errors = _errors(bad, planner)
    assert "the grasp changes along the transfer" in errors
    assert "moves in the hand" in errors
    assert "reaches a TCP" not in errors  # the swapped step is consistent in itself


def test_rejects_an_unstable_placement(plan, planner):
    bad = copy.deepcopy(plan)
    t, r = bad.steps[1], bad.steps[2]
    c, s = np.cos(0.6), np.sin(0.6)
    tilt = np.eye(4)
    tilt[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    pose = tilt @ t.object_pose
    low = (planner.object.mesh.vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].min()
    pose[2, 3] -= low  # resting on an edge or a corner
    for step in (t, r):
        step.object_pose = pose
        step.tcp = pose @ step.grasp
    assert "is not a stable placement" in _errors(bad, planner)


def test_rejects_a_plan_that_misses_the_goal(plan, planner):
    bad = copy.deepcopy(plan)
    g = bad.goal
    bad.goal = PoseQuery(g.idfreetabletopplacement, g.x + 0.05, g.y, g.yaw)
    assert "goal" in _errors(bad, planner)
    bad = copy.deepcopy(plan)
    bad.steps = bad.steps[:-2] + bad.steps[-1:]
    assert "step sequence" in _errors(bad, planner)


def test_stability_check_uses_the_hull(planner):
    v = planner.validator
    for pose in planner.free["rotmat"]:
        ok, why = v.stability(PoseQuery(0, 0.5, 0.1, 0.7).move() @ pose)
        assert ok, why
    up = planner.free["rotmat"][0].copy()
    up[2, 3] += 0.01
    assert "not on the table" in v.stability(up)[1]


def test_collision_check_agrees_with_the_planner_collider(planner):
    """Own fcl objects from the URDF against the kinematics module's collider on random configurations."""
    v = planner.validator
    robot = planner.robot
    rng = np.random.default_rng(0)
    q = rng.uniform(robot.lower, robot.upper, size=(150, robot.nq))
    place = np.repeat((PoseQuery(int(planner.placement_ids()[0]), 0.5, 0.0, 0.0).move() @ planner.free["rotmat"][0])[None], len(q), 0)
    lib = planner.ik.solver.collider.collides_q(q, place)
    own = np.array([bool(v.collisions(qi, place[0])) for qi in q])
    assert lib.any() and (~lib).any()
    assert (lib == own).mean() >= 0.99
    # and forward kinematics from the URDF text agrees with the library's
    for qi in q[:10]:
        assert np.allclose(v.fk(qi), robot.tcp_pose(qi), atol=1e-9)
