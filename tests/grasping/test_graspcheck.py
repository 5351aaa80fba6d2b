"""The independent grasp check's hand-into-part test: shrunk solids and coal's boolean collision, no penetration
depth. Against geometric truths: fingertips lowered into a slab (the depth is the deepest box corner's, by trimesh's
signed distance), a wall through a finger with no corner inside it, a hand inside a closed part, and the inward
offset of the hand body's hull (volume less area times the offset)."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh

from workbench.benchmarks.graspcheck import INTRUSION_TOL, _hand_model, hand_intrudes, hand_placements, shrunk
from workbench.robots.gripper import BUNDLED

HANDS = ["franka", "parallel60", str(BUNDLED["robotiq-2f85"])]


def _corners(opening: float, hand: str) -> np.ndarray:
    """Every box corner of the hand in the TCP frame."""
    out = []
    for g, M in hand_placements(opening, hand):
        if isinstance(g, coal.Box):
            h = np.asarray(g.halfSide)
            c = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * h
            out.append(c @ M[:3, :3].T + M[:3, 3])
    return np.vstack(out)


def _down(z: float) -> np.ndarray:
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # approach along world -z
    pose[2, 3] = z
    return pose


@pytest.mark.parametrize("hand", HANDS)
def test_fingertips_lowered_into_a_slab_count_from_the_tolerance(hand):
    slab = trimesh.creation.box((0.4, 0.4, 0.02))  # top face at z = 0.01
    w = 0.04
    tip = _corners(w, hand)[:, 2].max()  # fingertips' reach along the approach
    depths = np.array([0.0, 2e-4, 0.8e-3, 1.3e-3, 3e-3, 8e-3])
    poses = np.array([_down(0.01 + tip - d) for d in depths])
    got = hand_intrudes(slab, poses, np.full(len(poses), w), hand)
    # the truth: the deepest box corner's signed distance into the slab (a box into a half-space)
    truth = []
    for pose in poses:
        c = _corners(w, hand) @ pose[:3, :3].T + pose[:3, 3]
        truth.append(trimesh.proximity.signed_distance(slab, c).max())
    truth = np.array(truth)
    assert np.allclose(truth, depths, atol=1e-6)
    assert (got == (truth > INTRUSION_TOL)).all(), (got, truth)


def test_a_wall_through_a_finger_with_no_corner_inside_is_caught():
    w = 0.04
    boxes = [(np.asarray(g.halfSide), M) for g, M in hand_placements(w, "parallel60") if isinstance(g, coal.Box) and M[1, 3] > 0]
    half, M = max(boxes, key=lambda b: b[1][2, 3])  # the left finger
    height = 2 * half[2] - 4e-3  # within the finger's length, clear of the palm
    wall = trimesh.creation.box((0.003, 0.3, height))  # 3 mm thick, across both fingers' middle
    wall.apply_translation(M[:3, 3])
    corners = _corners(w, "parallel60")
    assert (trimesh.proximity.signed_distance(wall, corners) < 0).all()  # every corner outside the wall
    assert hand_intrudes(wall, np.eye(4)[None], np.array([w]), "parallel60").all()
    thin = trimesh.creation.box((2 * INTRUSION_TOL - 2e-4, 0.3, height))  # centred on the fingers' side faces: it
    thin.apply_translation(M[:3, 3] + [half[0], 0, 0])  # reaches 0.9 mm into them, within the tolerance
    assert not hand_intrudes(thin, np.eye(4)[None], np.array([w]), "parallel60").any()


def test_a_hand_wholly_inside_a_closed_part_is_caught():
    block = trimesh.creation.box((1.0, 1.0, 1.0))
    assert block.is_watertight
    assert hand_intrudes(block, np.eye(4)[None], np.array([0.04]), "franka").all()


def test_the_hand_body_hull_moves_in_by_the_tolerance():
    _, _, parts, _, _ = _hand_model("franka")
    body = next(g for _, g in parts if not isinstance(g, coal.Box))
    hull = trimesh.convex.convex_hull(np.array([body.point(i) for i in range(body.num_points)]))
    inner = shrunk(body, 1e-3)
    lost = hull.volume - inner.computeVolume()
    assert lost == pytest.approx(hull.area * 1e-3, rel=0.05)  # first order in the offset
    pts = np.array([inner.point(i) for i in range(inner.num_points)])
    assert (trimesh.proximity.signed_distance(hull, pts) >= 1e-3 - 1e-7).all()  # every vertex 1 mm inside


def test_a_spec_with_a_palm_mesh_is_checked_by_the_meshs_hull(tmp_path):
    """A gripper never seen before, its palm a cylinder mesh (spec `palm.mesh`): lowered palm-first into a slab, it
    intrudes exactly when the mesh's deepest vertex is more than the tolerance in (trimesh's signed distance)."""
    import yaml

    from workbench.robots.gripper import load_gripper

    palm = trimesh.creation.cylinder(radius=0.04, height=0.05, sections=24)
    palm.apply_translation([0, 0, 0.025])
    palm.export(tmp_path / "round_palm.stl")
    spec = {"name": "round-palm", "stroke": [0.0, 0.05], "tcp": [0.0, 0.0, 0.09],
            "pad": {"size": [0.015, 0.02], "thickness": 0.005}, "finger": {"size": [0.015, 0.01, 0.05]},
            "palm": {"mesh": "round_palm.stl"}}
    path = tmp_path / "round_palm.yaml"
    path.write_text(yaml.safe_dump(spec))
    assert load_gripper(str(path)).name == "round-palm"  # the workbench's loader takes it too
    slab = trimesh.creation.box((0.4, 0.4, 0.02))  # top face at z = 0.01
    depths = np.array([0.0, 5e-4, 1.5e-3, 4e-3])
    poses = np.repeat(np.eye(4)[None], len(depths), axis=0)
    poses[:, 2, 3] = 0.01 + 0.09 - depths  # the palm's base face (hand z = 0) `depth` below the slab's top
    got = hand_intrudes(slab, poses, np.full(len(poses), 0.03), str(path))
    truth = np.array([trimesh.proximity.signed_distance(slab, palm.vertices + [0, 0, p[2, 3] - 0.09]).max() for p in poses])
    assert np.allclose(truth, depths, atol=1e-6)
    assert (got == (truth > INTRUSION_TOL)).all(), (got, truth)
