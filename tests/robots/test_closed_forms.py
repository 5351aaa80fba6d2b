"""Every closed form the workbench picks (`robots.solvers.closed_form`) against pinocchio's FK on the URDF text.

For 2,000 random in-limit configurations per arm: every returned branch reproduces its pose (0.1 mm, 0.01 rad), the
generating configuration is among the branches, and the pose of each comes back; the Panda over its swept last joint.
The solver is read off the model: UR3 and UR10 loaded from their URDF files as a user's robot get the same form.
"""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pinocchio as pin
import pytest

from workbench.resources import erd_robots
from workbench.robots import parallel
from workbench.robots.solvers import REFINE, SWEEP, closed_form, describe
from workbench.robots.model import get_robot, pose_xyz_yaw, robot_from_urdf

N = 2000


def _fk(robot, qs: np.ndarray) -> np.ndarray:
    """TCP poses (M, 4, 4) of joint vectors (M, n) with pinocchio on the robot's URDF text (not the chain arrays the
    solvers read)."""
    model = pin.buildModelFromXML(robot.spec.urdf)
    data = model.createData()
    fid = model.getFrameId(robot.spec.tip_frame)
    idx = [model.joints[model.getJointId(n)].idx_q for n in robot.joint_names]
    full = np.tile(pin.neutral(model), (len(qs), 1))
    full[:, idx] = qs
    out = np.empty((len(qs), 4, 4))
    for k, q in enumerate(full):
        pin.framesForwardKinematics(model, data, q)
        out[k] = robot.base @ np.asarray(data.oMf[fid].homogeneous) @ robot.mount
    return out


def _check(robot, qs: np.ndarray) -> tuple[int, int]:
    """Solve the FK poses of `qs`; assert the three properties; return (poses, returned solutions)."""
    form = closed_form(robot)
    poses = _fk(robot, qs)
    joints, valid = form.solve(poses)
    assert joints.shape == (len(qs), form.branches, robot.nq) and valid.shape == (len(qs), form.branches)
    rows, cols = np.nonzero(valid)
    sol = joints[rows, cols]
    assert ((sol >= robot.lower - 1e-12) & (sol <= robot.upper + 1e-12)).all()
    back = _fk(robot, sol)
    dp = np.linalg.norm(back[:, :3, 3] - poses[rows, :3, 3], axis=1)
    cos = (np.einsum("nij,nij->n", back[:, :3, :3], poses[rows, :3, :3]) - 1) / 2
    dr = np.arccos(np.clip(cos, -1, 1))
    assert dp.max() < 1e-4 and dr.max() < 1e-2           # no returned solution fails its pose
    assert valid.any(axis=1).all()                        # every pose reproduced by some branch
    gap = np.abs(np.angle(np.exp(1j * (joints - qs[:, None])))).max(axis=2)
    assert np.where(valid, gap, np.inf).min(axis=1).max() < 1e-6   # the generating configuration recovered
    return len(qs), len(sol)


def test_ur5_three_parallel_axes_8_branches():
    ur5 = get_robot("ur5")
    form = closed_form(ur5)
    assert form.kind == "three parallel axes" and form.branches == 8
    qs = np.random.default_rng(1).uniform(ur5.lower, ur5.upper, (N, 6))
    n, found = _check(ur5, qs)
    assert found > 4 * n  # most poses have several real branches within the UR's +/- 2 pi limits


def test_ur5_joint_limits_keep_exactly_the_branches_within_them():
    """Limits narrower than a turn: a branch is kept iff each of its joints, moved by whole turns, fits its limits
    (checked on the branches solved without limits), and its joints are then those representatives."""
    robot = copy.copy(get_robot("ur5"))
    robot.lower = np.array([-1.0, -3.5, -2.0, -4.0, 0.5, -1.5])
    robot.upper = np.array([2.5, 0.5, 2.5, 1.0, 5.0, 1.5])
    poses = _fk(robot, np.random.default_rng(3).uniform(robot.lower, robot.upper, (300, 6)))
    q, valid = parallel.solve(parallel.parallel_ik(robot), poses)
    qu, vu = parallel.solve(parallel.parallel_ik(robot, limits=False), poses)
    turns = qu[..., None] + 2 * np.pi * np.array([0.0, -1.0, 1.0])          # q, q - 2 pi, q + 2 pi
    fits = (turns >= robot.lower[:, None]) & (turns <= robot.upper[:, None])
    assert (valid == (vu & fits.any(-1).all(-1))).all() and 0 < valid.sum() < vu.sum()
    pick = np.take_along_axis(turns, np.argmax(fits, -1)[..., None], -1)[..., 0]
    assert np.abs(q[valid] - pick[valid]).max() < 1e-12 and np.isnan(q[~valid]).all()


def test_puma560_spherical_wrist():
    puma = get_robot("puma560")
    assert closed_form(puma).kind == "spherical wrist"
    _check(puma, np.random.default_rng(2).uniform(puma.lower, puma.upper, (N, 6)))


def test_panda_over_its_last_joint_sweep():
    """The Panda with its 7th joint at one of the sweep's samples: the 6R arm left has a spherical shoulder (axes
    1-3 meet, axes 5-6 meet), solved backwards, 8 branches per sample; the elbow's limits (q4 < 0) mostly keep one
    of its two roots, so nearly every sample has at most 4 branches within the limits (He & Liu's count)."""
    panda = get_robot("panda")
    form = closed_form(panda)
    assert form.kind == f"spherical shoulder, panda_joint7 swept over {SWEEP} samples" and form.branches == 8 * SWEEP
    rng = np.random.default_rng(3)
    qs = rng.uniform(panda.lower, panda.upper, (N, 7))
    samples = np.linspace(panda.lower[6], panda.upper[6], SWEEP)
    qs[:, 6] = samples[rng.integers(0, SWEEP, N)]
    _check(panda, qs)
    _, valid = form.solve(_fk(panda, qs[:200]))
    per_sample = valid.reshape(200, SWEEP, 8).sum(axis=2)
    assert (per_sample <= 4).mean() > 0.95 and per_sample.max() > 0


def test_panda_refines_its_sweep_between_samples():
    """Configurations with the 7th joint between the sweep's samples: the refinement (REFINE sub-steps per interval,
    only next to samples with a branch, or everywhere when none has one) returns only branches that reproduce their
    poses within the limits, recovers the generating configuration wherever it solves its interval, and gives the IK
    stage the poses whose valid window of joint 7 falls between two samples."""
    from workbench.robots.collider import Scene
    from workbench.robots.ik import IKOptions, IKSolver

    panda = get_robot("panda")
    form = closed_form(panda)
    samples = np.linspace(panda.lower[6], panda.upper[6], SWEEP)
    between = (samples[:-1, None] + np.arange(1, REFINE) / REFINE * np.diff(samples)[:, None]).ravel()
    rng = np.random.default_rng(8)
    qs = rng.uniform(panda.lower, panda.upper, (N, 7))
    pick = rng.integers(0, len(between), N)
    qs[:, 6] = between[pick]
    poses = _fk(panda, qs)
    _, coarse = form.solve(poses)
    joints, valid = form.refine(poses, coarse)
    assert joints.shape == (N, 8 * len(between), 7)
    rows, cols = np.nonzero(valid)
    sol = joints[rows, cols]
    assert ((sol >= panda.lower - 1e-12) & (sol <= panda.upper + 1e-12)).all()
    back = _fk(panda, sol)
    assert np.linalg.norm(back[:, :3, 3] - poses[rows, :3, 3], axis=1).max() < 1e-4
    assert np.abs(back[:, :3, :3] - poses[rows, :3, :3]).max() < 1e-6
    per_sample = coarse.reshape(N, SWEEP, 8).any(axis=2)
    interval = pick // (REFINE - 1)
    used = per_sample[np.arange(N), interval] | per_sample[np.arange(N), interval + 1] | ~per_sample.any(axis=1)
    assert used.mean() > 0.95
    cols_of = 8 * pick[:, None] + np.arange(8)  # the generating angle's branches
    gap = np.abs(np.angle(np.exp(1j * (np.take_along_axis(joints, cols_of[..., None], 1) - qs[:, None])))).max(axis=2)
    mine = np.take_along_axis(valid, cols_of, 1)
    assert (np.where(mine, gap, np.inf).min(axis=1) < 1e-6)[used].all()
    assert not mine[~used].any()  # an interval away from every sample with a branch is not solved
    missed = np.flatnonzero(~coarse.any(axis=1))
    assert len(missed) >= 3  # windows of joint 7 narrower than the samples' spacing exist
    stage = IKSolver(panda, Scene(workspace_min=(-9, -9, -9), workspace_max=(9, 9, 9)), IKOptions(collide=False))
    assert stage.solve(poses[missed], poses[missed], None, 0)[1].all()


def test_the_form_is_read_off_the_model_not_the_name():
    """UR3 and UR10 from their URDF files (a user's robot, another name, another base) get the UR closed form; a
    9-joint arm and the numerical option get the numerical solver."""
    root = erd_robots() / "ur_description" / "urdf"
    rng = np.random.default_rng(4)
    for file in ("ur3_robot.urdf", "ur10_robot.urdf"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            arm = robot_from_urdf(root / file, "tool0", base=pose_xyz_yaw(0.1, -0.2, 0.05, 0.7), name="my_arm")
        assert closed_form(arm).kind == "three parallel axes"
        _check(arm, rng.uniform(arm.lower, arm.upper, (300, 6)))
    assert describe(get_robot("talos")).startswith("numerical")
    assert describe(get_robot("ur5"), numerical=True).startswith("numerical")
    assert "three parallel axes" in describe(get_robot("ur5"))


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_out_of_reach_has_no_branch(name):
    robot = get_robot(name)
    far = np.eye(4)
    far[:3, 3] = (3.0, 0.0, 0.5)
    assert not closed_form(robot).solve(far[None])[1].any()


def _dh_urdf(a: tuple, d: tuple, alpha_deg: tuple) -> str:
    """A 6R arm without geometry from standard DH rows (link i is joint i's frame), a 0.1 m tool past the flange."""
    out = ['<robot name="dh">', '<link name="base"/>']
    parent, origin = "base", (0.0, 0.0, 0.0)
    for i in range(6):
        out.append(f'<joint name="j{i + 1}" type="revolute"><parent link="{parent}"/><child link="l{i + 1}"/>'
                   f'<origin xyz="{origin[0]} 0 {origin[1]}" rpy="{origin[2]!r} 0 0"/><axis xyz="0 0 1"/>'
                   f'<limit lower="-3.14159" upper="3.14159" velocity="2" effort="10"/></joint><link name="l{i + 1}"/>')
        parent, origin = f"l{i + 1}", (a[i], d[i], float(np.radians(alpha_deg[i])))
    out.append(f'<joint name="flange" type="fixed"><parent link="{parent}"/><child link="tool"/><origin '
               f'xyz="{origin[0]} 0 {origin[1] + 0.1}" rpy="{origin[2]!r} 0 0"/></joint><link name="tool"/></robot>')
    return "\n".join(out)


def test_other_decomposable_arms_through_eaik(tmp_path):
    """An industrial arm whose shoulder is offset (KUKA-like DH: a1 = 25 mm, so axes 1 and 2 do not meet) has none
    of the workbench's own forms; EAIK's subproblem decomposition solves it, all branches, FK-checked."""
    urdf = tmp_path / "kuka_like.urdf"
    urdf.write_text(_dh_urdf((0.025, 0.455, 0.035, 0, 0, 0), (0.4, 0, 0, 0.42, 0, 0.08), (-90, 0, 90, -90, 90, 0)))
    arm = robot_from_urdf(urdf, "tool")
    form = closed_form(arm)
    assert form.kind.startswith("subproblem decomposition, EAIK")
    assert "EAIK" in describe(arm)
    _check(arm, np.random.default_rng(5).uniform(arm.lower, arm.upper, (N, 6)))


def test_panda_wrist_shell_never_rejects_a_reachable_pose():
    """The Panda fall-back's out-of-reach test (`solvers.wrist_shell`) against pinocchio's joint placements: the
    shoulder and the wrist (joints 1 and 5 of the URDF) of 2,000 random configurations, their distance inside
    [r_min, r_max] and reaching both ends over joint 4's range, the wrist on the circle about axis 7 in the TCP frame.
    Of 4,000 random poses around the arm, the rejected ones nearest the shell are out of reach for Levenberg-Marquardt
    from 48 seeds each (random configurations and the unlimited closed form's branches)."""
    from workbench.robots.chain import solve_ik
    from workbench.robots.solvers import wrist_shell

    panda = get_robot("panda")
    shell = wrist_shell(panda, 1e-4, 1e-3)
    tight = wrist_shell(panda, 0.0, 0.0, margin=0.0)
    rng = np.random.default_rng(7)
    qs = rng.uniform(panda.lower, panda.upper, (N, 7))
    qs[:400, 3] = np.linspace(panda.lower[3], panda.upper[3], 400)  # the elbow over its whole range
    model = pin.buildModelFromXML(panda.spec.urdf)
    data = model.createData()
    j1, j5 = model.getJointId(panda.joint_names[0]), model.getJointId(panda.joint_names[4])
    idx = [model.joints[model.getJointId(n)].idx_q for n in panda.joint_names]
    poses = _fk(panda, qs)
    dist, off = np.empty(N), np.empty((N, 2))
    for k, q in enumerate(qs):
        full = pin.neutral(model)
        full[idx] = q
        pin.forwardKinematics(model, data, full)
        s = panda.base[:3, :3] @ data.oMi[j1].translation + panda.base[:3, 3]
        w = panda.base[:3, :3] @ data.oMi[j5].translation + panda.base[:3, 3]
        assert np.allclose(s, shell.shoulder, atol=1e-9)
        dist[k] = np.linalg.norm(w - s)
        local = np.linalg.solve(poses[k], np.append(w, 1.0))[:3] - shell.center
        along = local @ shell.axis
        off[k] = along, np.linalg.norm(local - along * shell.axis)
    assert (dist >= tight.r_min - 1e-9).all() and (dist <= tight.r_max + 1e-9).all()
    assert [dist.min(), dist.max()] == pytest.approx([tight.r_min, tight.r_max], abs=1e-4)
    assert np.abs(off[:, 0]).max() < 1e-9 and np.abs(off[:, 1] - shell.radius).max() < 1e-9
    assert tight(poses).all()

    far = np.tile(np.eye(4), (2 * N, 1, 1))
    far[:, :3, 3] = rng.uniform((-1.2, -1.2, -0.6), (1.2, 1.2, 1.4), (2 * N, 3))
    far[:, :3, :3] = [pin.Quaternion(*(v / np.linalg.norm(v))).matrix() for v in rng.normal(size=(2 * N, 4))]
    out = ~shell(far)
    assert 0.2 < out.mean() < 0.95  # the test separates: some poses in, some out
    # how far each rejected pose's circle lies outside the shell; the closest 40 are the hard cases
    c = far[:, :3, :3] @ shell.center + far[:, :3, 3]
    n = far[:, :3, :3] @ shell.axis
    v = shell.shoulder - c
    a = np.einsum("ij,ij->i", v, n)
    b = np.linalg.norm(v - a[:, None] * n, axis=1)
    gap = np.maximum(np.hypot(a, b - shell.radius) - shell.r_max, shell.r_min - np.hypot(a, b + shell.radius))
    hard = np.flatnonzero(out)[np.argsort(gap[out])[:40]]
    assert gap[hard].max() < 0.05  # the sample does come close to the shell
    unlimited = closed_form(panda, limits=False)

    def reached(targets: np.ndarray) -> np.ndarray:
        qb, vb = unlimited.solve(targets)
        out = np.empty(len(targets), dtype=bool)
        for k, t in enumerate(targets):
            seeds = np.vstack([rng.uniform(panda.lower, panda.upper, (32, 7)), qb[k][vb[k]][:16]])
            out[k] = solve_ik(panda, np.repeat(t[None], len(seeds), axis=0), seeds, 300)[1].any()
        return out
    assert not reached(far[hard]).any()
    # the same search does find most reachable poses at the shell's edge (the arm stretched out, near its singularity)
    assert reached(poses[np.argsort(dist)[-10:]]).sum() >= 7
