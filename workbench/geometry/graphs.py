"""The regrasp roadmap, connecting start and goal poses to it, and searching it (Wan & Harada, Section V).

Graph (Section V, "Building the graph"): the nodes are the tabletop grips that are IK-feasible for a robot at the
grasp and both retractions (the `ik` table's three flags). Two nodes sharing `idfreeairgrip` are joined by a
transfer edge (carry the object from one placement to another with one grasp); two nodes sharing
`idtabletopplacements` by a transit edge (release and regrasp at one placement). Both relations are cliques, so
the graph is kept as two groupings of the node arrays (nodes sorted by grasp and by placement, CSR style) plus
the grasp graph H (G x G, scipy.sparse): grasps g, g' are adjacent when some placement has nodes of both. A path
of k transit edges is a walk of length k in H, so the fewest regrasps between two grasps is their breadth-first
distance in H (all pairs are computed once per roadmap); transfers follow as k + 1.

Queries (Section V, "Searching the graph"): a start or goal pose is a stable placement at a position and a yaw
that need not be on the grid. Its grips are the placement's free tabletop grips moved to the pose; each needs IK
at the grasp and both retractions without arm-table or arm-object collision, as the precomputation does.
Start grips join roadmap nodes with the same grasp by transfer edges, goal grips likewise, and a start grip
joins a goal grip directly when one grasp serves both. The search is a breadth-first search on the layered graph
(layer = number of regrasps) over pairs of start and goal grasps, cost (regrasps, transfers) lexicographic.
IK at the query poses is the expensive part, so it is evaluated lazily: in rounds, only the grips of the cheapest
pairs whose feasibility is unsettled, most promising first (the grasp's IK feasibility at the nearest grid
placements), first from the nearest stored solution and only when needed from the precomputation's fall-back
seeds, until the best plans are proven (`lazy=False` evaluates every grip first; the optimum is the same).

Cache: `load_planner` keeps the roadmap (and its IK adapter) per store file, object, robot, scene, retractions,
tabletop parameter set and a fingerprint of the IK rows, so repeated queries only connect and search.
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
