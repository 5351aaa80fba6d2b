"""Graph helpers shared by the planners: CSR-style grouping of items by an integer key (`_groups`) and the
expansion of group members back to item pairs (`_expand`), so cliques (nodes sharing a grasp or a placement) are
kept as groupings instead of edge lists.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # pragma: no cover

    pass


def _groups(keys: np.ndarray, n_groups: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR grouping: (ptr (n_groups + 1,), order) with the items of group k at order[ptr[k]:ptr[k + 1]], ascending."""
    order = np.argsort(keys, kind="stable")
    ptr = np.zeros(n_groups + 1, dtype=np.int64)
    np.cumsum(np.bincount(keys, minlength=n_groups), out=ptr[1:])
    return ptr, order


def _expand(ptr: np.ndarray, order: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Items of several groups at once: (items, position of their group in `groups`), without a Python loop."""
    groups = np.asarray(groups, dtype=np.int64)
    starts, counts = ptr[groups], ptr[groups + 1] - ptr[groups]
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    owner = np.repeat(np.arange(len(groups)), counts)
    offset = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    return order[np.repeat(starts, counts) + offset], owner
