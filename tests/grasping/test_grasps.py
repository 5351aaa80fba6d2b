"""Grasp planning on facets (Wan & Harada, Section III): geometric truths, independent collision checks, store."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest
import trimesh

from workbench.errors import WorkbenchError
from workbench.geometry.facets import segment
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.planners.wan_harada.stages import ensure_grasps
from workbench.robots.gripper import parametric_gripper
from workbench.store import Store
from workbench.store.grasps import load_grasps


@pytest.fixture(scope="module")
def box_plan(box, hand):
    return plan_grasps(box, hand, GraspParams())


def test_box_conventional_segmentation_has_six_facets(box):
    facets = segment(box.mesh, method="conventional")
    assert len(facets) == 6
    assert np.allclose(np.abs(facets.normals).sum(axis=1), 1.0)  # axis-aligned normals
    assert sorted(np.round(facets.areas * 1e4, 6)) == sorted([20, 20, 15, 15, 12, 12])
    assert (np.diff(facets.edge_ptr) == 4).all()  # each face bounded by its four rectangle edges


def test_box_grasps_are_antipodal_across_opposite_faces(box, box_plan):
    g = box_plan.grasps
    assert len(g) > 50
    # normals antiparallel and along a box axis; jaw width equals the box's size along that axis
    assert np.allclose(g.normal0, -g.normal1, atol=1e-9)
    axis = np.argmax(np.abs(g.normal0), axis=1)
    assert np.allclose(np.abs(g.normal0[np.arange(len(g)), axis]), 1.0)
    assert np.allclose(g.jawwidth, box.mesh.extents[axis], atol=1e-9)
    # contacts lie on the two faces, the TCP midway on its y axis, y pointing to contact0
    half = box.mesh.extents / 2
    assert np.allclose(np.abs(g.contact0[np.arange(len(g)), axis]), half[axis])
    assert np.allclose(g.poses[:, :3, 3], (g.contact0 + g.contact1) / 2)
    assert np.allclose(g.poses[:, :3, 1], g.normal0, atol=1e-9)
    rot = g.poses[:, :3, :3]
    assert np.allclose(rot @ rot.transpose(0, 2, 1), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(rot), 1.0)
    # all three face pairs are used (each size fits the 80 mm jaw)
    assert set(np.round(g.jawwidth, 6)) == {0.03, 0.04, 0.05}


def test_cylinder_over_segmentation_overlaps(cylinder):
    conv = segment(cylinder.mesh, method="conventional")
    over = segment(cylinder.mesh, method="over")
    conv_count = np.bincount(conv.tri_index, minlength=len(cylinder.mesh.faces))
    over_count = np.bincount(over.tri_index, minlength=len(cylinder.mesh.faces))
    assert (conv_count == 1).all()  # conventional: each triangle in exactly one facet
    assert (over_count >= 1).all() and (over_count >= 2).any()  # over-segmentation: facets overlap
    assert len(over) > len(conv)
    # every facet is within tau of its seed's normal
    for f in range(len(over)):
        tris = over.triangles_of(f)
        cosines = cylinder.mesh.face_normals[tris] @ cylinder.mesh.face_normals[over.seeds[f]]
        assert (cosines >= np.cos(over.tau) - 1e-12).all()
    # the facets holding a few triangles (repeats and "no triangle" included) are those a brute-force scan finds
    tri = np.r_[np.random.default_rng(0).integers(0, len(cylinder.mesh.faces), 40), -1, 3, 3]
    counts, held = over.holding(tri)
    brute = [[f for f in range(len(over)) if t in over.triangles_of(f)] for t in tri]
    assert counts.tolist() == [len(b) for b in brute] and held.tolist() == sum(brute, [])


def test_over_segmentation_plans_more_grasps_on_curved_objects(cylinder, hand, tube_paper):
    for obj in (cylinder, tube_paper):
        conv = plan_grasps(obj, hand, GraspParams(segmentation="conventional"))
        over = plan_grasps(obj, hand, GraspParams(segmentation="over"))
        assert len(over.grasps) > len(conv.grasps) > 0, obj.name


def _independent_collision_free(obj, hand, grasps, samples_per_box: int = 60) -> None:
    """Checks with exact ray-parity containment (trimesh's rtree caster, not python-fcl and not Embree, whose
    single-precision parity is unreliable near surfaces), with the fingers at each grasp's pre-grasp opening (its
    width plus the default 10 mm margin, capped at the stroke; CONVENTIONS.md, Gripper): no hand-body or
    pre-grasp-finger point inside the object, no object vertex inside the pre-grasp fingers' boxes, and each pad's
    swept box from its pre-grasp position free of the object but at its contact (the fingers within the planner's
    0.5 mm clearance)."""
    from trimesh.ray.ray_triangle import RayMeshIntersector

    inside = RayMeshIntersector(obj.mesh).contains_points
    rng = np.random.default_rng(0)
    body = hand.body
    body_pts = np.vstack([body.vertices, trimesh.sample.sample_surface(body, 250, seed=1)[0]])
    # the finger boxes with the pads together, shrunk by the planner's finger clearance (0.5 mm: a pre-grasp finger
    # may graze a wall by less); each moves out by half the opening
    tol = GraspParams().finger_clearance + 1e-9
    closed = [(ext - 2 * tol, pose) for ext, pose in hand.finger_poses(0.0)]
    finger_pts = [(np.sign(pose[1, 3]), np.vstack([trimesh.creation.box(ext, pose).vertices,
                                                    trimesh.sample.volume_rectangular(ext, 15, pose, seed=2)]))
                  for ext, pose in closed]
    pregrasp = np.minimum(grasps.jawwidth + 0.010, hand.jaw_max)
    ext = hand.pad_extents
    for k in range(len(grasps)):
        pose = grasps.poses[k]
        pts = np.vstack([body_pts] + [q + [0.0, side * pregrasp[k] / 2, 0.0] for side, q in finger_pts])
        assert not inside(pts @ pose[:3, :3].T + pose[:3, 3]).any(), f"grasp {k}: hand inside object"
        # pad sweeps: boxes from the pre-grasp pad down to its contact, in the TCP frame; the sweep stops 0.5 mm
        # short, plus the rise of a facet tilted against the jaw axis across the pad's face (CONVENTIONS: the pad
        # meets the object only at its contact)
        w = grasps.jawwidth[k]
        reach = np.hypot(ext[0] / 2, ext[2] / 2 + abs(hand.pad_center[2]))
        for side, normal in ((1, grasps.normal0[k]), (-1, grasps.normal1[k])):
            cos = float(normal @ (side * pose[:3, 1]))
            lo, hi = w / 2 + 5e-4 + reach * np.tan(np.arccos(min(cos, 1.0))), pregrasp[k] / 2 + ext[1] - tol
            if lo >= hi:
                continue  # the pad's tilt allowance covers its whole travel
            u = rng.random((samples_per_box, 3))
            local = np.column_stack([(u[:, 0] - 0.5) * (ext[0] - 2 * tol), side * (lo + u[:, 1] * (hi - lo)),
                                     hand.pad_center[2] + (u[:, 2] - 0.5) * (ext[2] - 2 * tol)])
            assert not inside(local @ pose[:3, :3].T + pose[:3, 3]).any(), f"grasp {k}: pad sweep hits object"
    # object vertices never inside any pre-grasp finger box
    inv = np.linalg.inv(grasps.poses)
    v = obj.mesh.vertices
    tcp_pts = np.einsum("gij,vj->gvi", inv[:, :3, :3], v) + inv[:, None, :3, 3]
    for box_ext, box_pose in closed:
        centre = box_pose[:3, 3][None, :] + np.sign(box_pose[1, 3]) * pregrasp[:, None] / 2 * np.array([0.0, 1.0, 0.0])
        local = np.einsum("ji,gvj->gvi", box_pose[:3, :3], tcp_pts - centre[:, None, :])
        assert not (np.abs(local) < box_ext / 2 - 1e-9).all(axis=2).any()


def test_box_grasps_are_collision_free_by_independent_check(box, hand, box_plan):
    _independent_collision_free(box, hand, box_plan.grasps)


@pytest.mark.parametrize("name", ["tube", "wheel", "tail", "drill"])
def test_bundled_grasps_are_collision_free_by_independent_check(bundled, hand, name):
    obj = bundled[name]
    plan = plan_grasps(obj, hand, GraspParams())
    assert len(plan.grasps) > 50
    pick = np.linspace(0, len(plan.grasps) - 1, 25).astype(int)
    sub = type(plan.grasps)(**{k: v[pick] for k, v in plan.grasps.__dict__.items()})
    _independent_collision_free(obj, hand, sub, samples_per_box=40)


def test_tube_grasps_are_collision_free_by_independent_check(tube_paper, hand):
    plan = plan_grasps(tube_paper, hand, GraspParams())
    assert len(plan.grasps) > 50
    pick = np.linspace(0, len(plan.grasps) - 1, 60).astype(int)
    sub = type(plan.grasps)(**{k: v[pick] for k, v in plan.grasps.__dict__.items()})
    _independent_collision_free(tube_paper, hand, sub, samples_per_box=40)
    # and the collided candidates really collide somewhere: level 2 removed some poses
    assert (~plan.candidate_free).any()


def test_concave_part_rejects_pad_inside_slot(hand):
    """A U-shaped part: grasps across the slot's inner walls would put a pad in the slot's far wall."""
    outer = trimesh.creation.box((0.06, 0.04, 0.03))
    slot = trimesh.creation.box((0.02, 0.05, 0.04))
    slot.apply_translation([0, 0, 0.01])
    part = from_trimesh(outer.difference(slot), "u_part")
    plan = plan_grasps(part, hand, GraspParams())
    assert len(plan.grasps) > 0
    # a grasp pinching the two inner slot walls (normals facing each other across the slot) would need
    # each pad to sweep through the opposite wall: none survive
    mid = plan.grasps.poses[:, :3, 3]
    inner = (np.abs(plan.grasps.jawwidth - 0.02) < 1e-6) & (np.abs(mid[:, 0]) < 1e-6)
    assert not inner.any()
    _independent_collision_free(part, hand, plan.grasps)


def test_parametric_gripper_respects_its_jaw(box):
    small = parametric_gripper(jaw_range=(0.0, 0.035), palm_box=(0.04, 0.08, 0.04))
    plan = plan_grasps(box, small, GraspParams())
    assert len(plan.grasps) > 0
    assert (plan.grasps.jawwidth <= 0.035).all()
    assert set(np.round(plan.grasps.jawwidth, 6)) == {0.03}


def test_planning_is_deterministic(box, hand):
    a = plan_grasps(box, hand, GraspParams(seed=3)).grasps
    b = plan_grasps(box, hand, GraspParams(seed=3)).grasps
    for key, value in a.__dict__.items():
        assert np.array_equal(value, getattr(b, key)), key
    c = plan_grasps(box, hand, GraspParams(seed=4)).grasps
    assert not (len(c) == len(a) and np.array_equal(c.poses, a.poses))


def test_counts_are_monotone(box, hand, box_plan):
    c = box_plan.counts
    assert c["samples"] >= c["samples_neighbour"]
    assert c["facet_samples"] >= c["facet_samples_distance"]
    # the pad model: one hand pose per kept facet sample and rotation, plus the fingertip variants, then width, cone,
    # centre of mass, level 2
    assert c["facet_samples_distance"] >= c["axes"]
    assert c["hand_poses"] == c["axes"] * box_plan.params.rotations + c["fingertip"]
    assert (c["hand_poses"] >= c["pads_left"] >= c["pads_width"] >= c["pads_cone"] >= c["pads_com"] >= c["hand_open"]
            >= c["grasps"])
    paper = plan_grasps(box, hand, GraspParams(contact_model="paper")).counts
    assert paper["contact_pairs"] >= paper["pairs_width"] >= paper["pairs_com"] >= paper["pairs_level1"]
    assert paper["hand_poses"] == paper["pairs_level1"] * box_plan.params.rotations >= paper["hand_open"] >= paper["grasps"]


@pytest.mark.parametrize("bad", [dict(tau=0.0), dict(tau=2.0), dict(rotations=0), dict(dist_min=0.03, dist_max=0.02),
                                 dict(com_max=-1.0), dict(density=0.0), dict(contact_model="magic"),
                                 dict(friction=-0.1), dict(finger_clearance=-1e-3), dict(lengths="elastic")])
def test_bad_parameters_are_refused(bad):
    with pytest.raises(WorkbenchError):
        GraspParams(**bad)


def test_bad_segmentation_method(box):
    with pytest.raises(WorkbenchError, match="segmentation method"):
        segment(box.mesh, method="watershed")


def test_store_round_trip_and_reuse(tmp_path, box, hand):
    db = tmp_path / "g.duckdb"
    params = GraspParams()
    first = ensure_grasps(db, box, hand, params)
    assert not first.reused and first.count == len(first.plan.grasps)
    with Store(db) as store:
        rows = load_grasps(store, first.idobject)
        n_rows = store.one("SELECT count(*) FROM freeairgrip")[0]
    g = first.plan.grasps
    assert np.allclose(rows["rotmat"], g.poses) and np.allclose(rows["contactpoint0"], g.contact0)
    assert np.allclose(rows["jawwidth"], g.jawwidth) and np.allclose(rows["contactnormal1"], g.normal1)
    again = ensure_grasps(db, box, hand, params)
    assert again.reused and again.idparamset == first.idparamset and again.count == first.count
    other = ensure_grasps(db, box, hand, GraspParams(rotations=4))
    assert not other.reused and other.idparamset != first.idparamset
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM freeairgrip")[0] == n_rows + other.count
        assert store.one("SELECT count(*) FROM object")[0] == 1


def test_stored_rotation_is_the_right_handed_angle_about_the_jaw_axis(box, hand):
    """`freeairgrip.rotation` is the angle that turns the reference approach z0 into the grasp's z about +y
    (right-handed), as the schema documents; recomputed here from the poses alone."""
    plan = plan_grasps(box, hand, GraspParams(rotations=8))
    g = plan.grasps
    assert len(g.poses) > 0
    y = g.poses[:, :3, 1]
    z = g.poses[:, :3, 2]
    ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    z0 = ref - np.einsum("ij,ij->i", ref, y)[:, None] * y
    z0 /= np.linalg.norm(z0, axis=1, keepdims=True)
    angle = np.arctan2(np.einsum("ij,ij->i", np.cross(z0, z), y), np.einsum("ij,ij->i", z0, z))
    diff = np.angle(np.exp(1j * (angle - g.rotation)))
    assert np.abs(diff).max() < 1e-9


def test_fingers_at_the_grasps_opening_are_checked(hand):
    """A plate with a flange 30 mm behind its edge: the fully open hand straddles the flange, but fingers closed on the
    10 mm plate would cut into it. Those poses are removed by level 2 at the grasp's opening, and every kept grasp
    passes the independent check (coal via pinocchio, fingers at the grasp's opening)."""
    from workbench.benchmarks.graspcheck import check_grasps

    plate = trimesh.creation.box((0.06, 0.010, 0.05))
    flange = trimesh.creation.box((0.06, 0.05, 0.006))
    flange.apply_translation([0, 0, -0.025 - 0.030])  # 30 mm below the plate's lower edge... along -z
    stem = trimesh.creation.box((0.06, 0.010, 0.032))
    stem.apply_translation([0, 0, -0.025 - 0.014])
    part = from_trimesh(trimesh.util.concatenate([plate, stem, flange]), "flanged_plate")
    # at full opening the approach straddles the flange (the pre-grasp opening removes these poses before)
    plan = plan_grasps(part, hand, GraspParams(pregrasp_margin=None))
    c = plan.counts
    assert c["hand_open"] > c["grasps"] > 0, c  # some poses fail only with the fingers at the grasp's opening
    g = plan.grasps
    pick = np.unique(np.linspace(0, len(g) - 1, 40).astype(int))
    v = check_grasps(part.mesh, g.poses[pick], g.jawwidth[pick], g.contact0[pick], g.contact1[pick], g.normal0[pick],
                     g.normal1[pick], plan.params.friction_coefficient)
    assert v.ok.all(), ((~v.clear).sum(), (~v.surface).sum(), (~v.cone).sum(), (~v.pads).sum())


def test_pad_model_keeps_the_paper_pairs_on_the_papers_tube(tube_paper, hand):
    """Where the paper's pairing finds a grasp, the pad model closes onto the same pair (CONVENTIONS.md, Gripper):
    under the same segmentation and fixed lengths, at least 90% of the paper model's grasps reappear pose for pose
    (TCP within 1 mm and 3 degrees, opening within 0.5 mm). The contacts themselves may move along a pad resting on a
    facet strip of the tube (a line contact: the pad model takes the touch nearest the axis). The pad model finds
    more, where the paper's rotation-invariant level-1 cylinder rejects a pair at every rotation while the pad
    rectangle fits at some; `workbench bench grasps` prints both counts."""
    paper = plan_grasps(tube_paper, hand, GraspParams(contact_model="paper", lengths="fixed")).grasps
    pads = plan_grasps(tube_paper, hand, GraspParams(lengths="fixed")).grasps
    assert len(paper) > 100
    # brute force over every pair of grasps: origin distance, rotation angle, opening
    d_origin = np.linalg.norm(paper.poses[:, None, :3, 3] - pads.poses[None, :, :3, 3], axis=2)
    cos = (np.einsum("aji,bji->ab", paper.poses[:, :3, :3], pads.poses[:, :3, :3]) - 1) / 2
    d_width = np.abs(paper.jawwidth[:, None] - pads.jawwidth[None])
    same = (d_origin <= 1e-3) & (cos >= np.cos(np.radians(3.0))) & (d_width <= 5e-4)
    assert same.any(axis=1).mean() >= 0.9, same.any(axis=1).mean()
    assert len(pads) > len(paper)


def test_literal_over_segmentation_runs_on_the_bracket_within_4_gib():
    """Every triangle a seed (merge_angle 0, the paper's "repeatedly examining all triangle meshes"): the facets and
    the boundary distances of every (facet, sample) pair fit in 4 GiB (distances compiled, without temporaries)."""
    code = textwrap.dedent("""
        import resource, warnings
        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
        warnings.simplefilter("ignore")
        from workbench.geometry.facets import segment
        from workbench.geometry.objects import load_object
        from workbench.geometry.sampling import distribute, sample_count
        from workbench.resources import bundled_objects
        mesh = load_object(bundled_objects()["bracket"]).mesh
        facets = segment(mesh, merge_angle=0.0)
        s = distribute(mesh, facets, sample_count(mesh, None, 0.01), 0.01, 0.002, 0.02, 0)
        print(len(mesh.faces), len(facets), len(s.pair_facet), int(s.pair_ok.sum()))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    tri, facets, pairs, kept = map(int, out.stdout.split())
    assert facets > 2000 and pairs > 10 * facets // 100 and kept > 0


def test_boundary_distances_match_a_brute_force_projection():
    """Each point's distance to its facet's boundary, in the facet's plane, against a brute force over every boundary
    edge of the facet in numpy; a facet's own boundary vertices lie at distance 0."""
    from workbench.benchmarks.organic import blob
    from workbench.geometry.facets import distance_to_boundary, segment

    mesh = blob(seed=4)
    facets = segment(mesh)
    rng = np.random.default_rng(1)
    fid = rng.integers(0, len(facets), 200)
    pts = facets.centers[fid] + rng.normal(0, 2e-3, (200, 3))
    got = distance_to_boundary(facets, fid, pts)
    for f, p, d in zip(fid, pts, got):
        n, seg = facets.normals[f], facets.edges[facets.edge_ptr[f]:facets.edge_ptr[f + 1]]
        a, b = seg[:, 0] - ((seg[:, 0] - p) @ n)[:, None] * n, seg[:, 1] - ((seg[:, 1] - p) @ n)[:, None] * n
        t = np.clip(((p - a) * (b - a)).sum(1) / ((b - a) ** 2).sum(1), 0, 1)
        assert np.isclose(d, np.linalg.norm(p - a - t[:, None] * (b - a), axis=1).min(), rtol=1e-9, atol=1e-15)
    corner = facets.edges[facets.edge_ptr[fid[:5]], 0]
    assert np.allclose(distance_to_boundary(facets, fid[:5], corner), 0.0, atol=1e-15)


def test_the_seeds_are_ordered_by_area_as_a_stable_sort_orders_them():
    """Segmentation's seed order (largest area first, ties by index, from the float's bits) against numpy's stable
    argsort of the negated areas: random areas, areas with many ties and zeros, one value, none."""
    from workbench.geometry._radix import descending_order

    rng = np.random.default_rng(2)
    for areas in (rng.random(50_000) * 1e-7, rng.integers(0, 4, 5_000) * 1e-6, np.full(7, 2e-5), np.zeros(0)):
        rounded = np.round(areas, 12)
        assert np.array_equal(descending_order(rounded.view(np.int64)), np.argsort(-rounded, kind="stable"))


def test_facet_boundaries_are_the_edges_a_facet_uses_once_on_open_and_non_manifold_meshes():
    """Every facet's boundary against a count of its triangles' edges in Python: the edges used once, in ascending
    order of their vertex pair. On a closed sphere, on the sphere with a hole cut in it (edges of one triangle) and
    on a box with a fin on one edge (an edge of three triangles)."""
    from collections import Counter

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    box = trimesh.creation.box((0.04, 0.03, 0.02))
    edge = box.edges_unique[0]
    fin = np.vstack([box.vertices, box.vertices[edge].mean(0) + [0.0, 0.0, 0.03]])
    meshes = [sphere, trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 2] < 0.02],
                                      process=False),
              trimesh.Trimesh(fin, np.vstack([box.faces, [[edge[0], edge[1], len(box.vertices)]]]), process=False)]
    for mesh in meshes:
        for method in ("over", "conventional"):
            facets = segment(mesh, np.radians(18), method)
            for f in range(len(facets)):
                uses = Counter(tuple(sorted(map(int, e))) for t in facets.triangles_of(f)
                               for e in zip(mesh.faces[t], np.roll(mesh.faces[t], -1)))
                once = np.array(sorted(e for e, k in uses.items() if k == 1)).reshape(-1, 2)
                got = facets.edges[facets.edge_ptr[f]:facets.edge_ptr[f + 1]]
                assert np.array_equal(got, mesh.vertices[once]), (method, f)
                length = np.linalg.norm(mesh.vertices[once[:, 1]] - mesh.vertices[once[:, 0]], axis=1).sum()
                assert np.isclose(facets.perimeters[f], length, rtol=1e-12, atol=0), (method, f)


def test_first_touches_of_one_rotation_match_the_full_set(tube_paper, hand):
    """Closing the pads at a single rotation gives the touches that rotation gets among all eight (the rotations are
    applied to the rotation-0 frame, whatever the first angle asked)."""
    from workbench.grasping.pads import first_touches

    mesh = tube_paper.mesh
    rng = np.random.default_rng(0)
    face = rng.choice(len(mesh.faces), 30, replace=False)
    origins, axes = mesh.triangles_center[face], mesh.face_normals[face]
    angles = 2 * np.pi * np.arange(8) / 8
    full = first_touches(mesh, origins, axes, angles, hand)
    for j in (1, 3, 6):
        one = first_touches(mesh, origins, axes, angles[j:j + 1], hand)
        rows = np.arange(len(face)) * 8 + j
        assert np.array_equal(one.hit, full.hit[rows])
        hit = one.hit
        assert hit.sum() > 10
        assert np.allclose(one.poses[hit], full.poses[rows][hit], atol=1e-12)
        assert np.allclose(one.point0[hit], full.point0[rows][hit], atol=1e-12)
        assert np.allclose(one.point1[hit], full.point1[rows][hit], atol=1e-12)


def test_a_mesh_is_segmented_once_per_parameters_and_again_when_it_changes():
    """Planning a part again with the same segmentation parameters (another density, friction or gripper) reuses its
    facets; other parameters, or a changed mesh, segment again, equal to a fresh mesh's segmentation."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.03)
    first = segment(mesh, np.radians(18))
    assert segment(mesh, np.radians(18)) is first
    with pytest.raises(ValueError):
        first.tri_index[0] = 1  # shared by every plan of the mesh: read-only
    other = segment(mesh, np.radians(10))
    fresh = segment(mesh.copy(), np.radians(10))
    assert other is not first and len(other) == len(fresh) and np.array_equal(other.tri_index, fresh.tri_index)
    mesh.vertices = mesh.vertices * np.array([1.0, 1.0, 2.0])  # stretched: other normals, other facets
    again = segment(mesh, np.radians(10))
    stretched = segment(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False), np.radians(10))
    assert again is not other and np.array_equal(again.tri_ptr, stretched.tri_ptr)
    assert np.array_equal(again.tri_index, stretched.tri_index) and not np.array_equal(again.tri_ptr, other.tri_ptr)


@pytest.mark.parametrize("name", ["tube", "bracket"])
def test_the_opening_is_the_contacts_distance_along_the_jaw_axis(bundled, hand, name):
    """The pads stop at their contacts: where several points of a pad's footprint touch within its tie (1 um), the
    contact is the one nearest the axis and the pad stops at its height, so every grasp's opening is its contacts'
    distance along the TCP's y axis and the TCP lies midway between them along it, to rounding, on the bundled tube
    and bracket (curved and faceted sides, where the first touches tie)."""
    g = plan_grasps(bundled[name], hand, GraspParams()).grasps
    assert len(g) > 100
    y = g.poses[:, :3, 1]
    along = np.einsum("ij,ij->i", g.contact0 - g.contact1, y)
    assert np.abs(along - g.jawwidth).max() < 1e-12
    assert np.abs(np.einsum("ij,ij->i", 0.5 * (g.contact0 + g.contact1) - g.poses[:, :3, 3], y)).max() < 1e-12
