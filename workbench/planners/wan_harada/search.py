"""The search of the regrasp graph (Wan & Harada, Section V, "Searching the graph").

Start grips join roadmap nodes with the same grasp by transfer edges, goal grips likewise, and a start grip joins
a goal grip directly when one grasp serves both. The search is a breadth-first search on the layered graph
(layer = number of regrasps) over pairs of start and goal grasps, cost (regrasps, transfers) lexicographic.
IK at the query poses is the expensive part, so it is evaluated lazily: in rounds, only the grips of the cheapest
pairs whose feasibility is unsettled, most promising first, until the best plans are proven (`lazy=False`
evaluates every grip first; the optimum is the same).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from workbench.planners.wan_harada.query import Side
from workbench.planners.wan_harada.roadmap import UNREACHED, Roadmap

if TYPE_CHECKING:  # pragma: no cover

    pass


@dataclass
class Route:
    """One way through the graph: the start grip, for each regrasp the node where the object is put down with the
    previous grasp and the node where it is grasped again (same placement), and the goal grip."""

    start_grip: int
    goal_grip: int
    regrasps: list[tuple[int, int]]

    @property
    def n_regrasps(self) -> int:
        return len(self.regrasps)

    @property
    def n_transfers(self) -> int:
        return len(self.regrasps) + 1


@dataclass
class SearchResult:
    """Routes best first (cost: regrasps, then transfers), the two sides, and timings in seconds (connect: IK at
    the start and goal poses; search: pairing, distances and route reconstruction)."""

    routes: list[Route]
    start: Side
    goal: Side
    timings: dict
    rounds: int = 0


def pair_costs(roadmap: Roadmap, start: Side, goal: Side) -> np.ndarray:
    """(nS, nG) regrasps of each start/goal grip pair ignoring IK at the query poses: 0 for one grasp serving both,
    the grasp graph's distance between two roadmap grasps, UNREACHED otherwise."""
    c = np.full((len(start.grasp), len(goal.grasp)), UNREACHED, dtype=np.int64)
    rs, rg = start.rindex, goal.rindex
    si, gi = np.flatnonzero(rs >= 0), np.flatnonzero(rg >= 0)
    if len(si) and len(gi):
        c[np.ix_(si, gi)] = roadmap.dist[np.ix_(rs[si], rg[gi])]
    same = start.grasp[:, None] == goal.grasp[None, :]
    c[same] = 0
    return c


def _first_unique(a: np.ndarray) -> np.ndarray:
    """The distinct values of `a` in order of first appearance."""
    _, first = np.unique(a, return_index=True)
    return a[np.sort(first)]


def search(roadmap: Roadmap, start: Side, goal: Side, evaluate: Callable[[list[tuple[Side, np.ndarray]], bool], None],
           alternatives: int = 2, lazy: bool = True,
           chunk: int = 8) -> SearchResult:
    """Fewest regrasps, then fewest transfers, between a start and a goal side (Section V, "Searching the graph").

    Breadth-first on the layered graph: a pair (start grip, goal grip) costs the regrasps of `pair_costs`, and a
    route exists when both grips are IK-feasible. `evaluate([(side, indices), ...], fallback)` sets the IK state and
    joints of grips of both sides in one call: tier 1 (nearest stored solution) for unknown grips, tier 2 (the
    fall-back seeds) for grips that failed tier 1 when `fallback`. With `lazy`, phase A takes the cheapest
    cost level that still has pairs of unsettled grips and evaluates up to `chunk` grips per side (doubling every
    round) from its pairs, most promising first (`prior`): unknown grips first, tier 2 only when the level has no
    unknown grip left; it ends when a confirmed pair costs no more than any unsettled one, so the best cost is the
    same as evaluating every grip first (`lazy=False`). Phase B gathers alternatives (at most one regrasp above the
    best) from tier 1 only, until `1 + alternatives` pairs are confirmed. Routes come best first: cost, then the
    robustness of the pair's contacts (`_robustness`, central contacts first), then the pair's order."""
    timings = {"connect": 0.0, "search": 0.0}
    want = 1 + max(0, int(alternatives))
    t0 = time.perf_counter()
    cost = pair_costs(roadmap, start, goal)
    finite = cost < UNREACHED
    prior_s = start.prior if start.prior is not None else np.full(len(start.grasp), 0.5)
    prior_g = goal.prior if goal.prior is not None else np.full(len(goal.grasp), 0.5)
    timings["search"] += time.perf_counter() - t0

    def run(new_s: np.ndarray, new_g: np.ndarray, fallback: bool) -> None:
        if len(new_s) or len(new_g):
            t = time.perf_counter()
            evaluate([(start, new_s), (goal, new_g)], fallback)
            timings["connect"] += time.perf_counter() - t

    if not lazy:
        run(np.flatnonzero(start.state == 0), np.flatnonzero(goal.state == 0), True)
        run(np.flatnonzero(start.state == -2), np.flatnonzero(goal.state == -2), True)
    rounds = 0
    while True:
        t = time.perf_counter()
        possible = finite & (start.state != -1)[:, None] & (goal.state != -1)[None, :]
        confirmed = possible & (start.state == 1)[:, None] & (goal.state == 1)[None, :]
        open_ = possible & ~confirmed
        vmin = int(cost[open_].min()) if open_.any() else UNREACHED
        best = int(cost[confirmed].min()) if confirmed.any() else UNREACHED
        if best > vmin:  # phase A: the optimum is not proven yet; settle the cheapest open level
            level = open_ & (cost == vmin)
        else:  # phase B: alternatives up to one regrasp above the best, from tier 1 only
            unknown = open_ & ((start.state == 0)[:, None] | (goal.state == 0)[None, :]) & (cost <= best + 1)
            if int((confirmed & (cost <= best + 1)).sum()) >= want or not unknown.any():
                timings["search"] += time.perf_counter() - t
                break
            level = unknown & (cost == int(cost[unknown].min()))
        ps, pg = np.nonzero(level)
        score = np.where(start.state[ps] == 1, 1.0, prior_s[ps]) * np.where(goal.state[pg] == 1, 1.0, prior_g[pg])
        order = np.lexsort((pg, ps, -np.round(score, 6)))
        ps, pg = ps[order], pg[order]
        m = chunk << min(rounds, 20)
        new_s = _first_unique(ps[start.state[ps] == 0])[:m]
        new_g = _first_unique(pg[goal.state[pg] == 0])[:m]
        fallback = not len(new_s) and not len(new_g)
        if fallback:  # every open pair of this level waits on grips that failed tier 1
            new_s = _first_unique(ps[start.state[ps] == -2])[:m]
            new_g = _first_unique(pg[goal.state[pg] == -2])[:m]
        timings["search"] += time.perf_counter() - t
        rounds += 1
        run(new_s, new_g, fallback)
    t = time.perf_counter()
    confirmed = finite & (start.state == 1)[:, None] & (goal.state == 1)[None, :]
    si, gi = np.nonzero(confirmed)
    if len(si):  # alternatives: at most one regrasp more than the best
        near = cost[si, gi] <= cost[si, gi].min() + 1
        si, gi = si[near], gi[near]
    order = np.lexsort((gi, si, -_robustness(start, goal, si, gi), cost[si, gi]))[:want]
    routes = [route(roadmap, start, goal, int(si[k]), int(gi[k])) for k in order]
    timings["search"] += time.perf_counter() - t
    return SearchResult(routes=routes, start=start, goal=goal, timings=timings, rounds=rounds)


def _robustness(start: Side, goal: Side, si: np.ndarray, gi: np.ndarray) -> np.ndarray:
    """The less robust contact grasp of each (start grip, goal grip) pair (0 where unknown), rounded so that the
    order does not hang on the last bits: among routes of equal cost the search prefers central contacts."""
    def of(side: Side, idx: np.ndarray) -> np.ndarray:
        if side.robust is None:
            return np.zeros(len(idx))
        return np.nan_to_num(np.asarray(side.robust, dtype=np.float64)[idx], nan=0.0)

    return np.round(np.minimum(of(start, si), of(goal, gi)), 6)


def route(roadmap: Roadmap, start: Side, goal: Side, s: int, g: int) -> Route:
    """The nodes of the cheapest route from start grip `s` to goal grip `g`: at each regrasp, among the placements
    where the current grasp and a grasp one step closer to the goal's meet, the one nearest to the object's current
    position plus its distance to the goal (ties: lowest node index)."""
    if start.grasp[s] == goal.grasp[g]:
        return Route(start_grip=s, goal_grip=g, regrasps=[])
    cur, tgt = int(start.rindex[s]), int(goal.rindex[g])
    left = int(roadmap.dist[cur, tgt])
    pos = start.pose[:2, 3]
    goal_xy = goal.pose[:2, 3]
    out = []
    while left > 0:
        a_nodes, _ = roadmap.nodes_of_grasps(np.array([cur]))
        places = roadmap.node_place[a_nodes]
        b_nodes, owner = roadmap.nodes_of_places(places)
        nb = roadmap.node_grasp[b_nodes]
        ok = (roadmap.dist[nb, tgt] == left - 1) & (nb != cur)
        a_sel, b_sel = a_nodes[owner[ok]], b_nodes[ok]
        xy = roadmap.position[a_sel, :2]
        score = np.linalg.norm(xy - pos, axis=1) + np.linalg.norm(xy - goal_xy, axis=1)
        k = np.lexsort((b_sel, a_sel, np.round(score, 9)))[0]
        a, b = int(a_sel[k]), int(b_sel[k])
        out.append((a, b))
        cur, pos, left = int(roadmap.node_grasp[b]), roadmap.position[a, :2], left - 1
    return Route(start_grip=s, goal_grip=g, regrasps=out)
