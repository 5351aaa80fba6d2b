"""Linking an arbitrary force-closure grasp to the representative roadmap R (Phoka & Sudsang, Section III-D):
Algorithm 1 (the grasp's representative grasp), `find_nearest_cluster` and Algorithm 2, Algorithm 3 (extending
R), and the local planner FindPath over the paper's sets S1..S4.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order

from workbench.params import single_blas
from workbench.planners.phoka_sudsang.forceclosure import ForceClosure, combinations_array
from workbench.planners.phoka_sudsang.switching import (
    FingerPlanner,
    Roadmap,
    _triples,
    construct_roadmap,
    grasp_keys,
    switching_edges,
)


def find_path(local: Roadmap, start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
    """FindPath(L, g, g'): the grasps of a shortest switching path in L, or None."""
    i, j = local.index(np.stack([start, goal]))
    if i < 0 or j < 0:
        return None
    p = local.path(int(i), np.array([j]))
    return None if p is None else local.grasps[p]


def local_path(tester: ForceClosure, sets: list[np.ndarray], start: np.ndarray, goal: np.ndarray) -> np.ndarray | None:
    """FindPath(ConstructRoadmap(S1, S2, S3, S4), start, goal), evaluated lazily.

    A bidirectional breadth-first search over the grasps with one contact from each set, testing force closure
    only for the grasps it reaches (one batch per layer) instead of for the whole product. It returns a shortest
    path of the local roadmap exactly when the eager construction would find one.

    Why this is exact when at most one contact c lies in two sets S_i, S_j (the case Algorithm 2 builds when p_x
    joins K_y' while its own cluster is also one of f's): every other contact lies in one set, so a grasp of the
    product has exactly one assignment of its contacts to the sets (c takes whichever of S_i, S_j the others leave
    free), and the search's states (slot tuples) are the local roadmap's vertices. An edge G -> G' = G - u + v
    keeps the slots of G's three shared contacts except when c is one of them and {c, u} fill slots {i, j}: then
    G' may hold v in c's slot and c in u's slot. Such swap moves are generated besides the one-slot moves, so the
    neighbours are exactly the eager roadmap's edges. More shared contacts fall back to the eager construction.
    """
    sets = [np.unique(np.asarray(s, dtype=np.int64)) for s in sets]
    allc = np.concatenate(sets)
    shared = len(allc) - len(np.unique(allc))
    if shared > 1:
        return find_path(construct_roadmap(tester, *sets), np.sort(start), np.sort(goal))
    swaps = []          # (c, i, j): c in S_i and S_j; a state with c in slot i may move c to slot j
    if shared == 1:
        vals, counts = np.unique(allc, return_counts=True)
        c = int(vals[counts > 1][0])
        i, j = (k for k, s in enumerate(sets) if c in s)
        swaps = [(c, i, j), (c, j, i)]
    n = tester.n
    g0, g1 = np.sort(start), np.sort(goal)
    s0, s1 = _slots(g0, sets), _slots(g1, sets)
    if s0 is None or s1 is None:
        return None
    if np.array_equal(g0, g1):
        return g0[None].copy()
    key = lambda g: grasp_keys(np.sort(g, axis=1), n)            # noqa: E731
    tested: dict[int, bool] = {}
    parents = [{int(key(g0[None])[0]): -1}, {int(key(g1[None])[0]): -1}]
    frontier = [s0[None], s1[None]]
    while len(frontier[0]) and len(frontier[1]):
        side = 0 if len(frontier[0]) <= len(frontier[1]) else 1
        f = frontier[side]
        nbrs, src = [], []
        for i, s in enumerate(sets):
            cand = np.repeat(f, len(s), axis=0)
            cand[:, i] = np.tile(s, len(f))
            keep = (cand[:, i:i + 1] != np.delete(cand, i, axis=1)).all(axis=1)    # distinct contacts
            nbrs.append(cand[keep])
            src.append(np.repeat(key(f), len(s))[keep])
        for c, i, j in swaps:       # c leaves slot i for slot j, dropping slot j's contact; v of S_i fills slot i
            at = f[f[:, i] == c]
            s = sets[i][sets[i] != c]
            if len(at) == 0 or len(s) == 0:
                continue
            cand = np.repeat(at, len(s), axis=0)
            cand[:, j] = c
            cand[:, i] = np.tile(s, len(at))
            srt = np.sort(cand, axis=1)
            keep = (srt[:, 1:] != srt[:, :-1]).all(axis=1)
            nbrs.append(cand[keep])
            src.append(np.repeat(key(at), len(s))[keep])
        cand, src = np.concatenate(nbrs), np.concatenate(src)
        ck = key(cand)
        fresh = np.array([k not in parents[side] for k in ck.tolist()], dtype=bool)
        cand, src, ck = cand[fresh], src[fresh], ck[fresh]
        ck, first = np.unique(ck, return_index=True)
        cand, src = cand[first], src[first]
        unknown = [i for i, k in enumerate(ck.tolist()) if k not in tested]
        if unknown:
            res = tester.exact(np.sort(cand[unknown], axis=1))
            tested.update(zip(ck[unknown].tolist(), res.tolist()))
        ok = np.array([tested[k] for k in ck.tolist()], dtype=bool)
        cand, src, ck = cand[ok], src[ok], ck[ok]
        for k, p in zip(ck.tolist(), src.tolist()):
            parents[side][k] = p
        meet = [k for k in ck.tolist() if k in parents[1 - side]]
        if meet:
            return _bidir_path(parents, meet[0], n)
        frontier[side] = cand
    return None


def _slots(g: np.ndarray, sets: list[np.ndarray]) -> np.ndarray | None:
    """The grasp's contacts ordered by the set each belongs to (None when no assignment exists)."""

    member = np.array([[c in set(s.tolist()) for s in sets] for c in g])
    for perm in permutations(range(4)):
        if all(member[k, perm[k]] for k in range(4)):
            out = np.empty(4, dtype=np.int64)
            out[list(perm)] = g
            return out
    return None


def _bidir_path(parents: list[dict[int, int]], meet: int, n: int) -> np.ndarray:
    """The grasps from the start (side 0) through `meet` to the goal (side 1)."""
    def chain(side: int) -> list[int]:
        out, k = [], meet
        while k != -1:
            out.append(k)
            k = parents[side][k]
        return out

    keys = chain(0)[::-1] + chain(1)[1:]
    k = np.asarray(keys, dtype=np.int64)
    return np.stack([k // n ** 3, k // n ** 2 % n, k // n % n, k % n], axis=1)


@dataclass(frozen=True)
class Link:
    """A switching path from a grasp to a vertex of R: `path` (P, 4) starts at the grasp, ends in R."""

    path: np.ndarray
    method: str
    vertex: int


def _rep_grasp(planner: FingerPlanner, g: np.ndarray) -> np.ndarray:
    """p_a', p_b', p_c', p_d': the representatives of the clusters of g's contacts (slot order kept)."""
    return planner.clustering.reps[planner.clustering.labels[g]]


def algorithm1_applies(planner: FingerPlanner, g: np.ndarray) -> int:
    """The vertex of g' in R, or -1 when g' is not a force-closure grasp of representatives (Alg. 1, line 2)."""
    gp = _rep_grasp(planner, g)
    if len(np.unique(gp)) < 4:
        return -1
    return int(planner.roadmap.index(gp[None])[0])


def algorithm1(planner: FingerPlanner, g: np.ndarray) -> Link | None:
    """Algorithm 1: switch g to g' inside the local roadmap of the clusters of g's contacts (None: fails)."""
    v = algorithm1_applies(planner, g)
    if v < 0:
        return None
    cl = planner.clustering
    sets = [cl.members(c) for c in cl.labels[g]]
    path = local_path(planner.tester, sets, g, planner.roadmap.grasps[v])
    return None if path is None else Link(path, "alg1", v)


@dataclass(frozen=True)
class NearestCluster:
    """X of FindNearestCluster: contact p_x (slot of g), its cluster K_x', the target K_y' and f' (a vertex of R)."""

    slot: int
    contact: int
    from_cluster: int
    to_cluster: int
    vertex: int
    distance: float


def find_nearest_cluster(planner: FingerPlanner, g: np.ndarray) -> NearestCluster | None:
    """FindNearestCluster: over the vertices f' of R one contact away from g', the move of p_x to K_y' with the
    smallest E(p_x, K_y') (Section III-D, Algorithm 2 line 2). None when no vertex of R is one contact away."""
    cl, rm = planner.clustering, planner.roadmap
    gp = _rep_grasp(planner, g)
    best: NearestCluster | None = None
    for slot in range(4):
        others = np.delete(gp, slot)
        if len(np.unique(others)) < 3:
            continue
        rows, fourth = rm.with_triple(np.sort(others))
        keep = fourth != gp[slot]          # f' = g' itself is not a move
        if not keep.any():
            continue
        rows, fourth = rows[keep], fourth[keep]
        target = cl.labels[fourth]
        dist = cl.E[g[slot], target]
        i = int(np.argmin(dist))
        if best is None or dist[i] < best.distance:
            best = NearestCluster(slot, int(g[slot]), int(cl.labels[g[slot]]), int(target[i]), int(rows[i]), float(dist[i]))
    return best


def algorithm2(planner: FingerPlanner, g: np.ndarray, x: NearestCluster | None = None) -> Link | None:
    """Algorithm 2: move p_x temporarily into K_y' and switch g to f' in the local roadmap of f's clusters."""
    x = find_nearest_cluster(planner, g) if x is None else x
    if x is None:
        return None
    cl = planner.clustering
    f = planner.roadmap.grasps[x.vertex]
    sets = []
    for rep in f:
        members = cl.members(int(cl.labels[rep]))
        if cl.labels[rep] == x.to_cluster:
            members = np.append(members, x.contact)       # Add p_x into K_y' (for this local roadmap only)
        sets.append(members)
    path = local_path(planner.tester, sets, g, f)
    return None if path is None else Link(path, "alg2", x.vertex)


@dataclass(frozen=True)
class Extension:
    """Algorithm 3's update of R: new vertices L (rows of `grasps` not in R), edges among them, edges to R."""

    grasps: np.ndarray          # (L, 4) new force-closure grasps not in R
    edges: np.ndarray           # (E, 2) among the new grasps
    cross: np.ndarray           # (C, 2) new grasp index, vertex of R
    tg: np.ndarray              # T_G: the contacts made representatives


@single_blas
def extend_roadmap(planner: FingerPlanner, g: np.ndarray) -> Extension:
    """Algorithm 3 lines 1-4: T_G = g, T_A = T_R + T_G, L = ConstructRoadmap(T_A, T_A, T_A, T_G), linked to R."""
    tg = np.unique(g)
    ta = np.unique(np.concatenate([planner.representatives, tg]))
    local = combinations_array(len(ta), 4)
    cand = ta[local[np.isin(ta[local], tg).any(axis=1)]]
    rm = planner.roadmap
    cand = cand[rm.index(cand) < 0]
    ok = planner.tester.test(cand, table=(planner.tester.span_table(ta), ta)) if len(cand) else np.zeros(0, dtype=bool)
    new = cand[ok]
    edges, _ = switching_edges(new, planner.n)
    cross = []
    tk, tr, _ = _triples(new, planner.n)
    lo = np.searchsorted(rm._tkeys, tk)
    hi = np.searchsorted(rm._tkeys, tk, side="right")
    counts = hi - lo
    if counts.sum():
        src = np.repeat(tr, counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        dst = rm._trows[np.repeat(lo, counts) + (np.arange(counts.sum()) - first)]
        cross = np.stack([src, dst], axis=1)
    return Extension(new, edges, np.asarray(cross, dtype=np.int64).reshape(-1, 2), tg.astype(np.int64))


def update_roadmap(planner: FingerPlanner, g: np.ndarray) -> Extension:
    """Algorithm 3 applied to R for good (line 4, "Update R by adding L and linking L to R"): T_G = g joins T_R and
    L = ConstructRoadmap(T_A, T_A, T_A, T_G) joins R; later links and queries use both."""
    ext = extend_roadmap(planner, np.sort(np.asarray(g, dtype=np.int64).reshape(4)))
    planner.apply(ext)
    return ext


def algorithm3(planner: FingerPlanner, g: np.ndarray, ext: Extension | None = None) -> Link | None:
    """Algorithm 3: add g's contacts as representatives and link g to the R that existed before the update."""
    v = int(planner.roadmap.index(g[None])[0])
    if v >= 0:
        return Link(g[None].copy(), "alg3", v)
    ext = extend_roadmap(planner, g) if ext is None else ext
    start = np.flatnonzero(grasp_keys(ext.grasps, planner.n) == grasp_keys(g[None], planner.n)[0])
    if len(start) == 0 or len(ext.cross) == 0:
        return None
    m = len(ext.grasps)
    e = ext.edges
    csr = csr_matrix((np.ones(2 * len(e), dtype=np.int8), (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))),
                     shape=(m, m))
    order, pred = breadth_first_order(csr, int(start[0]), directed=True, return_predecessors=True)
    linked = np.zeros(m, dtype=bool)
    linked[ext.cross[:, 0]] = True
    hit = order[linked[order]]
    if len(hit) == 0:
        return None
    chain = [int(hit[0])]
    while chain[-1] != start[0]:
        chain.append(int(pred[chain[-1]]))
    chain = chain[::-1]
    v = int(ext.cross[ext.cross[:, 0] == chain[-1], 1].min())
    return Link(np.vstack([ext.grasps[chain], planner.roadmap.grasps[v][None]]), "alg3", v)


def link(planner: FingerPlanner, g: np.ndarray, update: bool = False) -> Link | None:
    """Link a force-closure grasp to R (Section III-D): a vertex of R already ("roadmap"), else Algorithm 1, else
    2, else 3. With `update`, Algorithm 3 updates R itself (`update_roadmap`) and g becomes a vertex of R."""
    v = int(planner.roadmap.index(g[None])[0])
    if v >= 0:
        return Link(g[None].copy(), "roadmap", v)
    for alg in (algorithm1, algorithm2):
        out = alg(planner, g)
        if out is not None:
            return out
    if not update:
        return algorithm3(planner, g)
    update_roadmap(planner, g)
    v = int(planner.roadmap.index(g[None])[0])
    return Link(g[None].copy(), "alg3", v) if v >= 0 else None
