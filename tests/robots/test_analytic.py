"""Closed-form IK of spherical-wrist arms (Tournassoud et al. 1987, Section 5.2) checked against pinocchio's FK.

Every branch returned for a pose must reproduce that pose through pinocchio's forward kinematics on the URDF, and
the configuration the pose came from must be one of the 8 branches.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from workbench.benchmarks.ik import synthetic_grips
from workbench.errors import RobotError
from workbench.robots.analytic import (
    analytic_ik,
    nearest_branch,
    solve,
    spherical_wrist_reason,
)
from workbench.robots.collider import default_scene
from workbench.robots.ik import IKOptions, ik_feasibility
from workbench.robots.model import get_robot


@pytest.fixture(scope="module")
def puma():
    return get_robot("puma560")


def _fk(robot, qs: np.ndarray) -> np.ndarray:
    """TCP poses of joint vectors with pinocchio on the URDF text (not the solver's chain description)."""
    model = pin.buildModelFromXML(robot.spec.urdf)
    data = model.createData()
    fid = model.getFrameId("panda_hand_tcp")
    idx = [model.joints[model.getJointId(n)].idx_q for n in robot.joint_names]
    out = []
    for q in qs:
        full = pin.neutral(model)
        full[idx] = q
        pin.framesForwardKinematics(model, data, full)
        out.append(robot.base @ np.asarray(data.oMf[fid].homogeneous))
    return np.array(out)


def test_puma_has_spherical_wrist_others_not(puma):
    assert spherical_wrist_reason(puma) == ""
    assert "joints" in spherical_wrist_reason(get_robot("panda"))
    assert "spherical wrist" in spherical_wrist_reason(get_robot("ur5"))
    with pytest.raises(RobotError, match="no closed-form IK"):
        analytic_ik(get_robot("ur5"))


def test_eight_branches_reproduce_fk(puma):
    rng = np.random.default_rng(7)
    qs = rng.uniform(puma.lower, puma.upper, size=(1000, 6))
    poses = _fk(puma, qs)
    joints, valid = solve(analytic_ik(puma, limits=False), poses)
    assert joints.shape == (1000, 8, 6)
    assert valid.all()
    back = _fk(puma, joints.reshape(-1, 6)).reshape(1000, 8, 4, 4)
    assert np.abs(back - poses[:, None]).max() < 1e-9
    # the 8 branches are distinct and one of them is the configuration the pose came from
    diff = np.abs(np.angle(np.exp(1j * (joints - qs[:, None])))).max(axis=2)
    assert diff.min(axis=1).max() < 1e-9
    dist = np.abs(joints[:, :, None] - joints[:, None, :]).max(axis=3) + np.eye(8) * 10
    assert (dist.min(axis=(1, 2)) > 1e-6).mean() > 0.99


def test_joint_limits_applied(puma):
    rng = np.random.default_rng(3)
    qs = rng.uniform(puma.lower, puma.upper, size=(300, 6))
    joints, valid = solve(analytic_ik(puma), _fk(puma, qs))
    ok = joints[valid]
    assert ((ok >= puma.lower - 1e-12) & (ok <= puma.upper + 1e-12)).all()
    assert valid.any(axis=1).all()  # the generating configuration is within limits
    near, found = nearest_branch(joints, valid, qs, puma.lower, puma.upper)
    assert found.all() and np.abs(near - qs).max() < 1e-8
    # a pose out of reach has no branch
    far = np.eye(4)
    far[:3, 3] = (3.0, 0, 0.5)
    assert not solve(analytic_ik(puma), far[None])[1].any()


def test_roadmap_ik_stage_closed_form_option(puma):
    """The roadmap planner's IK stage with the closed form: every stored vector reproduces its target through pinocchio,
    and it finds at least every grip the numerical solver finds (the closed form is complete)."""
    grips, mesh, _ = synthetic_grips(xs=np.array([0.4, 0.55]), ys=np.array([-0.15, 0.15]), angles=4, approaches=4, offsets=1)
    scene = default_scene("puma560")
    closed = ik_feasibility(puma, grips, scene, 0.05, 0.05, mesh, IKOptions(chunk=64), workers=1, progress=False)
    numeric = ik_feasibility(puma, grips, scene, 0.05, 0.05, mesh, IKOptions(chunk=64, library=4096, solver="numerical"), workers=1,
                             progress=False)
    assert closed.feasible.any()
    assert not (numeric.feasible & ~closed.feasible).any()
    targets = grips["rotmat"]
    back = targets.copy()
    back[:, :3, 3] -= 0.05 * targets[:, :3, 2]
    up = back.copy()
    up[:, 2, 3] += 0.05
    for k, t in enumerate((targets, back, up)):
        rows = np.flatnonzero(closed.feasible[:, k])
        fk = _fk(puma, closed.joints[rows, k])
        assert np.abs(fk - t[rows]).max() < 1e-9


@pytest.mark.parametrize("limits", [True, False])
def test_reachable_agrees_with_the_branches(puma, limits):
    """The table's validity-only pass (no joint values, the last joint skipped when it spans a full turn) says
    "reachable" exactly where some full branch is valid, on poses in and out of reach, in and out of the limits;
    blocks of any size give the same answer."""
    from workbench.robots.analytic import reachable

    ik = analytic_ik(puma, limits=limits)
    rng = np.random.default_rng(5)
    q = rng.uniform(puma.lower - 0.5, puma.upper + 0.5, size=(300, 6))    # some outside the limits
    poses = _fk(puma, q)
    far = poses[:100].copy()
    far[:, :3, 3] *= rng.uniform(0.2, 3.0, size=(100, 1))                # many out of reach
    poses = np.concatenate([poses, far])
    expect = solve(ik, poses)[1].any(axis=1)
    assert 0 < expect.sum() < len(poses) or not limits
    assert np.array_equal(reachable(ik, poses), expect)
    assert np.array_equal(reachable(ik, poses, block=37), expect)


def test_the_puma_upper_arm_swings_beside_its_column():
    """The shipped PUMA 560's upper arm carries the DH offset d3 at the shoulder, so over its whole joint range it
    never meets the pedestal or the column (checked with pinocchio + coal on the URDF file alone)."""
    from workbench.robots.model import PUMA560_URDF

    model = pin.buildModelFromUrdf(str(PUMA560_URDF))
    from workbench.resources import erd_share

    geom = pin.buildGeomFromUrdf(model, str(PUMA560_URDF), pin.GeometryType.COLLISION, package_dirs=[str(erd_share())])
    link = {g.name: g for g in geom.geometryObjects}
    base = [i for i, g in enumerate(geom.geometryObjects) if model.frames[g.parentFrame].name == "puma_base"]
    upper = [i for i, g in enumerate(geom.geometryObjects) if model.frames[g.parentFrame].name == "puma_link2"]
    assert base and upper and link
    for a in base:
        for b in upper:
            geom.addCollisionPair(pin.CollisionPair(a, b))
    data, gdata = model.createData(), pin.GeometryData(geom)
    rng = np.random.default_rng(0)
    q = rng.uniform(model.lowerPositionLimit, model.upperPositionLimit, (2000, model.nq))
    q[:1000, 1] = np.linspace(model.lowerPositionLimit[1], model.upperPositionLimit[1], 1000)  # the whole swing
    hits = [pin.computeCollisions(model, data, geom, gdata, qi, True) for qi in q]
    assert not any(hits)


def test_puma_limits_and_reach_match_corkes_model():
    """The shipped PUMA 560 has the joint limits of Corke's `mdl_puma560` (qlim, degrees) in its DH frames, so its
    "ready" pose (upper arm and forearm straight up, q = (0, 90, -90, 0, 0, 0) deg) is within them, and over its
    limits the wrist centre reaches sqrt(d3^2 + (a2 + sqrt(a3^2 + d4^2))^2) = 0.877 m from the shoulder (pinocchio
    FK of the URDF file alone, a dense grid of q2 and q3)."""
    from workbench.robots.model import PUMA560_URDF

    corke = np.radians([[-160, 160], [-45, 225], [-225, 45], [-110, 170], [-100, 100], [-266, 266]])
    model = pin.buildModelFromUrdf(str(PUMA560_URDF))
    data = model.createData()
    idx = [model.joints[model.getJointId(f"puma_joint{i}")].idx_q for i in range(1, 7)]
    assert np.allclose(model.lowerPositionLimit[idx], corke[:, 0], atol=1e-12)
    assert np.allclose(model.upperPositionLimit[idx], corke[:, 1], atol=1e-12)
    shoulder_id, wrist_id = model.getJointId("puma_joint1"), model.getJointId("puma_joint5")

    def wrist(q2: float, q3: float) -> tuple[np.ndarray, np.ndarray]:
        q = pin.neutral(model)
        q[idx[1]], q[idx[2]] = q2, q3
        pin.forwardKinematics(model, data, q)
        return np.asarray(data.oMi[wrist_id].translation).copy(), np.asarray(data.oMi[shoulder_id].translation).copy()

    w, o = wrist(np.pi / 2, -np.pi / 2)  # ready: straight up
    assert w[2] - o[2] == pytest.approx(0.4318 + 0.4318, abs=1e-9)
    reach = np.sqrt(0.15005 ** 2 + (0.4318 + np.hypot(0.0203, 0.4318)) ** 2)
    grid = [(a, b) for a in np.linspace(*corke[1], 91) for b in np.linspace(*corke[2], 361)]
    dist = max(np.linalg.norm(np.subtract(*wrist(a, b))) for a, b in grid)
    assert dist == pytest.approx(reach, abs=2e-4) and reach == pytest.approx(0.877, abs=5e-4)
    # the mirrored limits (Lee and Fu's, in other frames) fall short of it: the elbow cannot straighten
    mirrored = max(np.linalg.norm(np.subtract(*wrist(a, b))) for a in np.linspace(*corke[2], 61)
                   for b in np.linspace(*corke[1], 121))
    assert mirrored < reach - 0.03
