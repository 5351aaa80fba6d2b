"""The roadmap planner's surface (Wan & Harada, Section V): a `Planner` holds one object's regrasp graph for one
robot and answers queries (`search`, `plan`), checks its plans with the independent validator built from its store
rows, and explains where start and goal attach. Build one with `stages.load_planner`.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from workbench.errors import PlanningError
from workbench.grasping.naming import per_part_numbers
from workbench.planners.wan_harada.motions import (
    DEFAULT_ACC,
    ExecOptions,
    ExecResult,
    plan_executable,
)
from workbench.planners.wan_harada.plans import make_plan
from workbench.planners.wan_harada.query import (
    GripIK,
    PoseQuery,
    Query,
    Side,
    check_query,
    match_pose,
    parse_pose,
)
from workbench.planners.wan_harada.roadmap import Roadmap, _failure
from workbench.planners.wan_harada.search import SearchResult, search
from workbench.robots.ik import KINDS, WORLDA, retract
from workbench.robots.selfcollision import AllowedPairs
from workbench.validation import (
    PlanValidator,
    TrajectoryValidator,
    ValidationReport,
    trajectory_validator_from_rows,
    validator_from_rows,
)

if TYPE_CHECKING:  # pragma: no cover

    from workbench.geometry.objects import ObjectModel
    from workbench.planners.wan_harada.plans import Plan
    from workbench.robots.collider import Scene
    from workbench.robots.ik import IKOptions
    from workbench.robots.model import Robot


class Planner:
    """The regrasp graph of one object and robot from a store, with what connecting a query needs: the stable
    placements and their free tabletop grips, the object, the robot, its scene (table) and the retractions
    (Section V). Build it with `load_planner`; `plan` answers a start/goal query."""

    def __init__(self, roadmap: Roadmap, free: dict[str, np.ndarray], ftg: dict[str, np.ndarray], obj: ObjectModel,
                 robot: Robot, scene: Scene, handx: float, worldz: float, ids: dict[str, int], ik_opts: IKOptions | None = None,
                 grid: dict[str, np.ndarray] | None = None, worlda: float = WORLDA):
        self.roadmap, self.free, self.ftg = roadmap, free, ftg
        self.grid = grid
        self.rows: dict = {}
        self.pregrasp_margin: float | None = None  # the grasps' pre-grasp margin (None: approached fully open)
        self._validator: PlanValidator | None = None
        self._trajectory_validators: dict = {}
        self.allowed: AllowedPairs | None = None  # self-collision pairs of the robot row (set by load_planner)
        self.last_motion: ExecResult | None = None
        self.object, self.robot, self.scene = obj, robot, scene
        self.handx, self.worldz, self.worlda = float(handx), float(worldz), float(worlda)
        self.ids = dict(ids)
        self.ik_opts = ik_opts
        self._ik: GripIK | None = None
        order = np.argsort(ftg["idfreetabletopplacement"], kind="stable")
        self._ftg_order = order
        self._ftg_keys = np.asarray(ftg["idfreetabletopplacement"])[order]
        self.numbers = per_part_numbers(free["idfreetabletopplacement"])  # store id -> number within the part

    @property
    def ik(self) -> GripIK:
        """IK for start and goal grips, warm-started from the roadmap's joint vectors (built on first use)."""
        if self._ik is None:

            rm = self.roadmap
            seeds_q = rm.joints.reshape(-1, rm.joints.shape[-1]) if rm.joints.size else np.zeros((0, self.robot.nq))
            seeds_tcp = (retract(rm.tcp, self.handx, self.worldz, self.worlda).reshape(-1, 4, 4) if rm.n_nodes
                         else np.zeros((0, 4, 4)))
            self._ik = GripIK(self.robot, self.scene, self.object.mesh, self.handx, self.worldz, seeds_q, seeds_tcp, self.ik_opts,
                              worlda=self.worlda)
        return self._ik

    def placement_ids(self, gripped: bool = False) -> list[int]:
        """The stable placements' ids; with `gripped`, only those with a grasp that clears the table."""
        ids = np.asarray(self.free["idfreetabletopplacement"])
        return [int(i) for i in (ids[np.isin(ids, self._ftg_keys)] if gripped else ids)]

    def query_pose(self, query: PoseQuery, label: str = "pose") -> np.ndarray:
        """translate(x, y, 0) @ yaw @ freetabletopplacement.rotmat, after checking the placement id and the table."""
        check_query(query, label)
        ids = self.free["idfreetabletopplacement"]
        hit = np.flatnonzero(ids == query.idfreetabletopplacement)
        if len(hit) == 0:
            raise _failure("unstable", f"{label} placement id {query.idfreetabletopplacement} is not a stable placement of "
                                f"{self.object.name} (its placements' store ids: {', '.join(str(int(i)) for i in ids)}, "
                                f"numbered 1-{len(ids)} within the part); give one of those")
        lo, hi = self.scene.table_min, self.scene.table_max
        if not (lo[0] <= query.x <= hi[0] and lo[1] <= query.y <= hi[1]):
            raise PlanningError(f"{label} position ({query.x:g}, {query.y:g}) is off the table (x {lo[0]:g}..{hi[0]:g}, "
                                f"y {lo[1]:g}..{hi[1]:g} m); give a position on it")
        move = query.move()
        # the part rests on its support polygon (stored in the free placement's table frame): all of it must lie on
        # the table, not only the centre of mass
        polygon = np.asarray(self.free["support"][hit[0]], dtype=np.float64).reshape(-1, 3)
        support = polygon[:, :2] @ move[:2, :2].T + move[:2, 3]
        over = float(np.max(np.r_[lo[0] - support[:, 0], support[:, 0] - hi[0], lo[1] - support[:, 1],
                                  support[:, 1] - hi[1], 0.0]))
        if over > 1e-9:
            raise PlanningError(f"{label} pose ({query.text(self.numbers)}) puts {over * 1000:.1f} mm of "
                                f"{self.object.name}'s support past the table's edge (x {lo[0]:g}..{hi[0]:g}, "
                                f"y {lo[1]:g}..{hi[1]:g} m); move it at least that far onto the table")
        return move @ self.free["rotmat"][hit[0]]

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
            has = ", ".join(str(self.numbers[i]) for i in self.placement_ids(gripped=True)) or "none has"
            raise _failure("nogrip", f"{label} placement {self.numbers[query.idfreetabletopplacement]} of {self.object.name} "
                                f"(store id {query.idfreetabletopplacement}) has no grasp that clears the table; choose a "
                                f"placement that has one (numbered within the part: {has})")
        grasp = np.asarray(self.ftg["idfreeairgrip"])[rows].astype(np.int64)
        order = np.argsort(grasp, kind="stable")
        rows, grasp = rows[order], grasp[order]
        tcp = query.move() @ np.asarray(self.ftg["rotmat"])[rows]
        n = len(rows)
        return Side(label=label, query=query, pose=pose, grasp=grasp, tcp=tcp, jawwidth=np.asarray(self.ftg["jawwidth"])[rows],
                    rindex=self.roadmap.grasp_index(grasp), state=np.zeros(n, dtype=np.int8),
                    joints=np.full((n, len(KINDS), self.robot.nq), np.nan), prior=self.prior(query, grasp),
                    robust=np.asarray(self.ftg["robustness"])[rows] if "robustness" in self.ftg else None)

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
                    "unreachable", f"{side.label} pose ({side.query.text(self.numbers)}) is not reachable by {self.robot.name}: none of its {len(side.grasp)} grasps "
                    f"has IK at the grasp, both retractions and both lifts (handx {self.handx:g} m, worldz {self.worldz:g} m, "
                    f"worlda {self.worlda:g} m) without collision; {self._unreachable_hint(side)}")
        a, b = self.attach(s), self.attach(g)
        head = (f"start ({s.query.text(self.numbers)}) and goal ({g.query.text(self.numbers)}) are not connected in the regrasp graph of {self.object.name} for "
                f"{self.robot.name}: no feasible grasp serves both, and the start's {s.n_feasible} feasible grasps reach roadmap components "
                f"{sorted(a['components']) or 'none'} while the goal's {g.n_feasible} reach {sorted(b['components']) or 'none'}")
        p, q = s.query.idfreetabletopplacement, g.query.idfreetabletopplacement
        if not self.placements_linked(p, q):
            raise _failure("unconnected", f"{head}; no robot could: no chain of stable placements sharing grasps that clear the table "
                           f"links placement {self.numbers.get(p, p)} to {self.numbers.get(q, q)} (a part flipped over needs a placement in between, held by a grasp "
                           f"both allow); choose another goal placement or plan more grasps")
        raise _failure("unconnected", f"{head}; add grid positions, angles or grasps (workbench placements "
                                      f"--x/--y/--angles/--max-grasps) and rebuild")

    def _unreachable_hint(self, side: Side) -> str:
        """What to change for a pose none of whose grips is feasible: closer when every grip is beyond the arm's reach
        (`robots.ik.ReachFilter`), else another position clear of the robot or another placement (the grips within
        reach collide, or have no IK within the joint limits)."""
        base = self.robot.base[:2, 3]
        far = f"{float(np.hypot(side.query.x - base[0], side.query.y - base[1])):.2f} m from the robot's base"
        targets = self.ik.targets(side.tcp)
        reach = np.asarray(self.ik.solver.prefilter(targets.reshape(-1, 4, 4)), dtype=bool).reshape(len(targets), -1)
        if not reach.all(axis=1).any():
            return f"every grasp is beyond the arm's reach ({far}): move the part closer to the robot"
        return (f"the grasps within the arm's reach ({far}) collide with the table, the part or the robot, or have no "
                f"IK within the joint limits: choose another position, clear of the robot, or another placement")

    def placements_linked(self, a: int, b: int) -> bool:
        """Whether stable placements `a` and `b` are joined by a chain of placements in which consecutive ones share a
        grasp that clears the table in both (the free tabletop grips, Section IV), whatever the robot can reach."""
        ids = np.sort(np.asarray(self.free["idfreetabletopplacement"], dtype=np.int64))
        place = np.searchsorted(ids, np.asarray(self.ftg["idfreetabletopplacement"], dtype=np.int64))
        grasps, g = np.unique(np.asarray(self.ftg["idfreeairgrip"], dtype=np.int64), return_inverse=True)
        # bipartite placement-grasp graph: placements are nodes 0..P-1, grasps P..P+G-1
        n = len(ids) + len(grasps)
        m = sp.coo_matrix((np.ones(len(place)), (place, len(ids) + g)), shape=(n, n))
        _, label = connected_components(m, directed=False)
        i, j = np.searchsorted(ids, [a, b])
        return bool(label[i] == label[j])

    def attach(self, side: Side) -> dict:
        """Where a side joins the roadmap: its feasible grasps, the roadmap nodes sharing them (transfer edges) and the
        connected components of those nodes."""
        feas = np.flatnonzero(side.state > 0)
        r = side.rindex[feas]
        r = np.unique(r[r >= 0])
        nodes, _ = self.roadmap.nodes_of_grasps(r)
        comps = np.unique(self.roadmap.component[nodes]) if len(nodes) else np.zeros(0, dtype=np.int64)
        return {"grasps": side.grasp[feas], "nodes": nodes, "components": [int(c) for c in comps]}

    @property
    def validator(self) -> PlanValidator:
        """The independent validator of this planner's store rows (built once, from the rows only)."""
        if self._validator is None:
            free = {int(i): p for i, p in zip(self.free["idfreetabletopplacement"], self.free["rotmat"])}
            self._validator = validator_from_rows(self.rows, free)
        return self._validator

    def trajectory_validator(self, acc) -> TrajectoryValidator:
        """The independent trajectory validator of this planner's store rows for acceleration limits `acc`."""
        key = tuple(np.broadcast_to(np.asarray(acc, dtype=np.float64), (self.robot.nq,)).tolist())
        if key not in self._trajectory_validators:
            self._trajectory_validators[key] = trajectory_validator_from_rows(self.rows, self.validator, np.array(key))
        return self._trajectory_validators[key]

    def validate(self, plan: Plan, require_motion: bool = False) -> ValidationReport:
        """Check one plan with the independent validator (see `workbench.validation`): its waypoints, and its timed
        trajectory when it has one (required with `require_motion`: a plan is executable only with its motions)."""
        report = self.validator.check(plan)
        if plan.segments:
            errors, knots = self.trajectory_validator(plan.acc or DEFAULT_ACC).check(plan, plan.segments)
            report = ValidationReport(report.ok and not errors, report.errors + errors, report.checks + knots)
        elif require_motion:
            report = ValidationReport(False, report.errors + ["the plan has no timed motions"], report.checks + 1)
        return report

    def plan(self, start: Query, goal: Query, alternatives: int = 2, lazy: bool = True, validate: bool = True,
             motion: bool = True, exec_opts: ExecOptions | None = None, physics=None, on_best=None) -> list[Plan]:
        """The best plan and up to `alternatives` next best (Section V), each checked by `workbench.validation` when
        `validate` (a plan that fails is dropped; PlanningError when none passes). With `motion` (the default) the
        plans are executable: their motions are planned and timed, failing nodes or grips removed and the graph
        searched again (`motions.plan_executable`); `last_motion` keeps the outcome. `physics` (a function of a plan
        returning None or (failing step, why), e.g. `simulation.stages.physics_check`) treats a plan that fails it
        like a failed motion. `on_best(plan, result)` sees the best plan, timed and unvalidated, before the
        alternatives are planned (with `motion`)."""

        if motion:
            best = None if on_best is None else (lambda r: on_best(r.plan, r.result))
            res = plan_executable(self, start, goal, exec_opts or ExecOptions(), alternatives=alternatives, physics=physics,
                                  on_best=best)
            self.last_motion = res
            result = res.result
            plans = [res.plan, *res.alternatives]
        else:
            result = self.search(start, goal, alternatives, lazy)
            plans = [make_plan(self, result, r, rank) for rank, r in enumerate(result.routes)]
        if validate:

            if not self.rows:
                raise PlanningError("this planner has no store rows to validate its plans against; build it with "
                                    "load_planner, or pass validate=False")
            reports = [self.validate(p, require_motion=motion) for p in plans]
            good = [p for p, rep in zip(plans, reports) if rep.ok]
            if not good:
                raise PlanningError(f"the plan found from {plans[0].start.text(self.numbers)} to {plans[0].goal.text(self.numbers)} fails validation: "
                                    f"{reports[0].errors[0]}; report this with the store")
            for rank, p in enumerate(good):
                p.rank = rank
            plans = good
        self.last = result
        return plans
