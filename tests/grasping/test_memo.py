"""Replanning a part with another segmentation threshold takes the rows of the jaw axes it has closed the pads along
before from the part's memo, and plans exactly the grasps a fresh computation plans."""

from __future__ import annotations

import pickle

import numpy as np

from workbench.geometry.objects import load_object
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.grasping.memo import RowMemo, memo, remember
from workbench.resources import bundled_objects


def _arrays(plan) -> dict[str, np.ndarray]:
    out = {f"grasps.{f}": getattr(plan.grasps, f) for f in plan.grasps.__dataclass_fields__}
    out.update({f"pairs.{f}": getattr(plan.pairs, f) for f in plan.pairs.__dataclass_fields__})
    out.update(candidate_poses=plan.candidate_poses, candidate_free=plan.candidate_free)
    return out


def test_a_new_threshold_reuses_the_unchanged_axes_and_plans_the_same_grasps(hand):
    tube = load_object(bundled_objects()["tube"])
    remember(tube.mesh)
    plan_grasps(tube, hand, GraspParams(tau=np.radians(18.0)))
    touches, hands = memo(tube.mesh, "first_touches"), memo(tube.mesh, "hand_hits")
    first_hits, first = touches.hits, touches.misses
    params = GraspParams(tau=np.radians(20.0))
    reused = plan_grasps(tube, hand, params)
    other = load_object(bundled_objects()["tube"])
    fresh = plan_grasps(other, hand, params)
    assert memo(other.mesh, "first_touches") is None  # a part that did not ask keeps nothing
    # most axes keep their facet's normal, some do not: both memos answer part of the replan, not all of it
    new_hits, new_misses = touches.hits - first_hits, touches.misses - first
    assert new_hits > 2 * new_misses > 0 and hands.hits > 0
    assert reused.counts == fresh.counts and reused.counts["gap"] > 0 and len(reused.grasps) > 100
    got, want = _arrays(reused), _arrays(fresh)
    for name, a in want.items():
        b = got[name]
        assert (a is None and b is None) or (a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)), name
    # the part still pickles (to a worker, say), with its memo left behind
    again = pickle.loads(pickle.dumps(tube))
    assert memo(again.mesh, "first_touches").rows == {} and np.array_equal(again.mesh.faces, tube.mesh.faces)


def test_the_memo_keeps_to_its_limit_and_answers_as_the_computation():
    rng = np.random.default_rng(3)
    pool = rng.normal(size=(60, 4))
    calls = []

    def compute(rows):
        calls.append(len(rows))
        x = batch[rows]
        return x.sum(axis=1), (x[:, :2] > 0)

    m = RowMemo(limit=12_000)  # room for about three calls' rows
    for step in range(12):
        batch = pool[:5]  # asked every time: never the least recently used, never dropped
        total, _ = m.get(b"c", batch, compute)
        assert calls == [5] and np.array_equal(total, batch.sum(axis=1))
        batch = pool[rng.integers(5, len(pool), 25)]
        total, positive = m.get(b"c", batch, compute)
        assert np.array_equal(total, batch.sum(axis=1)) and np.array_equal(positive, batch[:, :2] > 0)
        assert m.size <= m.limit
        other, _ = m.get(b"d%d" % step, batch[:3], compute)  # other constants: never answered from the rows above
        assert calls[-1] == 3 and np.array_equal(other, batch[:3].sum(axis=1))
        calls[1:] = []
    assert m.hits > 11 * 5
