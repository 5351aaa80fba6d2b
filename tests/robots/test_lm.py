"""The compiled Levenberg-Marquardt solve (`chain.solve_ik`): solutions checked by pinocchio's FK on the robot's URDF
(not through workbench.robots' kinematics), within the joint limits, and a row's answer independent of the rows
solved with it."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from workbench.robots.chain import solve_ik, tcp_positions
from workbench.robots.model import get_robot


def _pin_tcp(robot, q: np.ndarray) -> np.ndarray:
    """TCP poses (M, 4, 4) of joint vectors q (M, n) by pinocchio on the URDF text."""
    model = pin.buildModelFromXML(robot.spec.urdf)
    data = model.createData()
    fid = model.getFrameId(robot.spec.tip_frame)
    out = []
    for row in q:
        full = pin.neutral(model)
        for jn, v in zip(robot.joint_names, row):
            full[model.joints[model.getJointId(jn)].idx_q] = v
        for jn, v in robot.spec.locked:
            full[model.joints[model.getJointId(jn)].idx_q] = v
        pin.framesForwardKinematics(model, data, full)
        out.append(robot.base @ np.asarray(data.oMf[fid].homogeneous) @ robot.mount)
    return np.array(out)


@pytest.mark.parametrize("name", ["panda", "ur5", "talos"])
def test_solutions_reproduce_pinocchio_fk_within_limits_whatever_the_batch(name):
    robot = get_robot(name)
    rng = np.random.default_rng(7)
    q_true = rng.uniform(robot.lower, robot.upper, size=(60, robot.nq))
    targets = _pin_tcp(robot, q_true)
    seeds = np.clip(q_true + rng.normal(0.0, 0.3, q_true.shape), robot.lower, robot.upper)
    seeds[:5] = rng.uniform(robot.lower, robot.upper, size=(5, robot.nq))  # far seeds: rotations up to pi away
    q, ok = solve_ik(robot, targets, seeds, 200, tol_pos=1e-7, tol_rot=1e-7)
    assert ok.mean() > 0.8
    assert (q >= robot.lower - 1e-12).all() and (q <= robot.upper + 1e-12).all()
    back = _pin_tcp(robot, q[ok])
    assert np.abs(back[:, :3, 3] - targets[ok, :3, 3]).max() < 1e-6
    rel = np.einsum("nji,njk->nik", back[:, :3, :3], targets[ok, :3, :3])
    angle = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    assert angle.max() < 1e-6
    # one row at a time, or the rows reversed: the same bits
    single = [solve_ik(robot, targets[i:i + 1], seeds[i:i + 1], 200, 1e-7, 1e-7) for i in range(0, 60, 7)]
    assert np.array_equal(np.vstack([s[0] for s in single]), q[::7])
    assert np.array_equal(np.concatenate([s[1] for s in single]), ok[::7])
    qr, okr = solve_ik(robot, targets[::-1], seeds[::-1], 200, 1e-7, 1e-7)
    assert np.array_equal(qr[::-1], q) and np.array_equal(okr[::-1], ok)
    np.testing.assert_allclose(tcp_positions(robot, q_true), targets[:, :3, 3], atol=1e-12)


def test_a_pose_out_of_reach_does_not_converge_and_stays_in_limits():
    robot = get_robot("panda")
    target = np.eye(4)
    target[:3, 3] = [2.0, 0.0, 0.5]
    q, ok = solve_ik(robot, target[None], robot.home()[None], 100)
    assert not ok[0] and np.isfinite(q).all()
    assert (q >= robot.lower).all() and (q <= robot.upper).all()


@pytest.mark.parametrize("name", ["panda", "ur5", "puma560"])
def test_compiled_closed_forms_reproduce_pinocchio_fk_on_every_valid_branch(name):
    """The compiled closed forms: every valid branch of 60 random in-limit poses is within the limits and reproduces
    its pose by pinocchio's FK within 1e-6 m and 1e-6 rad; the generating configuration is among the branches, up to
    whole turns (the Panda: where its last joint sits on a sweep sample); the validity-only pass agrees."""
    from workbench.robots.analytic import analytic_ik, reachable
    from workbench.robots.solvers import closed_form

    robot = get_robot(name)
    rng = np.random.default_rng(11)
    q_true = rng.uniform(robot.lower, robot.upper, size=(60, robot.nq))
    form = closed_form(robot)
    if robot.nq == 7:  # on the sweep's samples, so the generating configuration is a branch
        samples = np.linspace(robot.lower[6], robot.upper[6], 16)
        q_true[:, 6] = samples[rng.integers(0, 16, len(q_true))]
    targets = _pin_tcp(robot, q_true)
    joints, valid = form.solve(targets)
    assert valid.any(axis=1).mean() > 0.95
    rows, branches = np.nonzero(valid)
    q = joints[rows, branches]
    assert (q >= robot.lower - 1e-12).all() and (q <= robot.upper + 1e-12).all()
    back = _pin_tcp(robot, q)
    assert np.abs(back[:, :3, 3] - targets[rows, :3, 3]).max() < 1e-6
    rel = np.einsum("nji,njk->nik", back[:, :3, :3], targets[rows, :3, :3])
    assert np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)).max() < 1e-6
    turns = np.abs(np.angle(np.exp(1j * (np.nan_to_num(joints) - q_true[:, None]))))  # a joint spanning 2 turns: either
    dist = np.where(valid, turns.max(axis=2), np.inf).min(axis=1)
    assert (dist[valid.any(axis=1)] < 1e-6).all()
    if name == "puma560":
        assert np.array_equal(reachable(analytic_ik(robot), targets), valid.any(axis=1))
