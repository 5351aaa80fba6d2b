"""Placements as a person names them: numbered within the part, described by the face they rest on."""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.geometry.objects import from_trimesh
from workbench.grasping.naming import (
    describe_placement,
    per_part_numbers,
    placement_lines,
    rest_name,
    resting_normal,
)
from workbench.grasping.placements import stable_placements


def test_a_box_rests_upright_upside_down_and_on_its_sides(box):
    pl = stable_placements(box)
    names = sorted(rest_name(resting_normal(m)) for m in pl.poses)
    assert names == ["on its side"] * 4 + ["upright", "upside down"]
    for pose, normal in zip(pl.poses, pl.normals):
        n = resting_normal(pose)
        assert np.allclose(n, normal / np.linalg.norm(normal), atol=1e-9)
        # independently: the vertices lying on the table are the face with that normal
        placed = trimesh.transform_points(box.mesh.vertices, pose)
        low = box.mesh.vertices[placed[:, 2] < 1e-9]
        assert np.ptp(low @ n) < 1e-9 and (low @ n).min() >= (box.mesh.vertices @ n).max() - 1e-9


def test_a_tilted_support_says_how_far():
    tilted = trimesh.creation.box((0.05, 0.04, 0.03))
    part = from_trimesh(tilted.apply_transform(trimesh.transformations.rotation_matrix(np.radians(40), [1, 0, 0])), "t")
    names = {rest_name(resting_normal(m)) for m in stable_placements(part).poses}
    assert {"tilted 40 deg", "tilted 140 deg"} <= names


def test_numbers_count_within_the_part_from_one():
    assert per_part_numbers(np.array([12, 5, 9])) == {5: 1, 9: 2, 12: 3}
    lines = placement_lines({7: np.eye(4), 3: np.diag([1.0, -1.0, -1.0, 1.0])})
    assert lines == ["placement 1: upside down, face normal (+0.00, +0.00, +1.00)",
                     "placement 2: upright, face normal (+0.00, +0.00, -1.00)"]
    assert describe_placement(2, [0, -2.0, 0], 0.5) == "placement 2: on its side, face normal (+0.00, -1.00, +0.00), stability 0.500"
