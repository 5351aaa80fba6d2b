"""Kernel rows remembered per part, so a replan with other grasp parameters redoes only the work that changed.

The pad model's first touches (`pads.first_touches`) and the hand's collision checks (`grasps.hand_hits`) compute
every row (a jaw axis with its hand rotations, a hand pose) from that row's inputs alone. Moving the segmentation
threshold in notebook 01 changes some facets and keeps most: a sample whose facet keeps its normal gives the same jaw
axis, bit for bit, hence the same first touches, the same pre-grasp re-search and the same hand checks. Each row's
result is kept in the part's mesh cache (dropped with the mesh, or when the mesh changes) under the exact bytes of
its inputs and of the call's constants, and only the rows not seen before are computed: the results are those of a
fresh computation, array-equal. Only a part that asks for it (`remember`, as the grasp explorer does) keeps rows: a
command plans its part once, and a benchmark times the computation itself.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from typing import Callable

import numpy as np
import trimesh

LIMIT = 32 * 2**20
"""Bytes of results kept per part and computation (keys included); the calls used least recently go first."""


class RowMemo:
    """Results of a row-wise computation, remembered by the exact bytes of each row's inputs."""

    def __init__(self, limit: int = LIMIT):
        self.limit = limit
        self.rows: dict[bytes, dict[bytes, tuple[int, int]]] = {}  # constants -> row's bytes -> (block, row in it)
        self.blocks: OrderedDict[int, tuple[tuple[np.ndarray, ...], bytes, list[bytes]]] = OrderedDict()
        self.size = self.next = 0
        self.hits = self.misses = 0
        self.lock = threading.Lock()

    def __reduce__(self):  # a pickled or copied part carries an empty memo: it is a cache, not data
        return RowMemo, (self.limit,)

    def get(self, constants: bytes, inputs: np.ndarray,
            compute: Callable[[np.ndarray], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
        """`compute(rows)`'s arrays (first axis: one entry per row of `inputs`) for every row of `inputs` (K, ...),
        calling `compute` only on the indices of the rows not remembered with the same `constants`."""
        with self.lock:  # one part planned from two threads: each call sees whole blocks
            return self._get(constants, inputs, compute)

    def _get(self, constants: bytes, inputs: np.ndarray,
             compute: Callable[[np.ndarray], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
        keys = row_keys(inputs)
        table = self.rows.setdefault(constants, {})
        found = [table.get(k) for k in keys]
        miss = np.array([i for i, f in enumerate(found) if f is None], dtype=np.int64)
        self.hits += len(keys) - len(miss)
        self.misses += len(miss)
        if len(miss) == len(keys):
            out = compute(miss)
            self._keep(out, constants, keys)
            return out
        hit = np.flatnonzero(np.array([f is not None for f in found]))
        block = np.array([found[i][0] for i in hit])
        at = np.array([found[i][1] for i in hit])
        new = compute(miss) if len(miss) else None
        like = new if new is not None else self.blocks[int(block[0])][0]
        out = tuple(np.empty((len(keys), *a.shape[1:]), dtype=a.dtype) for a in like)
        for b in np.unique(block):
            sel = block == b
            for o, a in zip(out, self.blocks[int(b)][0]):
                o[hit[sel]] = a[at[sel]]
            self.blocks.move_to_end(int(b))  # used: the last to be dropped
        if new is not None:
            for o, a in zip(out, new):
                o[miss] = a
            self._keep(new, constants, [keys[i] for i in miss])
        return out

    def _keep(self, arrays: tuple[np.ndarray, ...], constants: bytes, keys: list[bytes]) -> None:
        size = _size(arrays, keys)
        if not keys or size > self.limit:
            return
        bid, self.next = self.next, self.next + 1
        self.blocks[bid] = (tuple(np.array(a) for a in arrays), constants, keys)
        table = self.rows[constants]
        for i, k in enumerate(keys):
            table[k] = (bid, i)
        self.size += size
        while self.size > self.limit:
            old, (arrs, c, ks) = self.blocks.popitem(last=False)
            self.size -= _size(arrs, ks)
            table = self.rows[c]
            for k in ks:
                if table.get(k, (None,))[0] == old:
                    del table[k]


def _size(arrays: tuple[np.ndarray, ...], keys: list[bytes]) -> int:
    return sum(a.nbytes for a in arrays) + sum(len(k) + 100 for k in keys)  # about a dict entry's overhead per key


def row_keys(inputs: np.ndarray) -> list[bytes]:
    """One key per row of `inputs`: the row's bytes."""
    flat = np.ascontiguousarray(inputs).reshape(len(inputs), int(np.prod(inputs.shape[1:])))
    if not flat.size:
        return [b""] * len(flat)
    return flat.view(np.dtype((np.void, flat.dtype.itemsize * flat.shape[1]))).ravel().tolist()


def remember(mesh: trimesh.Trimesh) -> None:
    """Keep the rows of every later plan of `mesh` (notebook 01 does, for its part): until then, and for a command
    or a benchmark that plans a part once or times its plans, every row is computed and nothing is kept."""
    if mesh._cache[_KEY] is None:
        mesh._cache[_KEY] = {}


def remembered(mesh: trimesh.Trimesh, name: str, constants: bytes, inputs: np.ndarray,
               compute: Callable[[np.ndarray], tuple[np.ndarray, ...]]) -> tuple[np.ndarray, ...]:
    """`compute(rows)`'s arrays for every row of `inputs`: through the part's memo of the computation `name`
    (`RowMemo.get`) when `remember(mesh)` turned it on, else computed."""
    memos = mesh._cache[_KEY]
    if memos is None:
        return compute(np.arange(len(inputs)))
    return memos.setdefault(name, RowMemo()).get(constants, inputs, compute)


def memo(mesh: trimesh.Trimesh, name: str) -> RowMemo | None:
    """The part's memo of the computation `name` (None while it is not remembered)."""
    memos = mesh._cache[_KEY]
    return None if memos is None else memos.setdefault(name, RowMemo())


def forget(mesh: trimesh.Trimesh) -> None:
    """Drop what the memos of `mesh` hold (a benchmark measuring the computation from nothing); they stay on."""
    memos = mesh._cache[_KEY]
    if memos is not None:
        memos.clear()


_KEY = "workbench_memos"  # in the mesh's cache: dropped when the mesh changes
