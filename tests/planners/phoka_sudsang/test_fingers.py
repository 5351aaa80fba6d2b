"""Five-finger regrasp by contact-point clustering (Phoka & Sudsang): contacts, clustering, roadmap, Algorithms
1-3, queries, the store and the command line. Independent checks are written here (set arithmetic, Qhull,
brute-force loops), not taken from the library."""

from __future__ import annotations

import json
from itertools import combinations

import networkx as nx
import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull
from shapes import pebble  # noqa: E402

from workbench.cli.main import main
from workbench.errors import MeshError, ParameterError, WorkbenchError
from workbench.geometry.objects import from_trimesh
from workbench.planners.phoka_sudsang.clustering import (
    ClusterParams,
    cluster_contacts,
    cone_distance,
)
from workbench.planners.phoka_sudsang.contacts import ContactParams, contact_points
from workbench.planners.phoka_sudsang.experiments import sample_grasps
from workbench.planners.phoka_sudsang.forceclosure import friction_pyramid
from workbench.planners.phoka_sudsang.linking import (
    algorithm1,
    algorithm1_applies,
    algorithm2,
    algorithm3,
    find_nearest_cluster,
    find_path,
    local_path,
)
from workbench.planners.phoka_sudsang.query import (
    check_sequence,
    finger_assignment,
    query,
)
from workbench.planners.phoka_sudsang.switching import (
    Roadmap,
    build_planner,
    construct_roadmap,
    switching_edges,
)
from workbench.store import Store

PARAMS = ClusterParams(k=16, mu=0.5, sides=6, seed=0)




@pytest.fixture(scope="module")
def planner():
    cs = contact_points(from_trimesh(pebble(), "pebble"), ContactParams(faces=None))
    return build_planner(cs, PARAMS)


@pytest.fixture(scope="module")
def samples(planner):
    return sample_grasps(planner.tester, 300, seed=1)


def origin_inside(points: np.ndarray) -> bool:
    hull = ConvexHull(points)
    return bool((hull.equations[:, -1] < -1e-10).all())


def independent_check(planner, seq: np.ndarray, start: np.ndarray, goal: np.ndarray) -> None:
    """Starts at start, ends at goal, consecutive grasps share exactly three contacts, each grasp is force
    closure by a 6-D convex hull of its primitive wrenches."""
    seq = np.asarray(seq)
    assert set(seq[0].tolist()) == set(start.tolist()) and set(seq[-1].tolist()) == set(goal.tolist())
    for a, b in zip(seq[:-1], seq[1:]):
        assert len(set(a.tolist()) & set(b.tolist())) == 3
    for grasp in seq:
        assert len(set(grasp.tolist())) == 4
        assert origin_inside(planner.tester.wrenches[grasp].reshape(-1, 6))


# ---------------------------------------------------------------------------------------------------------- contacts

def test_contacts_are_centroids_with_inward_normals_after_decimation():
    ell = trimesh.creation.icosphere(subdivisions=4)
    ell.vertices = ell.vertices * np.array([0.05, 0.03, 0.02])
    cs = contact_points(from_trimesh(ell, "ellipsoid"), ContactParams(faces=300))
    assert 250 <= len(cs) <= 300 < len(ell.faces)
    assert np.allclose(cs.points, cs.mesh.triangles_center[cs.face])
    assert np.allclose(np.linalg.norm(cs.normals, axis=1), 1)
    # inward: the decimated mesh is closed with outward faces (positive volume), and each contact's normal is its
    # face's normal turned in; on this thin ellipsoid a few decimated slivers tilt away from the centre itself
    assert cs.mesh.is_watertight and cs.mesh.is_winding_consistent and cs.mesh.volume > 0
    assert np.allclose(cs.normals, -cs.mesh.face_normals[cs.face])
    assert (np.einsum("nc,nc->n", cs.normals, -cs.points) > 0).mean() > 0.97


def test_bad_contact_inputs():
    with pytest.raises(MeshError, match="empty|no faces"):
        contact_points(trimesh.Trimesh())
    with pytest.raises(ParameterError, match="faces"):
        contact_points(pebble(), ContactParams(faces=2))


# ---------------------------------------------------------------------------------------------------------- clustering

def test_cone_distance_matches_its_definition(planner):
    """d(i, j) = min over cyclic shifts of summed angles between wrenches about the pair's centroid, / m."""
    cs, m = planner.contacts, PARAMS.sides
    d = cone_distance(cs.points, cs.normals, PARAMS.mu, m, cs.radius)
    f = friction_pyramid(cs.normals, PARAMS.mu, m)
    assert np.allclose(d, d.T) and np.allclose(np.diag(d), 0)
    for i, j in [(0, 1), (3, 200), (319, 17), (50, 51)]:
        c = (cs.points[i] + cs.points[j]) / 2
        wi = np.hstack([f[i], np.cross((cs.points[i] - c) / cs.radius, f[i])])
        wj = np.hstack([f[j], np.cross((cs.points[j] - c) / cs.radius, f[j])])
        best = min(sum(np.arccos(np.clip(wi[k] @ wj[(k + x) % m] / np.linalg.norm(wi[k]) / np.linalg.norm(wj[(k + x) % m]), -1, 1))
                       for k in range(m)) for x in range(m))
        assert d[i, j] == pytest.approx(best / m, abs=2e-4)


def test_spectral_clustering_separates_the_faces_of_a_box():
    box = trimesh.creation.box((0.1, 0.08, 0.06)).subdivide().subdivide()
    cs = contact_points(from_trimesh(box, "box"), ContactParams(faces=None))
    cl = cluster_contacts(cs, ClusterParams(k=6, mu=0.4, sides=8))
    face = np.round(cs.normals).astype(int) @ np.array([1, 3, 9])      # one code per box face
    assert len(np.unique(face)) == 6
    for code in np.unique(face):
        assert len(np.unique(cl.labels[face == code])) == 1
    assert len(np.unique(cl.labels)) == 6


def test_representatives_and_matrix_e(planner):
    cl = planner.clustering
    assert (cl.labels[cl.reps] == np.arange(cl.k)).all()
    e = np.linalg.norm(cl.embedding[:, None, :] - cl.centers[None, :, :], axis=2)
    assert np.allclose(cl.E, e)
    for j in range(cl.k):
        members = np.flatnonzero(cl.labels == j)
        assert cl.reps[j] == members[np.argmin(e[members, j])]
    assert np.allclose(np.linalg.norm(cl.embedding, axis=1), 1)


def test_clustering_is_deterministic(planner):
    again = build_planner(planner.contacts, PARAMS)
    assert np.array_equal(again.clustering.labels, planner.clustering.labels)
    assert np.array_equal(again.roadmap.grasps, planner.roadmap.grasps)


def test_bad_clustering_parameters(planner):
    with pytest.raises(WorkbenchError, match="more than"):
        cluster_contacts(planner.contacts, ClusterParams(k=1000))
    # out of their declared ranges: refused when the parameters are made, before any work
    for kwargs, match in ((dict(k=3), "4 representatives"), (dict(mu=0.0), "friction"), (dict(sides=2), "pyramid")):
        with pytest.raises(ParameterError, match=match):
            ClusterParams(**kwargs)


# ---------------------------------------------------------------------------------------------------------- roadmap

def test_roadmap_vertices_are_the_force_closure_subsets_of_representatives(planner):
    reps = np.sort(planner.clustering.reps)
    every = np.array(list(combinations(reps, 4)))
    vertex = {tuple(r) for r in planner.roadmap.grasps}
    assert vertex <= {tuple(r) for r in every}
    pick = np.random.default_rng(2).choice(len(every), 600, replace=False)   # Qhull is slow: a sample of subsets
    for g in every[pick]:
        assert (tuple(g) in vertex) == origin_inside(planner.tester.wrenches[g].reshape(-1, 6))


def test_every_roadmap_edge_joins_grasps_sharing_exactly_three_contacts(planner):
    rm = planner.roadmap
    assert len(rm.edges) > 0
    for (a, b), (lifted, placed) in zip(rm.edges, rm.moves):
        ga, gb = set(rm.grasps[a].tolist()), set(rm.grasps[b].tolist())
        assert len(ga & gb) == 3 and ga - gb == {lifted} and gb - ga == {placed}
    # and no edge is missing: all vertex pairs sharing three contacts
    inc = np.zeros((len(rm), planner.n), dtype=int)
    inc[np.repeat(np.arange(len(rm)), 4), rm.grasps.ravel()] = 1
    shared = inc @ inc.T
    truth = {(int(i), int(j)) for i, j in zip(*np.nonzero(np.triu(shared == 3, 1)))}
    assert {tuple(sorted(map(int, e))) for e in rm.edges} == truth
    graph = nx.Graph()
    graph.add_nodes_from(range(len(rm)))
    graph.add_edges_from(rm.edges.tolist())
    assert nx.number_connected_components(graph) == rm.ncomponents


def test_roadmap_path_is_a_shortest_switching_path(planner):
    rm = planner.roadmap
    graph = nx.Graph(rm.edges.tolist())
    rng = np.random.default_rng(0)
    for _ in range(5):
        a, b = rng.choice(len(rm), 2, replace=False)
        p = rm.path(int(a), np.array([b]))
        if rm.components[a] != rm.components[b]:
            assert p is None
            continue
        assert p[0] == a and p[-1] == b and len(p) - 1 == nx.shortest_path_length(graph, int(a), int(b))


def test_switching_edges_of_a_small_set():
    g = np.array([[0, 1, 2, 3], [0, 1, 2, 4], [0, 1, 3, 4], [5, 6, 7, 8]])
    edges, moves = switching_edges(g, 9)
    assert {tuple(sorted(e)) for e in edges.tolist()} == {(0, 1), (0, 2), (1, 2)}
    assert Roadmap.from_grasps(g, 9).ncomponents == 2


# ---------------------------------------------------------------------------------------------------------- local planning

def test_lazy_local_path_agrees_with_the_eager_local_roadmap(planner, samples):
    """ConstructRoadmap + FindPath and the lazy bidirectional search find paths of the same length (or none)."""
    cl = planner.clustering
    checked = 0
    for g in samples[:40]:
        v = algorithm1_applies(planner, g)
        if v < 0 or checked == 8:
            continue
        target = planner.roadmap.grasps[v]
        sets = []
        for c in cl.labels[g]:                           # trimmed clusters keep the eager product small
            members = cl.members(c)
            keep = np.union1d(members[:7], np.concatenate([g, target])[np.isin(np.concatenate([g, target]), members)])
            sets.append(keep)
        eager = find_path(construct_roadmap(planner.tester, *sets), g, target)
        lazy = local_path(planner.tester, sets, g, target)
        assert (eager is None) == (lazy is None)
        if lazy is not None:
            assert len(lazy) == len(eager)
            independent_check(planner, lazy, g, target)
        checked += 1
    assert checked >= 5


def test_algorithms_link_grasps_to_the_roadmap(planner, samples):
    rm = planner.roadmap
    done = {"alg1": 0, "alg2": 0, "alg3": 0}
    for g in samples[:12]:
        for alg in (algorithm1, algorithm2, algorithm3):
            link = alg(planner, g)
            if link is None:
                continue
            independent_check(planner, link.path, g, rm.grasps[link.vertex])
            done[link.method] += 1
    assert all(v > 0 for v in done.values()), done


def test_find_nearest_cluster_is_the_smallest_e_distance(planner, samples):
    """Brute force over all vertices of R one contact away from g' (the clusters' representatives of g)."""
    cl, rm = planner.clustering, planner.roadmap
    for g in samples[:30]:
        gp = cl.reps[cl.labels[g]]
        best = np.inf
        for f in rm.grasps:
            for slot in range(4):
                others = np.delete(gp, slot)
                if len(set(others.tolist())) < 3 or not set(others.tolist()) <= set(f.tolist()):
                    continue
                y = (set(f.tolist()) - set(others.tolist())).pop()
                if y != gp[slot]:
                    best = min(best, cl.E[g[slot], cl.labels[y]])
        x = find_nearest_cluster(planner, g)
        if np.isinf(best):
            assert x is None
        else:
            assert x is not None and x.distance == pytest.approx(best)
            f = set(rm.grasps[x.vertex].tolist())
            assert len(f & set(gp.tolist())) == 3 and cl.labels[x.contact] == x.from_cluster


# ---------------------------------------------------------------------------------------------------------- queries

def test_queries_pass_an_independent_check(planner, samples):
    rng = np.random.default_rng(3)
    connected = 0
    for _ in range(6):
        i, j = rng.choice(len(samples), 2, replace=False)
        r = query(planner, samples[i], samples[j])
        if r.sequence is not None:
            independent_check(planner, r.sequence, samples[i], samples[j])
            assert check_sequence(planner.tester, r.sequence)
            connected += 1
    assert connected >= 5


def test_finger_assignment_places_one_finger_and_lifts_one(planner, samples):
    r = query(planner, samples[0], samples[5])
    fingers, placed, lifted = finger_assignment(r.sequence)
    for i, grasp in enumerate(r.sequence):
        assert set(fingers[i][fingers[i] >= 0].tolist()) == set(grasp.tolist())
        assert (fingers[i] < 0).sum() == 1
        if i:
            assert fingers[i - 1][placed[i]] < 0 and fingers[i][placed[i]] >= 0
            assert fingers[i - 1][lifted[i]] >= 0 and fingers[i][lifted[i]] < 0
            assert placed[i] != lifted[i]


def test_bad_queries_are_refused(planner, samples):
    g = samples[0]
    with pytest.raises(WorkbenchError, match="unknown contact"):
        query(planner, [g[0], g[1], g[2], 10_000], g)
    with pytest.raises(WorkbenchError, match="repeats"):
        query(planner, [g[0], g[0], g[1], g[2]], g)
    bad = next(c for c in combinations(range(planner.n), 4) if not planner.tester.exact(np.array([c]))[0])
    with pytest.raises(WorkbenchError, match="not force closure"):
        query(planner, list(bad), g)


# ---------------------------------------------------------------------------------------------------------- store and CLI

def test_store_round_trip_reuse_and_json(tmp_path):
    mesh = tmp_path / "pebble.stl"
    pebble().export(mesh)
    db, out = tmp_path / "f.duckdb", tmp_path / "f.json"
    args = ["fingers", str(mesh), "--db", str(db), "--faces", "0", "--clusters", "16", "--friction", "0.5",
            "--pyramid", "6", "--samples", "300", "--picks", "3", "--queries", "4"]
    assert main(args + ["--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    with Store(db) as store:
        counts = {t: store.one(f"SELECT count(*) FROM {t}")[0]
                  for t in ("fingercontact", "fingercluster", "fingermember", "fingergrasp", "fingeredge", "fingerquery")}
        contact = {int(r[0]): int(r[1]) for r in store.run("SELECT idfingercontact, idx FROM fingercontact")}
        assert counts["fingergrasp"] == doc["table1"]["vertex"] and counts["fingeredge"] == doc["table1"]["edges"]
        assert counts["fingerquery"] == 4 and counts["fingercluster"] == 16 and counts["fingermember"] == counts["fingercontact"]
    # the JSON's sequences are stored contact ids, grasp after grasp sharing three
    assert len(doc["queries"]) == 4 and any(q["connected"] for q in doc["queries"])
    for q in doc["queries"]:
        if q["connected"]:
            seq = q["sequence"]
            assert seq[0] == q["start"] and sorted(seq[-1]) == sorted(q["goal"])
            assert all(c in contact for grasp in seq for c in grasp)
            assert all(len(set(a) & set(b)) == 3 for a, b in zip(seq[:-1], seq[1:]))
    # a re-run reuses every stage: same numbers, no new rows
    out2 = tmp_path / "g.json"
    assert main(args + ["--json", str(out2)]) == 0
    doc2 = json.loads(out2.read_text())
    assert doc2["table1"] == doc["table1"] and doc2["queries"] == doc["queries"] and doc2["paramsets"] == doc["paramsets"]
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM fingeredge")[0] == counts["fingeredge"]
        assert store.one("SELECT count(*) FROM paramset")[0] == 3
    # the planner rebuilt from the store equals a fresh build
    from workbench.geometry.objects import load_object
    from workbench.planners.phoka_sudsang.stages import run_pipeline

    obj = load_object(mesh)
    r = run_pipeline(str(db), obj, ContactParams(faces=None), ClusterParams(k=16, mu=0.5, sides=6), 300, 3, 4)
    assert r.reused == (True, True)
    fresh = build_planner(r.planner.contacts, ClusterParams(k=16, mu=0.5, sides=6))
    assert np.array_equal(r.planner.clustering.labels, fresh.clustering.labels)
    assert np.array_equal(r.planner.clustering.reps, fresh.clustering.reps)
    assert np.allclose(r.planner.clustering.E, fresh.clustering.E)
    assert np.array_equal(r.planner.roadmap.grasps, fresh.roadmap.grasps)
    assert {tuple(e) for e in r.planner.roadmap.edges.tolist()} == {tuple(e) for e in fresh.roadmap.edges.tolist()}
    # stored ids map back to contact indices; an unknown id is refused
    assert np.array_equal(r.ids.to_index(r.ids.to_ids([5, 0, 17])), [5, 0, 17])
    with pytest.raises(WorkbenchError, match="not a stored contact"):
        r.ids.to_index([int(r.ids.ids.max()) + 1])


@pytest.mark.parametrize("extra, match", [(["--friction", "0"], "friction"), (["--pyramid", "2"], "pyramid"),
                                          (["--clusters", "5000"], "clusters")])
def test_cli_bad_input_is_one_line_and_status_2(tmp_path, capsys, extra, match):
    mesh = tmp_path / "pebble.stl"
    pebble().export(mesh)
    code = main(["fingers", str(mesh), "--db", str(tmp_path / "f.duckdb"), "--faces", "0", "--queries", "0",
                 "--picks", "0", *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and match in err
