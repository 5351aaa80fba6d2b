"""Five-finger regrasping by finger switching (Phoka & Sudsang, Sections III-A and III-C).

A grasp is four contact indices (rows kept ascending). Two force-closure grasps sharing three contacts switch into
each other: the fifth finger is placed on the new contact, then the finger on the dropped contact lifts.
`switching_edges` and `Roadmap` give that graph and its components; `build_roadmap` is R, every force-closure
4-subset of the representatives T_R; `construct_roadmap` is the paper's ConstructRoadmap(S1, S2, S3, S4).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import breadth_first_order, connected_components

from workbench.errors import PlanningError
from workbench.planners.phoka_sudsang.clustering import (
    Clustering,
    ClusterParams,
    cluster_contacts,
)
from workbench.planners.phoka_sudsang.contacts import ContactSet
from workbench.params import single_blas
from workbench.planners.phoka_sudsang.forceclosure import ForceClosure


class FingerPlanningError(PlanningError):
    """A query the five-finger planner cannot take: unknown contacts, grasps that are not force closure."""


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


@dataclass
class FingerPlanner:
    """Everything Section III-D needs: T_O (contacts), clusters (T_O labels, T_R, E), the tester and R.

    `persistent` (the paper's reading, default): Algorithm 3 in a query updates R for good ("Update R by adding L
    and linking L to R"): T_G joins the representatives and L joins R, so later queries reuse them; `updates`
    lists every update in order and `extra_reps` the contacts it made representatives. `base` is R as Section
    III-C builds it (Table I). With `persistent=False` each query extends a copy of R and forgets it (the one-off
    variant, kept for comparison)."""

    contacts: ContactSet
    clustering: Clustering
    tester: ForceClosure
    roadmap: Roadmap
    times: dict[str, float] = field(default_factory=dict)
    persistent: bool = True
    extra_reps: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    updates: list = field(default_factory=list)
    base: Roadmap | None = None

    def __post_init__(self) -> None:
        if self.base is None:
            self.base = self.roadmap

    @property
    def n(self) -> int:
        return len(self.contacts)

    @property
    def representatives(self) -> np.ndarray:
        """T_R: the clusters' representatives and the contacts Algorithm 3 added, ascending."""
        return np.union1d(self.clustering.reps, self.extra_reps).astype(np.int64)

    def apply(self, ext) -> None:
        """Add an Algorithm 3 extension (`linking.Extension`: its T_G and new vertices) to T_R and R for good."""
        self.extra_reps = np.union1d(self.extra_reps, ext.tg).astype(np.int64)
        if len(ext.grasps):
            self.roadmap = Roadmap.from_grasps(np.vstack([self.roadmap.grasps, ext.grasps]), self.n)
        self.updates.append(ext)

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


class _NoBar:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _bar(progress: bool, total: int, desc: str):
    if not progress:
        return _NoBar()
    import sys

    from tqdm import tqdm

    return tqdm(total=total, desc=desc, leave=not sys.stderr.isatty(), file=sys.stderr)  # a newline when piped
