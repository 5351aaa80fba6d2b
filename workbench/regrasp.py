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

import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Union

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, shortest_path

from .errors import PlanningError
from .tabletop import yaw

if TYPE_CHECKING:  # pragma: no cover
    import trimesh

    from .kinematics import IKOptions, Scene
    from .objects import ObjectModel
    from .plans import Plan
    from .robots import Robot
    from .store import Store

Query = Union["PoseQuery", np.ndarray, str]
"""A start or goal: a PoseQuery, a `PLACEMENT,X,Y,YAW` string, or a 4x4 object pose on a stable placement."""

UNREACHED = np.iinfo(np.int32).max
"""Distance of two grasps that no sequence of regrasps joins."""


def _failure(reason: str, message: str) -> PlanningError:
    """A PlanningError tagged with why the query fails (`reason`: input, unstable, nogrip, unreachable, unconnected)."""
    err = PlanningError(message)
    err.reason = reason
    return err


# ----------------------------------------------------------------------------------------------------------------
# The roadmap.


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


@dataclass
class Roadmap:
    """The regrasp graph of one object, robot, scene, retraction set and tabletop parameter set (Section V).

    Node arrays (N rows, one per feasible tabletop grip): idtabletopgrips, idtabletopplacements, idfreeairgrip,
    idfreetabletopplacement, tcp (N, 4, 4) TCP in the world, placement (N, 4, 4) object in the world, position
    (N, 3), yaw (N,), jawwidth (N,), joints (N, 3, nq) for grasp, handx, handxworldz (NaN when not loaded).
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


def build_roadmap(rows: dict[str, np.ndarray], feasible: np.ndarray | None = None) -> Roadmap:
    """The regrasp graph from tabletop grip rows and their IK feasibility (Section V, "Building the graph").

    `rows` follows `load_tabletop_grips` (idtabletopgrips, idtabletopplacements, idfreeairgrip, rotmat,
    placement_rotmat, tabletopposition, idfreetabletopplacement, jawwidth) plus optional `angle` (radians) and
    `joints` (N, 3, nq); `feasible` (N,) or (N, 3) selects the nodes (all three flags when (N, 3))."""
    t0 = time.perf_counter()
    n_all = len(rows["idtabletopgrips"])
    keep = np.ones(n_all, dtype=bool) if feasible is None else np.asarray(feasible, dtype=bool)
    if keep.ndim == 2:
        keep = keep.all(axis=1)
    if keep.shape != (n_all,):
        raise PlanningError(f"feasibility mask has shape {keep.shape}, expected ({n_all},) or ({n_all}, 3)")
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
        joints = np.full((len(idx), 3, 0), np.nan)
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


# ----------------------------------------------------------------------------------------------------------------
# Start and goal poses.


@dataclass(frozen=True)
class PoseQuery:
    """An object pose on the table: stable placement `idfreetabletopplacement` moved to (x, y) and turned by `yaw`
    about world z: translate(x, y, 0) @ yaw(theta) @ freetabletopplacement.rotmat."""

    idfreetabletopplacement: int
    x: float
    y: float
    yaw: float

    def move(self) -> np.ndarray:
        """The planar move applied to the free placement."""
        m = yaw(self.yaw)
        m[:2, 3] = (self.x, self.y)
        return m

    def text(self) -> str:
        return f"{self.idfreetabletopplacement},{self.x:g},{self.y:g},{self.yaw:g}"

    def as_dict(self) -> dict:
        return {"placement": self.idfreetabletopplacement, "x": self.x, "y": self.y, "yaw": self.yaw}


def parse_pose(text: str, label: str = "pose") -> PoseQuery:
    """`PLACEMENT,X,Y,YAW` (placement id, metres, metres, radians) as a PoseQuery; PlanningError on bad input."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 4:
        raise PlanningError(f"{label} {text!r} must be PLACEMENT,X,Y,YAW (placement id, x and y in m, yaw in rad), e.g. 1,0.5,0.1,0.785")
    try:
        pid = int(parts[0])
        x, y, yaw = (float(v) for v in parts[1:])
    except ValueError:
        raise PlanningError(f"{label} {text!r}: PLACEMENT must be an integer id and X, Y, YAW numbers (m, m, rad)") from None
    return check_query(PoseQuery(pid, x, y, yaw), label)


def check_query(query: PoseQuery, label: str) -> PoseQuery:
    """A PoseQuery with finite values, or a PlanningError naming `label`."""
    if not all(math.isfinite(v) for v in (query.x, query.y, query.yaw)):
        raise PlanningError(f"{label} ({query.text()}) has NaN or infinite values; give finite x, y (m) and yaw (rad)")
    return query


def match_pose(pose: np.ndarray, free_ids: np.ndarray, free_poses: np.ndarray, label: str = "pose",
               tol_pos: float = 2e-3, tol_rot: float = 0.02) -> PoseQuery:
    """The stable placement, position and yaw of an object pose in the world (4x4), within `tol_pos` m of the
    table contact height and `tol_rot` rad of tilt; PlanningError when the pose is not on a stable placement."""
    pose = np.asarray(pose, dtype=np.float64)
    if pose.shape != (4, 4) or not np.isfinite(pose).all():
        raise PlanningError(f"{label} must be a finite 4x4 transform, got shape {pose.shape}")
    r = pose[:3, :3]
    if np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0:
        raise PlanningError(f"{label} is not a rigid transform; give a rotation with orthonormal columns")
    best = (np.inf, -1, 0.0)
    for k, f in enumerate(np.asarray(free_poses)):
        m = r @ f[:3, :3].T  # should be a rotation about z
        tilt = float(np.arccos(np.clip(m[2, 2], -1.0, 1.0)))
        dz = abs(float(pose[2, 3] - f[2, 3]))
        score = tilt + dz / max(tol_pos, 1e-12) * tol_rot
        if score < best[0]:
            best = (score, k, tilt, dz)
    if best[1] < 0:
        raise PlanningError(f"{label}: the object has no stable placements; run `workbench placements` first")
    _, k, tilt, dz = best
    if tilt > tol_rot or dz > tol_pos:
        raise _failure("unstable", f"{label} is not on a stable placement: the nearest (id {int(free_ids[k])}) is {np.degrees(tilt):.1f} deg "
                            f"tilted and {dz * 1000:.1f} mm off in height; give a pose resting on one of the placements "
                            f"{', '.join(str(int(i)) for i in free_ids)}")
    f = free_poses[k]
    m = r @ f[:3, :3].T
    theta = math.atan2(m[1, 0], m[0, 0])
    xy = pose[:2, 3] - (yaw(theta)[:3, :3] @ f[:3, 3])[:2]
    return PoseQuery(int(free_ids[k]), float(xy[0]), float(xy[1]), float(theta))


# ----------------------------------------------------------------------------------------------------------------
# IK at the query poses (adapter over the kinematics module: batched IK, retractions, collisions).


class GripIK:
    """IK with retractions (grasp, handx, handxworldz) for grips at start and goal poses (Section IV's ik columns).

    Each of the three TCP poses is solved by the kinematics module's batched Levenberg-Marquardt: tier 1 from the
    stored roadmap solution whose TCP pose is nearest (k-d tree over position and weighted rotation), capped at
    `tier1_iters` iterations (most poses converge in a few; the rest are left to tier 2); tier 2 with the
    precomputation's own settings (its seed library, iteration limits, reachability pre-filter). Converged
    configurations are checked for arm-table, gripper-table and arm-object collision with the object at its pose,
    with the precomputation's collider. A grip is feasible when all three poses are."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None, handx: float, worldz: float,
                 seed_q: np.ndarray, seed_tcp: np.ndarray, opts: IKOptions | None = None, rho: float = 0.1,
                 tier1_iters: int = 15):
        from scipy.spatial import cKDTree

        from .kinematics import Collider, IKOptions

        self.robot, self.scene = robot, scene
        self.handx, self.worldz = float(handx), float(worldz)
        self.opts = opts or IKOptions()
        self.tier1_iters = min(int(tier1_iters), self.opts.iters_warm)
        self.collider = Collider(robot, scene, obj_mesh)
        self.rho = rho
        seed_q = np.asarray(seed_q, dtype=np.float64).reshape(-1, robot.nq)
        seed_tcp = np.asarray(seed_tcp, dtype=np.float64).reshape(-1, 4, 4)
        ok = np.isfinite(seed_q).all(axis=1)
        self.seed_q = seed_q[ok]
        self.tree = cKDTree(self._embed(seed_tcp[ok])) if ok.any() else None
        from . import kinematics

        reach = getattr(kinematics, "ReachFilter", None)  # the precomputation's reachability pre-filter
        self.prefilter = reach(robot, scene) if reach is not None else self._reach_sphere(robot, scene)
        self._library = None

    @staticmethod
    def _reach_sphere(robot, scene):
        centre, radius = robot.reach()
        wmin, wmax = np.asarray(scene.workspace_min, dtype=np.float64), np.asarray(scene.workspace_max, dtype=np.float64)

        def inside(poses: np.ndarray) -> np.ndarray:
            p = poses[..., :3, 3]
            return (np.linalg.norm(p - centre, axis=-1) <= radius) & (p >= wmin).all(-1) & (p <= wmax).all(-1)
        return inside

    def _embed(self, poses: np.ndarray) -> np.ndarray:
        return np.concatenate([poses[:, :3, 3], self.rho * poses[:, :3, :3].reshape(len(poses), 9)], axis=1)

    @property
    def library(self):  # -> kinematics.SeedLibrary
        if self._library is None:
            import inspect

            from .kinematics import SeedLibrary

            kw = {"collider": self.collider} if "collider" in inspect.signature(SeedLibrary).parameters else {}
            self._library = SeedLibrary(self.robot, self.opts.library, self.opts.seed, **kw)
        return self._library

    def _nearest_seeds(self, targets: np.ndarray) -> np.ndarray:
        """The library seeds the precomputation's fall-back tries for these targets."""
        o = self.opts
        if hasattr(o, "seed_pool"):
            return self.library.nearest(targets, o.seeds, pool=o.seed_pool, spread=o.seed_spread)
        return self.library.nearest(targets, o.seeds)

    def targets(self, tcp: np.ndarray) -> np.ndarray:
        """(n, 3, 4, 4) grasp, handx and handxworldz TCP poses."""
        from .kinematics import retract

        return retract(np.asarray(tcp, dtype=np.float64).reshape(-1, 4, 4), self.handx, self.worldz)

    def solve(self, tcp: np.ndarray, placements: np.ndarray, known: np.ndarray | None = None, warm: bool = True,
              fallback: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Feasible (n,) and joints (n, 3, nq) for TCP poses (n, 4, 4) of grips of the object at `placements` (n, 4, 4).

        Tier 1 (`warm`): every pose from its nearest stored solution, one batched solve. Tier 2 (`fallback`): the
        poses still unsolved from all their other seeds at once (second-nearest stored solution, the grasp's own
        solution for the retractions, the library's nearest seeds, as the precomputation does), keeping the first
        collision-free solution. `known` (n, 3, nq) holds poses already solved (NaN elsewhere), e.g. by tier 1.
        Joints are returned for every solved pose, also of infeasible grips (NaN where unsolved)."""
        from .kinematics import solve_ik

        o, robot = self.opts, self.robot
        n = len(tcp)
        q_out = np.full((n * 3, robot.nq), np.nan)
        if known is not None:
            q_out[:] = np.asarray(known, dtype=np.float64).reshape(n * 3, robot.nq)
        good = np.isfinite(q_out).all(axis=1)
        if n == 0:
            return np.zeros(0, dtype=bool), q_out.reshape(0, 3, robot.nq)
        flat = self.targets(tcp).reshape(n * 3, 4, 4)  # row = grip * 3 + kind
        place = np.repeat(np.asarray(placements, dtype=np.float64).reshape(-1, 4, 4), 3, axis=0)
        pre = np.asarray(self.prefilter(flat), dtype=bool)
        alive = np.repeat(pre.reshape(n, 3).all(axis=1), 3)  # a grip needs all three poses

        def attempt(rows: np.ndarray, q0: np.ndarray, iters: int) -> tuple[np.ndarray, np.ndarray]:
            """Solve rows (repeats allowed) from q0: (joint vectors, converged and collision-free)."""
            q, ok = solve_ik(robot, flat[rows], q0, iters, o.tol_pos, o.tol_rot)
            if ok.any():
                sel = np.flatnonzero(ok)
                ok[sel[self.collider.collides_q(q[sel], place[rows[sel]])]] = False
            return q, ok

        near = None
        rows = np.flatnonzero(alive & ~good)
        if self.tree is not None and len(rows):
            k = min(2, len(self.seed_q))
            _, near = self.tree.query(self._embed(flat[rows]), k=k)
            near = np.asarray(near).reshape(len(rows), k)
            if warm:
                q, ok = attempt(rows, self.seed_q[near[:, 0]], self.tier1_iters)
                q_out[rows[ok]], good[rows[ok]] = q[ok], True
        if fallback:
            left = ~good[rows]
            rows2, near2 = rows[left], (near[left] if near is not None else None)
            if len(rows2):
                seeds, owner = [], []
                if near2 is not None and near2.shape[1] > 1:  # the nearest stored solution was tier 1's seed
                    seeds.append(self.seed_q[near2[:, 1]])
                    owner.append(np.arange(len(rows2)))
                kind = rows2 % 3
                own = (kind > 0) & good[rows2 - kind]
                if own.any():
                    seeds.append(q_out[rows2[own] - kind[own]])
                    owner.append(np.flatnonzero(own))
                if o.seeds > 0:
                    lib = self._nearest_seeds(flat[rows2])
                    seeds.append(self.library.q[lib.ravel()])
                    owner.append(np.repeat(np.arange(len(rows2)), lib.shape[1]))
                if seeds:
                    owner = np.concatenate(owner)
                    q, ok = attempt(rows2[owner], np.concatenate(seeds), o.iters_seed)
                    hit = np.flatnonzero(ok)
                    win = hit[np.unique(owner[hit], return_index=True)[1]]
                    q_out[rows2[owner[win]]], good[rows2[owner[win]]] = q[win], True
        feas = good.reshape(n, 3).all(axis=1) & alive.reshape(n, 3)[:, 0]
        return feas, q_out.reshape(n, 3, robot.nq)


# ----------------------------------------------------------------------------------------------------------------
# The search.


@dataclass
class Side:
    """The grips of a start or goal pose: free-air grasp ids, TCP poses in the world, jaw widths, roadmap grasp index
    (-1 when the grasp has no roadmap node), IK state (0 unknown, 1 feasible, -1 infeasible, -2 not solved from the
    nearest stored solution, the fall-back seeds still untried), joints (NaN where unsolved), and `prior`:
    the share of the nearest grid placements where the same grasp is IK-feasible (evaluation order only)."""

    label: str
    query: PoseQuery
    pose: np.ndarray
    grasp: np.ndarray
    tcp: np.ndarray
    jawwidth: np.ndarray
    rindex: np.ndarray
    state: np.ndarray
    joints: np.ndarray
    prior: np.ndarray | None = None

    @property
    def n_feasible(self) -> int:
        return int((self.state > 0).sum())

    @property
    def n_evaluated(self) -> int:
        return int((self.state != 0).sum())


@dataclass
class Route:
    """One way through the graph: the start grip, for each regrasp the node where the object is put down with the
    previous grasp and the node where it is grasped again (same placement), and the goal grip."""

    start_grip: int
    goal_grip: int
    regrasps: list[tuple[int, int]]

    @property
    def n_regrasps(self) -> int:
        return len(self.regrasps)

    @property
    def n_transfers(self) -> int:
        return len(self.regrasps) + 1


@dataclass
class SearchResult:
    """Routes best first (cost: regrasps, then transfers), the two sides, and timings in seconds (connect: IK at
    the start and goal poses; search: pairing, distances and route reconstruction)."""

    routes: list[Route]
    start: Side
    goal: Side
    timings: dict
    rounds: int = 0


def pair_costs(roadmap: Roadmap, start: Side, goal: Side) -> np.ndarray:
    """(nS, nG) regrasps of each start/goal grip pair ignoring IK at the query poses: 0 for one grasp serving both,
    the grasp graph's distance between two roadmap grasps, UNREACHED otherwise."""
    c = np.full((len(start.grasp), len(goal.grasp)), UNREACHED, dtype=np.int64)
    rs, rg = start.rindex, goal.rindex
    si, gi = np.flatnonzero(rs >= 0), np.flatnonzero(rg >= 0)
    if len(si) and len(gi):
        c[np.ix_(si, gi)] = roadmap.dist[np.ix_(rs[si], rg[gi])]
    same = start.grasp[:, None] == goal.grasp[None, :]
    c[same] = 0
    return c


def _first_unique(a: np.ndarray) -> np.ndarray:
    """The distinct values of `a` in order of first appearance."""
    _, first = np.unique(a, return_index=True)
    return a[np.sort(first)]


def search(roadmap: Roadmap, start: Side, goal: Side, evaluate: Callable[[list[tuple[Side, np.ndarray]], bool], None],
           alternatives: int = 2, lazy: bool = True,
           chunk: int = 8) -> SearchResult:
    """Fewest regrasps, then fewest transfers, between a start and a goal side (Section V, "Searching the graph").

    Breadth-first on the layered graph: a pair (start grip, goal grip) costs the regrasps of `pair_costs`, and a
    route exists when both grips are IK-feasible. `evaluate([(side, indices), ...], fallback)` sets the IK state and
    joints of grips of both sides in one call: tier 1 (nearest stored solution) for unknown grips, tier 2 (the
    fall-back seeds) for grips that failed tier 1 when `fallback`. With `lazy`, phase A takes the cheapest
    cost level that still has pairs of unsettled grips and evaluates up to `chunk` grips per side (doubling every
    round) from its pairs, most promising first (`prior`): unknown grips first, tier 2 only when the level has no
    unknown grip left; it ends when a confirmed pair costs no more than any unsettled one, so the best cost is the
    same as evaluating every grip first (`lazy=False`). Phase B gathers alternatives (at most one regrasp above the
    best) from tier 1 only, until `1 + alternatives` pairs are confirmed. Routes come best first: cost, then the
    pair's order."""
    timings = {"connect": 0.0, "search": 0.0}
    want = 1 + max(0, int(alternatives))
    t0 = time.perf_counter()
    cost = pair_costs(roadmap, start, goal)
    finite = cost < UNREACHED
    prior_s = start.prior if start.prior is not None else np.full(len(start.grasp), 0.5)
    prior_g = goal.prior if goal.prior is not None else np.full(len(goal.grasp), 0.5)
    timings["search"] += time.perf_counter() - t0

    def run(new_s: np.ndarray, new_g: np.ndarray, fallback: bool) -> None:
        if len(new_s) or len(new_g):
            t = time.perf_counter()
            evaluate([(start, new_s), (goal, new_g)], fallback)
            timings["connect"] += time.perf_counter() - t

    if not lazy:
        run(np.flatnonzero(start.state == 0), np.flatnonzero(goal.state == 0), True)
        run(np.flatnonzero(start.state == -2), np.flatnonzero(goal.state == -2), True)
    rounds = 0
    while True:
        t = time.perf_counter()
        possible = finite & (start.state != -1)[:, None] & (goal.state != -1)[None, :]
        confirmed = possible & (start.state == 1)[:, None] & (goal.state == 1)[None, :]
        open_ = possible & ~confirmed
        vmin = int(cost[open_].min()) if open_.any() else UNREACHED
        best = int(cost[confirmed].min()) if confirmed.any() else UNREACHED
        if best > vmin:  # phase A: the optimum is not proven yet; settle the cheapest open level
            level = open_ & (cost == vmin)
        else:  # phase B: alternatives up to one regrasp above the best, from tier 1 only
            unknown = open_ & ((start.state == 0)[:, None] | (goal.state == 0)[None, :]) & (cost <= best + 1)
            if int((confirmed & (cost <= best + 1)).sum()) >= want or not unknown.any():
                timings["search"] += time.perf_counter() - t
                break
            level = unknown & (cost == int(cost[unknown].min()))
        ps, pg = np.nonzero(level)
        score = np.where(start.state[ps] == 1, 1.0, prior_s[ps]) * np.where(goal.state[pg] == 1, 1.0, prior_g[pg])
        order = np.lexsort((pg, ps, -np.round(score, 6)))
        ps, pg = ps[order], pg[order]
        m = chunk << min(rounds, 20)
        new_s = _first_unique(ps[start.state[ps] == 0])[:m]
        new_g = _first_unique(pg[goal.state[pg] == 0])[:m]
        fallback = not len(new_s) and not len(new_g)
        if fallback:  # every open pair of this level waits on grips that failed tier 1
            new_s = _first_unique(ps[start.state[ps] == -2])[:m]
            new_g = _first_unique(pg[goal.state[pg] == -2])[:m]
        timings["search"] += time.perf_counter() - t
        rounds += 1
        run(new_s, new_g, fallback)
    t = time.perf_counter()
    confirmed = finite & (start.state == 1)[:, None] & (goal.state == 1)[None, :]
    si, gi = np.nonzero(confirmed)
    if len(si):  # alternatives: at most one regrasp more than the best
        near = cost[si, gi] <= cost[si, gi].min() + 1
        si, gi = si[near], gi[near]
    order = np.lexsort((gi, si, cost[si, gi]))[:want]
    routes = [route(roadmap, start, goal, int(si[k]), int(gi[k])) for k in order]
    timings["search"] += time.perf_counter() - t
    return SearchResult(routes=routes, start=start, goal=goal, timings=timings, rounds=rounds)


def route(roadmap: Roadmap, start: Side, goal: Side, s: int, g: int) -> Route:
    """The nodes of the cheapest route from start grip `s` to goal grip `g`: at each regrasp, among the placements
    where the current grasp and a grasp one step closer to the goal's meet, the one nearest to the object's current
    position plus its distance to the goal (ties: lowest node index)."""
    if start.grasp[s] == goal.grasp[g]:
        return Route(start_grip=s, goal_grip=g, regrasps=[])
    cur, tgt = int(start.rindex[s]), int(goal.rindex[g])
    left = int(roadmap.dist[cur, tgt])
    pos = start.pose[:2, 3]
    goal_xy = goal.pose[:2, 3]
    out = []
    while left > 0:
        a_nodes, _ = roadmap.nodes_of_grasps(np.array([cur]))
        places = roadmap.node_place[a_nodes]
        b_nodes, owner = roadmap.nodes_of_places(places)
        nb = roadmap.node_grasp[b_nodes]
        ok = (roadmap.dist[nb, tgt] == left - 1) & (nb != cur)
        a_sel, b_sel = a_nodes[owner[ok]], b_nodes[ok]
        xy = roadmap.position[a_sel, :2]
        score = np.linalg.norm(xy - pos, axis=1) + np.linalg.norm(xy - goal_xy, axis=1)
        k = np.lexsort((b_sel, a_sel, np.round(score, 9)))[0]
        a, b = int(a_sel[k]), int(b_sel[k])
        out.append((a, b))
        cur, pos, left = int(roadmap.node_grasp[b]), roadmap.position[a, :2], left - 1
    return Route(start_grip=s, goal_grip=g, regrasps=out)


# ----------------------------------------------------------------------------------------------------------------
# A roadmap loaded from a store, ready for queries.


class Planner:
    """The regrasp graph of one object and robot from a store, with what connecting a query needs: the stable
    placements and their free tabletop grips, the object, the robot, its scene (table) and the retractions
    (Section V). Build it with `load_planner`; `plan` answers a start/goal query."""

    def __init__(self, roadmap: Roadmap, free: dict[str, np.ndarray], ftg: dict[str, np.ndarray], obj: ObjectModel,
                 robot: Robot, scene: Scene, handx: float, worldz: float, ids: dict[str, int], ik_opts: IKOptions | None = None,
                 grid: dict[str, np.ndarray] | None = None):
        self.roadmap, self.free, self.ftg = roadmap, free, ftg
        self.grid = grid
        self.rows: dict = {}
        self.object, self.robot, self.scene = obj, robot, scene
        self.handx, self.worldz = float(handx), float(worldz)
        self.ids = dict(ids)
        self.ik_opts = ik_opts
        self._ik: GripIK | None = None
        order = np.argsort(ftg["idfreetabletopplacement"], kind="stable")
        self._ftg_order = order
        self._ftg_keys = np.asarray(ftg["idfreetabletopplacement"])[order]

    @property
    def ik(self) -> GripIK:
        """IK for start and goal grips, warm-started from the roadmap's joint vectors (built on first use)."""
        if self._ik is None:
            from .kinematics import retract

            rm = self.roadmap
            seeds_q = rm.joints.reshape(-1, rm.joints.shape[-1]) if rm.joints.size else np.zeros((0, self.robot.nq))
            seeds_tcp = retract(rm.tcp, self.handx, self.worldz).reshape(-1, 4, 4) if rm.n_nodes else np.zeros((0, 4, 4))
            self._ik = GripIK(self.robot, self.scene, self.object.mesh, self.handx, self.worldz, seeds_q, seeds_tcp, self.ik_opts)
        return self._ik

    def placement_ids(self) -> list[int]:
        return [int(i) for i in self.free["idfreetabletopplacement"]]

    def query_pose(self, query: PoseQuery, label: str = "pose") -> np.ndarray:
        """translate(x, y, 0) @ yaw @ freetabletopplacement.rotmat, after checking the placement id and the table."""
        check_query(query, label)
        ids = self.free["idfreetabletopplacement"]
        hit = np.flatnonzero(ids == query.idfreetabletopplacement)
        if len(hit) == 0:
            raise _failure("unstable", f"{label} placement {query.idfreetabletopplacement} is not a stable placement of {self.object.name} "
                                f"(its placements: {', '.join(str(int(i)) for i in ids)}); give one of those ids")
        lo, hi = self.scene.table_min, self.scene.table_max
        if not (lo[0] <= query.x <= hi[0] and lo[1] <= query.y <= hi[1]):
            raise PlanningError(f"{label} position ({query.x:g}, {query.y:g}) is off the table (x {lo[0]:g}..{hi[0]:g}, "
                                f"y {lo[1]:g}..{hi[1]:g} m); give a position on it")
        return query.move() @ self.free["rotmat"][hit[0]]

    def side(self, query: Query, label: str = "start") -> Side:
        """The grips of a start or goal pose (Section V, Fig. 8): the placement's free tabletop grips moved with it.
        `query` is a PoseQuery, a `PLACEMENT,X,Y,YAW` string, or a 4x4 object pose matched to a stable placement."""
        if isinstance(query, str):
            query = parse_pose(query, label)
        elif not isinstance(query, PoseQuery):
            query = match_pose(query, self.free["idfreetabletopplacement"], self.free["rotmat"], label)
        pose = self.query_pose(query, label)
        lo = np.searchsorted(self._ftg_keys, query.idfreetabletopplacement, side="left")
        hi = np.searchsorted(self._ftg_keys, query.idfreetabletopplacement, side="right")
        rows = self._ftg_order[lo:hi]
        if len(rows) == 0:
            raise _failure("nogrip", f"{label} placement {query.idfreetabletopplacement} of {self.object.name} has no grasp that clears "
                                f"the table; choose another placement ({', '.join(map(str, self.placement_ids()))})")
        grasp = np.asarray(self.ftg["idfreeairgrip"])[rows].astype(np.int64)
        order = np.argsort(grasp, kind="stable")
        rows, grasp = rows[order], grasp[order]
        tcp = query.move() @ np.asarray(self.ftg["rotmat"])[rows]
        n = len(rows)
        return Side(label=label, query=query, pose=pose, grasp=grasp, tcp=tcp, jawwidth=np.asarray(self.ftg["jawwidth"])[rows],
                    rindex=self.roadmap.grasp_index(grasp), state=np.zeros(n, dtype=np.int8),
                    joints=np.full((n, 3, self.robot.nq), np.nan), prior=self.prior(query, grasp))

    def prior(self, query: PoseQuery, grasp: np.ndarray, k: int = 4) -> np.ndarray:
        """For each grasp at a query pose, the share of the `k` nearest grid placements of the same stable placement
        (position, and yaw at 0.1 m per rad) where the same grasp is IK-feasible; 0.5 where the grid has no row."""
        g = self.grid
        out = np.full(len(grasp), 0.5)
        if g is None or len(g["tp_free"]) == 0:
            return out
        cand = np.flatnonzero(g["tp_free"] == query.idfreetabletopplacement)
        if len(cand) == 0:
            return out
        dyaw = np.abs((g["tp_angle"][cand] - query.yaw + np.pi) % (2 * np.pi) - np.pi)
        d = np.hypot(g["tp_pos"][cand, 0] - query.x, g["tp_pos"][cand, 1] - query.y) + 0.1 * dyaw
        near = cand[np.lexsort((cand, d))[:k]]
        keys = near[None, :].astype(np.int64) * g["stride"] + np.asarray(grasp, dtype=np.int64)[:, None]
        pos = np.clip(np.searchsorted(g["keys"], keys), 0, len(g["keys"]) - 1)
        found = g["keys"][pos] == keys
        vals = np.where(found, g["feasible"][pos], np.nan)
        has = found.any(axis=1)
        out[has] = np.nanmean(vals[has], axis=1)
        return out

    def evaluate(self, requests: list[tuple[Side, np.ndarray]], fallback: bool = True) -> None:
        """IK with retractions for grips of one or more sides in one batch (sets their state and joints): tier 1 for
        unknown grips (state 0), then tier 2 when `fallback` for grips that failed tier 1 (state -2)."""
        requests = [(side, np.asarray(idx, dtype=np.int64)) for side, idx in requests if len(idx)]
        if not requests:
            return
        tcp = np.concatenate([side.tcp[idx] for side, idx in requests])
        place = np.concatenate([np.repeat(side.pose[None], len(idx), axis=0) for side, idx in requests])
        known = np.concatenate([side.joints[idx] for side, idx in requests])
        unknown = np.concatenate([side.state[idx] == 0 for side, idx in requests])
        feas, joints = self.ik.solve(tcp, place, known, warm=bool(unknown.any()), fallback=fallback)
        k = 0
        for side, idx in requests:
            f = feas[k:k + len(idx)]
            side.state[idx] = np.where(f, 1, -1 if fallback else -2)
            side.joints[idx] = joints[k:k + len(idx)]
            k += len(idx)

    def search(self, start: Query, goal: Query, alternatives: int = 2, lazy: bool = True) -> SearchResult:
        """Connect start and goal and search (Section V); PlanningError names an unreachable or unconnected pose."""
        t0 = time.perf_counter()
        s, g = self.side(start, "start"), self.side(goal, "goal")
        t_sides = time.perf_counter() - t0
        result = search(self.roadmap, s, g, self.evaluate, alternatives, lazy)
        result.timings["connect"] += t_sides
        if not result.routes:
            self.explain(result)
        return result

    def explain(self, result: SearchResult) -> None:
        """Raise the PlanningError that says why no route exists (evaluates the remaining grips to tell)."""
        s, g = result.start, result.goal
        self.evaluate([(side, np.flatnonzero(side.state == 0)) for side in (s, g)], fallback=True)
        self.evaluate([(side, np.flatnonzero(side.state == -2)) for side in (s, g)], fallback=True)
        for side in (s, g):
            if side.n_feasible == 0:
                raise _failure(
                    "unreachable", f"{side.label} pose ({side.query.text()}) is not reachable by {self.robot.name}: none of its {len(side.grasp)} grasps "
                    f"has IK at the grasp and both retractions (handx {self.handx:g} m, worldz {self.worldz:g} m) without collision; "
                    f"move it closer to the robot or choose another placement")
        a, b = self.attach(s), self.attach(g)
        raise _failure(
            "unconnected", f"start ({s.query.text()}) and goal ({g.query.text()}) are not connected in the regrasp graph of {self.object.name} for "
            f"{self.robot.name}: no feasible grasp serves both, and the start's {s.n_feasible} feasible grasps reach roadmap components "
            f"{sorted(a['components']) or 'none'} while the goal's {g.n_feasible} reach {sorted(b['components']) or 'none'}; "
            f"add grid positions, angles or grasps (workbench placements --x/--y/--angles/--max-grasps) and rebuild")

    def attach(self, side: Side) -> dict:
        """Where a side joins the roadmap: its feasible grasps, the roadmap nodes sharing them (transfer edges) and the
        connected components of those nodes."""
        feas = np.flatnonzero(side.state > 0)
        r = side.rindex[feas]
        r = np.unique(r[r >= 0])
        nodes, _ = self.roadmap.nodes_of_grasps(r)
        comps = np.unique(self.roadmap.component[nodes]) if len(nodes) else np.zeros(0, dtype=np.int64)
        return {"grasps": side.grasp[feas], "nodes": nodes, "components": [int(c) for c in comps]}

    def plan(self, start: Query, goal: Query, alternatives: int = 2, lazy: bool = True, validate: bool = True) -> list[Plan]:
        """The best plan and up to `alternatives` next best (Section V), each checked by `workbench.validate` when
        `validate` (a plan that fails is dropped; PlanningError when none passes)."""
        from .plans import make_plan

        result = self.search(start, goal, alternatives, lazy)
        plans = [make_plan(self, result, r, rank) for rank, r in enumerate(result.routes)]
        if validate:
            from .validate import validator_for

            if not self.rows:
                raise PlanningError("this planner has no store rows to validate its plans against; build it with "
                                    "load_planner, or pass validate=False")
            checker = validator_for(self)
            reports = [checker.check(p) for p in plans]
            good = [p for p, rep in zip(plans, reports) if rep.ok]
            if not good:
                raise PlanningError(f"the plan found from {result.start.query.text()} to {result.goal.query.text()} fails validation: "
                                    f"{reports[0].errors[0]}; report this with the store")
            for rank, p in enumerate(good):
                p.rank = rank
            plans = good
        self.last = result
        return plans


_PLANNERS: dict[tuple, Planner] = {}


def _scene_from(params: dict) -> tuple[Scene, IKOptions]:
    from dataclasses import fields

    from .kinematics import IKOptions, Scene

    def pick(cls, d):
        names = {f.name for f in fields(cls)}
        return {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names}

    sd = params.get("scene", params) if isinstance(params.get("scene"), dict) else params
    scene = Scene(**pick(Scene, sd))
    od = next((params[k] for k in ("ik", "opts", "options", "ik_options") if isinstance(params.get(k), dict)), None)
    opts = IKOptions(**pick(IKOptions, od)) if od else IKOptions()
    return scene, opts


def load_planner(db: str | Path | Store, object_name: str, robot_name: str | int, handx: float | None = None, worldz: float | None = None,
                 idtabletop: int | None = None, idscene: int | None = None) -> Planner:
    """The regrasp graph of `object_name` for `robot_name` (a stored robot name or idrobot) from a store (path or
    Store), built from the latest tabletop parameter set and the IK run with the most rows (or the one with these
    retractions or this scene); cached per store file, object, robot, scene, retractions and parameter set, so
    repeated queries only connect and search."""
    from .store import Store
    from .store.objects import get_object
    from .store.placements import latest_tabletop_paramset, load_free_tabletop_grips, load_placements
    from .store import plans as sql
    from .store.robots import ik_runs, ikret_row, robot_row, scene_row

    store = db if isinstance(db, Store) else Store(db)
    try:
        oid, obj = get_object(store, object_name)
        tt = latest_tabletop_paramset(store, oid) if idtabletop is None else int(idtabletop)
        rrow = robot_row(store, robot_name)
        # the run with the most rows (then the newest) first: (idscene, idikret)
        runs = [(int(r["idscene"]), int(r["idikret"])) for r in
                sorted(ik_runs(store, idtabletop=tt, idrobot=rrow["idrobot"]), key=lambda r: (-r["rows"], -r["last"]))]
        if handx is not None or worldz is not None:
            runs = [r for r in runs if _ret_match(ikret_row(store, r[1]), handx, worldz)]
        if idscene is not None:
            runs = [r for r in runs if r[0] == int(idscene)]
        if not runs:
            raise PlanningError(f"store {store.path} has no IK of {object_name}'s tabletop grips for robot {robot_name}"
                                f"{'' if handx is None and worldz is None else f' with handx {handx}, worldz {worldz}'}; "
                                f"run `workbench ik --db {store.path} --object {object_name} --robot {robot_name}` first")
        idscene, idikret = runs[0][0], runs[0][1]
        fp = sql.ik_fingerprint(store, tt, rrow["idrobot"], idscene, idikret)
        key = (str(store.path.resolve()), oid, tt, rrow["idrobot"], rrow["digest"], idscene, idikret, fp, obj.digest)
        if key in _PLANNERS:
            return _PLANNERS[key]
        t0 = time.perf_counter()
        robot = _robot_from_row(rrow)
        rows = sql.roadmap_rows(store, tt, rrow["idrobot"], idscene, idikret, robot.nq)
        t_load = time.perf_counter() - t0
        roadmap = build_roadmap(rows, rows["feasible"])
        roadmap.timings["load"] = t_load
        pl = sql.placements_of_tabletop(store, tt)
        free = load_placements(store, pl)
        ftg = load_free_tabletop_grips(store, pl)
        sparams = scene_row(store, idscene)
        scene, opts = _scene_from(sparams)
        hx, wz = ikret_row(store, idikret)
        ids = {"idobject": oid, "idrobot": rrow["idrobot"], "idscene": idscene, "idikret": idikret, "idtabletop": tt, "idplacements": pl}
        planner = Planner(roadmap, free, ftg, obj, robot, scene, hx, wz, ids, opts, grid=grid_index(rows))
        roadmap.key = key
        planner.rows = {"robot": rrow, "scene": sparams}  # raw store rows, for the independent validator
        planner.ik.library  # build the IK adapter and its seed library now, not during the first query
        if len(_PLANNERS) >= 8:
            _PLANNERS.pop(next(iter(_PLANNERS)))
        _PLANNERS[key] = planner
        return planner
    finally:
        if store is not db:
            store.close()


def grid_index(rows: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every tabletop grip's IK feasibility (all three flags) keyed by (tabletop placement index, free-air grasp id),
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


def _ret_match(ret: tuple[float, float], handx: float | None, worldz: float | None) -> bool:
    return (handx is None or abs(ret[0] - handx) < 1e-9) and (worldz is None or abs(ret[1] - worldz) < 1e-9)


def _robot_from_row(row: dict) -> Robot:
    """The library robot of a stored `robot` row: the built-in of that name at the stored base (it must have the
    stored kinematics digest), or the stored URDF."""
    from .robots import ROBOTS, Robot, RobotSpec, builtin_robot

    name = row["name"]
    builtin = name if name in ROBOTS else name.rsplit("-", 1)[0]  # "panda-<digest>": a panda at another base
    if builtin in ROBOTS:
        robot = builtin_robot(builtin, base=row["base"])
        if row.get("digest") and robot.spec.digest != row["digest"]:
            raise PlanningError(f"robot {row['name']!r} in the store was computed with other kinematics (URDF, frames, base or "
                                f"locked joints) than the library's; rebuild its IK stage (workbench build / ik) in a new store")
    else:
        robot = Robot(RobotSpec(name=row["name"], urdf=row["urdf"], urdf_path="", tip_frame=row["tip_frame"],
                                tcp_frame=row["tcp_frame"], mount=row["mount"], base=row["base"],
                                joints=tuple(row["joint_names"]),
                                locked=tuple((str(k), float(v)) for k, v in dict(row.get("locked") or {}).items())))
    if list(robot.joint_names) != list(row["joint_names"]):
        raise PlanningError(f"robot {row['name']!r}: the stored joint order {row['joint_names']} differs from the library's "
                            f"{list(robot.joint_names)}; rebuild the ik stage")
    return robot
