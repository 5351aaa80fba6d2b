"""The pad contact model's first touches (CONVENTIONS.md, Gripper) against computations that share none of its code."""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.grasping import _padkernel
from workbench.grasping.pads import first_touches, pad_rectangle


def _bumpy(subdivisions: int = 4) -> trimesh.Trimesh:
    """A 60 mm sphere with smooth bumps: no face parallel to a pad, contacts off the jaw axis."""
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.03)
    v = m.vertices
    r = 1 + 0.08 * np.sin(5 * v[:, 0] / 0.03) * np.cos(4 * v[:, 1] / 0.03)
    return trimesh.Trimesh(v * r[:, None], m.faces, process=False)


def test_first_touch_is_the_highest_surface_point_in_the_pad_footprint(hand):
    """Rays cast along -y through a dense grid over the left pad's rectangle find the surface's highest point there:
    the first touch is at least that high, and no higher than it plus the grid's slope error."""
    mesh = _bumpy()
    rng = np.random.default_rng(1)
    face = rng.choice(len(mesh.faces), 12, replace=False)
    origins, axes = mesh.triangles_center[face], mesh.face_normals[face]
    angles = np.array([0.0, 1.1])
    t = first_touches(mesh, origins, axes, angles, hand)
    assert t.hit.all()
    cx, cz, hx, hz = pad_rectangle(hand)
    gx, gz = np.meshgrid(np.linspace(-hx, hx, 41) + cx, np.linspace(-hz, hz, 41) + cz)
    for h in range(len(t)):
        frame = t.poses[h]
        x, y, z, o = frame[:3, 0], frame[:3, 1], frame[:3, 2], frame[:3, 3]
        starts = o + gx.reshape(-1, 1) * x + gz.reshape(-1, 1) * z + 0.2 * y
        locs, ray, _ = mesh.ray.intersects_location(starts, np.tile(-y, (len(starts), 1)), multiple_hits=False)
        top = ((locs - o) @ y).max()
        touch = (t.point0[h] - o) @ y
        # the pad's contact lies in its rectangle, on the surface
        local = np.linalg.solve(frame[:3, :3], t.point0[h] - o)
        assert abs(local[0] - cx) <= hx + 1e-9 and abs(local[2] - cz) <= hz + 1e-9
        assert trimesh.proximity.closest_point(mesh, t.point0[h][None])[1][0] < 1e-9
        assert touch >= top - 1e-7
        assert touch <= top + 1e-3  # 1 mm: a grid step (0.5 mm) on slopes of at most about 60 degrees


def test_hierarchy_and_scan_give_the_same_touches(hand):
    """The triangle hierarchy only chooses which triangles are tested: its touches equal a scan of every triangle
    (one leaf holding them all), on a curved mesh and on a flat-subdivided one where many triangles tie; with more
    hand rotations than one search serves at once (64), and each rotation's touches equal its search alone."""
    for mesh in (_bumpy(5), trimesh.creation.box((0.04, 0.05, 0.03)).subdivide().subdivide().subdivide()):
        rng = np.random.default_rng(2)
        face = rng.choice(len(mesh.faces), 40, replace=False)
        origins, axes = mesh.triangles_center[face], mesh.face_normals[face]
        angles = 2 * np.pi * np.arange(70) / 70
        alone = first_touches(mesh, origins, axes, angles[[3, 67]], hand)
        tree = first_touches(mesh, origins, axes, angles, hand)
        scan = _padkernel.triangle_bvh(mesh.vertices, mesh.faces, mesh.face_normals, leaf=len(mesh.faces))
        assert len(scan[0]) == 2  # one leaf: the root
        mesh._cache["workbench_pad_bvh"] = scan
        brute = first_touches(mesh, origins, axes, angles, hand)
        assert tree.hit.sum() > 100
        assert np.array_equal(tree.hit, brute.hit)
        assert np.array_equal(tree.tri0, brute.tri0) and np.array_equal(tree.tri1, brute.tri1)
        assert np.allclose(tree.poses, brute.poses, atol=1e-12)
        both = tree.poses.reshape(40, 70, 4, 4)[:, [3, 67]].reshape(-1, 4, 4)
        assert np.array_equal(both, alone.poses)


def test_pad_offsets_place_contacts_on_the_pads(hand):
    """On a box face parallel to the pads the contact is the sampled point on the jaw axis, at the pad's centre in x;
    every offset lies within the pad (|offset| <= 1)."""
    from workbench.geometry.objects import from_trimesh
    from workbench.grasping.grasps import GraspParams, plan_grasps
    from workbench.grasping.pads import edge_share, pad_offsets, pad_rectangle

    box = from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")
    g = plan_grasps(box, hand, GraspParams()).grasps
    off = np.vstack([pad_offsets(g.poses, g.contact0, hand), pad_offsets(g.poses, g.contact1, hand)])
    assert (np.abs(off) <= 1 + 1e-9).all()
    cx, cz, hx, hz = pad_rectangle(hand)
    on_axis = np.abs(np.einsum("gji,gj->gi", g.poses[:, :3, :3], g.contact0 - g.poses[:, :3, 3])[:, [0, 2]]).max(axis=1) < 1e-9
    assert on_axis.sum() > 10
    assert np.allclose(off[: len(g)][on_axis], [-cx / hx, -cz / hz])
    assert 0.0 <= edge_share(g.poses, g.contact0, g.contact1, hand) < 0.5


def test_a_pad_starting_inside_the_part_touches_nothing(hand):
    """A pad whose window start lies inside the part (a 10 mm slab's top and bottom faces cross its starting plane
    inside its footprint) starts in the material: no first touch, not a touch on the material past its start."""
    slab = trimesh.creation.box((0.04, 0.04, 0.01))
    origin, axis = np.zeros((1, 3)), np.array([[0.0, 1.0, 0.0]])
    ref = np.array([[0.0, 0.0, 1.0]])
    outside = first_touches(slab, origin, axis, np.zeros(1), hand, ref=ref, windows=np.array([[-0.03, 0.03]]))
    assert outside.hit.all() and np.isclose(outside.width[0], 0.04)
    inside = first_touches(slab, origin, axis, np.zeros(1), hand, ref=ref, windows=np.array([[-0.01, 0.03]]))
    assert not inside.hit.any()


def test_parallel60_grasps_of_the_planebody_keep_both_fingers_out_of_it():
    """The parallel60 fingers are their pads: a gap grasp whose right pad started inside the planebody's wall held
    a finger 1.5 mm inside it at the grasp's opening. Every grasp passes coal's check of the hand at the grasp's and
    the pre-grasp opening (benchmarks.graspcheck, none of the planner's code)."""
    from workbench.benchmarks.graspcheck import check_grasps
    from workbench.cli.gripper import load_gripper
    from workbench.geometry.objects import load_object
    from workbench.grasping.grasps import GraspParams, plan_grasps
    from workbench.resources import bundled_objects

    obj = load_object(bundled_objects()["planebody"])
    params = GraspParams()
    g = plan_grasps(obj, load_gripper("parallel60"), params).grasps
    assert len(g) >= 50
    v = check_grasps(obj.mesh, g.poses, g.jawwidth, g.contact0, g.contact1, g.normal0, g.normal1,
                     params.friction_coefficient, hand="parallel60", pregrasp_margin=params.pregrasp_margin)
    assert v.ok.all(), np.flatnonzero(~v.ok)


def test_a_first_touch_outside_the_friction_cone_skips_only_the_right_pad(hand):
    """With the cone given, a pose whose left touch's normal (the mesh's own face normal, read here) lies outside it
    keeps its left touch and is not a hit; every other pose, and every pose `need` names, is exactly the full
    search's."""
    mesh = _bumpy(4)
    rng = np.random.default_rng(5)
    face = rng.choice(len(mesh.faces), 60, replace=False)
    axes = mesh.face_normals[face] + rng.normal(scale=0.25, size=(60, 3))  # jaw axes off the surface normals
    origins, angles = mesh.triangles_center[face], np.linspace(0, 2 * np.pi, 8, endpoint=False)
    cos_f = np.cos(np.arctan(0.3))
    need = rng.random(60 * 8) < 0.2
    full = first_touches(mesh, origins, axes, angles, hand)
    early = first_touches(mesh, origins, axes, angles, hand, cone=cos_f, need=need)
    y = full.poses[:, :3, 1]
    inside = (full.tri0 >= 0) & (np.einsum("ij,ij->i", mesh.face_normals[np.maximum(full.tri0, 0)], y) >= cos_f)
    skipped = (full.tri0 >= 0) & ~inside & ~need
    assert skipped.sum() > 50 and (inside & full.hit).sum() > 50
    kept = ~skipped
    assert np.array_equal(early.hit[kept], full.hit[kept])
    assert np.array_equal(early.tri0, full.tri0) and np.array_equal(early.tri1[kept], full.tri1[kept])
    assert np.array_equal(early.poses[kept], full.poses[kept]) and np.array_equal(early.point0, full.point0)
    assert not early.hit[skipped].any() and (early.tri1[skipped] == -1).all()


def test_the_hierarchy_splits_space_at_every_node():
    """The triangles are ordered so that every node of the implicit tree holds those of one box of space: at each
    node, the centres of its left child's triangles all come before its right child's along some axis."""
    from workbench.grasping._padkernel import _select

    mesh = _bumpy(4)
    shape, slots, leaf, tri_s, _ = _padkernel.triangle_bvh(mesh.vertices, mesh.faces, mesh.face_normals)
    assert np.array_equal(np.sort(slots[slots >= 0]), np.arange(len(mesh.faces)))
    assert np.array_equal(tri_s, mesh.triangles[slots[slots >= 0]])  # each slot's corners, gathered from the mesh
    centre = mesh.triangles_center
    P = len(shape) // 2

    def members(node: int) -> np.ndarray:
        lo, hi = node, node
        while lo < P:
            lo, hi = 2 * lo, 2 * hi + 1
        s = slots[(lo - P) * leaf:(hi - P + 1) * leaf]
        return s[s >= 0]

    split = 0
    for node in range(1, P):
        a, b = members(2 * node), members(2 * node + 1)
        if len(a) and len(b):
            split += 1
            assert any(centre[a, k].max() <= centre[b, k].min() for k in range(3)), node
    assert split > 100
    # the selection it rests on, against a sort: ties broken by index
    rng = np.random.default_rng(0)
    for n in (2, 3, 4, 9, 200):
        pc = rng.integers(0, 4, size=(n, 3)).astype(float)
        order = rng.permutation(n).astype(np.int64)
        key = sorted(zip(pc[:, 1], order))
        k = int(rng.integers(0, n))
        _select(pc, order, 1, 0, n, k)
        assert sorted(zip(pc[:k, 1], order[:k])) == key[:k]


def test_the_partition_of_a_large_node_selects_as_a_sort_does_and_bounds_both_sides():
    """`_partition`, which splits a large node by a histogram, against a sort: the same triangles before the split
    (ties by index), the centres moved with them, and each side's bounds those of its centres; on coarse centres with
    many ties, on centres all equal along the axis, and on a range inside the array."""
    from workbench.grasping._padkernel import _partition

    rng = np.random.default_rng(3)
    for n, a, b, levels, ax in ((5_000, 0, 5_000, 7, 0), (3_000, 400, 2_900, 1_000_000, 2), (600, 0, 600, 1, 1)):
        pc = rng.integers(0, levels, size=(n, 3)).astype(float) * 1e-3
        order = rng.permutation(n).astype(np.int64)
        m = int(rng.integers(a + 1, b))
        rows = {int(o): tuple(c) for o, c in zip(order, pc)}
        key = sorted(zip(pc[a:b, ax], order[a:b]))
        before, after = order[:a].copy(), order[b:].copy()
        left, right = np.empty(6), np.empty(6)
        box = pc[a:b, ax].min(), pc[a:b, ax].max()
        _partition(pc, order, ax, a, b, m, box[0], box[1], np.empty(n, dtype=np.int64), np.empty((n, 3)),
                   np.empty(n, dtype=np.int64), np.empty(1024, dtype=np.int64), left, right)
        assert sorted(zip(pc[a:m, ax], order[a:m])) == key[:m - a]
        assert np.array_equal(order[:a], before) and np.array_equal(order[b:], after)
        assert all(rows[int(o)] == tuple(c) for o, c in zip(order, pc))
        assert np.array_equal(left, np.r_[pc[a:m].min(0), pc[a:m].max(0)])
        assert np.array_equal(right, np.r_[pc[m:b].min(0), pc[m:b].max(0)])
