"""Grasps with one finger inside a hole or cavity (CONVENTIONS.md, Gripper: the pads close from full opening, half
the jaw range either side of the TCP): a bin's wall gripped from above, a frame's bar lying flat, a washer's rim."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.benchmarks.graspcheck import check_grasps
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.grasping.pads import first_touches, gap_windows
from workbench.grasping.placements import free_tabletop_grips, stable_placements


def _frame(outer=0.1, inner=0.076, thickness=0.008):
    return trimesh.creation.box((outer, outer, thickness)).difference(
        trimesh.creation.box((inner, inner, 2 * thickness)))


def _bin(side=0.09, height=0.05, wall=0.004):
    cavity = trimesh.creation.box((side - 2 * wall, side - 2 * wall, height))
    cavity.apply_translation((0, 0, wall))
    return trimesh.creation.box((side, side, height)).difference(cavity)


@pytest.fixture(scope="module")
def frame():
    return from_trimesh(_frame(), "frame")


@pytest.fixture(scope="module")
def open_bin():
    return from_trimesh(_bin(), "bin")


def test_gap_windows_on_a_frame_bar_follow_the_line_crossings(frame, hand):
    """Along x through the frame's +x bar (12 mm wide, a 76 mm hole beyond): from its outer face the inner pad starts
    in the hole, 6 + J/2 mm below the sample, and the outer pad J/2 - 6 mm above; from the hole's face the same bar
    with the pads' roles swapped. Both windows computed by hand from the crossings at x = 50, 38, -38, -50 mm."""
    J = hand.jaw_max
    origins = np.array([[0.05, 0.0, 0.0], [0.038, 0.0, 0.0]])
    axes = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    idx, win, _ = gap_windows(frame.mesh, origins, axes, J)
    assert idx.tolist() == [0, 1]
    want = np.array([[-0.006 - J / 2, -0.006 + J / 2]] * 2)
    assert np.allclose(win, want, atol=1e-6)
    # the pads then touch the bar's two faces: a 12 mm grasp with the TCP in the bar
    t = first_touches(frame.mesh, origins[:1], axes[:1], np.zeros(1), hand, windows=win[:1])
    assert t.hit[0] and t.width[0] == pytest.approx(0.012, abs=1e-6)
    assert t.poses[0, 0, 3] == pytest.approx(0.044, abs=1e-6)


def test_a_hole_too_small_for_the_open_jaw_is_entered_at_the_pre_grasp_opening(hand):
    """A 60 mm frame with a 30 mm hole: across its 15 mm bar, a pad starting at full opening (40 mm from the TCP)
    would start in the far bar, so there is no window; at the pre-grasp opening (the bar plus 10 mm) the inner pad
    starts 5 mm inside the hole. Where the open jaw fits (the frame above), its windows stay as they are. The pads then close on the bar's two faces, and the grasps planned with it pass the
    independent check (trimesh, coal) at the grasp's and the pre-grasp opening."""
    small = _frame(outer=0.06, inner=0.03, thickness=0.008)
    origin, axis = np.array([[0.03, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    assert len(gap_windows(small, origin, axis, hand.jaw_max)[0]) == 0
    idx, win, _ = gap_windows(small, origin, axis, hand.jaw_max, margin=0.01)
    assert idx.tolist() == [0] and np.allclose(win, [[-0.0075 - 0.0125, -0.0075 + 0.0125]], atol=1e-6)
    big = np.array([[0.05, 0.0, 0.0]])
    assert np.array_equal(gap_windows(_frame(), big, axis, hand.jaw_max, margin=0.01)[1],
                          gap_windows(_frame(), big, axis, hand.jaw_max)[1])
    t = first_touches(small, origin, axis, np.zeros(1), hand, windows=win)
    assert t.hit[0] and t.width[0] == pytest.approx(0.015, abs=1e-6)
    obj = from_trimesh(small, "small frame")
    params = GraspParams()
    g = plan_grasps(obj, hand, params).grasps
    radial = np.abs(np.einsum("ij,ij->i", g.poses[:, :2, 1], g.poses[:, :2, 3] / np.linalg.norm(
        g.poses[:, :2, 3], axis=1, keepdims=True).clip(1e-12)))
    across = np.flatnonzero(np.isclose(g.jawwidth, 0.015, atol=1e-4) & (np.abs(g.poses[:, 2, 1]) < 1e-6) & (radial > 0.999))
    assert len(across) > 0
    v = check_grasps(obj.mesh, g.poses[across], g.jawwidth[across], g.contact0[across], g.contact1[across],
                     g.normal0[across], g.normal1[across], params.friction_coefficient,
                     pregrasp_margin=params.pregrasp_margin)
    assert v.ok.all()


def test_a_pad_blocked_at_full_opening_starts_again_at_the_pre_grasp_opening(hand):
    """The 100 mm frame with a bridge across its hole on its top face, at x = 0 to 8 mm: along the axis through the
    +x bar the hole is clear (the line meets the bar at x = 50 and 38 mm, then the far bar), so the full-opening
    window stands, but the inner pad starting there (x = 4 mm) cuts the bridge inside its footprint at every
    rotation. The narrow window (the bar's 12 mm plus the 10 mm margin) starts it 5 mm inside the hole, clear:
    `gap_touches` finds the 12 mm grasp across the bar there, and the planned grasps across the bar pass the
    independent check."""
    from workbench.grasping.grasps import gap_touches

    bridge = trimesh.creation.box((0.008, 0.1, 0.0045))
    bridge.apply_translation((0.004, 0.0, 0.00575))
    part = _frame().union(bridge)
    origin, axis = np.array([[0.05, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]])
    idx, win, narrow = gap_windows(part, origin, axis, hand.jaw_max, margin=0.01)
    assert idx.tolist() == [0]
    assert np.allclose(win, [[-0.006 - hand.jaw_max / 2, -0.006 + hand.jaw_max / 2]], atol=1e-6)
    assert np.allclose(narrow, [[-0.006 - 0.011, -0.006 + 0.011]], atol=1e-6)
    assert np.isnan(gap_windows(part, origin, axis, hand.jaw_max)[2]).all()  # no margin: no narrow window
    angles = 2 * np.pi * np.arange(8) / 8
    full = first_touches(part, origin, axis, angles, hand, windows=win, block=5e-4)
    assert not full.hit.any()
    t = gap_touches(part, origin, axis, angles, hand, None, win, narrow, 5e-4)
    assert t.hit.all() and np.allclose(t.width, 0.012, atol=1e-6) and np.allclose(t.poses[:, 0, 3], 0.044, atol=1e-6)
    obj = from_trimesh(part, "bridged frame")
    params = GraspParams()
    g = plan_grasps(obj, hand, params).grasps
    across = np.flatnonzero(np.isclose(g.jawwidth, 0.012, atol=1e-4) & (np.abs(g.poses[:, 0, 1]) > 0.999)
                            & (g.poses[:, 0, 3] > 0.04))
    assert len(across) > 0
    v = check_grasps(obj.mesh, g.poses[across], g.jawwidth[across], g.contact0[across], g.contact1[across],
                     g.normal0[across], g.normal1[across], params.friction_coefficient,
                     pregrasp_margin=params.pregrasp_margin)
    assert v.ok.all()


def test_no_gap_window_where_the_pads_start_outside_or_cannot_reach(box, hand):
    """A solid box narrower than the jaw is gripped from outside only; one wider than the jaw along the axis has no
    surface facing the other pad within reach."""
    m = box.mesh
    c = m.bounds.mean(axis=0)
    origins = np.array([[m.bounds[1, 0], c[1], c[2]]])
    idx, _, _ = gap_windows(m, origins, np.array([[1.0, 0.0, 0.0]]), hand.jaw_max)
    assert len(idx) == 0
    wide = trimesh.creation.box((0.12, 0.03, 0.03))
    idx, _, _ = gap_windows(wide, np.array([[0.06, 0.0, 0.0]]), np.array([[1.0, 0.0, 0.0]]), hand.jaw_max)
    assert len(idx) == 0


def _top_down(placements, grasps, hand, k):
    p, g, world = free_tabletop_grips(placements, grasps.poses, hand)
    keep = (p == k) & (world[:, 2, 2] < -0.999)
    return g[keep]


def test_an_open_bin_standing_up_is_gripped_by_its_wall_from_above(open_bin, hand):
    """A 90 mm bin is wider than the 80 mm jaw: standing on its base, the only grip from above is a wall, one finger
    inside. Without gap windows there is none; with them every such grip holds a 4 mm wall between its contacts and
    passes the independent check (trimesh closest points, coal)."""
    base = stable_placements(open_bin)
    up = int(np.flatnonzero(base.normals[:, 2] < -0.999)[0])  # resting on its base: its -z face down
    plain = plan_grasps(open_bin, hand, GraspParams(gap_grasps=False))
    plan = plan_grasps(open_bin, hand, GraspParams())
    assert plan.counts["gap"] > 0
    assert len(_top_down(base, plain.grasps, hand, up)) == 0
    g = plan.grasps
    sel = _top_down(base, g, hand, up)
    assert len(sel) >= 20
    assert np.allclose(g.jawwidth[sel], 0.004, atol=1e-6)
    # one contact on an outer face (|coordinate| 45 mm), the other on the inner face behind it (41 mm)
    c0, c1 = np.abs(g.contact0[sel, :2]).max(axis=1), np.abs(g.contact1[sel, :2]).max(axis=1)
    assert np.allclose(np.sort(np.c_[c0, c1], axis=1), [0.041, 0.045], atol=1e-6)
    v = check_grasps(open_bin.mesh, g.poses[sel], g.jawwidth[sel], g.contact0[sel], g.contact1[sel], g.normal0[sel],
                     g.normal1[sel], GraspParams().friction_coefficient)
    assert v.ok.all()


def test_a_frame_lying_flat_is_gripped_across_its_bars(frame, hand):
    """A 100 mm frame lying flat: no top-down grip in either placement without gap windows, and some in both with
    them, across a 12 mm bar."""
    base = stable_placements(frame)
    assert len(base.poses) == 2
    plain = plan_grasps(frame, hand, GraspParams(gap_grasps=False))
    plan = plan_grasps(frame, hand, GraspParams())
    for k in range(2):
        assert len(_top_down(base, plain.grasps, hand, k)) == 0
        sel = _top_down(base, plan.grasps, hand, k)
        assert len(sel) >= 4
        assert np.allclose(plan.grasps.jawwidth[sel], 0.012, atol=1e-6)


def test_gap_grasps_change_nothing_on_a_part_without_holes(box, hand):
    plain = plan_grasps(box, hand, GraspParams(gap_grasps=False))
    plan = plan_grasps(box, hand, GraspParams())
    assert plan.counts["gap"] == 0
    assert np.array_equal(plan.grasps.poses, plain.grasps.poses)


def test_the_friction_cone_check_during_the_search_changes_no_grasp(frame, open_bin, hand, monkeypatch):
    """The search skips the right pad of a pose whose left touch is outside the friction cone, except where a
    fingertip variant or a pre-grasp search may still make it a grasp. Planned again with that check off (every pose
    searched in full), a frame, a bin, a washer, a ring and a bumpy blob get bit-identical grasps and counts."""
    from workbench.benchmarks.organic import blob, torus, washer
    from workbench.grasping import pads

    parts = [frame, open_bin, from_trimesh(washer(0.06, 0.03, 0.005), "washer"),
             from_trimesh(torus(0.05, 0.012), "ring"), from_trimesh(blob(seed=3), "blob")]
    fields = ("poses", "jawwidth", "contact0", "contact1", "normal0", "normal1", "facet0", "facet1")
    keys = ("hand_poses", "pads_left", "pads_width", "pads_cone", "pads_com", "hand_open", "grasps")
    early = [plan_grasps(p, hand, GraspParams()) for p in parts]
    searched = pads._touches
    monkeypatch.setattr(pads, "_touches", lambda *a: searched(*a[:9], -2.0, *a[10:]))  # cone off
    for part, plan in zip(parts, early):
        part.mesh._cache.clear()
        full = plan_grasps(part, hand, GraspParams())
        assert len(plan.grasps) > 0, part.name
        for f in fields:
            assert np.array_equal(getattr(plan.grasps, f), getattr(full.grasps, f)), (part.name, f)
        assert [plan.counts[k] for k in keys] == [full.counts[k] for k in keys], part.name
    assert sum(p.counts["pads_left"] < p.counts["hand_poses"] for p in early) >= 3  # the check had poses to skip
