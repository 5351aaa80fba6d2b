"""Five-finger queries (Phoka & Sudsang, Section III-D): a finger-switching sequence from a start to a goal grasp
through R, its check (every grasp in force closure, consecutive grasps sharing three contacts) and the finger
assignment that plays it with five fingers.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from workbench.params import single_blas
from workbench.planners.phoka_sudsang.forceclosure import ForceClosure
from workbench.planners.phoka_sudsang.linking import (
    extend_roadmap,
    link,
    update_roadmap,
)
from workbench.planners.phoka_sudsang.switching import FingerPlanner, Roadmap


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
    the search runs in the updated roadmap. With `planner.persistent` (the paper's "Update R", default) the
    updates stay in R for later queries; otherwise they are local to this query (R itself is not changed).
    """
    t0 = time.perf_counter()
    g = planner.check_grasp(start, "start grasp")
    h = planner.check_grasp(goal, "goal grasp")
    if np.array_equal(g, h):
        return QueryResult(g, h, g[None].copy(), "same", "same", time.perf_counter() - t0)
    keep = planner.persistent
    lg, lh = link(planner, g, update=keep), link(planner, h, update=keep)
    rm = planner.roadmap            # after any update: vertices are looked up again from each link's last grasp
    seq = None
    if lg is not None and lh is not None:
        vg, vh = (int(rm.index(x.path[-1][None])[0]) for x in (lg, lh))
        if vg >= 0 and vh >= 0 and rm.components[vg] == rm.components[vh]:
            mid = rm.path(vg, np.array([vh]))
            seq = _join([lg.path, rm.grasps[mid], lh.path[::-1]])
    if seq is None:
        seq = _search_updated(planner, g, h) if keep else _search_extended(planner, g, h)
    return QueryResult(g, h, seq, lg.method if lg else "none", lh.method if lh else "none", time.perf_counter() - t0)


def _search_updated(planner: FingerPlanner, g: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """Algorithm 3 for g and h applied to R for good (those not yet vertices), then a search in R."""
    for x in (g, h):
        if planner.roadmap.index(x[None])[0] < 0:
            update_roadmap(planner, x)
    rm = planner.roadmap
    i, j = rm.index(np.stack([g, h]))
    if i < 0 or j < 0 or rm.components[i] != rm.components[j]:
        return None
    p = rm.path(int(i), np.array([j]))
    return None if p is None else rm.grasps[p]


def _join(parts: list[np.ndarray]) -> np.ndarray:
    """Concatenate grasp paths whose ends meet, dropping the repeated junctions."""
    out = [parts[0]]
    last = parts[0][-1] if len(parts[0]) else None  # the previous non-empty part's end (a part may be one grasp)
    for p in parts[1:]:
        if len(p) and last is not None and np.array_equal(p[0], last):
            p = p[1:]
        if len(p):
            last = p[-1]
        out.append(p)
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
