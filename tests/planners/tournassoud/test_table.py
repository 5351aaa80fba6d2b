"""Grasp classes, the grasp-placement table and backward chaining (Tournassoud et al. 1987, Sections 2-6)."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest
import trimesh

from workbench.errors import PlanningError, WorkbenchError
from workbench.geometry.objects import from_trimesh
from workbench.grasping.placements import stable_placements
from workbench.planners.tournassoud.chaining import (
    NoSequence,
    chain,
    grasp_query,
    placement_query,
)
from workbench.planners.tournassoud.classes import ClassParams, grasp_classes
from workbench.planners.tournassoud.plans import (
    Realiser,
    plan_grasp_query,
    plan_placement_query,
)
from workbench.planners.tournassoud.table import (
    GraspPlacementTable,
    TableParams,
    build_table,
    runs,
)
from workbench.resources import erd_share
from workbench.robots.collider import Scene
from workbench.validation import PlanValidator


def test_box_has_three_face_face_classes(box, hand):
    classes = grasp_classes(box, hand)
    assert [c.kind for c in classes] == ["face/face"] * 3
    assert sorted(round(c.opening, 6) for c in classes) == [0.03, 0.04, 0.05]
    for c in classes:
        assert np.allclose(np.abs(c.normal), np.round(np.abs(c.normal)))      # along a box axis
        assert np.allclose(c.point, 0, atol=1e-9)                              # centre of the overlap
        assert abs(c.eccentricity) < 1e-9
        g = c.pose(0.7)
        assert np.allclose(g[:3, :3] @ g[:3, :3].T, np.eye(3)) and np.linalg.det(g[:3, :3]) > 0
        assert np.allclose(g[:3, 1], c.normal)                                 # jaw axis = n_i


def test_l_part_classes_of_fig1(lpart, hand):
    classes = grasp_classes(lpart, hand)
    assert all(c.kind == "face/face" for c in classes)
    got = sorted((round(c.opening, 6), tuple(np.abs(np.round(c.normal, 6)))) for c in classes)
    assert got == sorted([(0.03, (0.0, 1.0, 0.0)),                       # the two L-shaped faces
                          (0.02, (0.0, 0.0, 1.0)), (0.06, (0.0, 0.0, 1.0)),  # across each leg and along the upright
                          (0.02, (1.0, 0.0, 0.0)), (0.06, (1.0, 0.0, 0.0))])
    inside = lpart.mesh.contains(np.array([c.point for c in classes]))
    assert inside.all()                                                   # C_i lies between the contacts, in the part
    for c in classes:
        assert 0 < c.legal_range <= 2 * np.pi + 1e-9


def test_face_edge_and_face_vertex_classes(hand, extrude):
    wedge = from_trimesh(extrude([(-0.025, 0), (0.025, 0), (0, 0.03)], [(0, 1, 2)], 0.04), "wedge")
    kinds = [(c.kind, round(c.opening, 6), tuple(np.round(c.normal, 6))) for c in grasp_classes(wedge, hand)]
    assert ("face/edge", 0.03, (0.0, 0.0, -1.0)) in kinds                 # base against the ridge
    pyramid = from_trimesh(trimesh.creation.cone(radius=0.03, height=0.03, sections=4), "pyramid")
    fv = [c for c in grasp_classes(pyramid, hand) if c.kind == "face/vertex"]
    assert len(fv) == 1 and abs(fv[0].opening - 0.03) < 1e-9 and np.allclose(fv[0].point, [0, 0, 0.015])


def test_table_far_away_no_limits_is_theta_range_times_all_phi(box, hand, make_puma):
    classes = grasp_classes(box, hand)
    pl = stable_placements(box).poses
    robot = make_puma(base_z=-0.4)  # shoulder 0.27 m above the table: every orientation reachable near H
    steps = {"theta_step": np.radians(10.0), "phi_step": np.radians(10.0)}
    t = build_table(classes, pl, robot, hand, TableParams(table_point=(0.45, 0.0), clearance=-1.0, limits=False, **steps),
                    progress=False)
    expect = np.broadcast_to(t.hand_object[:, None, :, None], t.q.shape)
    assert t.hand_object.any(axis=1).all()
    assert np.array_equal(t.q, expect)
    # with the table at its place, the hand-table stage prunes (jaw vertical on a resting face is impossible)
    near = build_table(classes, pl, robot, hand, TableParams(table_point=(0.45, 0.0), limits=False, **steps),
                       progress=False)
    assert near.q.sum() < t.q.sum() and not (near.q & ~t.q).any()


def _bfs(q: np.ndarray, start: np.ndarray, goal: np.ndarray) -> int | None:
    """Fewest placements between a start and a goal grasp over the explicit graph (grasp) - (placement) - (grasp)."""
    c_n, p_n, t_n, f_n = q.shape
    dist = {}
    todo = deque()
    for c, t in zip(*np.nonzero(start)):
        dist[("g", c, t)] = 0
        todo.append(("g", c, t))
    while todo:
        node = todo.popleft()
        d = dist[node]
        if node[0] == "g":
            if goal[node[1], node[2]]:
                return d // 2
            nbrs = [("p", j, f) for j, f in zip(*np.nonzero(q[node[1], :, node[2], :]))]
        else:
            nbrs = [("g", c, t) for c, t in zip(*np.nonzero(q[:, node[1], :, node[2]]))]
        for nb in nbrs:
            if nb not in dist:
                dist[nb] = d + 1
                todo.append(nb)
    return None


@pytest.mark.parametrize("seed", range(12))
def test_backward_chaining_is_minimal_like_bfs(seed):
    rng = np.random.default_rng(seed)
    shape = (4, 3, 6, 5)
    q = rng.random(shape) < rng.uniform(0.03, 0.12)
    t = GraspPlacementTable(theta=np.arange(6) * np.pi / 3, phi=np.arange(5) * 2 * np.pi / 5, hand_object=q.any(axis=(1, 3)),
                            hand_table=q.any(axis=3), q=q, placements=np.repeat(np.eye(4)[None], 3, axis=0), frame=np.eye(4))
    for _ in range(6):
        start = np.zeros((4, 6), dtype=bool)
        start[rng.integers(4), rng.integers(6)] = True
        goal = np.zeros((4, 6), dtype=bool)
        goal[rng.integers(4), rng.integers(0, 6, size=2)] = True
        levels = chain(t, start, goal)
        expect = _bfs(q, start, goal)
        assert (levels is None) == (expect is None)
        if levels is None:
            continue
        assert len(levels) - 1 == expect
        if not (start & goal).any():
            c, ti = np.argwhere(start)[0]
            gc = int(np.argwhere(goal)[0][0])
            lo = t.theta[np.flatnonzero(goal[gc])].min()
            hi = t.theta[np.flatnonzero(goal[gc])].max()
            if (goal[gc] == ((t.theta >= lo) & (t.theta <= hi))).all():
                seq = grasp_query(t, (int(c), float(t.theta[ti])), gc, (lo, hi))
                assert seq.regrasps == expect
                # each step of the sequence is a legal transition (Proposition 1)
                for k, (j, f) in enumerate(seq.placements):
                    (c0, t0), (c1, t1) = seq.grasps[k], seq.grasps[k + 1]
                    assert q[c0, j, t0, f] and q[c1, j, t1, f]
    # placement queries against the same brute force with start/goal sets from placements
    for _ in range(6):
        ps, fs, pg, fg = rng.integers(3), rng.integers(5), rng.integers(3), rng.integers(5)
        a, b = q[:, ps, :, fs], q[:, pg, :, fg]
        if not a.any() or not b.any():
            with pytest.raises(PlanningError):
                placement_query(t, (int(ps), float(t.phi[fs])), (int(pg), float(t.phi[fg])))
            continue
        expect = _bfs(q, a, b)
        if expect is None:
            with pytest.raises(PlanningError, match="does not connect"):
                placement_query(t, (int(ps), float(t.phi[fs])), (int(pg), float(t.phi[fg])))
        else:
            assert placement_query(t, (int(ps), float(t.phi[fs])), (int(pg), float(t.phi[fg]))).regrasps == expect


def test_ranges_keep_both_ends():
    """A goal range keeps the samples at both of its ends, typed in degrees or given in radians: [a, a] is the sample
    at a, [a, a + 5] the two samples, for every 5-degree sample (float rounding put 15 of them outside before)."""
    from workbench.cli.gpplan import parse_goal
    from workbench.planners.tournassoud.chaining import in_range, nearest_sample
    from workbench.planners.tournassoud.table import grid

    theta = grid(np.radians(5.0))
    for k, deg in enumerate(np.arange(0, 360, 5)):
        for rng in ((np.radians(deg), np.radians(deg)), parse_goal(f"0,{deg}:{deg}")[1], (k * np.pi / 36, k * np.pi / 36)):
            assert np.flatnonzero(in_range(theta, rng)).tolist() == [k]
        both = np.flatnonzero(in_range(theta, parse_goal(f"0,{deg}:{deg + 5}")[1])).tolist()
        assert sorted(both) == sorted([k, (k + 1) % 72])
        assert nearest_sample(theta, np.radians(deg)) == k
    assert in_range(theta, (0.0, 2 * np.pi)).all() and in_range(theta, parse_goal("0,-10:350")[1]).all()


def test_runs_wrap_around():
    vals = np.arange(8.0)
    assert runs(np.array([1, 1, 0, 0, 1, 0, 1, 1], dtype=bool), vals) == [(4.0, 4.0), (6.0, 1.0)]
    assert runs(np.zeros(8, dtype=bool), vals) == []
    assert runs(np.ones(8, dtype=bool), vals) == [(0.0, 7.0)]


SCENE = Scene(table_min=(0.15, -0.8))  # the table clear of the lowered PUMA's pedestal


def _setup(obj, hand, robot):
    """Classes, table, realiser and an independent validator (built here from the URDF text and the meshes). The
    PUMA stands 0.3 m lower than its default pedestal (shoulder 0.37 m above the table), where more of its wrist
    orientations at H are free of its forearm (the realiser rejects self-collisions like the roadmap planner's IK)."""
    classes = grasp_classes(obj, hand)
    pl = stable_placements(obj)
    table = build_table(classes, pl.poses, robot, hand, TableParams(table_point=(0.45, 0.1)), progress=False)
    scene = SCENE
    realiser = Realiser(robot, scene, obj.mesh)
    r = robot
    validator = PlanValidator(r.spec.urdf, r.spec.tip_frame, r.mount, r.base, list(r.joint_names),
                              (scene.table_min, scene.table_max, scene.table_thickness), obj.mesh.vertices, obj.mesh.faces,
                              obj.com, hand.collision_mesh(), hand_links=r.spec.drop_geometry,
                              free_poses={j: p for j, p in enumerate(pl.poses)}, package_dirs=(str(erd_share()),))
    return classes, table, realiser, validator


@pytest.fixture(scope="module")
def low_puma(make_puma):
    return make_puma(base_z=-0.3)


@pytest.fixture(scope="module")
def box_setup(box, hand, low_puma):
    return _setup(box, hand, low_puma)


def test_l_part_sequences_pass_the_validator(lpart, hand, low_puma):
    puma560 = low_puma
    classes, table, realiser, validator = _setup(lpart, hand, puma560)
    rng = np.random.default_rng(1)
    legal = np.argwhere(table.hand_object)
    n = 0
    for _ in range(12):
        c, t = legal[rng.integers(len(legal))]
        goal = int((c + rng.integers(1, len(classes))) % len(classes))  # another class: at least one regrasp
        try:
            seq, plan = plan_grasp_query(table, classes, realiser, puma560, "L", (int(c), float(table.theta[t])), goal,
                                         (0.0, 2 * np.pi))
        except PlanningError:
            continue
        if plan is None:
            continue
        rep = validator.check(plan)
        assert rep.ok, rep.errors
        n += 1
    assert n >= 3


def test_every_sequence_passes_the_validator(box_setup, low_puma):
    puma560 = low_puma
    classes, table, realiser, validator = box_setup
    n = 0
    for a in range(len(classes)):
        for b in (a, (a + 1) % len(classes)):
            try:
                seq, plan = plan_grasp_query(table, classes, realiser, puma560, "box", (a, np.radians(15)), b,
                                             (np.radians(60), np.radians(120)))
            except NoSequence:
                continue
            if plan is None:
                continue
            rep = validator.check(plan)
            assert rep.ok, rep.errors
            assert plan.regrasps == seq.regrasps
            n += 1
    for ps, pg in [(0, 3), (0, 1), (2, 5), (4, 1)]:
        try:
            seq, plan = plan_placement_query(table, classes, realiser, puma560, "box", (ps, 0.0), (pg, 1.0))
        except NoSequence:
            continue
        assert np.allclose(plan.goal_pose, table.object_pose(pg, 1.0))  # the query's angle, not its nearest sample
        rep = validator.check(plan)
        assert rep.ok, rep.errors
        assert plan.regrasps == seq.regrasps
        n += 1
    assert n >= 4


def test_executable_plan_with_motions(box_setup, low_puma):
    """With motions the plan carries a timed trajectory (the roadmap planner's motion planner) that the independent
    trajectory validator accepts: self-collision, table and object contacts, joint position, velocity and
    acceleration limits at every knot."""
    from workbench.planners.wan_harada.motions import ExecOptions
    from workbench.robots.selfcollision import allowed_pairs
    from workbench.validation import TrajectoryValidator

    classes, table, realiser, validator = box_setup
    seq, plan = plan_placement_query(table, classes, realiser, low_puma, "box", (0, 0.0), (2, 1.0), ExecOptions(max_removed=3))
    assert plan.segments and plan.duration > 0 and plan.regrasps == seq.regrasps >= 1
    assert validator.check(plan).ok
    hand = low_puma.gripper
    allowed = list(allowed_pairs(low_puma).allowed)
    tv = TrajectoryValidator(validator, hand.body, trimesh.Trimesh(*_fingers(hand)), allowed, np.array(plan.acc),
                             urdf=low_puma.spec.urdf, jaw_max=hand.jaw_max)
    errors, knots = tv.check(plan, plan.segments)
    assert not errors and knots > 0


def test_grasp_query_motions_pass_the_trajectory_validator(box_setup, low_puma):
    """Section 6's grasp-to-grasp query realised with its timed motions (as `gpplan` plans by default): the
    independent trajectory validator replays every knot (self-collision, table and object contacts, limits, knot
    spacing), not only the waypoints; the plan keeps the sequence's regrasps and its step grasps are the sequence's."""
    from workbench.planners.wan_harada.motions import ExecOptions
    from workbench.robots.selfcollision import allowed_pairs
    from workbench.validation import TrajectoryValidator

    classes, table, realiser, validator = box_setup
    hand = low_puma.gripper
    tv = None
    done = 0
    for a, b in [(0, 1), (1, 2), (2, 0), (0, 2)]:
        try:
            seq, plan = plan_grasp_query(table, classes, realiser, low_puma, "box", (a, np.radians(15)), b,
                                         (np.radians(60), np.radians(120)), ExecOptions())
        except NoSequence:
            continue
        if tv is None:
            tv = TrajectoryValidator(validator, hand.body, trimesh.Trimesh(*_fingers(hand)),
                                     list(allowed_pairs(low_puma).allowed), np.array(plan.acc), urdf=low_puma.spec.urdf,
                                     jaw_max=hand.jaw_max)
        assert plan.segments and plan.regrasps == seq.regrasps >= 1
        assert validator.check(plan).ok
        errors, knots = tv.check(plan, plan.segments)
        assert not errors and knots > 100, errors
        t_n = len(table.theta)
        assert {s.idfreeairgrip for s in plan.steps} == {c * t_n + t for c, t in seq.grasps}
        done += 1
        if done == 2:
            break
    assert done >= 1


def _fingers(hand):
    boxes = [trimesh.creation.box(extents=e, transform=p) for e, p in hand.finger_poses(hand.jaw_max)]
    m = trimesh.util.concatenate(boxes)
    return m.vertices, m.faces


def test_bad_queries(box_setup):
    classes, table, _, _ = box_setup
    with pytest.raises(PlanningError, match="does not exist"):
        grasp_query(table, (99, 0.0), 0, (0.0, 1.0))
    with pytest.raises(PlanningError, match="placement 42 does not exist"):
        placement_query(table, (42, 0.0), (0, 0.0))
    with pytest.raises(WorkbenchError, match="theta step"):
        TableParams(theta_step=0.0)


def test_an_unserved_angle_is_a_result_naming_the_served_ones():
    """A start angle at which no grasp holds the placement is no sequence (a result, exit 0 on the command line), and
    the message lists the angles that are served, wrapping around 360 degrees, as read off the table here."""
    phi = np.radians(np.arange(0, 360, 30.0))
    q = np.zeros((2, 2, 4, len(phi)), dtype=bool)
    q[0, 0, 1, [0, 1, 10, 11]] = True  # placement 0 served at 300..30 degrees, across 0
    q[1, 1, 2, 5] = True
    t = GraspPlacementTable(theta=np.arange(4) * np.pi / 2, phi=phi, hand_object=q.any(axis=(1, 3)),
                            hand_table=q.any(axis=3), q=q, placements=np.repeat(np.eye(4)[None], 2, axis=0), frame=np.eye(4))
    with pytest.raises(NoSequence, match=r"no grasp can pick the object at placement 0, 90.0 deg; .*grasps at 300 to 30 through 0 deg"):
        placement_query(t, (0, np.radians(90)), (1, np.radians(150)))
    with pytest.raises(NoSequence, match=r"no grasp can put the object at placement 1, 0.0 deg; .*grasps at 150 deg"):
        placement_query(t, (0, 0.0), (1, 0.0))
    # a placement no grasp holds at any angle: not another angle, but more grasp points or another table point
    q[1, 1] = False
    t = GraspPlacementTable(theta=t.theta, phi=phi, hand_object=q.any(axis=(1, 3)), hand_table=q.any(axis=3), q=q,
                            placements=t.placements, frame=np.eye(4))
    with pytest.raises(NoSequence, match=r"placement 1, 0.0 deg; no angle of placement 1 has a grasp at this table "
                                         r"point: more grasp points per class \(`workbench gptable --points N`\)"):
        placement_query(t, (0, 0.0), (1, 0.0))


def test_minimum_contact_area(box, hand):
    """Section 5.1: the pad must cover `min_contact_area` of the face overlap at every legal theta."""
    pad = float(hand.pad_extents[0] * hand.pad_extents[2])
    assert len(grasp_classes(box, hand, ClassParams(min_contact_area=0.9 * pad))) == 3   # every box face covers the pad
    assert grasp_classes(box, hand, ClassParams(min_contact_area=1.1 * pad)) == []       # more than the pad itself
    # a bar 6 mm thick: across its 30 mm width the faces are 6 mm strips, narrower than the pad
    bar = from_trimesh(trimesh.creation.box((0.06, 0.006, 0.03)), "bar")
    plain = grasp_classes(bar, hand)
    strict = grasp_classes(bar, hand, ClassParams(min_contact_area=0.5 * pad))
    assert any(abs(c.opening - 0.03) < 1e-9 for c in plain)
    assert not any(abs(c.opening - 0.03) < 1e-9 for c in strict)
    assert any(abs(c.opening - 0.006) < 1e-9 for c in strict)


def test_narrow_legal_range_is_kept():
    """Section 5.1: a class is kept whenever its legal theta range is non-empty, even when it is narrower than the
    coarse candidate step (15 degrees): the candidates are compared again at the full step, and the range's ends are
    bisected to the true boundaries."""
    from workbench.planners.tournassoud.classes import select_point
    from workbench.planners.tournassoud.table import grid

    theta = grid(np.radians(5.0))
    coarse = theta[::3]
    lo, hi = np.radians(106.0), np.radians(114.0)      # 8 degrees, no coarse sample (105, 120) inside, one 5-degree one

    def free_at(t, point=None):
        t = np.mod(np.asarray(t, dtype=float), 2 * np.pi)
        return (t >= lo) & (t <= hi) & bool(point[0] == 1.0)   # only the second candidate is ever free

    cands = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    point, intervals = select_point(cands, free_at, theta, coarse, np.radians(0.01))
    assert point[0] == 1.0
    assert len(intervals) == 1 and np.allclose(intervals[0], (lo, hi), atol=np.radians(0.011))
    # nothing free at any sample: no class
    assert select_point(cands, lambda t, point=None: np.zeros(len(np.atleast_1d(t)), bool), theta, coarse, 0.01) is None
    # the documented threshold drops narrow classes only when asked
    assert ClassParams().min_range == 0.0
    with pytest.raises(WorkbenchError):
        ClassParams(min_range=-1.0)


def test_several_grasp_points_connect_the_l_part(lpart, hand, puma560):
    """Section 2.3's remedy for elongated parts (a discrete set of grasp points per feature pair, as in Handey): on the
    L-part, one point per class leaves the placement on the slanted hull face reachable only by the class it alone
    uses (the query says so); with three points per pair every placement query of the table has an answer, each
    extra point is a class of the same feature pair adding theta samples its first point lacks."""
    from workbench.planners.tournassoud.chaining import NoSequence, placement_groups

    pl = stable_placements(lpart)
    tp = TableParams(theta_step=np.radians(10), phi_step=np.radians(10), table_point=(0.45, 0.1))
    one = build_table(grasp_classes(lpart, hand), pl.poses, puma560, hand, tp, progress=False)
    classes = grasp_classes(lpart, hand, ClassParams(points=3))
    three = build_table(classes, pl.poses, puma560, hand, tp, progress=False)
    assert len(placement_groups(one)) > 1 and len(placement_groups(three)) == 1
    split = next(g for g in placement_groups(one) if len(g) == 1).pop()
    other = (split + 1) % len(pl)
    with pytest.raises(NoSequence, match=f"placement {split} is held only by"):
        placement_query(one, (other, 0.0), (split, 0.0))
    assert placement_query(three, (other, 0.0), (split, 0.0)).regrasps >= 0
    by_pair: dict = {}
    for c in classes:
        by_pair.setdefault(tuple(c.features["faces"]), []).append(c)
    assert len(by_pair) == 5 and max(len(v) for v in by_pair.values()) > 1
    for group in by_pair.values():
        first = group[0].legal(three.theta)
        for extra in group[1:]:
            assert (extra.legal(three.theta) & ~first).any()                # adds angles the first point lacks
            assert not np.allclose(extra.point, group[0].point)
    assert lpart.mesh.contains(np.array([c.point for c in classes])).all()


def test_rasterise_matches_point_in_triangle():
    """The scan-line rasteriser marks exactly the cells whose centre lies in (or on) a triangle (brute force)."""
    from workbench.planners.tournassoud.features import rasterise

    rng = np.random.default_rng(3)
    for k in range(40):
        tris = rng.uniform(0, 1, (int(rng.integers(1, 8)), 3, 2))
        if k % 2:
            tris = np.round(tris * 10) / 10                     # vertices on cell centres, horizontal edges
        cell = 1 / 20
        mask = rasterise(tris, np.array([-0.025, -0.025]), cell, (22, 22)).mask
        i, j = np.mgrid[0:22, 0:22]
        pts = np.stack([j.ravel() * cell, i.ravel() * cell], axis=1)   # the cell centres
        inside = np.zeros(len(pts), dtype=bool)
        for a, b, c in tris:
            m = np.array([b - a, c - a]).T
            if abs(np.linalg.det(m)) < 1e-12:
                continue
            uv = np.linalg.solve(m, (pts - a).T).T
            inside |= (uv >= -1e-9).all(axis=1) & (uv.sum(axis=1) <= 1 + 1e-9)
        near_edge = np.zeros(len(pts), dtype=bool)   # centres within 1e-6 of an edge may go either way
        for t in tris:
            for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                d = b - a
                s = np.clip(((pts - a) @ d) / max(d @ d, 1e-18), 0, 1)
                near_edge |= np.linalg.norm(pts - (a + s[:, None] * d), axis=1) < 1e-6
        assert (mask.ravel() == inside)[~near_edge].all()


def test_blocked_everywhere_agrees_with_fcl(hand):
    """The cheap pre-test (an object vertex inside the disc a pad covers at every theta) rejects a grasp point only
    where fcl finds the hand colliding at every theta sample; a point on a plain face is not rejected."""
    from workbench.planners.tournassoud.classes import HandObject, grasp_poses

    boxm = trimesh.creation.box((0.04, 0.04, 0.04))
    bump = trimesh.creation.cone(radius=0.003, height=0.003)
    bump.apply_translation([0.004, 0.0, 0.02])                      # a 3 mm spike on the +z face, 4 mm off centre
    obj = from_trimesh(trimesh.util.concatenate([boxm, bump]), "bumpy")
    ho = HandObject(obj, hand, 5e-4)
    n = np.array([0.0, 0.0, 1.0])
    cls = {"normal": n, "u": np.array([1.0, 0, 0]), "v": np.array([0, 1.0, 0]), "opening": 0.04}
    pts = np.array([[0.0, 0.0, 0.0], [0.0, 0.012, 0.0], [0.012, 0.0, 0.0]])
    blocked = ho.blocked_everywhere(cls, pts)
    theta = np.radians(np.arange(0, 360, 5.0))
    fcl_free = np.array([(~np.asarray(ho.free(cls, p, theta))).sum() < len(theta) for p in pts])
    assert blocked[0] and not fcl_free[0]                          # the spike sits in the pad at every angle
    assert not blocked[1]                                           # 12 mm away: outside the covered disc
    assert not (blocked & fcl_free).any()
    assert grasp_poses(n, cls["u"], cls["v"], pts[0], theta).shape == (len(theta), 4, 4)


def test_an_empty_table_names_the_stage_that_emptied_it(box, hand, puma560):
    """Zero is a result (issue 10): a table point 2.5 m away leaves only the IK stage to blame; a 3 mm plate whose
    classes grasp it across its width only is emptied by the table (the pads centred on a 3 mm part reach into it);
    a table with the part at reach is not empty."""
    classes = grasp_classes(box, hand)
    pl = stable_placements(box).poses
    far = build_table(classes, pl, puma560, hand, TableParams(table_point=(2.5, 0.0)), progress=False)
    assert not far.q.any() and far.hand_table.any()
    assert far.empty_reason().startswith("inverse kinematics")
    plate = from_trimesh(trimesh.creation.box((0.06, 0.05, 0.003)), "plate")
    side = [c for c in grasp_classes(plate, hand) if abs(c.normal[2]) < 0.5]
    flat = stable_placements(plate).poses
    t = build_table(side, flat, puma560, hand, TableParams(table_point=(0.45, 0.0)), progress=False)
    assert side and t.hand_object.any() and not t.q.any()
    assert t.empty_reason().startswith("hand-table")
    near = build_table(classes, pl, puma560, hand, TableParams(table_point=(0.45, 0.0)), progress=False)
    assert near.q.any() and near.empty_reason() is None
