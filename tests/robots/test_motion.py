"""Motions between waypoints and their timing (issue 12): straight joint lines, RRT-Connect around the table, TCP
lines, limits, determinism. Cross-checks use pinocchio FK on the URDF and python-fcl, not the planner's code."""

from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import trimesh

from workbench.robots.chain import solve_ik
from workbench.robots.collider import default_scene
from workbench.robots.model import builtin_robot
from workbench.robots.motion import MotionChecker, joint_motion, tcp_line
from workbench.robots.timing import (
    TimedSegment,
    Trajectory,
    resample,
    time_line,
    time_spline,
    time_stops,
    to_csv,
    to_json,
    within_limits,
)

# Two Panda configurations holding a box above the table whose straight joint line takes the hand under the table top.
QA = np.array([0.75, 1.51, -0.35, -0.21, 0.0, 1.59, 0.7])
QB = np.array([-0.51, 1.66, -1.44, -1.85, 0.96, 2.64, 1.09])
GRASP = np.diag([1.0, -1.0, -1.0, 1.0])  # TCP at the box centre, pointing down (TCP pose in the object frame)
BOX = (0.05, 0.04, 0.03)


@pytest.fixture(scope="module")
def panda():
    return builtin_robot("panda")


@pytest.fixture(scope="module")
def checker(panda):
    return MotionChecker(panda, default_scene("panda"), trimesh.creation.box(BOX))


class Independent:
    """Pinocchio FK on the full URDF and python-fcl: the held box's lowest point and the arm's links against the table."""

    def __init__(self, robot):
        self.model = pin.buildModelFromXML(robot.spec.urdf)
        self.data = self.model.createData()
        self.tcp = self.model.getFrameId("panda_hand_tcp")
        self.corners = np.array(trimesh.creation.box(BOX).vertices)

    def tcp_pose(self, q):
        full = pin.neutral(self.model)
        full[:7] = q
        pin.framesForwardKinematics(self.model, self.data, full)
        return np.asarray(self.data.oMf[self.tcp].homogeneous)

    def box_bottom(self, q):
        obj = self.tcp_pose(q) @ np.linalg.inv(GRASP)
        return float((self.corners @ obj[:3, :3].T + obj[:3, 3])[:, 2].min())


def test_straight_line_through_the_table_is_replanned(panda, checker):
    checker.set_holding(GRASP)
    assert checker.valid(QA) and checker.valid(QB)
    line = checker.line_samples(QA, QB)
    assert np.abs(np.diff(line, axis=0)).max() <= np.radians(1.0) + 1e-12
    ind = Independent(panda)
    bottoms = np.array([ind.box_bottom(q) for q in line])
    assert bottoms.min() < -0.02  # independently: the straight line takes the box 2+ cm under the table top
    assert not checker.line_free(QA, QB)
    jp = joint_motion(checker, QA, QB)
    assert jp is not None and jp.method == "rrtconnect" and len(jp.path) >= 3
    assert np.allclose(jp.path[0], QA) and np.allclose(jp.path[-1], QB)
    for a, b in zip(jp.path[:-1], jp.path[1:]):
        for q in checker.line_samples(a, b):
            assert ind.box_bottom(q) > -1e-3  # the held object never goes below the table top (1 mm tolerance)
    # same seed, same path; the timed trajectory too
    again = joint_motion(checker, QA, QB)
    assert np.array_equal(again.path, jp.path)
    vlim = panda.model.velocityLimit
    assert np.array_equal(time_spline(jp.path, vlim, 3.0).q, time_spline(again.path, vlim, 3.0).q)


def test_free_line_is_kept(checker):
    checker.set_free()
    qa = np.array([0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785])
    qb = qa + np.array([0.8, 0.2, 0.0, 0.3, 0.0, -0.2, 0.0])
    jp = joint_motion(checker, qa, qb)
    assert jp.method == "line" and len(jp.path) == 2


def test_tcp_line_is_straight(panda, checker):
    checker.set_free()
    qa = np.array([0.0, 0.1, 0.0, -2.2, 0.0, 2.3, 0.785])
    ind = Independent(panda)
    ta = ind.tcp_pose(qa)
    target = ta.copy()
    target[2, 3] -= 0.08  # straight down 8 cm
    qb, ok = solve_ik(panda, target[None], qa[None], 100)
    assert ok[0]
    path = tcp_line(panda, checker, qa, qb[0])
    assert path is not None and len(path) >= 17  # 8 cm at 5 mm or finer
    pts = np.array([ind.tcp_pose(q)[:3, 3] for q in path])
    off = np.linalg.norm(np.cross(pts - ta[:3, 3], [0, 0, 1.0]), axis=1)
    assert off.max() < 2e-4 and np.abs(np.diff(pts[:, 2])).max() <= 0.005 + 1e-4


def test_trajectories_respect_limits(panda, checker):
    vlim = np.asarray(panda.model.velocityLimit)
    alim = np.full(7, 3.0)
    checker.set_holding(GRASP)
    path = joint_motion(checker, QA, QB).path
    for traj in (time_line(QA, QB, vlim, alim), time_stops(path, vlim, alim), time_spline(path, vlim, alim)):
        assert within_limits(traj, panda.lower, panda.upper, vlim, alim) == []
        assert np.abs(np.diff(traj.q, axis=0)).max() <= np.radians(1.0) + 1e-9  # knots at the check resolution
        assert np.allclose(traj.q[0], path[0]) and np.allclose(traj.q[-1], path[-1])
        assert np.abs(traj.qd[[0, -1]]).max() == 0.0  # rest to rest
        # velocities are the derivative of positions (independent finite differences at mid-knots)
        mid = 0.5 * (traj.t[1:] + traj.t[:-1])
        fd = np.diff(traj.q, axis=0) / np.diff(traj.t)[:, None]
        assert np.abs(fd - traj.sample(mid)[1]).max() < 0.05 * vlim.max()
    line = time_line(QA, QB, vlim, alim)
    peak = np.abs(line.qd).max(axis=0)
    assert np.isclose((peak / vlim).max(), 1.0, atol=1e-6) or np.isclose((np.abs(line.accelerations()) / alim).max(), 1.0, atol=0.05)


def test_export_round_trip(panda):
    vlim = np.asarray(panda.model.velocityLimit)
    a = time_line(QA, QB, vlim, 3.0)
    segs = [TimedSegment("transfer", "transfer", 0, True, 0.0, a, "line"),
            TimedSegment("gripper", "release", 1, False, a.duration, Trajectory(np.array([0.0, 0.5]), np.stack([QB, QB]), np.zeros((2, 7))), "dwell")]
    d = json.loads(to_json(segs, list(panda.joint_names)))
    assert np.isclose(d["duration"], a.duration + 0.5)
    back = TimedSegment.from_dict(d["segments"][0])
    assert np.allclose(back.traj.q, a.q)
    rows = to_csv(segs, list(panda.joint_names)).strip().splitlines()
    assert len(rows) == 1 + len(a.t) + 2 and rows[0].startswith("t,segment,kind,caption")
    frames = resample(segs, 30.0)
    assert np.isclose(frames["t"][1], 1 / 30) and frames["segment"][-1] == 1


def test_the_toppra_grid_is_toppras_own():
    """The grid the spline timing hands TOPP-RA is point for point the one toppra would propose itself."""
    import toppra as ta
    from toppra.interpolator import propose_gridpoints as toppras

    from workbench.robots.timing import propose_gridpoints

    rng = np.random.default_rng(3)
    for _ in range(12):
        pts = np.cumsum(rng.normal(0, rng.uniform(0.01, 0.5), (int(rng.integers(3, 30)), 7)), axis=0)
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
        geo = ta.SplineInterpolator(s / s[-1], pts, bc_type="natural")
        for n in (60, 300):
            assert np.array_equal(propose_gridpoints(geo, n), np.asarray(toppras(geo, max_err_threshold=1e-3, min_nb_points=n)))
