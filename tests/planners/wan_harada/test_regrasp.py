"""The regrasp graph and its search (Wan & Harada, Section V): graph build, regrasp counts against a brute-force
search over the same tables, lazy against full evaluation, impossible queries, plans and their storage."""

from __future__ import annotations

import heapq
import json
import re

import numpy as np
import pytest

from workbench.errors import PlanningError
from workbench.planners.wan_harada.planner import Planner
from workbench.planners.wan_harada.query import PoseQuery, Side, match_pose, parse_pose
from workbench.planners.wan_harada.roadmap import UNREACHED, build_roadmap
from workbench.planners.wan_harada.search import search
from workbench.planners.wan_harada.tabletop import TabletopParams

SMALL = TabletopParams(x_min=0.4, x_max=0.6, nx=3, y_min=-0.15, y_max=0.15, ny=2, angles=4, max_grasps=12)


# ----------------------------------------------------------------------------------------------------------------
# Brute force: Dijkstra with lexicographic (transits, transfers) costs over explicit node-level edges.


def brute_force(node_grasp, node_place, start_grasps, goal_grasps):
    """Fewest (regrasps, transfers) from any feasible start grip to any feasible goal grip: Dijkstra over the grip
    graph itself, every transfer edge (same grasp) and transit edge (same placement, roadmap nodes only) taken one
    by one; None if unconnected."""
    n = len(node_grasp)
    s0, g0 = n, n + len(start_grasps)  # vertices: roadmap nodes, start grips, goal grips
    grasp = np.concatenate([node_grasp, start_grasps, goal_grasps]).astype(np.int64)
    place = np.concatenate([node_place, np.full(len(start_grasps) + len(goal_grasps), -1)]).astype(np.int64)
    index = np.arange(len(grasp))
    dist = {v: (0, 0) for v in range(s0, g0)}
    heap = [((0, 0), v) for v in range(s0, g0)]
    done = set()
    while heap:
        d, v = heapq.heappop(heap)
        if v in done:
            continue
        done.add(v)
        if v >= g0:
            return d
        transfer = (grasp == grasp[v]) & (index != v) & ((index < s0) | (index >= g0))
        transit = (place == place[v]) & (index != v) & (index < n) & (v < n)
        for u, w in [(int(u), (d[0], d[1] + 1)) for u in np.flatnonzero(transfer)] + \
                    [(int(u), (d[0] + 1, d[1])) for u in np.flatnonzero(transit & ~transfer)]:
            if w < dist.get(u, (UNREACHED, UNREACHED)):
                dist[u] = w
                heapq.heappush(heap, (w, u))
    return None


def synthetic(rng, n_grasps=7, n_places=9, density=0.35, p_feasible=0.6, chain=False):
    """Random tabletop grip rows (grasp x placement incidence) with a random IK feasibility; `chain` adds a band
    (placement k holds grasps k and k + 1) so that long regrasp sequences occur."""
    inc = rng.random((n_grasps, n_places)) < density
    if chain:
        k = np.arange(min(n_grasps - 1, n_places))
        inc[k, k] = inc[k + 1, k] = True
    g, p = np.nonzero(inc)
    n = len(g)
    eye = np.repeat(np.eye(4)[None], n, axis=0)
    rows = {"idtabletopgrips": np.arange(1, n + 1), "idtabletopplacements": p + 100, "idfreeairgrip": g + 10,
            "idfreetabletopplacement": np.zeros(n, dtype=int), "rotmat": eye, "placement_rotmat": eye,
            "tabletopposition": np.column_stack([rng.random(n), rng.random(n), np.zeros(n)]), "angle": np.zeros(n),
            "jawwidth": np.full(n, 0.03)}
    return rows, rng.random(n) < p_feasible


def synthetic_side(rng, label, grasp_ids, p_feasible=0.7, roadmap=None):
    k = len(grasp_ids)
    pose = np.eye(4)
    side = Side(label=label, query=PoseQuery(0, 0.0, 0.0, 0.0), pose=pose, grasp=np.asarray(grasp_ids, dtype=np.int64),
                tcp=np.repeat(pose[None], k, axis=0), jawwidth=np.full(k, 0.03),
                rindex=roadmap.grasp_index(grasp_ids), state=np.zeros(k, dtype=np.int8), joints=np.full((k, 3, 0), np.nan),
                prior=rng.random(k))
    hidden = rng.random(k) < p_feasible
    tier1 = hidden & (rng.random(k) < 0.7)  # some feasible grips need the fall-back seeds
    return side, hidden, tier1


def reveal(hidden_by_side):
    """An `evaluate` that uncovers the hidden feasibility: tier 1 finds only `tier1`, the fall-back finds all."""
    def evaluate(requests, fallback=True):
        for side, idx in requests:
            hidden, tier1 = hidden_by_side[side.label]
            ok = hidden[idx] if fallback else tier1[idx]
            side.state[idx] = np.where(ok, 1, -1 if fallback else -2)
    return evaluate


def test_graph_groups_edges_and_components_follow_the_tables():
    rng = np.random.default_rng(0)
    rows, feas = synthetic(rng, 6, 8)
    rm = build_roadmap(rows, feas)
    keep = np.flatnonzero(feas)
    assert rm.n_nodes == len(keep)
    g, p = rows["idfreeairgrip"][keep], rows["idtabletopplacements"][keep]
    # explicit pair counts against the grouped counts
    same_g = (g[:, None] == g[None, :]) & ~np.eye(len(g), dtype=bool)
    same_p = (p[:, None] == p[None, :]) & ~np.eye(len(g), dtype=bool)
    assert rm.n_transfer_edges == same_g.sum() // 2
    assert rm.n_transit_edges == same_p.sum() // 2
    # every node reaches exactly the nodes of its component (transitive closure of both relations)
    reach = same_g | same_p | np.eye(len(g), dtype=bool)
    for _ in range(len(g)):
        reach = reach | ((reach.astype(int) @ reach.astype(int)) > 0)
    assert np.array_equal(reach, rm.component[:, None] == rm.component[None, :])
    # grasp distance 1 <=> the two grasps share a placement
    for a in range(rm.n_grasps):
        for b in range(rm.n_grasps):
            share = bool(np.intersect1d(p[g == rm.grasp_ids[a]], p[g == rm.grasp_ids[b]]).size)
            assert (rm.dist[a, b] == 1) == (share and a != b)


@pytest.mark.parametrize("seed", range(40))
def test_search_matches_brute_force_on_random_tables(seed):
    rng = np.random.default_rng(seed)
    ng = int(rng.integers(4, 11))
    chain = seed % 2 == 1
    rows, feas = synthetic(rng, n_grasps=ng, n_places=int(rng.integers(4, 13)), p_feasible=0.8, chain=chain,
                           density=float(rng.uniform(0.03, 0.1) if chain else rng.uniform(0.15, 0.4)))
    rm = build_roadmap(rows, feas)
    all_grasps = np.arange(10, 12 + ng)  # includes grasps with no roadmap node
    sg = np.sort(rng.choice(all_grasps, size=int(rng.integers(1, 5)), replace=False))
    gg = np.sort(rng.choice(all_grasps, size=int(rng.integers(1, 5)), replace=False))
    if chain:  # from one end of the band to the other
        sg, gg = np.union1d(sg[:1], [10]), np.union1d(gg[:1], [9 + ng])
    results = []
    for lazy in (True, False):
        r = np.random.default_rng(seed + 1000)
        s, hs, ts = synthetic_side(r, "start", sg, roadmap=rm, p_feasible=0.85)
        g, hg, tg = synthetic_side(r, "goal", gg, roadmap=rm, p_feasible=0.85)
        res = search(rm, s, g, reveal({"start": (hs, ts), "goal": (hg, tg)}), alternatives=2, lazy=lazy)
        results.append(res)
    node_grasp_ids = rm.grasp_ids[rm.node_grasp]
    expect = brute_force(node_grasp_ids, rm.node_place, sg[hs], gg[hg])
    for res in results:
        if expect is None:
            assert res.routes == []
            continue
        best = res.routes[0]
        assert (best.n_regrasps, best.n_transfers) == expect
        # routes come best first and every route is a valid walk of the graph
        costs = [r.n_regrasps for r in res.routes]
        assert costs == sorted(costs) and costs[-1] <= costs[0] + 1
        for r in res.routes:
            assert res.start.state[r.start_grip] == 1 and res.goal.state[r.goal_grip] == 1
            cur = res.start.grasp[r.start_grip]
            for a, b in r.regrasps:
                assert rm.node_place[a] == rm.node_place[b]  # release and regrasp at one placement
                assert node_grasp_ids[a] == cur and node_grasp_ids[b] != cur  # carried with the current grasp
                cur = node_grasp_ids[b]
            assert cur == res.goal.grasp[r.goal_grip]  # the last grasp places the object at the goal


def test_lazy_search_evaluates_fewer_grips_for_the_same_cost():
    rng = np.random.default_rng(7)
    rows, feas = synthetic(rng, n_grasps=30, n_places=40, density=0.3, p_feasible=0.8)
    rm = build_roadmap(rows, feas)
    sg, gg = np.arange(10, 40, 1), np.arange(10, 40, 2)
    out = {}
    for lazy in (True, False):
        r = np.random.default_rng(3)
        s, hs, ts = synthetic_side(r, "start", sg, roadmap=rm)
        g, hg, tg = synthetic_side(r, "goal", gg, roadmap=rm)
        res = search(rm, s, g, reveal({"start": (hs, ts), "goal": (hg, tg)}), alternatives=0, lazy=lazy)
        out[lazy] = (res.routes[0].n_regrasps, s.n_evaluated + g.n_evaluated)
    assert out[True][0] == out[False][0]
    assert out[True][1] < out[False][1]


def test_pose_parsing_and_matching():
    assert parse_pose("3, 0.5, -0.1, 1.57", "start") == PoseQuery(3, 0.5, -0.1, 1.57)
    for bad in ("3,0.5,0.1", "a,0.5,0.1,0", "3,nan,0,0", "3,0.5,inf,0"):
        with pytest.raises(PlanningError, match="start"):
            parse_pose(bad, "start")
    free = np.repeat(np.eye(4)[None], 2, axis=0)
    free[1, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # on another face
    free[1, 2, 3] = 0.02
    q = PoseQuery(8, 0.42, -0.07, 2.5)
    pose = q.move() @ free[1]
    got = match_pose(pose, np.array([7, 8]), free)
    assert got.idfreetabletopplacement == 8 and np.allclose([got.x, got.y, got.yaw], [0.42, -0.07, 2.5])
    tilted = pose.copy()
    c, s = np.cos(0.3), np.sin(0.3)
    tilted[:3, :3] = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ pose[:3, :3]
    with pytest.raises(PlanningError, match="not on a stable placement"):
        match_pose(tilted, np.array([7, 8]), free)


# ----------------------------------------------------------------------------------------------------------------
# A real store: the tube on a small grid with the Panda (grasps, placements, IK).


@pytest.fixture(scope="module")
def small_store(tmp_path_factory, bundled):
    from workbench.planners.wan_harada.stages import build_all

    db = tmp_path_factory.mktemp("regrasp") / "small.duckdb"
    build_all(db, bundled["tube"], "panda", tparams=SMALL, workers=1, progress=False)
    return db


@pytest.fixture(scope="module")
def planner(small_store):
    from workbench.planners.wan_harada.stages import load_planner

    return load_planner(small_store, "tube", "panda")


def _queries(planner, n, seed):
    rng = np.random.default_rng(seed)
    ids = planner.placement_ids()
    return [tuple(PoseQuery(int(rng.choice(ids)), float(rng.uniform(0.4, 0.6)), float(rng.uniform(-0.15, 0.15)),
                            float(rng.uniform(-np.pi, np.pi))) for _ in range(2)) for _ in range(n)]


def test_store_search_matches_brute_force_over_the_stored_tables(small_store, planner):
    from workbench.store import Store
    from workbench.store import wan_harada as sql

    ids = planner.ids
    with Store(small_store) as store:
        rows = sql.roadmap_rows(store, ids["idtabletop"], ids["idrobot"], ids["idscene"], ids["idikret"], planner.robot.nq)
    feasible = rows["feasible"].all(axis=1)
    assert planner.roadmap.n_nodes == feasible.sum() > 0
    solved = 0
    for start, goal in _queries(planner, 6, 1):
        try:
            full = planner.search(start, goal, alternatives=0, lazy=False)
        except PlanningError:
            continue
        lazy = planner.search(start, goal, alternatives=0, lazy=True)
        s, g = full.start, full.goal
        expect = brute_force(rows["idfreeairgrip"][feasible], rows["idtabletopplacements"][feasible],
                             s.grasp[s.state == 1], g.grasp[g.state == 1])
        assert (full.routes[0].n_regrasps, full.routes[0].n_transfers) == expect
        assert lazy.routes[0].n_regrasps == expect[0]
        solved += 1
    assert solved >= 3


def test_plans_have_steps_joints_and_round_trip(planner, small_store, tmp_path):
    from workbench.planners.wan_harada.plans import Plan
    from workbench.planners.wan_harada.stages import save_plan
    from workbench.store import Store
    from workbench.store.wan_harada import load_plan_rows

    found = None
    for start, goal in _queries(planner, 20, 2):
        try:
            plans = planner.plan(start, goal, alternatives=2)
        except PlanningError:
            continue
        if plans[0].regrasps >= 1:
            found = plans
            break
    assert found is not None, "no query of the small store needs a regrasp"
    best = found[0]
    kinds = [s.kind for s in best.steps]
    assert kinds[0] == "pick" and kinds[-1] == "place" and kinds.count("regrasp") == best.regrasps
    assert best.transfers == best.regrasps + 1
    for s in best.steps:
        assert s.q_grasp.shape == s.q_approach.shape == s.q_retract.shape == (planner.robot.nq,)
        assert np.allclose(s.object_pose @ s.grasp, s.tcp)
    assert [p.regrasps for p in found] == sorted(p.regrasps for p in found)
    # JSON round trip
    again = Plan.from_json(best.to_json(tmp_path / "plan.json"))
    assert again.grasps == best.grasps and np.allclose(again.steps[1].q_grasp, best.steps[1].q_grasp)
    assert json.loads((tmp_path / "plan.json").read_text())["regrasps"] == best.regrasps
    # the store's plan tables
    with Store(small_store) as store:
        pid = save_plan(store, best)
        row, steps = load_plan_rows(store, pid)
    assert row["regrasps"] == best.regrasps and steps.num_rows == len(best.steps)
    assert steps.column("kind").to_pylist() == kinds
    assert np.allclose(steps.column("jnt_grasp").to_pylist()[1], best.steps[1].q_grasp)
    # same inputs, same plan
    assert planner.plan(best.start, best.goal, alternatives=2)[0].grasps == best.grasps


def test_impossible_queries_say_why(planner):
    ids = planner.placement_ids()
    with pytest.raises(PlanningError, match="not a stable placement of tube"):
        planner.plan(PoseQuery(max(ids) + 7, 0.5, 0.0, 0.0), PoseQuery(ids[0], 0.5, 0.0, 0.0))
    with pytest.raises(PlanningError, match="off the table"):
        planner.plan(PoseQuery(ids[0], 3.0, 0.0, 0.0), PoseQuery(ids[0], 0.5, 0.0, 0.0))
    # the centre of mass on the table, 1 mm from its edge: half the part's support overhangs it
    edge = float(planner.scene.table_max[0]) - 0.001
    placed = np.asarray(planner.object.mesh.vertices) @ planner.free["rotmat"][0][:3, :3].T + planner.free["rotmat"][0][:3, 3]
    overhang = float(placed[placed[:, 2] <= placed[:, 2].min() + 1e-4, 0].max()) - 0.001  # the support's reach in x
    with pytest.raises(PlanningError, match="mm of tube's support past the table's edge") as err:
        planner.plan(PoseQuery(ids[0], 0.5, 0.0, 0.0), PoseQuery(ids[0], edge, 0.0, 0.0))
    assert float(re.search(r"puts ([0-9.]+) mm", str(err.value)).group(1)) == pytest.approx(overhang * 1000, abs=0.15)
    with pytest.raises(PlanningError, match="NaN"):
        planner.plan(PoseQuery(ids[0], float("nan"), 0.0, 0.0), PoseQuery(ids[0], 0.5, 0.0, 0.0))
    with pytest.raises(PlanningError, match="goal pose .* is not reachable by panda: .* every grasp is beyond the "
                                            "arm's reach .*move the part closer"):
        planner.plan(PoseQuery(ids[-1], 0.5, 0.0, 0.0), PoseQuery(ids[-1], 0.95, 0.75, 0.0))
    # on the robot's own base: within reach, where the arm stands in the way (not "move it closer")
    with pytest.raises(PlanningError, match=r"goal pose .* not reachable .* the grasps within the arm's reach \(0.05 m "
                                            r"from the robot's base\) collide .* clear of the robot"):
        planner.plan(PoseQuery(ids[-1], 0.5, 0.0, 0.0), PoseQuery(ids[-1], 0.05, 0.0, 0.0))
    # a pose given as a 4x4 transform that rests on no stable placement
    pose = PoseQuery(ids[0], 0.5, 0.0, 0.0).move() @ planner.free["rotmat"][0]
    pose[:3, 3] += [0, 0, 0.03]
    with pytest.raises(PlanningError, match="not on a stable placement"):
        planner.plan(pose, PoseQuery(ids[0], 0.5, 0.0, 0.0))


def test_unconnected_start_and_goal_get_their_message(planner):
    """Without roadmap nodes, a start and a goal on placements sharing no grasp are reachable but not connected."""
    ftg = planner.ftg
    grasps = {int(p): set(ftg["idfreeairgrip"][ftg["idfreetabletopplacement"] == p].tolist()) for p in planner.placement_ids()}
    pair = next(((a, b) for a in grasps for b in grasps if grasps[a] and grasps[b] and not grasps[a] & grasps[b]), None)
    assert pair is not None
    empty = build_roadmap({"idtabletopgrips": np.zeros(0, int), "idtabletopplacements": np.zeros(0, int),
                           "idfreeairgrip": np.zeros(0, int), "idfreetabletopplacement": np.zeros(0, int),
                           "rotmat": np.zeros((0, 4, 4)), "placement_rotmat": np.zeros((0, 4, 4)),
                           "tabletopposition": np.zeros((0, 3)), "angle": np.zeros(0), "jawwidth": np.zeros(0),
                           "joints": np.zeros((0, 3, planner.robot.nq))})
    # the placements' store ids as in a store holding other parts before this one: messages number them within the part
    shift = lambda rows: {**rows, "idfreetabletopplacement": np.asarray(rows["idfreetabletopplacement"]) + 100}  # noqa: E731
    cut = Planner(empty, shift(planner.free), shift(planner.ftg), planner.object, planner.robot, planner.scene,
                  planner.handx, planner.worldz, planner.ids, planner.ik_opts)
    cut._ik = planner.ik
    start, goal = PoseQuery(pair[0], 0.45, 0.0, 0.0), PoseQuery(pair[1], 0.55, 0.05, 1.0)
    try:
        planner.search(start, goal, alternatives=0)  # both reachable in the full graph?
    except PlanningError as exc:
        pytest.skip(f"this pair is not reachable: {exc}")
    a, b = planner.numbers[pair[0]], planner.numbers[pair[1]]
    with pytest.raises(PlanningError, match="not connected in the regrasp graph") as err:
        cut.plan(PoseQuery(pair[0] + 100, 0.45, 0.0, 0.0), PoseQuery(pair[1] + 100, 0.55, 0.05, 1.0))
    assert f"start ({a},0.45,0,0 deg) and goal ({b},0.55,0.05,57.2958 deg)" in str(err.value)


def test_command_line_yaw_is_in_degrees_and_bounded():
    q = parse_pose("1,0.5,0.1,90", "--goal", degrees=True)
    assert np.isclose(q.yaw, np.pi / 2) and q.text_degrees() == "1,0.5,0.1,90"
    assert np.isclose(parse_pose("1,0.5,0.1,1.5708").yaw, 1.5708)  # the library takes radians
    with pytest.raises(PlanningError, match=r"outside \[-360, 360\]"):
        parse_pose("3,0.55,-0.1,400", "--goal", degrees=True)


def test_a_regrasp_graph_above_the_memory_budget_is_refused_before_loading_or_solving(small_store, monkeypatch, bundled):
    """The graph's memory grows with the tabletop grips (about 6 kB each once loaded): above the budget, loading the
    planner and solving the IK it needs are refused in one line naming the grip count and what to lower, and the
    store is left as it was."""
    from workbench.params import BUDGET_ENV, MemoryBudgetError
    from workbench.planners.wan_harada.stages import load_planner, run_ik
    from workbench.robots.model import get_robot
    from workbench.store import Store

    with Store(small_store, read_only=True) as store:
        grips = store.one("SELECT count(*) FROM tabletopgrips")[0]
        ik_rows = store.one("SELECT count(*) FROM ik")[0]
    monkeypatch.setenv(BUDGET_ENV, str(6000 * grips - 1))
    with pytest.raises(MemoryBudgetError, match=rf"the regrasp graph of {grips:,} tabletop grips .*--max-grasps"):
        load_planner(small_store, "tube", "panda")
    with Store(small_store) as store, pytest.raises(MemoryBudgetError, match="regrasp graph"):
        run_ik(store, "tube", get_robot("ur5"), workers=1, progress=False)
    with Store(small_store, read_only=True) as store:
        assert store.one("SELECT count(*) FROM ik")[0] == ik_rows
    monkeypatch.setenv(BUDGET_ENV, str(6000 * grips + 1))
    assert load_planner(small_store, "tube", "panda").roadmap.n_grips == grips
