"""The pre-grasp opening (CONVENTIONS.md, Gripper): the hand approaches at the grasp's opening plus a margin, capped
at the stroke, and must clear the part along the approach; checked against an independent coal test."""

from __future__ import annotations

import coal
import manifold3d as mf
import numpy as np
import pytest
import trimesh

from workbench.errors import ParameterError
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps, pregrasp_widths
from workbench.robots.gripper import franka_hand

APPROACH = 0.05


def _box(lo, hi) -> mf.Manifold:
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return mf.Manifold.cube((hi - lo).tolist()).translate(lo.tolist())


def comb(wall_y: float) -> trimesh.Trimesh:
    """A 30 mm block on a base plate with a wall either side at |y| >= `wall_y`, 70 mm tall: gripped across the
    block from above, the Franka fingers at full opening (their wide base 51-66 mm out) reach into the walls' tops,
    at the block's opening plus 10 mm (31-46 mm out) they pass beside them."""
    part = _box([-0.02, -0.06, 0.0], [0.02, 0.06, 0.01]) + _box([-0.02, -0.015, 0.0], [0.02, 0.015, 0.05])
    for s in (1, -1):
        part = part + _box([-0.02, min(s * wall_y, s * 0.06), 0.0], [0.02, max(s * wall_y, s * 0.06), 0.07])
    m = part.to_mesh()
    return trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts), process=True)


@pytest.fixture(scope="module")
def hand():
    return franka_hand()


def _coal_boxes(gripper, opening: float, shrink: float):
    return [(coal.Box(*np.maximum(ext - 2 * shrink, 1e-6)), pose) for ext, pose in gripper.finger_poses(opening)]


def _coal_hits(gripper, mesh: trimesh.Trimesh, pose: np.ndarray, opening: float, shrink: float,
               step: float = 0.001) -> bool:
    """Independent check: the hand body (coal BVH of its mesh) and every finger box (coal boxes) at `opening`,
    stepped `step` apart from APPROACH back along -z to `pose`, against the part."""
    obj = coal.BVHModelOBBRSS()
    obj.beginModel(len(mesh.faces), len(mesh.vertices))
    obj.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    obj.addTriangles(np.asarray(mesh.faces, dtype=np.int32))
    obj.endModel()
    body = coal.BVHModelOBBRSS()
    body.beginModel(len(gripper.body.faces), len(gripper.body.vertices))
    body.addVertices(np.asarray(gripper.body.vertices, dtype=np.float64))
    body.addTriangles(np.asarray(gripper.body.faces, dtype=np.int32))
    body.endModel()
    shapes = [(body, np.eye(4))] + _coal_boxes(gripper, opening, shrink)
    for d in np.arange(0.0, APPROACH + 1e-9, step):
        at = pose.copy()
        at[:3, 3] -= d * pose[:3, 2]
        for geom, local in shapes:
            m = at @ local
            req, res = coal.CollisionRequest(), coal.CollisionResult()
            if coal.collide(geom, coal.Transform3s(m[:3, :3], m[:3, 3]), obj, coal.Transform3s(), req, res):
                return True
    return False


def _top_down_block(plan) -> np.ndarray:
    """Indices of the grasps across the central block from straight above, at its mid-height."""
    g = plan.grasps
    return np.flatnonzero((np.abs(g.jawwidth - 0.03) < 1e-6) & (g.poses[:, 2, 2] < -0.999)
                          & (np.abs(g.poses[:, 2, 3] - 0.035) < 0.012) & (np.abs(g.poses[:, 1, 1]) > 0.999))


def test_pregrasp_width_is_width_plus_margin_capped_at_stroke():
    w = np.array([0.0, 0.03, 0.075, 0.08])
    assert np.allclose(pregrasp_widths(w, 0.08, 0.01), [0.01, 0.04, 0.08, 0.08])
    assert np.allclose(pregrasp_widths(w, 0.08, None), 0.08)
    for bad in (-0.001, float("nan"), 1.0):
        with pytest.raises(ParameterError, match="pregrasp_margin"):
            GraspParams(pregrasp_margin=bad)
    full = GraspParams(pregrasp_margin=None)  # the stored parameter set, hence the store's digest, tells them apart
    assert GraspParams.from_dict(full.as_dict()) == full != GraspParams()


def test_grasp_between_walls_needs_the_pregrasp_opening(hand):
    obj = from_trimesh(comb(0.050), name="comb")
    pre = plan_grasps(obj, hand, GraspParams())
    full = plan_grasps(obj, hand, GraspParams(pregrasp_margin=None))
    kept = _top_down_block(pre)
    assert len(kept) >= 1, "the block between the walls gets its top-down grasp at the pre-grasp opening"
    assert len(_top_down_block(full)) == 0, "at full opening the fingers' base reaches into the walls"
    pose = pre.grasps.poses[kept[0]]
    # independently: the full-open hand hits the walls at the grasp, the pre-grasp hand clears them all the way in
    assert _coal_hits(hand, obj.mesh, pose, hand.jaw_max, 5e-4, step=APPROACH)
    assert not _coal_hits(hand, obj.mesh, pose, 0.04, 5e-4)


def test_pregrasp_sweep_refusals_match_an_independent_check(hand):
    """Walls nearer (|y| >= 30 mm) stand in the path of the pre-grasp fingers' wide base: the top-down block grasp
    is refused, and every refusal and every kept grasp agrees with coal stepping the approach 1 mm at a time."""
    obj = from_trimesh(comb(0.030), name="comb_tight")
    plan = plan_grasps(obj, hand, GraspParams())
    assert len(_top_down_block(plan)) == 0
    params = plan.params
    cand = plan.candidate_poses
    widths = plan.pairs.width[plan.candidate_pair]
    rng = np.random.default_rng(0)
    kept = np.flatnonzero(plan.candidate_free)
    # level 2's refusals: candidates the approach check removed (the fingers' check at the grasp comes after it)
    from workbench.grasping.grasps import approach_collides
    hit = approach_collides(hand, cand, params.pregrasp(widths, hand), obj.mesh, APPROACH,
                            params.finger_clearance)
    refused = np.flatnonzero(hit)
    assert len(kept) > 0 and len(refused) > 0
    for i in rng.choice(kept, min(15, len(kept)), replace=False):
        assert not _coal_hits(hand, obj.mesh, cand[i], params.pregrasp(widths[[i]], hand)[0], 5e-4), i
    confirmed = [_coal_hits(hand, obj.mesh, cand[i], params.pregrasp(widths[[i]], hand)[0], 5e-4)
                 for i in rng.choice(refused, min(15, len(refused)), replace=False)]
    assert all(confirmed), confirmed


def test_contact_offsets_and_robustness_are_stored(hand, tmp_path):
    """Each contact's place on its pad, checked against the finger box read directly (its inner face's rectangle in
    the TCP frame), and the robustness score round trip through the store; rows from before it load as NaN."""
    import duckdb

    from workbench.grasping.grasps import contact_robustness
    from workbench.planners.wan_harada.stages import ensure_grasps
    from workbench.store import Store
    from workbench.store.grasps import load_grasps

    obj = from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), name="box")
    g = plan_grasps(obj, hand, GraspParams()).grasps
    ext, pose = hand.finger_boxes[hand.pad]
    centre, half = pose[:3, 3][[0, 2]], ext[[0, 2]] / 2
    for contact, offset in ((g.contact0, g.offset0), (g.contact1, g.offset1)):
        local = np.einsum("gji,gj->gi", g.poses[:, :3, :3], contact - g.poses[:, :3, 3])
        assert np.allclose(offset, (local[:, [0, 2]] - centre) / half, atol=1e-9)
    assert (np.abs(g.offset0) <= 1 + 1e-9).all() and (np.abs(g.offset1) <= 1 + 1e-9).all()
    worst = np.maximum(np.abs(g.offset0).max(axis=1), np.abs(g.offset1).max(axis=1))
    assert np.allclose(g.robustness, np.clip(1 - worst, 0, 1))
    assert np.allclose(contact_robustness(np.zeros((1, 2)), np.array([[0.0, 1.5]])), 0.0)
    db = tmp_path / "g.duckdb"
    res = ensure_grasps(db, obj, hand, GraspParams())
    with Store(db) as store:
        stored = load_grasps(store, res.idobject, res.idparamset)
    assert np.allclose(np.sort(stored["robustness"]), np.sort(g.robustness))
    con = duckdb.connect(str(db))  # rows written before the column existed (the migration adds it empty)
    con.execute("UPDATE freeairgrip SET robustness = NULL")
    con.close()
    with Store(db) as store:
        assert np.isnan(load_grasps(store, res.idobject, res.idparamset)["robustness"]).all()
