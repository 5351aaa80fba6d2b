"""Force closure of 4-contact frictional grasps, batched (Phoka & Sudsang, Sections II and III-B).

Hard contacts with Coulomb friction: each friction cone is an m-sided pyramid whose edges, taken
counterclockwise about the inward normal, are unit forces; with the torque about a reference point they are
the contact's primitive wrenches (Section III-B1). Torques are divided by a length (the object's radius by
default) so that forces and torques are commensurate; force closure does not depend on that choice.

A grasp is force closure when its primitive wrenches positively span R^6, i.e. the origin lies strictly
inside their convex hull. Two tests:

- `SpanTable`, the necessary condition of reference [5] (Niparnan & Sudsang): the force components, and the
  torque components, of the primitive wrenches must each positively span R^3. A set of 3-D vectors fails to
  positively span exactly when some u != 0 has u.v <= 0 for all of them, and such a u can be taken on an
  extreme ray, orthogonal to two of the vectors; two vectors come from at most two contacts, so the candidate
  directions are precomputed per pair of contacts and their validity per third contact is kept as bit masks.
  A 4-subset is then rejected with a few integer ANDs.
- `strictly_inside`, the exact test, the linear program equivalent to reference [4]'s Q-distance sign:
  the origin is strictly inside conv(W) iff W has rank 6 and some lambda >= 1 has W lambda = 0. Its phase-1
  simplex runs on all grasps of a batch at once in numpy; the rare instance that does not settle within the
  iteration cap is solved by scipy's HiGHS.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Callable

import numpy as np
from scipy.optimize import linprog

from workbench.errors import WorkbenchError
from workbench.geometry.vectors import cross
from workbench.params import Params, param

# Directions u with u.v <= SPAN_TOL for all (unit-scale) v are treated as separating.
SPAN_TOL = 1e-12
# Pivots per item before the batched simplex hands an item to HiGHS.
MAX_PIVOTS = 60
_PAIRS6 = np.array([(0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1)])


class ForceClosureError(WorkbenchError):
    """Bad friction parameters or grasps that index missing contacts."""


@dataclass(frozen=True)
class FrictionParams(Params):
    """Coulomb friction coefficient `mu`, pyramid sides `sides` (the paper's m)."""

    mu: float = param(0.3, gt=0, le=10, help="Coulomb friction coefficient", flag="--friction")
    sides: int = param(8, ge=3, le=64, integer=True, help="sides m of the friction pyramid", flag="--pyramid")

    def validate(self) -> "FrictionParams":
        """Ranges are checked at construction; kept for callers that validate explicitly."""
        return self


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents t1, t2 with t1 x t2 = n, a fixed function of n (equal normals give equal frames)."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    axis = np.zeros_like(n)
    axis[np.arange(len(n)), np.argmin(np.abs(n), axis=1)] = 1.0
    t1 = np.cross(n, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    return t1, t2


def friction_pyramid(normals: np.ndarray, mu: float, sides: int) -> np.ndarray:
    """(N, m, 3) unit edge forces of the m-sided friction pyramids, counterclockwise about each normal."""
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    t1, t2 = tangent_frames(n)
    theta = 2.0 * np.pi * np.arange(sides) / sides
    f = n[:, None, :] + mu * (np.cos(theta)[None, :, None] * t1[:, None, :] + np.sin(theta)[None, :, None] * t2[:, None, :])
    return f / np.linalg.norm(f, axis=2, keepdims=True)


def primitive_wrenches(points: np.ndarray, normals: np.ndarray, mu: float, sides: int, ref: np.ndarray,
                       length: float = 1.0) -> np.ndarray:
    """(N, m, 6) primitive wrenches w(f_ik, r_i, o) = (f_ik, (r_i - o) x f_ik / length) (Section III-B1)."""
    f = friction_pyramid(normals, mu, sides)
    arm = (np.asarray(points, dtype=np.float64).reshape(-1, 3) - np.asarray(ref, dtype=np.float64)) / length
    return np.concatenate([f, np.cross(arm[:, None, :], f)], axis=2)


# ----------------------------------------------------------------------------------------------------------
# Prefilter: positive span of force and of torque components ([5])


def _pair_candidates(vectors: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Directions u orthogonal to two vectors of a pair of contacts with u.v <= 0 for all the pair's vectors.

    vectors (K, m, 3); pairs (P, 2). Returns the pair index (C,) and unit directions (C, 3) of the valid
    candidates, grouped by pair. Two edges of one contact only matter when adjacent (a plane through
    non-adjacent edges of a convex pyramid cuts it); pairs whose vectors are all parallel (or zero) also get the
    directions orthogonal to their line.
    """
    m = vectors.shape[1]
    x = np.concatenate([vectors[pairs[:, 0]], vectors[pairs[:, 1]]], axis=1)          # (P, 2m, 3)
    cross_a, cross_b = np.meshgrid(np.arange(m), np.arange(m, 2 * m), indexing="ij")
    adj = np.arange(m)
    ia = np.concatenate([cross_a.ravel(), adj, adj + m])
    ib = np.concatenate([cross_b.ravel(), (adj + 1) % m, (adj + 1) % m + m])
    u = cross(x[:, ia], x[:, ib])                                                      # (P, C0, 3)
    longest = x[np.arange(len(x)), np.argmax((x * x).sum(axis=2), axis=1)]
    e1, e2 = tangent_frames(np.where((longest * longest).sum(axis=1, keepdims=True) > 0, longest, [0.0, 0.0, 1.0]))
    u = np.concatenate([u, -u, e1[:, None], -e1[:, None], e2[:, None], -e2[:, None]], axis=1)
    norm = np.sqrt((u * u).sum(axis=2))
    ok = norm > 1e-9
    u /= np.where(ok, norm, 1.0)[..., None]
    ok &= np.matmul(x, u.transpose(0, 2, 1)).max(axis=1) <= SPAN_TOL      # max over the middle axis is fast
    pair, cand = np.nonzero(ok)
    return pair, u[pair, cand]


class SpanTable:
    """Positive-span prefilter of [5] for 4-subsets of K contacts, from per-contact vector sets (K, m, 3) each.

    `sets` are e.g. the force edges and the torque edges of the K contacts; `may_span(g)` is False for a
    4-subset g (local indices) when the vectors of one set do not positively span R^3, which rules out force
    closure. Building costs O(K^3 m); a query costs six table look-ups per grasp and set.
    """

    def __init__(self, *sets: np.ndarray):
        k = sets[0].shape[0]
        self.k = k
        pa, pb = np.triu_indices(k, 1)
        self.pairs = np.stack([pa, pb], 1)
        self.pindex = np.full((k, k), -1, dtype=np.int64)
        self.pindex[pa, pb] = np.arange(len(pa))
        self.pindex[pb, pa] = np.arange(len(pa))
        self.masks = [self._masks(np.asarray(v, dtype=np.float64)) for v in sets]

    def _masks(self, vectors: np.ndarray) -> np.ndarray:
        """(P, K, words) uint64: bit c of (p, k) says candidate c of pair p is valid for contact k's vectors."""
        pair, u = _pair_candidates(vectors, self.pairs)
        npairs, k = len(self.pairs), self.k
        start = np.searchsorted(pair, np.arange(npairs))
        rank = np.arange(len(pair)) - start[pair]
        words = max(1, (int(rank.max(initial=0)) + 64) // 64)
        masks = np.zeros((npairs, k, words), dtype=np.uint64)
        if len(pair) == 0:
            return masks
        m = vectors.shape[1]
        valid = (u @ vectors.transpose(1, 0, 2).reshape(-1, 3).T).reshape(len(u), m, k).max(axis=1) <= SPAN_TOL
        # candidate bits within a (pair, word) are distinct powers of two, so their OR is their sum
        bits = np.left_shift(np.uint64(1), (rank % 64).astype(np.uint64))
        vals = valid * bits[:, None]
        group = pair * words + rank // 64
        first = np.flatnonzero(np.r_[True, np.diff(group) != 0])
        summed = np.add.reduceat(vals, first, axis=0)
        flat = masks.transpose(0, 2, 1).reshape(npairs * words, k).copy()
        flat[group[first]] = summed
        return np.ascontiguousarray(flat.reshape(npairs, words, k).transpose(0, 2, 1))

    def may_span(self, grasps: np.ndarray) -> np.ndarray:
        """(G,) bool: True where every vector set of the 4-subset positively spans R^3 (force closure possible)."""
        g = np.asarray(grasps, dtype=np.int64).reshape(-1, 4)
        keep = np.ones(len(g), dtype=bool)
        for a, b, c, d in _PAIRS6:
            p = self.pindex[g[:, a], g[:, b]]
            for mask in self.masks:
                sep = (mask[p, g[:, c]] & mask[p, g[:, d]]).any(axis=1)
                keep &= ~sep
        return keep


# ----------------------------------------------------------------------------------------------------------
# Exact test: origin strictly inside the convex hull of the primitive wrenches ([4], as a linear program)


def strictly_inside(w: np.ndarray, max_iter: int | None = None, threads: int = 2, gram: np.ndarray | None = None,
                    total: np.ndarray | None = None) -> np.ndarray:
    """(B,) bool: the origin is strictly inside the convex hull of each batch item's points w (B, n, d).

    Equivalent: rank(W) = d and W lambda = 0 for some lambda >= 1. Items are first screened by two exact
    certificates computed for all at once (a separating direction y with all w.y > 0, and a strictly positive
    null vector), the rest go through the phase-1 simplex. The batch is split over `threads` threads (numpy
    releases the GIL in its array operations). `gram` (B, d, d) = W^T W and `total` (B, d) = W^T 1 may be given
    when they are cheaper to assemble by the caller.
    """
    w = np.asarray(w, dtype=np.float64)
    if w.ndim != 3:
        raise ForceClosureError(f"wrench batch must have shape (B, n, d), got {w.shape}")
    pick = (lambda a, p: None if a is None else a[p])
    cap = MAX_PIVOTS if max_iter is None else max_iter
    return _threaded(len(w), threads, lambda p: _decide(w[p], cap, pick(gram, p), pick(total, p)))


def _threaded(count: int, threads: int, work: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """`work(indices)` over `threads` contiguous parts of range(count), concatenated."""
    out = np.zeros(count, dtype=bool)
    parts = np.array_split(np.arange(count), threads) if threads > 1 and count > 4096 else [np.arange(count)]
    if len(parts) > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(len(parts)) as pool:
            results = list(pool.map(work, parts))
    else:
        results = [work(parts[0])]
    for p, r in zip(parts, results):
        out[p] = r
    return out


def _decide(w: np.ndarray, max_iter: int, gram: np.ndarray | None, total: np.ndarray | None) -> np.ndarray:
    """One thread's share: screen in cache-sized chunks, then the simplex on the undecided items."""
    out = np.zeros(len(w), dtype=bool)
    lp: list[np.ndarray] = []
    step = 4096
    for s in range(0, len(w), step):
        decided, inside = _screen(w[s:s + step], None if gram is None else gram[s:s + step],
                                  None if total is None else total[s:s + step])
        out[s:s + step] = inside
        lp.append(s + np.flatnonzero(~decided))
    rest = np.concatenate(lp) if lp else np.zeros(0, dtype=np.int64)
    if len(rest):
        out[rest] = _phase1(w[rest], max_iter)
    return out


def _screen(w: np.ndarray, gram: np.ndarray | None = None, total: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Items decided without the simplex: (decided, inside) from rank and the two certificates."""
    bsz, n, d = w.shape
    decided = np.ones(bsz, dtype=bool)
    inside = np.zeros(bsz, dtype=bool)
    if bsz == 0:
        return decided, inside
    if gram is None:
        gram = w.transpose(0, 2, 1) @ w                                    # (B, d, d)
    if total is None:
        total = np.einsum("bnk->bk", w)
    # rank d, else not force closure: the determinant (from a Cholesky factor) settles clear cases,
    # eigenvalues the rest
    scale = np.trace(gram, axis1=1, axis2=2) / d
    chol = np.linalg.cholesky(gram + (1e-12 * scale)[:, None, None] * np.eye(d))
    diag = np.einsum("bii->bi", chol)
    full = np.prod((diag * diag) / scale[:, None], axis=1) > 1e-6
    unsure = np.flatnonzero(~full)
    if len(unsure):
        ev = np.linalg.eigvalsh(gram[unsure])
        full[unsure] = ev[:, 0] > 1e-10 * np.maximum(ev[:, -1], 1e-300)
    idx = np.flatnonzero(full)
    if len(idx) == 0:
        return decided, inside
    # y = (W^T W)^-1 W^T 1: if all w.y > 0 a closed half-space holds every point (outside); else
    # lambda = 1 - W y is the projection of 1 onto the null space of W^T, and lambda > 0 proves inside
    y = np.linalg.solve(gram[idx], total[idx][..., None])                   # (B, d, 1)
    side = (w[idx] @ y)[..., 0]
    separated = side.min(axis=1) > 1e-12 * np.sqrt((y * y).sum(axis=(1, 2)))
    positive = (1.0 - side).min(axis=1) > 1e-9
    inside[idx[positive]] = True
    decided[idx[~separated & ~positive]] = False
    return decided, inside


def _tableau(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Phase-1 tableaux of A mu = -A 1 (A = w^T, rows signed so the right side is >= 0), and tolerances.

    No artificial columns are kept (an artificial that leaves the basis never needs to re-enter): rows
    0..d-1 the constraints, row d the reduced costs of the sum of artificials, last column the values.
    """
    bsz, n, d = w.shape
    a = w.transpose(0, 2, 1)
    b = -a.sum(axis=2)
    sign = np.where(b < 0, -1.0, 1.0)
    t = np.empty((bsz, d + 1, n + 1))
    t[:, :d, :n] = a * sign[:, :, None]
    t[:, :d, n] = b * sign
    t[:, d, :] = -t[:, :d, :].sum(axis=1)
    size = 1.0 + np.abs(b).sum(axis=1)
    return t, 1e-11 * size, 1e-9 * size


def _phase1(w: np.ndarray, max_iter: int, pool: int = 1024) -> np.ndarray:
    """Feasibility of A mu = -A 1, mu >= 0 (A = w^T) by the phase-1 simplex with Dantzig's rule.

    A pool of tableaux pivots together; a slot whose item has settled takes the next item, so the cost is
    the sum of the items' pivot counts rather than a batch's maximum.
    """
    total, n, d = w.shape
    feasible = np.zeros(total, dtype=bool)
    fallback: list[int] = []
    size = min(pool, total)
    t, tol_cost, tol_feas = _tableau(w[:size])
    item = np.arange(size)
    steps = np.zeros(size, dtype=np.int64)
    queued = size
    while len(item):
        rows = np.arange(len(item))
        cost = t[:, d, :n]
        e = cost.argmin(axis=1)
        settled = cost[rows, e] > -tol_cost
        stuck = ~settled & (steps >= max_iter)
        if settled.any() or stuck.any():
            feasible[item[settled]] = -t[settled, d, n] <= tol_feas[settled]
            fallback.extend(item[stuck].tolist())
            free = np.flatnonzero(settled | stuck)
            take = min(len(free), total - queued)
            if take:
                slots = free[:take]
                t[slots], tol_cost[slots], tol_feas[slots] = _tableau(w[queued:queued + take])
                item[slots] = np.arange(queued, queued + take)
                steps[slots] = 0
                e[slots] = t[slots, d, :n].argmin(axis=1)
                queued += take
            gone = free[take:]
            if len(gone):
                keep = np.ones(len(item), dtype=bool)
                keep[gone] = False
                t, tol_cost, tol_feas, item, steps, e = t[keep], tol_cost[keep], tol_feas[keep], item[keep], steps[keep], e[keep]
                rows = np.arange(len(item))
                if not len(item):
                    break
        colfull = t[rows, :, e]                                       # (B, d+1)
        col = colfull[:, :d]
        positive = col > 1e-12
        ratio = np.where(positive, t[:, :d, n] / np.where(positive, col, 1.0), np.inf)
        leave = ratio.argmin(axis=1)
        ok = positive[rows, leave]
        if not ok.all():                  # no positive entry: numerically degenerate, left to the fallback
            steps[~ok] = max_iter
            colfull[~ok] = 0.0
        prow = t[rows, leave, :]
        prow /= np.where(ok, col[rows, leave], 1.0)[:, None]
        t -= colfull[:, :, None] * prow[:, None, :]
        t[rows[ok], leave[ok], :] = prow[ok]
        steps += 1
    # degenerate cycling or slow instances: solve them exactly one by one
    for i in fallback:
        feasible[i] = _lp_feasible(w[i])
    return feasible


def _lp_feasible(w: np.ndarray) -> bool:
    """W lambda = 0 with lambda >= 1, by scipy's HiGHS (fallback of the batched simplex)."""

    n = len(w)
    res = linprog(np.zeros(n), A_eq=w.T, b_eq=np.zeros(w.shape[1]), bounds=[(1.0, None)] * n, method="highs")
    return bool(res.status == 0)


# ----------------------------------------------------------------------------------------------------------
# The tester of an object's contacts


class ForceClosure:
    """Batched force-closure tests for 4-contact grasps over one object's contact points.

    Torques are about `ref` (the centre of mass) divided by `length` (the object's radius), see the module doc.
    """

    def __init__(self, points: np.ndarray, normals: np.ndarray, params: FrictionParams, ref: np.ndarray | None = None,
                 length: float | None = None):
        params.validate()
        self.params = params
        self.points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.normals = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
        self.ref = self.points.mean(0) if ref is None else np.asarray(ref, dtype=np.float64)
        if length is None:
            length = float(np.linalg.norm(self.points - self.ref, axis=1).max(initial=0.0)) or 1.0
        self.length = float(length)
        self.wrenches = primitive_wrenches(self.points, self.normals, params.mu, params.sides, self.ref, self.length)
        self.n = len(self.points)
        self._gram = np.einsum("nki,nkj->nij", self.wrenches, self.wrenches)    # per contact: sum of w w^T
        self._total = self.wrenches.sum(axis=1)                                 # per contact: sum of w

    def _inside(self, g: np.ndarray, threads: int = 2) -> np.ndarray:
        """The exact test on grasps g (G, 4), W^T W and W^T 1 assembled from per-contact sums, in threads."""
        def work(part: np.ndarray) -> np.ndarray:
            c = g[part]
            gram = self._gram[c[:, 0]] + self._gram[c[:, 1]] + self._gram[c[:, 2]] + self._gram[c[:, 3]]
            total = self._total[c[:, 0]] + self._total[c[:, 1]] + self._total[c[:, 2]] + self._total[c[:, 3]]
            return _decide(self.wrenches[c].reshape(len(c), 4 * self.params.sides, 6), MAX_PIVOTS, gram, total)

        return _threaded(len(g), threads, work)

    def _check(self, grasps: np.ndarray) -> np.ndarray:
        g = np.asarray(grasps, dtype=np.int64)
        if g.ndim != 2 or g.shape[1] != 4:
            raise ForceClosureError(f"grasps must have shape (G, 4), got {g.shape}")
        if len(g) and (g.min() < 0 or g.max() >= self.n):
            raise ForceClosureError(f"grasp contact index out of range 0..{self.n - 1}: use indices of the contact set")
        return g

    def span_table(self, ids: np.ndarray) -> SpanTable:
        """The prefilter table of contacts `ids` (force components, torque components about the reference)."""
        w = self.wrenches[np.asarray(ids, dtype=np.int64)]
        return SpanTable(w[:, :, :3], w[:, :, 3:])

    def exact(self, grasps: np.ndarray) -> np.ndarray:
        """(G,) bool: the exact test (origin strictly inside the hull of the 4m primitive wrenches)."""
        g = self._check(grasps)
        return self._inside(g)

    def prefilter(self, grasps: np.ndarray) -> np.ndarray:
        """(G,) bool: the necessary condition of [5]; False rules force closure out."""
        g = self._check(grasps)
        ids, local = np.unique(g, return_inverse=True)
        return self.span_table(ids).may_span(local.reshape(g.shape))

    def test(self, grasps: np.ndarray, table: tuple[SpanTable, np.ndarray] | None = None) -> np.ndarray:
        """(G,) bool force closure: prefilter (with a table over the grasps' contacts) then the exact test.

        `table` = (SpanTable, ids) reuses a table built for contact ids `ids` that cover every grasp.
        """
        g = self._check(grasps)
        if len(g) == 0:
            return np.zeros(0, dtype=bool)
        if table is None:
            ids, local = np.unique(g, return_inverse=True)
            local = local.reshape(g.shape)
            if len(ids) ** 3 > 400 * len(g) and len(ids) > 40:
                return self.exact(g)  # too many distinct contacts for a table to pay off
            tab = self.span_table(ids)
        else:
            tab, ids = table
            local = np.searchsorted(ids, g)
        ok = tab.may_span(local)
        sel = np.flatnonzero(ok)
        ok[sel] = self._inside(g[sel])
        return ok

    def subsets(self, ids: np.ndarray, progress: bool = False) -> np.ndarray:
        """(V, 4) all force-closure 4-subsets of contacts `ids`, each row sorted ascending (Section III-C)."""
        ids = np.unique(np.asarray(ids, dtype=np.int64))
        if len(ids) < 4:
            return np.zeros((0, 4), dtype=np.int64)
        table = self.span_table(ids)
        local = combinations_array(len(ids), 4)
        cand = ids[local[table.may_span(local)]]
        if progress:
            import sys

            from tqdm import tqdm

            out = np.zeros(len(cand), dtype=bool)
            step = 32768
            for s in tqdm(range(0, len(cand), step), desc="force closure", unit="batch",
                          leave=not sys.stderr.isatty(), file=sys.stderr):
                out[s:s + step] = self._inside(cand[s:s + step])
        else:
            out = self._inside(cand)
        return cand[out]


def combinations_array(n: int, r: int) -> np.ndarray:
    """(C(n, r), r) all r-subsets of range(n) in lexicographic order, rows ascending."""
    if r == 4:
        # vectorised: for each (a, b) pair, the (c, d) pairs above b
        a, b = np.triu_indices(n, 1)
        c, d = np.triu_indices(n, 1)
        parts = []
        for j in range(n - 2):
            sel = c > j
            m = b == j
            if not m.any():
                continue
            cc, dd = c[sel], d[sel]
            aa = np.repeat(a[m], len(cc))
            parts.append(np.stack([aa, np.full_like(aa, j), np.tile(cc, m.sum()), np.tile(dd, m.sum())], 1))
        out = np.concatenate(parts) if parts else np.zeros((0, 4), dtype=np.int64)
        return out[np.lexsort(out.T[::-1])]
    return np.array(list(combinations(range(n), r)), dtype=np.int64).reshape(-1, r)
