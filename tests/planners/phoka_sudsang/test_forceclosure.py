"""Force closure of 4-contact grasps (Phoka & Sudsang Section II; prefilter of [5], exact LP test of [4]).

Cross-checks against brute-force convex hulls written here with scipy's Qhull.
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull

from workbench.errors import WorkbenchError
from workbench.geometry.objects import from_trimesh
from workbench.planners.phoka_sudsang import forceclosure as fcm
from workbench.planners.phoka_sudsang.contacts import ContactParams, contact_points
from workbench.planners.phoka_sudsang.forceclosure import (
    ForceClosure,
    FrictionParams,
    SpanTable,
    combinations_array,
    friction_pyramid,
    primitive_wrenches,
    strictly_inside,
)


def hull_contains_origin(points: np.ndarray) -> bool:
    """Origin strictly inside the convex hull: every facet's plane has the origin on its inner side."""
    hull = ConvexHull(points)
    return bool((hull.equations[:, -1] < -1e-10).all())


def random_contacts(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Points near a unit sphere with roughly inward, perturbed normals (generic positions)."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    nrm = -p + 0.4 * rng.normal(size=(n, 3))
    return p * rng.uniform(0.8, 1.2, size=(n, 1)), nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def test_friction_pyramid_edges():
    """Unit edges at angle atan(mu) from the normal, counterclockwise about it, equal normals equal frames."""
    n = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, 1.0]])
    f = friction_pyramid(n, 0.4, 6)
    assert f.shape == (3, 6, 3)
    assert np.allclose(np.linalg.norm(f, axis=2), 1)
    assert np.allclose(np.einsum("nkc,nc->nk", f, n), np.cos(np.arctan(0.4)))
    turn = np.cross(f, np.roll(f, -1, axis=1))
    assert (np.einsum("nkc,nc->nk", turn, n) > 0).all()
    assert np.allclose(f[0], f[2])


def test_primitive_wrench_torque_is_arm_cross_force():
    p, n = np.array([[0.1, 0.2, 0.3]]), np.array([[0, 0, -1.0]])
    w = primitive_wrenches(p, n, 0.5, 4, ref=np.array([0.1, 0.0, 0.0]), length=0.5)
    assert np.allclose(w[0, :, 3:], np.cross(np.array([0.0, 0.2, 0.3]) / 0.5, w[0, :, :3]))


def test_tetrahedron_face_contacts_are_force_closure():
    """Four contacts at the face centroids of a tetrahedron with enough friction: force closure."""
    tet = trimesh.Trimesh([[0, 0, 0], [0.06, 0, 0], [0, 0.06, 0], [0, 0, 0.06]], [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    tet.fix_normals()
    cs = contact_points(from_trimesh(tet, "tet"), ContactParams(faces=None))
    assert len(cs) == 4
    centre = tet.vertices.mean(0)
    assert (np.einsum("nc,nc->n", cs.normals, centre - cs.points) > 0).all()   # inward normals
    fc = ForceClosure(cs.points, cs.normals, FrictionParams(0.5, 8), ref=cs.com, length=cs.radius)
    g = np.array([[0, 1, 2, 3]])
    assert fc.exact(g)[0] and fc.prefilter(g)[0] and fc.test(g)[0]
    assert hull_contains_origin(fc.wrenches.reshape(-1, 6))


def test_four_contacts_on_one_face_are_not_force_closure():
    """All forces push into one half-space: the prefilter and the exact test both reject."""
    pts = np.array([[0.01, 0.01, 0.03], [-0.01, 0.01, 0.03], [0.01, -0.01, 0.03], [-0.01, -0.012, 0.03]])
    nrm = np.tile([0, 0, -1.0], (4, 1))
    fc = ForceClosure(pts, nrm, FrictionParams(0.8, 8), ref=np.zeros(3), length=0.05)
    g = np.array([[0, 1, 2, 3]])
    assert not fc.exact(g)[0]
    assert not fc.prefilter(g)[0]
    assert not fc.test(g)[0]


def test_exact_and_prefilter_against_brute_force_hulls():
    """On random grasps: exact test == Qhull in 6-D; the prefilter == Qhull positive span of force and torque
    components in 3-D, and never rejects a grasp the exact test accepts."""
    pts, nrm = random_contacts(40, seed=3)
    fc = ForceClosure(pts, nrm, FrictionParams(0.45, 6), ref=np.zeros(3), length=1.0)
    rng = np.random.default_rng(4)
    grasps = np.unique(np.sort(np.array([rng.choice(40, 4, replace=False) for _ in range(500)]), axis=1), axis=0)
    exact, pre = fc.exact(grasps), fc.prefilter(grasps)
    w = fc.wrenches[grasps]                                             # (G, 4, m, 6)
    brute = np.array([hull_contains_origin(x.reshape(-1, 6)) for x in w])
    span = np.array([hull_contains_origin(x[..., :3].reshape(-1, 3)) and hull_contains_origin(x[..., 3:].reshape(-1, 3))
                     for x in w])
    assert 0.1 < exact.mean() < 0.9                                     # both outcomes exercised
    assert (exact == brute).all()
    assert (pre == span).all()
    assert not (exact & ~pre).any()
    assert (~pre).sum() > 0.2 * (~exact).sum()                          # the prefilter does reject
    assert (fc.test(grasps) == exact).all()


def test_span_table_matches_direct_positive_span():
    """The pair-table prefilter agrees with a direct 3-D hull test on every 4-subset of 12 contacts."""
    pts, nrm = random_contacts(12, seed=8)
    f = friction_pyramid(nrm, 0.3, 5)
    table = SpanTable(f)
    subsets = combinations_array(12, 4)
    direct = np.array([hull_contains_origin(f[s].reshape(-1, 3)) for s in subsets])
    assert (table.may_span(subsets) == direct).all()


def test_strictly_inside_simple_sets():
    """A 6-simplex around the origin is inside; shifted away it is not; a flat (rank-5) set never is."""
    rng = np.random.default_rng(0)
    simplex = np.vstack([np.eye(6), -np.ones((1, 6))]) + 0.05 * rng.normal(size=(7, 6))
    shifted = simplex + np.array([3.0, 0, 0, 0, 0, 0])
    flat = simplex.copy()
    flat[:, 5] = 0.0
    out = strictly_inside(np.stack([simplex, shifted, flat]))
    assert out.tolist() == [True, False, False]


def test_simplex_fallback_gives_the_same_answers(monkeypatch):
    """Items left over by the batched simplex (here: an iteration cap of 1) are solved by HiGHS, same answers."""
    pts, nrm = random_contacts(20, seed=5)
    fc = ForceClosure(pts, nrm, FrictionParams(0.5, 4), ref=np.zeros(3), length=1.0)
    grasps = combinations_array(20, 4)[::7]
    full = fc.exact(grasps)
    calls = []
    original = fcm._lp_feasible
    monkeypatch.setattr(fcm, "MAX_PIVOTS", 1)
    monkeypatch.setattr(fcm, "_lp_feasible", lambda w: calls.append(1) or original(w))
    assert (fc.exact(grasps) == full).all()
    assert len(calls) > 10


def test_subsets_are_all_force_closure_four_subsets():
    pts, nrm = random_contacts(14, seed=6)
    fc = ForceClosure(pts, nrm, FrictionParams(0.5, 6), ref=np.zeros(3), length=1.0)
    ids = np.arange(2, 14)
    found = fc.subsets(ids)
    every = np.array(list(combinations(ids, 4)))
    assert {tuple(r) for r in found} == {tuple(r) for r in every[fc.exact(every)]}


def test_combinations_array_matches_itertools():
    for n in (4, 5, 9):
        assert np.array_equal(combinations_array(n, 4), np.array(list(combinations(range(n), 4))))


@pytest.mark.parametrize("mu, sides", [(0.0, 8), (-0.2, 8), (float("nan"), 8), (0.5, 2), (0.5, 3.5)])
def test_bad_friction_parameters(mu, sides):
    with pytest.raises(WorkbenchError, match="friction|pyramid"):
        ForceClosure(np.zeros((4, 3)), np.tile([0, 0, 1.0], (4, 1)), FrictionParams(mu, sides))


def test_grasps_with_unknown_contacts_are_refused():
    pts, nrm = random_contacts(6, seed=1)
    fc = ForceClosure(pts, nrm, FrictionParams())
    with pytest.raises(WorkbenchError, match="out of range"):
        fc.exact(np.array([[0, 1, 2, 6]]))
