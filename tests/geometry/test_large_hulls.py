"""The paths for full-resolution hulls give what plain dense computations give on hulls small enough for both."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.geometry.objects import from_trimesh, load_object
from workbench.geometry.hull import merge_tolerance
from workbench.geometry.supports import SLIVER_SHARE, SLIVER_TILT, coplanar_groups
from workbench.grasping.placements import stable_placements
from workbench.grasping.pads import _extents
from workbench.resources import bundled_objects


def _hulls():
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    rng = np.random.default_rng(3)
    noisy = trimesh.Trimesh(sphere.vertices * (1 + 0.002 * rng.standard_normal((len(sphere.vertices), 1))), sphere.faces)
    flat = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=200)
    return [sphere.convex_hull, noisy.convex_hull, flat.convex_hull,
            load_object(bundled_objects()["bracket"]).mesh.convex_hull]


def _greedy(verts, faces, normals, areas, facet_of, distance, flat, cos_a, share=np.inf, cos_flat=2.0):
    """The greedy grouping written plainly, every free facet tested against each seed: (group of every face). A
    facet within `flat` but tilted joins only with at most `share` of the seed's area or within `cos_flat`."""
    T = facet_of.max() + 1
    order = np.argsort(facet_of, kind="stable")
    starts = np.flatnonzero(np.r_[True, np.diff(facet_of[order]) != 0])
    area = np.bincount(facet_of, weights=areas, minlength=T)
    fn = np.column_stack([np.bincount(facet_of, weights=normals[:, a] * areas, minlength=T) for a in range(3)])
    length = np.linalg.norm(fn, axis=1, keepdims=True)
    fn = np.where(length > 1e-300, fn / np.where(length > 1e-300, length, 1), normals[order[starts]])
    label = np.full(T, -1)
    group = 0
    for seed in np.lexsort((np.arange(T), -area)):
        if label[seed] >= 0:
            continue
        h = verts @ fn[seed]
        top = h[faces[facet_of == seed]].max()
        low = np.minimum.reduceat(h[faces[order]].min(axis=1), starts) - top  # per facet, its lowest vertex
        facing = fn @ fn[seed]
        sliver = (area <= share * area[seed]) | (facing >= cos_flat)
        join = (label < 0) & (((low >= -distance) & (facing >= cos_a)) | ((low >= -flat) & (facing > 0) & sliver))
        join[seed] = True
        label[join] = group
        group += 1
    return label[facet_of]


@pytest.mark.parametrize("distance,angle", [(5e-4, np.radians(3.0)), (2e-3, np.radians(10.0))])
def test_walked_hull_groups_equal_a_plain_greedy_pass(distance, angle):
    for hull in _hulls():
        verts, faces = np.asarray(hull.vertices), np.asarray(hull.faces)
        normals, areas = np.asarray(hull.face_normals), np.asarray(hull.area_faces)
        tol = merge_tolerance(verts)
        facets = _greedy(verts, faces, normals, areas, np.arange(len(faces)), tol, tol, 2.0)
        label = _greedy(verts, faces, normals, areas, facets, distance, 0.25 * distance, np.cos(angle),
                        SLIVER_SHARE, np.cos(SLIVER_TILT))
        groups, n = coplanar_groups(hull, distance, angle)
        assert len(groups) == label.max() + 1
        assert all(np.array_equal(g, np.flatnonzero(label == i)) for i, g in enumerate(groups))
        wn = np.array([(normals[g] * areas[g, None]).sum(axis=0) for g in groups])
        assert np.allclose(n, wn / np.linalg.norm(wn, axis=1, keepdims=True), rtol=0, atol=1e-12)
        assert len(groups) < len(hull.faces)  # some faces were merged, not only singletons compared


@pytest.mark.parametrize("seed", [2, 6, 8])
def test_a_part_subdivided_and_saved_as_stl_keeps_its_placements(tmp_path, seed):
    """A part subdivided (the same surface) and written to STL (float32) has its hull's edges and flat sides rounded
    into slivers: it keeps the coarse part's placements, stabilities, probabilities and rocking flags."""
    rng = np.random.default_rng(seed)
    # an irregular polyhedron: many tilted neighbours, supports held with small margins
    coarse = trimesh.convex.convex_hull(rng.standard_normal((60, 3)) * [0.03, 0.024, 0.02])
    fine = coarse
    for _ in range(3):
        fine = fine.subdivide()
    fine.export(tmp_path / "fine.stl")
    part = load_object(tmp_path / "fine.stl")
    assert len(trimesh.convex.convex_hull(part.mesh.vertices).faces) > 2 * len(coarse.faces)  # rounding split it
    a = stable_placements(from_trimesh(coarse, "coarse"))
    b = stable_placements(part)
    assert len(a) >= 5 and len(b) == len(a)
    assert np.allclose(b.normals, a.normals, atol=1e-5)
    assert np.allclose(b.stability, a.stability, atol=1e-4)
    assert np.allclose(b.probability, a.probability, atol=1e-4) and np.array_equal(b.rocking, a.rocking)


def test_blocked_extents_equal_the_dense_ones():
    rng = np.random.default_rng(4)
    d = rng.standard_normal((300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    v = rng.standard_normal((5000, 3))
    for dense in (1000, 10_000_000):
        hi, lo = _extents(d, v, dense=dense)
        assert np.allclose(hi, (d @ v.T).max(axis=1), rtol=0, atol=1e-12)
        assert np.allclose(lo, (d @ v.T).min(axis=1), rtol=0, atol=1e-12)


def test_the_hull_of_the_possible_hull_vertices_is_the_hull_of_them_all():
    """Qhull is given only the vertices that can be hull vertices: those inside a flat fan of faces or on a straight
    crease between two flat sides are left out. The hull is the plain hull of every vertex (the same corners, volume
    and area), on parts subdivided in place (their sides' and edges' midpoints left out), a concave L whose inner
    crease is left out, and a curved blob and a pyramid whose vertices all stay."""
    from scipy.spatial import ConvexHull

    from workbench.benchmarks.organic import blob
    from workbench.geometry.hull import convex_hull, hull_points

    box = trimesh.creation.box((0.04, 0.03, 0.02)).subdivide().subdivide()
    prism = trimesh.creation.cylinder(radius=0.02, height=0.05, sections=3).subdivide().subdivide()
    ell = trimesh.boolean.union([trimesh.creation.box(bounds=[[0, 0, 0], [0.06, 0.03, 0.01]]),
                                 trimesh.creation.box(bounds=[[0, 0, 0], [0.01, 0.03, 0.05]])], engine="manifold")
    ell = ell.subdivide().subdivide()
    pyramid = trimesh.Trimesh([[0, 0, 0], [0.04, 0, 0], [0.04, 0.04, 0], [0, 0.04, 0], [0.02, 0.02, 0.03]],
                              [[0, 2, 1], [0, 3, 2], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    curved = blob(seed=3)
    # the corners kept: the box's 8, the prism's 6, the L's 12 (its concave ones too), every vertex of the others
    for mesh, corners in ((box, 8), (prism, 6), (ell, 12), (curved, len(curved.vertices)), (pyramid, 5)):
        mesh = from_trimesh(mesh, "part").mesh
        kept = hull_points(mesh.vertices, mesh.faces, mesh.face_normals, mesh.is_watertight)
        assert len(kept) == corners, (len(kept), corners)
        plain = ConvexHull(mesh.vertices)
        hull = convex_hull(kept)
        assert np.isclose(hull.volume, plain.volume, rtol=1e-9) and np.isclose(hull.area, plain.area, rtol=1e-9)
        assert {tuple(p) for p in np.round(hull.vertices, 12)} <= {tuple(p) for p in np.round(mesh.vertices[plain.vertices], 12)}
