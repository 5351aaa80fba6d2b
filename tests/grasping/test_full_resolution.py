"""Grasps of a full-resolution mesh (over 400,000 triangles) hold against that mesh, checked with coal."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh

from workbench.geometry.objects import from_trimesh, load_object
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.resources import bundled_objects


def _full_resolution_tube() -> trimesh.Trimesh:
    """The bundled tube subdivided to 433,152 triangles: the same surface at a scan's resolution."""
    m = load_object(bundled_objects()["tube"]).mesh
    for _ in range(4):
        m = m.subdivide()
    return m


def _coal_mesh(mesh: trimesh.Trimesh) -> coal.CollisionObject:
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(mesh.faces), len(mesh.vertices))
    model.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    model.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    model.endModel()
    return coal.CollisionObject(model, coal.Transform3s())


def test_full_resolution_grasps_touch_and_clear_the_full_mesh(hand):
    mesh = _full_resolution_tube()
    assert len(mesh.faces) > 400_000
    params = GraspParams(rotations=4)
    plan = plan_grasps(from_trimesh(mesh, "scan"), hand, params)
    g = plan.grasps
    assert len(g) >= 50
    target = _coal_mesh(mesh)
    dreq, creq = coal.DistanceRequest(), coal.CollisionRequest()
    probe = coal.CollisionObject(coal.Sphere(1e-7), coal.Transform3s())
    for k in np.linspace(0, len(g) - 1, 60).astype(int):
        # both contacts lie on the full mesh (within 0.1 mm)
        for c in (g.contact0[k], g.contact1[k]):
            probe.setTranslation(np.asarray(c, dtype=np.float64))
            assert coal.distance(probe, target, dreq, coal.DistanceResult()) <= 1e-4
        # the contacts are the pads' first touches: on the jaw axis's two sides, the opening their distance along it
        y = g.poses[k, :3, 1]
        assert abs((g.contact0[k] - g.contact1[k]) @ y - g.jawwidth[k]) < 1e-12  # the pads stop at their contacts
        # no finger box at the grasp's opening, shrunk by the finger clearance, enters the full mesh
        for ext, pose in hand.finger_poses(float(g.jawwidth[k])):
            box = coal.CollisionObject(coal.Box(*np.maximum(np.asarray(ext) - 2 * params.finger_clearance, 1e-6)))
            world = g.poses[k] @ pose
            box.setTransform(coal.Transform3s(world[:3, :3], world[:3, 3]))
            assert not coal.collide(box, target, creq, coal.CollisionResult())


@pytest.mark.parametrize("subdivisions", [0, 2])
def test_hand_volumes_meet_the_part_exactly_where_coal_says(hand, subdivisions):
    """The compiled hand check (`hand_hits`: convex volumes against the pad model's triangle hierarchy) agrees with
    coal's boolean collision, pose by pose, for the hand's own swept body and a finger box placed at random about
    the bundled wheel, half of them touching it; also on the wheel subdivided 16-fold (a deeper hierarchy, whose
    nodes lie inside most of the body's face planes)."""
    from workbench.grasping.grasps import box_corners, hand_hits, swept_body

    mesh = load_object(bundled_objects()["wheel"]).mesh
    for _ in range(subdivisions):
        mesh = mesh.subdivide()
    target = _coal_mesh(mesh)
    rng = np.random.default_rng(3)
    q = rng.normal(size=(120, 4))
    poses = np.tile(np.eye(4), (120, 1, 1))
    for k in range(120):
        poses[k, :3, :3] = trimesh.transformations.quaternion_matrix(q[k] / np.linalg.norm(q[k]))[:3, :3]
    poses[:, :3, 3] = mesh.centroid + rng.uniform(-1, 1, (120, 3)) * mesh.extents
    body = swept_body(hand, 0.02)
    ext = np.array([0.022, 0.015, 0.02])
    points = coal.StdVec_Vec3s()
    for v in np.asarray(body.vertices, dtype=np.float64):
        points.append(v)
    pieces = [(np.asarray(body.vertices), coal.Convex.convexHull(points, False, None)), (box_corners(ext), coal.Box(*ext))]
    hits = 0
    for points, shape in pieces:
        got = hand_hits(mesh, [points], poses[:, None])
        for k in range(120):
            probe = coal.CollisionObject(shape, coal.Transform3s(poses[k, :3, :3], poses[k, :3, 3]))
            assert got[k] == bool(coal.collide(probe, target, coal.CollisionRequest(), coal.CollisionResult())), k
        hits += int(got.sum())
    assert 40 <= hits <= 200


def test_hull_and_hierarchy_built_beside_segmentation_give_the_same_plan(hand, monkeypatch):
    """A large part's first plan builds its convex hull and triangle hierarchy in a second thread: the grasps, the
    hull and the hierarchy are array-equal to those of a plan that builds them in turn (forced here on the bundled
    tube, by lowering the size from which the thread starts)."""
    import workbench.grasping.grasps as grasps

    mesh = load_object(bundled_objects()["tube"]).mesh
    plans, meshes = [], []
    for size in (10**12, 0):
        monkeypatch.setattr(grasps, "PREBUILD_TRIANGLES", size)
        obj = from_trimesh(mesh.copy(), "tube")
        plans.append(plan_grasps(obj, hand, GraspParams(rotations=4)))
        meshes.append(obj.mesh)
    serial, threaded = plans
    assert len(serial.grasps) > 0
    for f in serial.grasps.__dataclass_fields__:
        assert np.array_equal(getattr(serial.grasps, f), getattr(threaded.grasps, f)), f
    a, b = (m.convex_hull for m in meshes)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    for x, y in zip(*(m._cache["workbench_pad_bvh"] for m in meshes)):
        assert np.array_equal(x, y)


def test_grasp_counts_hold_as_the_part_is_subdivided(hand):
    """Time follows the part, not its triangles, and so do the grasps: a 60 mm blob scan at 960 triangles subdivided
    four-fold per level (the same surface) up to 245,760 triangles, and the bundled wheel up to 16 times its
    triangles, keep their grasp counts within 20% of the coarsest level's, with the same sampling seed."""
    from workbench.benchmarks.organic import blob

    for name, mesh, levels in (("blob", blob(seed=1, rows=12, cols=24), 4),
                               ("wheel", load_object(bundled_objects()["wheel"]).mesh, 2)):
        counts = []
        for level in range(levels + 1):
            counts.append(len(plan_grasps(from_trimesh(mesh, name), hand, GraspParams()).grasps))
            mesh = mesh.subdivide()
        assert min(counts) > 1000, (name, counts)
        assert all(abs(c - counts[0]) <= 0.2 * counts[0] for c in counts), (name, counts)
