"""Tests of the MuJoCo drop test in tests/physics.py: stable rests stay, balanced or tilted objects fall."""

from __future__ import annotations

import numpy as np
import trimesh
from physics import drop_test
from scipy.spatial.transform import Rotation

STILL_DEG = 0.1  # a resting object turns less than this in one second
STILL_M = 0.0005  # and its centre of mass moves less than this
FALLEN_DEG = 10.0


def resting_pose(mesh: trimesh.Trimesh, rotation: Rotation, xy=(0.1, -0.05)) -> np.ndarray:
    """The 4x4 pose that turns `mesh` by `rotation` and puts its lowest point on z = 0 at `xy`."""
    pose = np.eye(4)
    pose[:3, :3] = rotation.as_matrix()
    pose[:2, 3] = xy
    pose[2, 3] = -(mesh.vertices @ pose[:3, :3].T)[:, 2].min()
    return pose


def test_cube_resting_on_a_face_stays():
    cube = trimesh.creation.box((0.05, 0.05, 0.05))
    angle, moved = drop_test(cube, resting_pose(cube, Rotation.identity()))
    assert angle < STILL_DEG and moved < STILL_M


def test_cube_balanced_on_an_edge_falls():
    cube = trimesh.creation.box((0.05, 0.05, 0.05))
    angle, _ = drop_test(cube, resting_pose(cube, Rotation.from_euler("x", 45, degrees=True)))
    assert angle > FALLEN_DEG


def test_cylinder_standing_on_its_flat_end_stays():
    cylinder = trimesh.creation.cylinder(radius=0.03, height=0.08, sections=48)
    angle, moved = drop_test(cylinder, resting_pose(cylinder, Rotation.identity()))
    assert angle < STILL_DEG and moved < STILL_M


def test_tall_box_standing_upright_stays():
    tall = trimesh.creation.box((0.02, 0.02, 0.2))
    angle, moved = drop_test(tall, resting_pose(tall, Rotation.identity()))
    assert angle < STILL_DEG and moved < STILL_M


def test_tall_box_tilted_20_degrees_on_its_edge_falls():
    tall = trimesh.creation.box((0.02, 0.02, 0.2))
    angle, moved = drop_test(tall, resting_pose(tall, Rotation.from_euler("x", 20, degrees=True)))
    assert angle > FALLEN_DEG and moved > 0.02


def test_mesh_away_from_its_frame_origin_rests_where_the_pose_puts_it():
    """The body frame is the mesh frame: an off-centre mesh at a turned pose still rests on a face."""
    block = trimesh.creation.box((0.05, 0.04, 0.03))
    block.apply_translation([0.2, -0.1, 0.15])
    angle, moved = drop_test(block, resting_pose(block, Rotation.from_euler("xz", [90, 30], degrees=True)))
    assert angle < STILL_DEG and moved < STILL_M
