"""The experiments of Phoka & Sudsang's Tables II and III: sampled force-closure grasps, local-planning
statistics of Algorithms 1-3 (%run, #connect) and random start/goal queries.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from workbench.params import single_blas
from workbench.planners.phoka_sudsang.forceclosure import ForceClosure
from workbench.planners.phoka_sudsang.linking import (
    algorithm1,
    algorithm1_applies,
    algorithm2,
    algorithm3,
    find_nearest_cluster,
)
from workbench.planners.phoka_sudsang.query import QueryResult, check_sequence, query
from workbench.planners.phoka_sudsang.switching import (
    FingerPlanner,
    FingerPlanningError,
    _bar,
    grasp_keys,
)


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
