"""The paths for full-resolution hulls give what the dense computations give on hulls small enough for both."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.geometry.objects import load_object
from workbench.geometry.supports import coplanar_groups
from workbench.grasping.pads import _farthest
from workbench.resources import bundled_objects


def _hulls():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    rng = np.random.default_rng(3)
    noisy = trimesh.Trimesh(sphere.vertices * (1 + 0.002 * rng.standard_normal((len(sphere.vertices), 1))), sphere.faces)
    flat = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=200)
    return [sphere.convex_hull, noisy.convex_hull, flat.convex_hull,
            load_object(bundled_objects()["bracket"]).mesh.convex_hull]


@pytest.mark.parametrize("distance,angle", [(5e-4, np.radians(3.0)), (2e-3, np.radians(10.0))])
def test_walked_hull_groups_equal_the_dense_pass(distance, angle):
    for hull in _hulls():
        dense, n_dense = coplanar_groups(hull, distance, angle)
        walked, n_walked = coplanar_groups(hull, distance, angle, walk_above=0)
        assert len(walked) == len(dense)
        assert all(np.array_equal(a, b) for a, b in zip(walked, dense))
        assert np.array_equal(n_walked, n_dense)
    assert len(dense) < len(hull.faces)  # some faces were merged, not only singletons compared


def test_blocked_extents_equal_the_dense_ones():
    rng = np.random.default_rng(4)
    d = rng.standard_normal((300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    v = rng.standard_normal((5000, 3))
    assert np.allclose(_farthest(d, v, dense=1000), (d @ v.T).max(axis=1), rtol=0, atol=1e-12)
    assert np.allclose(_farthest(d, v), (d @ v.T).max(axis=1), rtol=0, atol=1e-12)
