"""Stable placements, free tabletop grips and the tabletop roadmap data (Wan & Harada, Sections IV and VI)."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import trimesh
from matplotlib.path import Path

from workbench.errors import WorkbenchError
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.grasping.placements import (
    PlacementParams,
    free_tabletop_grips,
    stable_placements,
)
from workbench.planners.wan_harada.stages import ensure_grasps, ensure_placements
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.store import Store
from workbench.store.placements import load_tabletop_grips

SMALL_GRID = TabletopParams(x_min=0.4, x_max=0.6, nx=2, y_min=-0.1, y_max=0.1, ny=2, angles=4, max_grasps=30)


def _check_rest_pose(obj, pose):
    placed = obj.mesh.vertices @ pose[:3, :3].T + pose[:3, 3]
    com = pose[:3, :3] @ obj.com + pose[:3, 3]
    assert abs(placed[:, 2].min()) < 1e-9  # lowest point on the table
    assert np.allclose(com[:2], 0, atol=1e-9)  # centre of mass above the origin
    assert np.allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)


def test_cube_has_six_placements_with_four_grip_families(hand):
    cube = from_trimesh(trimesh.creation.box((0.05, 0.05, 0.05)), "cube")
    pl = stable_placements(cube)
    assert len(pl) == 6
    assert np.allclose(pl.stability, 1.0)  # margin 25 mm over height 25 mm
    for pose in pl.poses:
        _check_rest_pose(cube, pose)
    grasps = plan_grasps(cube, hand, GraspParams()).grasps
    p, g, world = free_tabletop_grips(pl, grasps.poses, hand)
    for k in range(6):
        normals = np.einsum("ij,gj->gi", pl.poses[k, :3, :3], grasps.normal0[g[p == k]])
        # the left pad touches one of the four vertical faces: four families, never the top or bottom face
        families = {tuple(n) for n in np.round(normals, 6)}
        assert families == {(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0)}
        # and the approach never comes from under the table
        assert (world[p == k][:, 2, 2] <= 1e-9).all()


def test_long_thin_box_stability_follows_geometry():
    bar = from_trimesh(trimesh.creation.box((0.02, 0.03, 0.15)), "bar")
    pl = stable_placements(bar, PlacementParams(min_stability=0.0))
    assert len(pl) == 6
    # stability = half the narrower support side over the centre-of-mass height, per face pair
    expected = sorted([0.01 / 0.015, 0.01 / 0.015, 0.015 / 0.01, 0.015 / 0.01, 0.01 / 0.075, 0.01 / 0.075])
    assert np.allclose(sorted(pl.stability), expected)
    strict = stable_placements(bar, PlacementParams(min_stability=0.2))
    assert len(strict) == 4  # standing on an end is too tippy
    assert np.allclose(sorted(strict.rejected_stability), [0.01 / 0.075] * 2)


def test_tube_stands_on_rims_not_on_curved_side():
    tube = from_trimesh(trimesh.creation.annulus(r_min=0.02, r_max=0.03, height=0.08, sections=64), "tube")
    pl = stable_placements(tube)
    assert len(pl) == 2
    # standing: the axis (object z) is vertical in both placements
    assert np.allclose(np.abs(pl.poses[:, 2, 2]), 1.0)
    # the curved side's flat strips are rejected: their stability is tan(pi / sections)
    assert np.allclose(pl.rejected_stability, np.tan(np.pi / 64), rtol=1e-6)


@pytest.mark.parametrize("radius", [0.003, 0.005])
def test_a_thin_faceted_rod_rests_on_its_strips_not_on_the_edges_between_them(radius):
    """A 32-sided rod 6 mm across: each side strip lies within the sliver distance of its neighbour's plane, but is
    as large as it, so the two are not one support (joined, the rod would rest on the edge between them, scored on
    a polygon that only touches the table along that edge). Every side rests on its own strip, as on a 10 mm rod:
    stability tan(pi / 32), below the default threshold, and the strip flat on the table."""
    rod = from_trimesh(trimesh.creation.cylinder(radius=radius, height=0.2, sections=32), "rod")
    assert len(stable_placements(rod)) == 0
    pl = stable_placements(rod, PlacementParams(min_stability=0.09))
    assert len(pl) == 32 and np.allclose(pl.stability, np.tan(np.pi / 32), rtol=1e-6)
    hull = np.asarray(rod.mesh.convex_hull.vertices)
    for pose in pl.poses:
        z = (hull @ pose[:3, :3].T + pose[:3, 3])[:, 2]
        assert z.min() == pytest.approx(0.0, abs=1e-12)
        assert (np.abs(z) <= 1e-9).sum() == 4  # the strip's four corners touch, not an edge's two


def test_foil_thinner_than_the_coplanar_tolerance_rests_on_either_side():
    """A 10 micron foil: its two sides lie within the 0.5 mm merge distance of each other but face away from each
    other, so they stay two supports (merged, their normals cancelled and the placement stage divided by zero)."""
    import warnings

    foil = from_trimesh(trimesh.creation.box((0.05, 0.04, 1e-5)), "foil")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        p = stable_placements(foil)
    assert len(p) == 2
    assert np.allclose(np.sort(p.normals[:, 2]), [-1.0, 1.0])
    assert (p.stability > 100).all()  # 20 mm of margin over a 5 micron height


def test_off_centre_mass_tips_over():
    """An L-shaped part cannot rest on the face whose support its centre of mass overhangs."""
    a = trimesh.creation.box((0.10, 0.02, 0.02))
    b = trimesh.creation.box((0.02, 0.02, 0.08))
    b.apply_translation([0.04, 0, 0.05])
    part = from_trimesh(a.union(b), "ell")
    pl = stable_placements(part, PlacementParams(min_stability=0.0))
    assert len(pl.rejected_stability) > 0 and (pl.rejected_stability <= 0).all()
    for support in pl.supports:
        # an independent point-in-polygon check of the centre of mass's projection
        assert Path(support[:, :2]).contains_point((0.0, 0.0))


def test_drop_test_of_every_placement_of_the_bundled_objects(bundled):
    import physics

    for name in sorted(bundled):
        obj = bundled[name]
        for pose in stable_placements(obj).poses:
            angle, shift = physics.drop_test(obj.mesh, pose)
            assert angle < 2.0 and shift < 0.002, (name, angle, shift)


@pytest.fixture(scope="module")
def built(tmp_path_factory, hand, tube_paper):
    db = tmp_path_factory.mktemp("pl") / "p.duckdb"
    g = ensure_grasps(db, tube_paper, hand, GraspParams())
    r = ensure_placements(db, g.idobject, tube_paper, g.idparamset, hand, PlacementParams(), SMALL_GRID)
    return db, g, r


def test_drop_test_of_every_stored_placement(built):
    """Placements read back from the store (with the stored mesh) rest in MuJoCo: < 2 degrees and 2 mm in 1 s."""
    import physics

    from workbench.planners.wan_harada.stages import get_object

    db, g, r = built
    with Store(db) as store:
        _, obj = get_object(store, "TU")
        rows = store.query_arrays("SELECT rotmat FROM freetabletopplacement WHERE idparamset = ?", [r.idplacements])
    poses = rows["rotmat"].reshape(-1, 4, 4)
    assert len(poses) == len(r.placements["stability"]) > 0
    fresh = stable_placements(obj)  # the rocking flag and probability round-trip through the store
    assert np.array_equal(r.placements["rocking"] == 1, fresh.rocking) and np.isin(r.placements["rocking"], (0, 1)).all()
    assert np.allclose(r.placements["probability"], fresh.probability)
    for pose in poses:
        angle, shift = physics.drop_test(obj.mesh, pose)
        assert angle < 2.0 and shift < 0.002, (angle, shift)


def test_tabletop_grips_keep_hand_above_table(built, hand):
    db, g, r = built
    with Store(db) as store:
        rows = load_tabletop_grips(store, g.idobject, r.idtabletop)
    assert r.n_tabletop_grips == len(rows["jawwidth"]) > 0
    verts = hand.collision_mesh().vertices  # every vertex, not the planner's hull points
    z = np.einsum("nj,vj->nv", rows["rotmat"][:, 2, :3], verts) + rows["rotmat"][:, 2, 3:4]
    assert z.min() >= 0.002 - 1e-12


def test_tabletop_rows_agree_with_their_sources(built):
    db, g, r = built
    with Store(db) as store:
        joined = store.query_arrays(
            "SELECT t.rotmat AS tg, p.rotmat AS tp, f.rotmat AS fa, t.contactpoint0 AS c0, f.contactpoint0 AS f0, "
            "p.tabletopposition AS pos, a.value AS angle, fp.rotmat AS fp "
            "FROM tabletopgrips t JOIN tabletopplacements p USING (idtabletopplacements) "
            "JOIN freeairgrip f USING (idfreeairgrip) JOIN angle a USING (idangle) "
            "JOIN freetabletopplacement fp ON fp.idfreetabletopplacement = p.idfreetabletopplacement")
        n_tp = store.one("SELECT count(*) FROM tabletopplacements WHERE idparamset = ?", [r.idtabletop])[0]
    tg, tp, fa, fp = (joined[k].reshape(-1, 4, 4) for k in ("tg", "tp", "fa", "fp"))
    assert np.allclose(tg, tp @ fa, atol=1e-12)  # TCP in world = object in world @ TCP in object
    c0 = np.einsum("nij,nj->ni", tp[:, :3, :3], joined["f0"]) + tp[:, :3, 3]
    assert np.allclose(joined["c0"], c0, atol=1e-12)
    # object pose = translate(position) @ yaw(angle) @ free placement
    c, s = np.cos(joined["angle"]), np.sin(joined["angle"])
    assert np.allclose(tp[:, 0, :3], c[:, None] * fp[:, 0, :3] - s[:, None] * fp[:, 1, :3], atol=1e-12)
    assert np.allclose(tp[:, :2, 3], joined["pos"][:, :2] + np.column_stack([c * fp[:, 0, 3] - s * fp[:, 1, 3], s * fp[:, 0, 3] + c * fp[:, 1, 3]]), atol=1e-12)
    assert n_tp == len(r.placements["stability"]) * 4 * 4


def test_rerun_reuses_and_new_parameters_add_a_set(built, hand, tube_paper):
    db, g, r = built
    with Store(db) as store:
        before = store.one("SELECT count(*) FROM tabletopgrips")[0]
    again = ensure_placements(db, g.idobject, tube_paper, g.idparamset, hand, PlacementParams(), SMALL_GRID)
    assert again.reused and again.idtabletop == r.idtabletop
    wider = TabletopParams(**{**SMALL_GRID.as_dict(), "angles": 2})
    other = ensure_placements(db, g.idobject, tube_paper, g.idparamset, hand, PlacementParams(), wider)
    assert not other.reused and other.idtabletop != r.idtabletop and other.idplacements == r.idplacements
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM tabletopgrips")[0] == before + other.n_tabletop_grips
        assert store.one("SELECT count(*) FROM tabletopgrips g JOIN tabletopplacements p USING (idtabletopplacements) "
                         "WHERE p.idparamset = ?", [r.idtabletop])[0] == r.n_tabletop_grips


def test_killed_run_leaves_store_as_it_was_and_resumes(tmp_path, hand, box):
    """SIGKILL in the middle of the tabletop stage's transaction: nothing of it is stored; the re-run completes."""
    db = tmp_path / "k.duckdb"
    g = ensure_grasps(db, box, hand, GraspParams())
    script = textwrap.dedent(f"""
        import os, signal, trimesh
        from workbench.store import Store
        from workbench.geometry.objects import from_trimesh
        from workbench.robots.gripper import franka_hand
        from workbench.planners.wan_harada.stages import ensure_placements
        from workbench.grasping.placements import PlacementParams
        from workbench.planners.wan_harada.tabletop import TabletopParams
        original = Store.insert
        def insert(self, table, columns):
            n = original(self, table, columns)
            if table == "tabletopgrips":
                os.kill(os.getpid(), signal.SIGKILL)  # after rows went in, before COMMIT
            return n
        Store.insert = insert
        box = from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")
        ensure_placements({str(db)!r}, {g.idobject}, box, {g.idparamset}, franka_hand(), PlacementParams(),
                          TabletopParams(**{SMALL_GRID.as_dict()!r}))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM tabletopgrips")[0] == 0
        assert store.one("SELECT count(*) FROM tabletopplacements")[0] == 0
        assert store.one("SELECT count(*) FROM paramset WHERE stage = 'tabletop'")[0] == 0
        placed = store.one("SELECT count(*) FROM freetabletopplacement")[0]
        assert placed == 6  # the placements stage had committed before the kill
        assert store.one("SELECT count(*) FROM freeairgrip")[0] == g.count
    r = ensure_placements(db, g.idobject, box, g.idparamset, hand, PlacementParams(), SMALL_GRID)
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM tabletopgrips")[0] == r.n_tabletop_grips > 0
        assert store.one("SELECT count(*) FROM freetabletopplacement")[0] == 6


@pytest.mark.parametrize("bad", [dict(nx=0), dict(angles=0), dict(x_min=1.0, x_max=0.0), dict(max_grasps=0),
                                 dict(y_min=float("nan"))])
def test_bad_grid_is_refused(bad):
    with pytest.raises(WorkbenchError):
        TabletopParams(**bad)


def test_bad_stability_threshold_is_refused():
    with pytest.raises(WorkbenchError):
        PlacementParams(min_stability=-1)


def test_grasp_cap_keeps_every_placement_in_the_roadmap():
    from workbench.planners.wan_harada.tabletop import select_grasps

    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (300, 1, 1))
    poses[:, :3, 3] = rng.random((300, 3))
    usable = np.zeros((3, 300), dtype=bool)
    usable[0, :250] = True  # a placement most grasps serve
    usable[1, 100:290] = True
    usable[2, [295, 296, 297, 298, 299]] = True  # a placement only five grasps serve
    chosen = select_grasps(poses, usable, 20)
    assert len(np.unique(chosen)) == len(chosen) and 20 <= len(chosen) <= 24
    assert usable[2, chosen].sum() >= 4 and usable[:, chosen].any(axis=0).all()
    assert np.array_equal(chosen, select_grasps(poses, usable, 20))  # deterministic
    assert len(select_grasps(poses, usable, None)) == 295  # every usable grasp when uncapped


@pytest.mark.parametrize("r_min,r_max,height", [(0.010, 0.025, 0.006), (0.015, 0.030, 0.005)])
def test_a_washer_lying_flat_is_gripped_from_above_by_the_fingertips(hand, r_min, r_max, height):
    """A washer 5 or 6 mm thick lying flat: a pad centred on the rim would reach 9.5 mm below it, into the table, so
    without fingertip grasps no grasp survives either placement. With them (GraspParams.fingertip_margin) some do on
    both sides, also where the hand moved back lifts the jaw axis off the part (the pads then close on the rim with
    their tips), and each kept grip, checked here by brute force on the gripper's collision mesh and finger boxes,
    stays above the table with both contacts on the pads' faces and the part between them."""
    washer = from_trimesh(trimesh.creation.annulus(r_min=r_min, r_max=r_max, height=height), "washer")
    places = stable_placements(washer)
    assert len(places) == 2  # flat on either side
    centre_only = plan_grasps(washer, hand, GraspParams(fingertip_margin=None)).grasps
    p, _, _ = free_tabletop_grips(places, centre_only.poses, hand)
    assert len(centre_only) > 0 and len(p) == 0
    plan = plan_grasps(washer, hand, GraspParams())
    g = plan.grasps
    assert plan.counts["fingertip"] > 0
    p, k, world = free_tabletop_grips(places, g.poses, hand)
    assert len(p) > 0 and set(p.tolist()) == {0, 1}
    assert abs(int((p == 0).sum()) - int((p == 1).sum())) <= 0.2 * len(p)  # the two sides alike
    body = np.asarray(hand.collision_mesh().vertices)
    for pi, gi, tcp in zip(p, k, world):
        pts = [body] + [trimesh.creation.box(ext, pose).vertices + [0, np.sign(pose[1, 3]) * g.jawwidth[gi] / 2, 0]
                        for ext, pose in hand.finger_poses(0.0)]
        low = min(float((np.asarray(q) @ tcp[:3, :3].T + tcp[:3, 3])[:, 2].min()) for q in pts)
        assert low >= 0.002 - 1e-9
        # the contacts lie on the pads (within their rectangles) and inside the washer's 6 mm height on the table
        for c in (g.contact0[gi], g.contact1[gi]):
            z = (places.poses[pi] @ np.r_[c, 1.0])[2]
            assert -1e-9 <= z <= height + 1e-9
        # the TCP sits above the part: the hand was moved back along its approach
        assert tcp[2, 3] > height


def _ray_shares(mesh: trimesh.Trimesh, com: np.ndarray, normals: np.ndarray, n: int = 40000) -> np.ndarray:
    """Monte Carlo: the share of uniformly random directions from the centre of mass whose ray leaves the part
    through each support (faces within 1 degree of its normal), by ray casting, without solid-angle formulas."""
    rng = np.random.default_rng(5)
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    _, ray, tri = mesh.ray.intersects_location(np.tile(com, (n, 1)), d, multiple_hits=False)
    face_n = mesh.face_normals[tri]
    share = np.array([(face_n @ nn >= np.cos(np.radians(1.0))).sum() for nn in normals]) / n
    return share


def test_rest_probabilities_of_boxes_match_ray_statistics():
    from workbench.geometry.objects import from_trimesh, load_object
    from workbench.geometry.symmetry import part_symmetry
    from workbench.resources import bundled_objects
    from workbench.grasping.placements import stable_placements

    cube = from_trimesh(trimesh.creation.box((0.04, 0.04, 0.04)), "cube")
    p = stable_placements(cube)
    assert len(p) == 6 and np.isclose(p.probability.sum(), 1.0)
    assert np.ptp(p.probability) <= 0.01 * p.probability.mean()
    # the bundled tube's two flat sides are swapped by a half turn: equally likely, whatever the hull's triangulation
    # (its quasi-static flow alone gives them 0.468 and 0.456)
    tube = load_object(bundled_objects()["tube"])
    p = stable_placements(tube)
    turn = part_symmetry(tube.mesh.convex_hull, centre=tube.com).turns
    assert len(turn) == 2 and np.allclose(turn[1] @ p.normals[0], p.normals[1], atol=1e-6)
    assert p.probability[0] == pytest.approx(p.probability[1], abs=1e-12) and np.isclose(p.probability.sum(), 1.0)
    long = from_trimesh(trimesh.creation.box((0.10, 0.03, 0.02)), "long")
    p = stable_placements(long)
    assert len(p) == 6 and np.all(np.diff(p.probability) <= 1e-12)  # ordered, most likely first
    assert np.allclose(np.abs(p.normals[:2]), [0, 0, 1])  # the two 100 x 30 mm faces are the likeliest
    assert np.allclose(p.probability, _ray_shares(long.mesh, long.com, p.normals), atol=0.01)


def test_faceted_round_sides_get_a_low_probability_and_rock():
    from workbench.geometry.objects import from_trimesh
    from workbench.geometry.supports import coplanar_groups, rest_probabilities, stabilities
    from workbench.grasping.placements import PlacementParams, stable_placements

    # a 37 mm pin lying on its faceted round side, with two flats milled 6 mm deep
    pin = trimesh.boolean.intersection([trimesh.creation.cylinder(radius=0.0185, height=0.05, sections=24),
                                        trimesh.creation.box((0.04, 0.025, 0.06))], engine="manifold")
    obj = from_trimesh(pin, "pin")
    p = stable_placements(obj)
    side = np.abs(p.normals[:, 2]) < 0.5  # round side or flats
    flats = side & (np.abs(p.normals[:, 1]) > 0.999)
    facets = side & ~flats
    assert facets.sum() >= 4 and flats.sum() == 2
    assert (p.stability[facets] >= 0.1).all()  # the support-polygon score keeps the facets the part rolls off
    assert (p.probability[facets] < 0.05).all() and (p.probability[facets] < p.probability[flats].min() / 4).all()
    assert p.rocking[facets].all() and not p.rocking[flats].any()
    kept = stable_placements(obj, PlacementParams(min_probability=0.05))
    assert len(kept) == int((~facets).sum()) and not kept.rocking.any()
    steady = stable_placements(obj, PlacementParams(reject_rocking=True))
    assert len(steady) == int((~p.rocking).sum()) and not steady.rocking.any()
    assert np.allclose(np.sort(steady.stability), np.sort(p.stability[~p.rocking]))
    # the stated tilt: tipped by atan(min_stability) about any edge of its support polygon, every kept placement's
    # centre of mass stays over the support (checked on the placed vertices, without the stability formula)
    tilt = np.arctan(PlacementParams().min_stability)
    for pose, support in zip(p.poses, p.supports):
        com = pose[:3, :3] @ obj.com + pose[:3, 3]
        ring = support[:, :2]
        for a, b in zip(ring, np.roll(ring, -1, axis=0)):
            edge = (b - a) / np.linalg.norm(b - a)
            inward = np.array([-edge[1], edge[0]])  # counter-clockwise ring: the interior is on the left
            r, h = float((com[:2] - a) @ inward), float(com[2])
            # rotated by the tilt about the edge, toward the outside: the horizontal offset from the pivot
            assert r * np.cos(tilt) - h * np.sin(tilt) > 0, (r, h)
    # a 12-sided bar's sides (30 degrees apart, tipping at 15) rock; a hexagonal bar's (60 degrees) do not
    for sections, rocks in ((12, True), (6, False)):
        bar = from_trimesh(trimesh.creation.cylinder(radius=0.015, height=0.06, sections=sections), "bar")
        hull = bar.mesh.convex_hull
        groups, normals = coplanar_groups(hull, 5e-4, np.radians(1.0))
        held = stabilities(hull, bar.com, groups, normals) > 0
        prob, rocking = rest_probabilities(hull, bar.com, groups, normals, held, np.radians(35.0))
        sides = np.abs(normals[:, 2]) < 0.5
        assert sides.sum() == sections and np.isclose(prob.sum(), 1.0)
        assert (rocking[sides] == rocks).all() and not rocking[~sides].any(), sections
