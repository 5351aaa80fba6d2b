"""The regrasp graph of Wan & Harada (Section V, "Building the graph").

The nodes are the tabletop grips that are IK-feasible for a robot at all five poses of the `ik` table (the grasp,
the two retractions of the empty hand, handx and handx + worldz, and the two lifts of the held object, worlda and
worlda + worldz), as in the paper's reference implementation. Two nodes sharing `idfreeairgrip` are joined by a transfer edge (carry the object from one
placement to another with one grasp); two nodes sharing `idtabletopplacements` by a transit edge (release and
regrasp at one placement). Both relations are cliques, so the graph is kept as two groupings of the node arrays
(nodes sorted by grasp and by placement, CSR style) plus the grasp graph H (G x G, scipy.sparse): grasps g, g' are
adjacent when some placement has nodes of both. A path of k transit edges is a walk of length k in H, so the
fewest regrasps between two grasps is their breadth-first distance in H (all pairs are computed once per
roadmap); transfers follow as k + 1.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, shortest_path

from workbench.errors import PlanningError
from workbench.params import check_memory
from workbench.geometry.graphs import _expand, _groups

if TYPE_CHECKING:  # pragma: no cover

    pass


UNREACHED = np.iinfo(np.int32).max
"""Distance of two grasps that no sequence of regrasps joins."""


# reasons that answer a valid query (no plan exists for it), as opposed to bad input (input, unstable)
NO_RESULT = frozenset({"nogrip", "unreachable", "unconnected", "exhausted"})


def _failure(reason: str, message: str) -> PlanningError:
    """A PlanningError tagged with why the query fails (`reason`: input, unstable, nogrip, unreachable, unconnected)."""
    err = PlanningError(message)
    err.reason = reason
    return err


@dataclass
class Roadmap:
    """The regrasp graph of one object, robot, scene, retraction set and tabletop parameter set (Section V).

    Node arrays (N rows, one per feasible tabletop grip): idtabletopgrips, idtabletopplacements, idfreeairgrip,
    idfreetabletopplacement, tcp (N, 4, 4) TCP in the world, placement (N, 4, 4) object in the world, position
    (N, 3), yaw (N,), jawwidth (N,), joints (N, 5, nq) for the five poses of `robots.ik.KINDS` (NaN when not loaded).
    Groupings: grasp_ids (G,) and node_grasp (N,) index into them; place_ids (T,) and node_place (N,).
    `adjacency` is the grasp graph H (G, G); `dist` its all-pairs breadth-first distance (UNREACHED when
    unconnected); `component` labels the nodes' connected components of the transfer + transit graph.
    """

    idtabletopgrips: np.ndarray
    idtabletopplacements: np.ndarray
    idfreeairgrip: np.ndarray
    idfreetabletopplacement: np.ndarray
    tcp: np.ndarray
    placement: np.ndarray
    position: np.ndarray
    yaw: np.ndarray
    jawwidth: np.ndarray
    joints: np.ndarray
    grasp_ids: np.ndarray
    node_grasp: np.ndarray
    place_ids: np.ndarray
    node_place: np.ndarray
    grasp_ptr: np.ndarray
    grasp_order: np.ndarray
    place_ptr: np.ndarray
    place_order: np.ndarray
    adjacency: sp.csr_matrix
    dist: np.ndarray
    component: np.ndarray
    n_components: int
    n_transfer_edges: int
    n_transit_edges: int
    n_grips: int = 0
    key: tuple = ()
    timings: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return int(len(self.idtabletopgrips))

    @property
    def n_grasps(self) -> int:
        return int(len(self.grasp_ids))

    @property
    def n_placements(self) -> int:
        return int(len(self.place_ids))

    def grasp_index(self, idfreeairgrip: np.ndarray) -> np.ndarray:
        """Roadmap grasp index of free-air grasp ids, -1 for grasps without a node."""
        ids = np.asarray(idfreeairgrip, dtype=np.int64)
        if len(self.grasp_ids) == 0:
            return np.full(ids.shape, -1, dtype=np.int64)
        k = np.clip(np.searchsorted(self.grasp_ids, ids), 0, len(self.grasp_ids) - 1)
        return np.where(self.grasp_ids[k] == ids, k, -1)

    def nodes_of_grasps(self, grasps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes of roadmap grasps (indices) and which input grasp each belongs to."""
        return _expand(self.grasp_ptr, self.grasp_order, grasps)

    def nodes_of_places(self, places: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nodes at roadmap placements (indices) and which input placement each belongs to."""
        return _expand(self.place_ptr, self.place_order, places)

    def component_sizes(self) -> np.ndarray:
        """Node count of each connected component, largest first."""
        if self.n_nodes == 0:
            return np.zeros(0, dtype=np.int64)
        return np.sort(np.bincount(self.component))[::-1]

    def summary(self) -> dict:
        """Sizes for printing: nodes, edges, grasps, placements, components."""
        sizes = self.component_sizes()
        return {"grips": self.n_grips, "nodes": self.n_nodes, "transfer_edges": self.n_transfer_edges,
                "transit_edges": self.n_transit_edges, "grasps": self.n_grasps, "placements": self.n_placements,
                "components": self.n_components, "largest_component": int(sizes[0]) if len(sizes) else 0}


GRAPH_BYTES_PER_GRIP = 6000  # loading the regrasp graph, per tabletop grip (measured 5.2-6.7 kB at 39k-152k grips)


def check_graph_memory(grips: int) -> None:
    """Refuse a regrasp graph of `grips` tabletop grips above the memory budget, in one line (Section V)."""
    check_memory(GRAPH_BYTES_PER_GRIP * grips, f"the regrasp graph of {grips:,} tabletop grips",
                 "lower the table grid (--x/--y N, --angles), --max-grasps, or the placements (raise --min-stability)")


def build_roadmap(rows: dict[str, np.ndarray], feasible: np.ndarray | None = None) -> Roadmap:
    """The regrasp graph from tabletop grip rows and their IK feasibility (Section V, "Building the graph").

    `rows` follows `load_tabletop_grips` (idtabletopgrips, idtabletopplacements, idfreeairgrip, rotmat,
    placement_rotmat, tabletopposition, idfreetabletopplacement, jawwidth) plus optional `angle` (radians) and
    `joints` (N, K, nq); `feasible` (N,) or (N, K) selects the nodes (all K flags when (N, K): the five poses of
    `robots.ik.KINDS`, as the paper's reference implementation requires)."""
    t0 = time.perf_counter()
    n_all = len(rows["idtabletopgrips"])
    keep = np.ones(n_all, dtype=bool) if feasible is None else np.asarray(feasible, dtype=bool)
    if keep.ndim == 2:
        keep = keep.all(axis=1)
    if keep.shape != (n_all,):
        raise PlanningError(f"feasibility mask has shape {keep.shape}, expected ({n_all},) or ({n_all}, 5)")
    idx = np.flatnonzero(keep)
    take = lambda name, default=None: (np.asarray(rows[name])[idx] if name in rows else default)  # noqa: E731
    tcp = np.asarray(rows["rotmat"], dtype=np.float64).reshape(-1, 4, 4)[idx]
    placement = np.asarray(rows["placement_rotmat"], dtype=np.float64).reshape(-1, 4, 4)[idx]
    if "angle" in rows:
        yaw_ = np.asarray(rows["angle"], dtype=np.float64)[idx]
    else:  # the yaw of the placement relative to its free placement is not stored without the angle table
        yaw_ = np.full(len(idx), np.nan)
    joints = take("joints")
    if joints is None:
        joints = np.full((len(idx), 5, 0), np.nan)
    g_ids, node_grasp = np.unique(take("idfreeairgrip").astype(np.int64), return_inverse=True)
    p_ids, node_place = np.unique(take("idtabletopplacements").astype(np.int64), return_inverse=True)
    node_grasp, node_place = node_grasp.ravel().astype(np.int64), node_place.ravel().astype(np.int64)
    n, g, t = len(idx), len(g_ids), len(p_ids)
    grasp_ptr, grasp_order = _groups(node_grasp, g)
    place_ptr, place_order = _groups(node_place, t)
    # incidence grasp x placement; H = I I^T without its diagonal
    inc = sp.csr_matrix((np.ones(n, dtype=np.int32), (node_grasp, node_place)), shape=(g, t))
    inc.data[:] = 1
    adj = (inc @ inc.T).tocsr()
    adj.setdiag(0)
    adj.eliminate_zeros()
    adj.data[:] = 1
    if g:
        d = shortest_path(adj, method="D", directed=False, unweighted=True)
        dist = np.where(np.isfinite(d), d, UNREACHED).astype(np.int32)
    else:
        dist = np.zeros((0, 0), dtype=np.int32)
    # connected components of the transfer + transit graph: components of the bipartite grasp-placement graph
    if n:
        bip = sp.bmat([[None, inc], [inc.T, None]], format="csr")
        n_comp, labels = connected_components(bip, directed=False)
        comp = labels[node_grasp]
        _, comp = np.unique(comp, return_inverse=True)  # renumber to the components that have nodes
        n_comp = int(comp.max()) + 1
    else:
        comp, n_comp = np.zeros(0, dtype=np.int64), 0
    per_g = np.diff(grasp_ptr)
    per_p = np.diff(place_ptr)
    return Roadmap(
        idtabletopgrips=take("idtabletopgrips").astype(np.int64), idtabletopplacements=take("idtabletopplacements").astype(np.int64),
        idfreeairgrip=take("idfreeairgrip").astype(np.int64),
        idfreetabletopplacement=take("idfreetabletopplacement").astype(np.int64) if "idfreetabletopplacement" in rows else np.full(n, -1),
        tcp=tcp, placement=placement, position=np.asarray(take("tabletopposition"), dtype=np.float64).reshape(-1, 3),
        yaw=yaw_, jawwidth=np.asarray(take("jawwidth"), dtype=np.float64), joints=np.asarray(joints, dtype=np.float64),
        grasp_ids=g_ids, node_grasp=node_grasp, place_ids=p_ids, node_place=node_place,
        grasp_ptr=grasp_ptr, grasp_order=grasp_order, place_ptr=place_ptr, place_order=place_order,
        adjacency=adj, dist=dist, component=np.asarray(comp, dtype=np.int64), n_components=n_comp,
        n_transfer_edges=int((per_g * (per_g - 1) // 2).sum()), n_transit_edges=int((per_p * (per_p - 1) // 2).sum()),
        n_grips=n_all, timings={"build": time.perf_counter() - t0})


def grid_index(rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every tabletop grip's IK feasibility (all five flags) keyed by (tabletop placement index, free-air grasp id),
    with each tabletop placement's stable placement, position and yaw (for `Planner.prior`)."""
    tp, first, inv = np.unique(np.asarray(rows["idtabletopplacements"]), return_index=True, return_inverse=True)
    grasp = np.asarray(rows["idfreeairgrip"], dtype=np.int64)
    stride = int(grasp.max()) + 1 if len(grasp) else 1
    keys = inv.ravel().astype(np.int64) * stride + grasp
    order = np.argsort(keys, kind="stable")
    feas = np.asarray(rows["feasible"]).reshape(len(grasp), -1).all(axis=1)
    return {"tp_free": np.asarray(rows["idfreetabletopplacement"])[first], "tp_pos": np.asarray(rows["tabletopposition"])[first],
            "tp_angle": np.asarray(rows["angle"], dtype=np.float64)[first], "keys": keys[order], "feasible": feas[order].astype(np.float64),
            "stride": np.int64(stride)}
