"""Five-finger regrasp planning by finger switching (Phoka & Sudsang, Sections III-A, III-C, III-D).

A grasp is four contact indices (rows kept ascending). Two force-closure grasps sharing three contacts switch
into each other: the fifth finger is placed on the new contact, then the finger on the dropped contact lifts.

- `switching_edges`, `Roadmap`: a graph of force-closure grasps and its connected components.
- `build_roadmap`: R, every force-closure 4-subset of the representatives T_R (Section III-C).
- `construct_roadmap` / `find_path`: the paper's ConstructRoadmap(S1, S2, S3, S4) and FindPath.
- `algorithm1`, `find_nearest_cluster`, `algorithm2`, `algorithm3`: linking an arbitrary force-closure
  grasp to R (Section III-D, Algorithms 1-3).
- `query`: a finger-switching sequence from a start to a goal grasp through R.
- `sample_grasps`, `local_planning_stats`: the experiments of Tables II and III.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from .clustering import ClusterParams, Clustering, cluster_contacts
from .contacts import ContactSet
from .errors import PlanningError
from .forceclosure import ForceClosure, combinations_array, single_blas


class FingerPlanningError(PlanningError):
    """A query the five-finger planner cannot take: unknown contacts, grasps that are not force closure."""


# ----------------------------------------------------------------------------------------------------------
# Graphs of grasps


def grasp_keys(grasps: np.ndarray, n: int) -> np.ndarray:
    """One int64 per grasp (rows ascending, contact indices < n <= 2**15)."""
    g = np.asarray(grasps, dtype=np.int64).reshape(-1, 4)
    return ((g[:, 0] * n + g[:, 1]) * n + g[:, 2]) * n + g[:, 3]


def _triples(grasps: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For every grasp and dropped slot: the key of the other three contacts, the grasp row, the dropped slot."""
    g = np.asarray(grasps, dtype=np.int64)
    keys, rows, slots = [], [], []
    for drop in range(4):
        keep = [c for c in range(4) if c != drop]
        t = g[:, keep]
        keys.append((t[:, 0] * n + t[:, 1]) * n + t[:, 2])
        rows.append(np.arange(len(g)))
        slots.append(np.full(len(g), drop))
    return np.concatenate(keys), np.concatenate(rows), np.concatenate(slots)


def switching_edges(grasps: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Edges (E, 2) between distinct grasps sharing exactly three contacts, and (E, 2) (lifted, placed) contacts.

    Two distinct 4-sets share three contacts exactly when one of their triples is equal, so grouping all
    triples by key and pairing within each group yields every edge once.
    """
    g = np.asarray(grasps, dtype=np.int64)
    keys, rows, slots = _triples(g, n)
    order = np.argsort(keys, kind="stable")
    keys, rows, slots = keys[order], rows[order], slots[order]
    bounds = np.flatnonzero(np.diff(keys)) + 1
    group_end = np.repeat(np.append(bounds, len(keys)), np.diff(np.concatenate([[0], bounds, [len(keys)]])))
    pos = np.arange(len(keys))
    later = group_end - pos - 1
    src = np.repeat(pos, later)
    first = np.repeat(np.cumsum(later) - later, later)
    dst = src + 1 + (np.arange(len(src)) - first)
    edges = np.stack([rows[src], rows[dst]], axis=1)
    moves = np.stack([g[rows[src], slots[src]], g[rows[dst], slots[dst]]], axis=1)
    return edges, moves


class Roadmap:
    """A graph of force-closure grasps (rows ascending, sorted); edges join grasps sharing three contacts.

    Grasps sharing a triple of contacts form a clique, so connectivity and shortest paths are computed on the
    much sparser bipartite graph of grasps and their triples (a grasp-triple-grasp step is one switch); the
    explicit edge list (`edges`, `moves`) is built on first use.
    """

    def __init__(self, grasps: np.ndarray, n: int, edges: np.ndarray | None = None, moves: np.ndarray | None = None):
        self.grasps = np.asarray(grasps, dtype=np.int64).reshape(-1, 4)
        self.n = int(n)
        self.keys = grasp_keys(self.grasps, self.n)
        self._edges, self._moves = edges, moves
        v = len(self.grasps)
        tk, tr, ts = _triples(self.grasps, self.n)
        order = np.argsort(tk, kind="stable")
        self._tkeys, self._trows, self._tslots = tk[order], tr[order], ts[order]
        tid = np.cumsum(np.r_[False, np.diff(self._tkeys) != 0]) if len(tk) else np.zeros(0, dtype=np.int64)
        nodes = v + (int(tid[-1]) + 1 if len(tid) else 0)
        a, b = self._trows, v + tid
        self.csr = csr_matrix((np.ones(2 * len(a), dtype=np.int8), (np.concatenate([a, b]), np.concatenate([b, a]))),
                              shape=(nodes, nodes))
        if v:
            _, labels = connected_components(self.csr, directed=True, connection="weak")
            _, self.components = np.unique(labels[:v], return_inverse=True)
            self.ncomponents = int(self.components.max()) + 1
        else:
            self.components, self.ncomponents = np.zeros(0, dtype=np.int64), 0

    @classmethod
    def from_grasps(cls, grasps: np.ndarray, n: int) -> "Roadmap":
        """The roadmap of a set of force-closure grasps (rows sorted, duplicates dropped)."""
        g = np.sort(np.asarray(grasps, dtype=np.int64).reshape(-1, 4), axis=1)
        _, first = np.unique(grasp_keys(g, n), return_index=True)
        return cls(g[first], n)

    @property
    def edges(self) -> np.ndarray:
        """(E, 2) vertex pairs sharing three contacts."""
        if self._edges is None:
            self._edges, self._moves = switching_edges(self.grasps, self.n)
        return self._edges

    @property
    def moves(self) -> np.ndarray:
        """(E, 2) per edge the contact lifted from the first grasp and the contact placed to make the second."""
        if self._moves is None:
            self._edges, self._moves = switching_edges(self.grasps, self.n)
        return self._moves

    def __len__(self) -> int:
        return int(len(self.grasps))

    def index(self, grasps: np.ndarray) -> np.ndarray:
        """Vertex index of each grasp (-1 where absent)."""
        k = grasp_keys(np.sort(np.asarray(grasps, dtype=np.int64).reshape(-1, 4), axis=1), self.n)
        if len(self.keys) == 0:
            return np.full(len(k), -1, dtype=np.int64)
        pos = np.minimum(np.searchsorted(self.keys, k), len(self.keys) - 1)
        return np.where(self.keys[pos] == k, pos, -1)

    def with_triple(self, triple: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vertices containing the three (ascending) contacts, and each one's fourth contact."""
        t = np.asarray(triple, dtype=np.int64)
        key = (t[0] * self.n + t[1]) * self.n + t[2]
        lo, hi = np.searchsorted(self._tkeys, [key, key + 1])
        rows, slots = self._trows[lo:hi], self._tslots[lo:hi]
        return rows, self.grasps[rows, slots]

    def path(self, source: int, targets: np.ndarray) -> list[int] | None:
        """A shortest switching path (vertex list) from `source` to the nearest of `targets`, or None."""
        targets = np.atleast_1d(np.asarray(targets, dtype=np.int64))
        order, pred = breadth_first_order(self.csr, source, directed=True, return_predecessors=True)
        mask = np.zeros(self.csr.shape[0], dtype=bool)
        mask[targets] = True
        hit = order[mask[order]]
        if len(hit) == 0:
            return None
        out = [int(hit[0])]
        while out[-1] != source:
            out.append(int(pred[out[-1]]))
        return [v for v in out[::-1] if v < len(self)]


# ----------------------------------------------------------------------------------------------------------
# Planner state and the paper's procedures


@dataclass
class FingerPlanner:
    """Everything Section III-D needs: T_O (contacts), clusters (T_O labels, T_R, E), the tester and R."""

    contacts: ContactSet
    clustering: Clustering
    tester: ForceClosure
    roadmap: Roadmap
    times: dict[str, float] = field(default_factory=dict)

    @property
    def n(self) -> int:
        return len(self.contacts)

    def check_grasp(self, grasp: np.ndarray | list[int], what: str = "grasp") -> np.ndarray:
        """A valid grasp as ascending indices, or a FingerPlanningError naming what is wrong."""
        g = np.asarray(grasp).reshape(-1)
        if len(g) != 4 or not np.issubdtype(g.dtype, np.integer):
            raise FingerPlanningError(f"{what} {list(np.asarray(grasp).reshape(-1))} must be four contact indices")
        bad = [int(c) for c in g if c < 0 or c >= self.n]
        if bad:
            raise FingerPlanningError(f"{what} uses unknown contact {bad[0]}: contacts are 0..{self.n - 1}")
        if len(set(g.tolist())) < 4:
            raise FingerPlanningError(f"{what} {g.tolist()} repeats a contact; give four distinct contacts")
        g = np.sort(g.astype(np.int64))
        if not self.tester.exact(g[None])[0]:
            raise FingerPlanningError(f"{what} {g.tolist()} is not force closure; pick a force-closure grasp "
                                      f"(e.g. from sample_grasps)")
        return g


@single_blas
def build_roadmap(tester: ForceClosure, reps: np.ndarray, progress: bool = False) -> Roadmap:
    """R: every force-closure 4-subset of the representatives is a vertex (Section III-C)."""
    return Roadmap.from_grasps(tester.subsets(reps, progress=progress), tester.n)


@single_blas
def build_planner(contacts: ContactSet, params: ClusterParams = ClusterParams(), progress: bool = False) -> FingerPlanner:
    """Cluster T_O, pick T_R and build R; `times` holds the seconds of clustering and roadmap."""
    t0 = time.perf_counter()
    clustering = cluster_contacts(contacts, params)
    t1 = time.perf_counter()
    tester = ForceClosure(contacts.points, contacts.normals, params.friction, ref=contacts.com, length=contacts.radius)
    roadmap = build_roadmap(tester, clustering.reps, progress=progress)
    t2 = time.perf_counter()
    return FingerPlanner(contacts, clustering, tester, roadmap, times={"clustering": t1 - t0, "roadmap": t2 - t1})


def construct_roadmap(tester: ForceClosure, s1: np.ndarray, s2: np.ndarray, s3: np.ndarray, s4: np.ndarray) -> Roadmap:
    """ConstructRoadmap(S1, S2, S3, S4): force-closure grasps with one contact from each set, as a roadmap."""
    sets = [np.unique(np.asarray(s, dtype=np.int64)) for s in (s1, s2, s3, s4)]
    mesh = np.stack(np.meshgrid(*sets, indexing="ij"), axis=-1).reshape(-1, 4)
    mesh = np.sort(mesh, axis=1)
    mesh = mesh[(np.diff(mesh, axis=1) > 0).all(axis=1)]
    cand = np.unique(mesh, axis=0)
    if len(cand) == 0:
        return Roadmap.from_grasps(np.zeros((0, 4), dtype=np.int64), tester.n)
    ids = np.unique(np.concatenate(sets))
    ok = tester.test(cand, table=(tester.span_table(ids), ids))
    return Roadmap.from_grasps(cand[ok], tester.n)


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
    path of the local roadmap exactly when the eager construction would find one. Sets that overlap (a contact
    in two sets) fall back to the eager construction.
    """
    sets = [np.unique(np.asarray(s, dtype=np.int64)) for s in sets]
    allc = np.concatenate(sets)
    shared = len(allc) - len(np.unique(allc))
    if shared > 1:
        return find_path(construct_roadmap(tester, *sets), np.sort(start), np.sort(goal))
    # with at most one contact in two sets, every grasp of the product has one slot assignment, so slot-wise
    # switches are exactly the local roadmap's edges
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
    from itertools import permutations

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


@single_blas
def extend_roadmap(planner: FingerPlanner, g: np.ndarray) -> Extension:
    """Algorithm 3 lines 1-4: T_G = g, T_A = T_R + T_G, L = ConstructRoadmap(T_A, T_A, T_A, T_G), linked to R."""
    tg = np.unique(g)
    ta = np.unique(np.concatenate([planner.clustering.reps, tg]))
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
    return Extension(new, edges, np.asarray(cross, dtype=np.int64).reshape(-1, 2))


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


def link(planner: FingerPlanner, g: np.ndarray) -> Link | None:
    """Link a force-closure grasp to R: Algorithm 1, else 2, else 3 (Section III-D)."""
    for alg in (algorithm1, algorithm2, algorithm3):
        out = alg(planner, g)
        if out is not None:
            return out
    return None


@dataclass(frozen=True)
class QueryResult:
    """A finger-switching sequence (S, 4) from start to goal (None when not connected), with how each end linked."""

    start: np.ndarray
    goal: np.ndarray
    sequence: np.ndarray | None
    start_method: str
    goal_method: str
    seconds: float

    @property
    def connected(self) -> bool:
        return self.sequence is not None


@single_blas
def query(planner: FingerPlanner, start: np.ndarray | list[int], goal: np.ndarray | list[int]) -> QueryResult:
    """A regrasp sequence from `start` to `goal` (Section III-D): link both to R, then search R.

    When the linked vertices lie in different components of R, both grasps are added to R by Algorithm 3 and
    the search runs in the updated roadmap. The update is local to this query (R itself is not changed).
    """
    t0 = time.perf_counter()
    g = planner.check_grasp(start, "start grasp")
    h = planner.check_grasp(goal, "goal grasp")
    if np.array_equal(g, h):
        return QueryResult(g, h, g[None].copy(), "same", "same", time.perf_counter() - t0)
    lg, lh = link(planner, g), link(planner, h)
    rm = planner.roadmap
    seq = None
    if lg is not None and lh is not None and rm.components[lg.vertex] == rm.components[lh.vertex]:
        mid = rm.path(lg.vertex, np.array([lh.vertex]))
        seq = _join([lg.path, rm.grasps[mid], lh.path[::-1]])
    if seq is None:
        seq = _search_extended(planner, g, h)
    return QueryResult(g, h, seq, lg.method if lg else "none", lh.method if lh else "none", time.perf_counter() - t0)


def _join(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate grasp paths whose ends meet, dropping the repeated junctions."""
    out = [parts[0]]
    for p in parts[1:]:
        out.append(p[1:] if len(p) and np.array_equal(p[0], out[-1][-1]) else p)
    return np.vstack(out)


def _search_extended(planner: FingerPlanner, g: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """Breadth-first search from g to h in R updated by Algorithm 3 for both g and h."""
    rm = planner.roadmap
    extra = [e.grasps for e in (extend_roadmap(planner, g), extend_roadmap(planner, h))]
    union = Roadmap.from_grasps(np.vstack([rm.grasps, *extra]), planner.n)
    i, j = union.index(np.stack([g, h]))
    if i < 0 or j < 0:
        return None
    p = union.path(int(i), np.array([j]))
    return None if p is None else union.grasps[p]


# ----------------------------------------------------------------------------------------------------------
# Sequences and experiments


def check_sequence(tester: ForceClosure, sequence: np.ndarray) -> bool:
    """True when every grasp is force closure and consecutive grasps share exactly three contacts."""
    s = np.asarray(sequence, dtype=np.int64).reshape(-1, 4)
    if len(s) == 0 or not tester.exact(np.sort(s, axis=1)).all():
        return False
    for a, b in zip(s[:-1], s[1:]):
        if len(set(a.tolist()) & set(b.tolist())) != 3:
            return False
    return True


def finger_assignment(sequence: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which of the five fingers touches which contact along a sequence.

    Returns (S, 5) contacts per finger (-1: the free finger), and per step the finger placed and the finger
    lifted to reach it (-1 at the first grasp). Fingers 0-3 start on the first grasp, finger 4 is free.
    """
    s = np.asarray(sequence, dtype=np.int64).reshape(-1, 4)
    fingers = np.full((len(s), 5), -1, dtype=np.int64)
    placed = np.full(len(s), -1, dtype=np.int64)
    lifted = np.full(len(s), -1, dtype=np.int64)
    if len(s) == 0:
        return fingers, placed, lifted
    fingers[0, :4] = s[0]
    for i in range(1, len(s)):
        cur = fingers[i - 1].copy()
        new = (set(s[i].tolist()) - set(s[i - 1].tolist())).pop()
        old = (set(s[i - 1].tolist()) - set(s[i].tolist())).pop()
        free = int(np.flatnonzero(cur < 0)[0])
        up = int(np.flatnonzero(cur == old)[0])
        cur[free], cur[up] = new, -1
        fingers[i], placed[i], lifted[i] = cur, free, up
    return fingers, placed, lifted


@single_blas
def sample_grasps(tester: ForceClosure, count: int, seed: int = 0, batch: int = 20000, max_tries: int = 200) -> np.ndarray:
    """`count` distinct random force-closure grasps (rows ascending), drawn uniformly over 4-subsets."""
    rng = np.random.default_rng(seed)
    n = tester.n
    if n < 4:
        raise FingerPlanningError(f"{n} contact points cannot make a 4-contact grasp; keep more triangles")
    found = np.zeros((0, 4), dtype=np.int64)
    for _ in range(max_tries):
        cand = np.sort(rng.random((batch, n)).argsort(axis=1)[:, :4], axis=1) if n <= 64 else _draw(rng, n, batch)
        cand = cand[(np.diff(cand, axis=1) > 0).all(axis=1)]
        ok = tester.exact(cand)
        merged = np.vstack([found, cand[ok]])
        _, first = np.unique(grasp_keys(merged, n), return_index=True)
        found = merged[np.sort(first)]
        if len(found) >= count:
            return found[:count]
    raise FingerPlanningError(f"found only {len(found)} force-closure grasps of {count} asked; raise the friction coefficient")


def _draw(rng: np.random.Generator, n: int, batch: int) -> np.ndarray:
    return np.sort(rng.integers(0, n, size=(batch, 4)), axis=1)


@dataclass
class LocalStats:
    """Table II (Algorithms 1-3) and Table III (queries) numbers for one object."""

    samples: int = 0
    alg1_run: float = 0.0
    alg1_connect: int = 0
    alg1_picked: int = 0
    alg2_run: float = 0.0
    alg2_connect: int = 0
    alg2_picked: int = 0
    alg3_connect: int = 0
    alg3_picked: int = 0
    queries: list[QueryResult] = field(default_factory=list)


@single_blas
def local_planning_stats(planner: FingerPlanner, samples: np.ndarray, picks: int = 30, seed: int = 0,
                         progress: bool = False) -> LocalStats:
    """Table II as Section IV runs it: verification rates of Algorithms 1 and 2 over the sampled grasps, then
    `picks` random passing grasps per algorithm planned to R; Algorithm 3 on `picks` grasps passing neither."""
    rng = np.random.default_rng(seed)
    st = LocalStats(samples=len(samples))
    pass1 = np.array([algorithm1_applies(planner, g) >= 0 for g in samples])
    nearest = [find_nearest_cluster(planner, g) for g in samples]
    pass2 = np.array([x is not None for x in nearest])
    st.alg1_run, st.alg2_run = 100.0 * pass1.mean(), 100.0 * pass2.mean()
    bar = _bar(progress, 3 * picks, "local planning")
    for which, passing in ((1, pass1), (2, pass2)):
        idx = np.flatnonzero(passing)
        pick = rng.choice(idx, size=min(picks, len(idx)), replace=False) if len(idx) else idx
        ok = 0
        for i in pick:
            out = algorithm1(planner, samples[i]) if which == 1 else algorithm2(planner, samples[i], nearest[i])
            ok += out is not None and check_sequence(planner.tester, out.path)
            bar.update()
        if which == 1:
            st.alg1_connect, st.alg1_picked = ok, len(pick)
        else:
            st.alg2_connect, st.alg2_picked = ok, len(pick)
    idx = np.flatnonzero(~pass1 & ~pass2)
    pick = rng.choice(idx, size=min(picks, len(idx)), replace=False) if len(idx) else idx
    for i in pick:
        out = algorithm3(planner, samples[i])
        st.alg3_connect += out is not None and check_sequence(planner.tester, out.path)
        bar.update()
    st.alg3_picked = len(pick)
    bar.close()
    return st


@single_blas
def random_queries(planner: FingerPlanner, samples: np.ndarray, count: int, seed: int = 0,
                   progress: bool = False) -> list[QueryResult]:
    """Table III: `count` random (start, goal) pairs of sampled force-closure grasps, each queried."""
    rng = np.random.default_rng(seed)
    out = []
    bar = _bar(progress, count, "queries")
    for _ in range(count):
        i, j = rng.choice(len(samples), size=2, replace=False)
        out.append(query(planner, samples[i], samples[j]))
        bar.update()
    bar.close()
    return out


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(progress: bool, total: int, desc: str):
    if not progress:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, leave=False)
