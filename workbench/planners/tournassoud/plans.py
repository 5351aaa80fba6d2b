"""From a chaining sequence to joint vectors and a plan in the roadmap planner's format (Tournassoud et al. 1987,
Section 6: "a sequence of grasps and placements"; the plan format of `workbench.plans`).

Every conjunction (grasp G_i at theta, placement P_j at phi) of a sequence gets three joint vectors, as in the roadmap
planner's plans: `grasp` (TCP at the grasp), `approach` (backed off by `handx` along the TCP's -z) and `retract`
(the approach raised by `worldz`). Each is an IK branch within the joint limits whose arm and hand clear the table and
whose arm clears the object (the IK solver's collider); approach and retract start from the grasp's configuration
(with the closed form: the branch nearest to it).

The table only checks the grasp's IK (Section 5.2). A conjunction that fails here (no collision-free branch or no
approach/retract) is removed from a copy of the table and the query is answered again, so the returned sequence is
still the shortest among the conjunctions that can be executed.

Plan steps (validator order pick, (transfer, regrasp)*, place):
- placement query: pick at the start placement with the first grasp, then per regrasp a transfer to an intermediate
  placement and a regrasp there, and place at the goal placement with the last grasp;
- grasp query (the object starts and ends in the hand): pick and transfer both hold the initial grasp at the first
  intermediate placement (the configuration where it is put down), then regrasp/transfer pairs, and the last regrasp
  and the place both hold the final grasp at the last placement.
A grasp's id (`idfreeairgrip`) is class * T + theta sample; placements are the placement class indices.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from workbench.errors import PlanningError
from workbench.planners.tournassoud.chaining import (
    NoSequence,
    Sequence,
    grasp_query,
    placement_query,
)
from workbench.planners.tournassoud.classes import GraspClass
from workbench.planners.tournassoud.table import GraspPlacementTable, rz
from workbench.planners.wan_harada.motions import ExecOptions, MotionResult, plan_motion
from workbench.planners.wan_harada.plans import Plan, PlanStep
from workbench.planners.wan_harada.query import PoseQuery
from workbench.robots.analytic import analytic_ik, solve, spherical_wrist_reason
from workbench.robots.collider import Scene
from workbench.robots.ik import WORLDA, IKOptions, IKSolver, held_placements, retract
from workbench.robots.model import Robot
from workbench.robots.motion import MotionChecker
from workbench.robots.selfcollision import allowed_pairs


@dataclass
class Conjunction:
    """A grasp (class, theta sample) with a placement (placement, phi sample) and its three joint vectors."""

    grasp: tuple[int, int]
    placement: tuple[int, int]
    object_pose: np.ndarray
    tcp: np.ndarray
    q: np.ndarray  # (5, n): grasp, approach (handx), retract (handxworldz), worlda, worldaworldz
    phi: float = 0.0  # the placement's angle (the sample's, or the query's own at its start and goal)


class Realiser:
    """IK and collision checks for conjunctions through the workbench's IK solver (`robots.ik.IKSolver`): its
    closed form for spherical-wrist arms (every branch tried as a seed), its Levenberg-Marquardt tiers from library
    seeds otherwise; its collider rejects arm or hand against the table and arm against the object."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh, handx: float = 0.05, worldz: float = 0.05, seed: int = 0,
                 worlda: float = WORLDA):
        self.robot, self.handx, self.worldz, self.worlda = robot, handx, worldz, worlda
        self.closed = not spherical_wrist_reason(robot)
        self.opts = IKOptions(solver="auto" if self.closed else "numerical", library=8192, seed=seed, self_collide=True)
        self.solver = IKSolver(robot, scene, self.opts, obj_mesh)
        self.ik = analytic_ik(robot) if self.closed else None
        self.scene, self.obj_mesh = scene, obj_mesh
        self._checker: tuple | None = None

    def motion_checker(self, opts: ExecOptions) -> MotionChecker:
        """The motion checker of the robot, table and object (built once per motion options)."""
        if self._checker is None or self._checker[0] != opts.motion:
            self._checker = (opts.motion, MotionChecker(self.robot, self.scene, self.obj_mesh, allowed_pairs(self.robot),
                                                        opts.motion))
        return self._checker[1]

    def grasp_free(self, object_poses: np.ndarray, tcps: np.ndarray) -> np.ndarray:
        """(K,) bool, closed-form arms only: whether some IK branch of each grasp pose is within the joint limits and
        free of self-collisions, of the table and of the resting object away from the fingers (the motion checker's
        test, `robots.motion.MotionChecker.valid`). A necessary condition of `configurations`, cheap enough to sweep
        a whole (class, placement) block of the table: the table itself (Section 5.2) checks joint limits only."""
        checker = self.motion_checker(ExecOptions())
        q, valid = solve(self.ik, tcps)
        out = np.zeros(len(tcps), dtype=bool)
        for k in range(len(tcps)):
            branches = np.flatnonzero(valid[k])
            if not len(branches):
                continue
            checker.set_resting(object_poses[k], False)
            out[k] = any(checker.valid(q[k, b]) for b in branches)
        return out

    def seeds(self, pose: np.ndarray, q_prev: np.ndarray | None) -> np.ndarray:
        """Seeds for the grasp: the previous configuration first, then every closed-form branch or diverse library seeds."""
        if self.ik is not None:
            q, ok = solve(self.ik, pose[None])
            cand = q[0, ok[0]]
        else:
            cand = self.solver.library.q[self.solver.library_seeds(pose[None])[0]]
        if q_prev is not None and len(cand):
            cand = cand[np.argsort(np.abs(cand - q_prev).sum(axis=1), kind="stable")]
        return cand

    def configurations(self, object_pose: np.ndarray, tcp: np.ndarray, q_prev: np.ndarray | None) -> np.ndarray | None:
        """(5, n) joint vectors at the roadmap planner's five poses (grasp, handx, handxworldz, worlda, worldaworldz;
        the object held at the two lifts), or None when no seed gives all five collision-free."""
        poses = retract(tcp[None], self.handx, self.worldz, self.worlda)[0]  # (5, 4, 4)
        place = held_placements(poses[None], object_pose[None])[0]  # (5, 4, 4): lifted with the hand at the lifts
        o = self.opts
        for q0 in self.seeds(poses[0], q_prev):
            qg, ok = self.solver.solve(poses[:1], place[:1], q0[None], o.iters_seed)
            if not ok[0]:
                continue
            out = [qg[0]]
            for k, start in ((1, 0), (2, 1), (3, 0), (4, 3)):  # each from its neighbour on the way
                q, okk = self.solver.solve(poses[k:k + 1], place[k:k + 1], out[start][None], o.iters_warm)
                if not okk[0]:
                    break
                out.append(q[0])
            if len(out) == 5:
                return np.stack(out)
        return None


def conjunction_poses(table: GraspPlacementTable, classes: list[GraspClass], grasp: tuple[int, int], placement: tuple[int, int],
                      theta: float | None = None, phi: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(object pose in the world, TCP in the world, grasp = TCP in the object frame) of a conjunction (Section 4.1),
    at the samples' angles or at the given exact `theta`, `phi`."""
    c, t = grasp
    j, f = placement
    obj = table.object_pose(j, table.phi[f] if phi is None else phi)
    g = classes[c].pose(table.theta[t] if theta is None else theta)
    return obj, obj @ g, g


def working_copy(table: GraspPlacementTable) -> GraspPlacementTable:
    """A copy of the table whose Q may lose conjunctions (the stored table stays as it is)."""
    return GraspPlacementTable(theta=table.theta, phi=table.phi, hand_object=table.hand_object, hand_table=table.hand_table,
                               q=table.q.copy(), placements=table.placements, frame=table.frame, timings=table.timings)


def realise(query, table: GraspPlacementTable, classes: list[GraspClass], realiser: Realiser, attempts: int = 40,
            copy: bool = True, **kw) -> tuple[Sequence, list[Conjunction]]:
    """Answer `query` (grasp_query or placement_query with keyword arguments `kw`) and give every conjunction its
    joint vectors; failing conjunctions are removed from a copy of the table (from `table` itself when not `copy`),
    with the failing samples of the rest of their phi row, and the query re-run."""
    work = working_copy(table) if copy else table
    rows_done: set[tuple] = set()
    legal = int(work.q.sum())
    for _ in range(attempts):
        try:
            seq = query(work, **kw)
        except NoSequence as exc:
            dropped = legal - int(work.q.sum())
            if not dropped:
                raise
            raise NoSequence(f"after dropping {dropped} table sample(s) whose approach, retract or arm fails its collision "
                             f"checks (a larger --handx/--worldz or another table point may keep them): {exc}") from None
        pairs = seq.conjunctions()
        out, q_prev, bad = [], None, None
        for k, (g, p) in enumerate(pairs):
            # the query's own angles, not their nearest samples, at the initial grasp / the start and goal poses
            theta = seq.theta_ini if (seq.kind == "grasp" and k == 0) else None
            phi = seq.extra.get("phi_start") if k == 0 else (seq.extra.get("phi_goal") if k == len(pairs) - 1 else None)
            obj, tcp, _ = conjunction_poses(work, classes, g, p, theta, phi)
            q = realiser.configurations(obj, tcp, q_prev)
            if q is None:
                bad = (g, p)
                break
            out.append(Conjunction(g, p, obj, tcp, q, work.phi[p[1]] if phi is None else phi))
            q_prev = q[0]
        if bad is None:
            return seq, out
        (c, t), (j, f) = bad
        work.q[c, j, t, f] = False
        # the same grasp at the same placement usually fails at its other angles too (the arm's reach and self-
        # collisions vary slowly): test the rest of its block (closed form) or phi row (numerical IK) now, once, and
        # drop every failing sample (configurations() tries every seed, so a failure does not depend on the previous
        # configuration)
        if realiser.ik is not None and (c, j) not in rows_done:
            # closed form: sweep the whole (class, placement) block once with the cheap grasp-pose test
            rows_done.add((c, j))
            ts, fs = np.nonzero(work.q[c, j])
            objs = work.frame[None] @ rz(work.phi[fs]) @ work.placements[j]
            ok = realiser.grasp_free(objs, objs @ classes[c].pose(work.theta[ts]))
            work.q[c, j, ts[~ok], fs[~ok]] = False
        elif realiser.ik is None and (c, j, t) not in rows_done:
            rows_done.add((c, j, t))
            for f2 in np.flatnonzero(work.q[c, j, t]):
                o2, tcp2, _ = conjunction_poses(work, classes, (c, t), (j, int(f2)))
                if realiser.configurations(o2, tcp2, None) is None:
                    work.q[c, j, t, f2] = False
        work._matrix = None
    raise NoSequence(f"no executable regrasp sequence after {attempts} attempts: the table's conjunctions fail their approach, "
                        f"retract or arm collision checks; try another table point or larger handx/worldz")


def step_conjunctions(kind: str, n: int) -> tuple[list[str], list[int]]:
    """The plan's step kinds and, per step, the index of the conjunction it realises (see the module docstring)."""
    if kind == "placement":
        return ["pick"] + ["transfer", "regrasp"] * ((n - 2) // 2) + ["place"], list(range(n))
    kinds, which = ["pick", "transfer"], [0, 0]
    for k in range(1, n - 1, 2):
        kinds += ["regrasp", "transfer"]
        which += [k, k + 1]
    return kinds + ["regrasp", "place"], which + [n - 1, n - 1]


def to_plan(seq: Sequence, conj: list[Conjunction], table: GraspPlacementTable, classes: list[GraspClass], robot: Robot,
            object_name: str, handx: float, worldz: float) -> Plan:
    """The plan of a realised sequence in the roadmap planner's format (see the module docstring)."""
    if not conj:
        raise PlanningError("the query needs no regrasp: the initial grasp is already in the goal range; nothing to plan")
    t_n = len(table.theta)
    hx, hy = table.frame[0, 3], table.frame[1, 3]

    def step(kind: str, cj: Conjunction, theta: float | None = None) -> PlanStep:
        (c, t), (j, _) = cj.grasp, cj.placement
        g = np.linalg.solve(cj.object_pose, cj.tcp)
        return PlanStep(kind=kind, idfreeairgrip=int(c * t_n + t), idfreetabletopplacement=int(j), position=np.array([hx, hy, 0.0]),
                        yaw=float(cj.phi), object_pose=cj.object_pose, tcp=cj.tcp, grasp=g,
                        jawwidth=float(classes[c].opening), q_approach=cj.q[1], q_grasp=cj.q[0], q_retract=cj.q[2],
                        q_worlda=cj.q[3], q_worldaworldz=cj.q[4])

    kinds, which = step_conjunctions(seq.kind, len(conj))
    steps = [step(k, conj[i]) for k, i in zip(kinds, which)]
    first, last = steps[0], steps[-1]
    start = PoseQuery(first.idfreetabletopplacement, float(hx), float(hy), first.yaw)
    goal = PoseQuery(last.idfreetabletopplacement, float(hx), float(hy), last.yaw)
    return Plan(object=object_name, robot=robot.name, joint_names=list(robot.joint_names), start=start, goal=goal,
                start_pose=first.object_pose, goal_pose=last.object_pose, steps=steps, handx=handx, worldz=worldz,
                timings={"search": seq.seconds})


def add_motions(plan: Plan, realiser: Realiser, opts: ExecOptions) -> MotionResult:
    """Plan and time the motions of a plan with the roadmap planner's motion planner (`wan_harada.motions.plan_motion`,
    CONVENTIONS.md "Plans and motions"); on success they are attached to the plan (segments, the waypoints on the
    IK branch the motions use, acceleration limits, time)."""
    robot = realiser.robot
    checker = realiser.motion_checker(opts)
    vlim = np.asarray(robot.model.velocityLimit, dtype=np.float64)
    t0 = time.perf_counter()
    res, lines = plan_motion(checker, plan.steps, vlim, opts.acc, opts.motion.seed, plan.worlda, plan.worldz)
    if res.ok:
        for st, ln in zip(plan.steps, lines):
            st.q_retract, st.q_approach, st.q_grasp = ln.q_retract, ln.q_approach, ln.q_grasp
            st.q_worlda, st.q_worldaworldz = ln.q_worlda, ln.q_worldaworldz
        plan.segments = res.segments
        plan.acc = np.broadcast_to(np.asarray(opts.acc, dtype=np.float64), (robot.nq,)).tolist()
        plan.timings["motion"] = time.perf_counter() - t0
    return res


def _plan(query, table, classes, realiser: Realiser, robot: Robot, object_name: str, motions: ExecOptions | None,
          **kw) -> tuple[Sequence, Plan | None]:
    """Answer, realise and plan a query; with `motions`, a conjunction whose motion fails (the step's lines, or the
    move into the next step) is removed from a working copy of the table and the query answered again, at most
    `motions.max_removed` times (as the roadmap planner removes failing nodes)."""
    work = working_copy(table)
    removed, last = 0, ""
    while True:
        try:
            seq, conj = realise(query, work, classes, realiser, copy=False, **kw)
        except NoSequence as exc:
            if not removed:
                raise
            raise NoSequence(f"after removing {removed} conjunction(s) whose motions failed (last failure: {last}): {exc}") from None
        if not conj:
            return seq, None
        plan = to_plan(seq, conj, work, classes, robot, object_name, realiser.handx, realiser.worldz)
        if motions is None:
            return seq, plan
        res = add_motions(plan, realiser, motions)
        if res.ok:
            plan.removed = removed
            return seq, plan
        last = res.reason
        if removed >= motions.max_removed:
            raise NoSequence(f"no executable regrasp sequence after removing {removed} conjunction(s) whose motions failed "
                             f"(limit --max-removed {motions.max_removed}); last failure: {last}")
        i = res.blame[1] if res.blame[0] == "step" else res.blame[2]
        cj = conj[step_conjunctions(seq.kind, len(conj))[1][i]]
        (c, t), (j, f) = cj.grasp, cj.placement
        work.q[c, j, t, f] = False
        work._matrix = None
        removed += 1


def plan_grasp_query(table, classes, realiser: Realiser, robot: Robot, object_name: str, initial: tuple[int, float],
                     goal_class: int, goal_range: tuple[float, float], motions: ExecOptions | None = None) -> tuple[Sequence, Plan | None]:
    """Section 6's query, realised and turned into a plan (None when no regrasp is needed); with `motions`, an
    executable plan with its timed motions."""
    return _plan(grasp_query, table, classes, realiser, robot, object_name, motions, initial=initial, goal_class=goal_class,
                 goal_range=goal_range)


def plan_placement_query(table, classes, realiser: Realiser, robot: Robot, object_name: str, start: tuple[int, float],
                         goal: tuple[int, float], motions: ExecOptions | None = None) -> tuple[Sequence, Plan]:
    """The placement-to-placement query, realised and turned into a plan; with `motions`, an executable plan with its
    timed motions."""
    return _plan(placement_query, table, classes, realiser, robot, object_name, motions, start=start, goal=goal)
