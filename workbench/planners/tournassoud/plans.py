"""From a chaining sequence to joint vectors and a plan in the roadmap planner's format (Tournassoud et al. 1987,
Section 6: "a sequence of grasps and placements"; the plan format of `workbench.plans`).

Every conjunction (grasp G_i at theta, placement P_j at phi) of a sequence gets three joint vectors, as in the roadmap
planner's plans: `grasp` (TCP at the grasp), `approach` (backed off by `handx` along the TCP's -z) and `retract`
(the approach raised by `worldz`). Each is an IK branch within the joint limits whose arm and hand clear the table and
whose arm clears the object (the IK solver's collider); approach and retract start from the grasp's configuration
(with the closed form: the branch nearest to it).

The table only checks the grasp's IK (Section 5.2); the paper assumes the arm's paths away (Section 1). A
conjunction that fails here (no collision-free branch or no approach/retract) is removed from a copy of the table
and the query is answered again, so the returned sequence is still the shortest among the conjunctions that can be
executed. With motions, a failed motion between two conjunctions removes every sample needing the same change of arm
configuration (`learn_removal`: the same IK branch switch over the neighbouring theta and phi samples of the same
class and placement), not one sample at a time. Every removal is recorded (`Removal`) and the table's own answer
kept beside the executable one (`explanation` prints both).

Plan steps (validator order pick, (transfer, regrasp)*, place):
- placement query: pick at the start placement with the first grasp, then per regrasp a transfer to an intermediate
  placement and a regrasp there, and place at the goal placement with the last grasp;
- task query (`plan_task_query`, Fig. 1): the same with the pick at the task's pick-up and the place at its
  destination, away from H, both checked against the task's obstacles; the plan may start with the part already
  in the hand at the pick-up and end with it still held at the destination (`Plan.start_held`, `end_held`: the
  motions begin with the lift out of the pick-up, end with the insertion);
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
from workbench.grasping.grasps import PREGRASP_MARGIN, pregrasp_widths
from workbench.planners.tournassoud.chaining import (
    NoSequence,
    Sequence,
    grasp_query,
    placement_query,
)
from workbench.planners.tournassoud.classes import GraspClass
from workbench.planners.tournassoud.table import GraspPlacementTable, rz
from workbench.planners.tournassoud.task import task_query
from workbench.planners.wan_harada.motions import ExecOptions, MotionResult, attach_motions, plan_motion
from workbench.planners.wan_harada.plans import Plan, PlanObstacle, PlanStep
from workbench.planners.wan_harada.query import PoseQuery
from workbench.robots.analytic import analytic_ik, solve, spherical_wrist_reason
from workbench.robots.collider import Scene
from workbench.robots.ik import ON_THE_WAY, WORLDA, IKOptions, IKSolver, held_placements, retract
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
    position: tuple[float, float] | None = None  # where the part rests (x, y); None: the table point H
    lift: np.ndarray | None = None  # world TCP move grasp -> worlda (the insertion backwards); None: up by worlda


class Realiser:
    """IK and collision checks for conjunctions through the workbench's IK solver (`robots.ik.IKSolver`): its
    closed form for spherical-wrist arms (every branch tried as a seed), its Levenberg-Marquardt tiers from library
    seeds otherwise; its collider rejects arm or hand against the table and arm against the object. With `obstacles`
    ((mesh, world pose) pairs: a task's pick-up and destination, `task.Obstacle`), the five configurations of a
    conjunction and every motion are also checked against them (the motion checker's). The motion checker's
    fingers are at the grasp's opening while the part is held and at its pre-grasp opening (the opening plus
    `pregrasp_margin`, capped at the stroke; None: full opening) while the empty hand is at the part (CONVENTIONS.md,
    Gripper)."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh, handx: float = 0.05, worldz: float = 0.05, seed: int = 0,
                 worlda: float = WORLDA, obstacles: tuple = (), pregrasp_margin: float | None = PREGRASP_MARGIN):
        self.robot, self.handx, self.worldz, self.worlda = robot, handx, worldz, worlda
        self.pregrasp_margin = pregrasp_margin
        self.obstacles = tuple(obstacles)
        self.closed = not spherical_wrist_reason(robot)
        self.opts = IKOptions(solver="auto" if self.closed else "numerical", library=8192, seed=seed, self_collide=True)
        self.solver = IKSolver(robot, scene, self.opts, obj_mesh)
        self.ik = analytic_ik(robot) if self.closed else None
        self.scene, self.obj_mesh = scene, obj_mesh
        self._checker: tuple | None = None

    def motion_checker_default(self) -> MotionChecker:
        """The motion checker with the default motion options (or the last one built)."""
        return self._checker[1] if self._checker is not None else self.motion_checker(ExecOptions())

    def motion_checker(self, opts: ExecOptions) -> MotionChecker:
        """The motion checker of the robot, table and object (built once per motion options)."""
        if self._checker is None or self._checker[0] != opts.motion:
            self._checker = (opts.motion, MotionChecker(self.robot, self.scene, self.obj_mesh, allowed_pairs(self.robot),
                                                        opts.motion, self.obstacles))
        return self._checker[1]

    def pregrasp(self, opening: float) -> float:
        """The empty hand's jaw opening at a grasp of `opening` (m)."""
        return float(pregrasp_widths(np.array([opening]), self.robot.gripper.jaw_max, self.pregrasp_margin)[0])

    def grasp_free(self, object_poses: np.ndarray, tcps: np.ndarray, opening: float) -> np.ndarray:
        """(K,) bool, closed-form arms only: whether some IK branch of each grasp pose is within the joint limits and
        free of self-collisions, of the table and of the resting object away from the fingers (the motion checker's
        test, `robots.motion.MotionChecker.valid`). A necessary condition of `configurations`, cheap enough to sweep
        a whole (class, placement) block of the table: the table itself (Section 5.2) checks joint limits only. The
        fingers are at the pre-grasp opening of a grasp of `opening`."""
        checker = self.motion_checker(ExecOptions())
        checker.set_jaw(self.pregrasp(opening))
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

    def configurations(self, object_pose: np.ndarray, tcp: np.ndarray, q_prev: np.ndarray | None,
                       lift: np.ndarray | None = None, opening: float | None = None) -> np.ndarray | None:
        """(5, n) joint vectors at the roadmap planner's five poses (grasp, handx, handxworldz, worlda, worldaworldz;
        the object held at the two lifts; with `lift`, worlda is the grasp moved by it in the world, the start of an
        insertion), or None when no seed gives all five collision-free (the fingers at the grasp's `opening` and its
        pre-grasp opening, default full opening)."""
        poses = retract(tcp[None], self.handx, self.worldz, self.worlda)[0]  # (5, 4, 4)
        if lift is not None:
            poses[3, :3, 3] = tcp[:3, 3] + lift
            poses[4, :3, 3] = poses[3, :3, 3] + [0.0, 0.0, self.worldz]
        place = held_placements(poses[None], object_pose[None])[0]  # (5, 4, 4): lifted with the hand at the lifts
        o = self.opts
        for q0 in self.seeds(poses[0], q_prev):
            qg, ok = self.solver.solve(poses[:1], place[:1], q0[None], o.iters_seed)
            if not ok[0]:
                continue
            out = [qg[0]]
            for k, start in ON_THE_WAY:  # each from its neighbour on the way
                q, okk = self.solver.solve(poses[k:k + 1], place[k:k + 1], out[start][None], o.iters_warm)
                if not okk[0]:
                    break
                out.append(q[0])
            if len(out) == 5 and self._clear(np.stack(out), object_pose, tcp, opening):
                return np.stack(out)
        return None

    def _clear(self, q: np.ndarray, object_pose: np.ndarray, tcp: np.ndarray, opening: float | None = None) -> bool:
        """Whether the five configurations clear the obstacles (the part resting at the first three, the fingers at
        the pre-grasp opening; held at the lifts, at the grasp's); True without obstacles."""
        if not self.obstacles:
            return True
        checker = self.motion_checker_default()
        jaw = self.robot.gripper.jaw_max if opening is None else opening
        checker.set_resting(object_pose, False)
        checker.set_jaw(self.pregrasp(jaw) if opening is not None else jaw)
        if not all(checker.valid(x) for x in q[:3]):
            return False
        checker.set_holding(np.linalg.solve(object_pose, tcp))
        checker.set_jaw(jaw)
        return all(checker.valid(x) for x in q[3:])


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


@dataclass
class Removal:
    """A conjunction the table allows but the arm does not, removed while realising a query (with `samples` table
    samples in all, itself and the neighbours that need the same thing): `motion` is what failed ("ik": no
    collision-free IK branch with its approach and lifts; "lines": the step's straight TCP lines; "transfer" or
    "transit": the joint motion from the previous conjunction `previous`), at plan step `step` (0-based) of the
    sequence tried; `branches` the closed-form IK branches (bits 4 elbow, 2 shoulder, 1 wrist) of the motion's two
    ends when they are known."""

    motion: str
    step: int
    conjunction: tuple[tuple[int, int], tuple[int, int]]
    reason: str
    samples: int = 1
    previous: tuple[tuple[int, int], tuple[int, int]] | None = None
    branches: tuple[int, int] | None = None

    def text(self, table: GraspPlacementTable) -> str:
        """One line: which conjunction (class, theta; placement, phi in degrees), which motion at which step, why."""
        def cj(x):
            (c, t), (j, f) = x
            return f"(class {c} at {np.degrees(table.theta[t]):.0f} deg, placement {j} at {np.degrees(table.phi[f]):.0f} deg)"
        where = f"step {self.step + 1}"
        move = {"ik": "its IK", "lines": "its approach/lift lines"}.get(self.motion, f"the {self.motion} from {cj(self.previous)}"
                                                                           if self.previous else f"the {self.motion}")
        switch = (f"; IK branch {self.branches[0]} -> {self.branches[1]}" if self.branches and self.branches[0] != self.branches[1]
                  else "")
        return f"{where}: {cj(self.conjunction)} fails {move}: {self.reason}{switch}; {self.samples} table sample(s) removed"

    def as_dict(self) -> dict:
        return {"motion": self.motion, "step": self.step, "conjunction": [list(map(int, x)) for x in self.conjunction],
                "previous": None if self.previous is None else [list(map(int, x)) for x in self.previous],
                "branches": None if self.branches is None else list(map(int, self.branches)),
                "reason": self.reason, "samples": int(self.samples)}


def realise(query, table: GraspPlacementTable, classes: list[GraspClass], realiser: Realiser,
            attempts: int | None = None, copy: bool = True, log: list[Removal] | None = None,
            **kw) -> tuple[Sequence, list[Conjunction]]:
    """Answer `query` (grasp_query or placement_query with keyword arguments `kw`) and give every conjunction its
    joint vectors; failing conjunctions are removed from a copy of the table (from `table` itself when not `copy`),
    with the failing samples of the rest of their phi row, and the query re-run until an answer's conjunctions all
    have joint vectors or the table has no answer (each attempt removes at least one sample; `attempts` caps them).
    Each removal is appended to `log`."""
    work = working_copy(table) if copy else table
    rows_done: set[tuple] = set()
    legal = int(work.q.sum())
    tries = 0
    while attempts is None or tries < attempts:
        tries += 1
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
            end = _task_end(seq, k, len(pairs))
            lift = None
            if end is not None:  # the task's pick-up or destination, away from H
                obj = seq.extra[f"{end}_pose"]
                tcp = obj @ classes[g[0]].pose(work.theta[g[1]])
                lift = seq.extra.get(f"{end}_lift")
            q = realiser.configurations(obj, tcp, q_prev, lift, classes[g[0]].opening)
            if q is None:
                bad = (k, g, p)
                break
            out.append(Conjunction(g, p, obj, tcp, q, work.phi[p[1]] if phi is None else phi,
                                   None if end is None else seq.extra[f"{end}_xy"], lift))
            q_prev = q[0]
        if bad is None:
            return seq, out
        k, (c, t), (j, f) = bad
        end = _task_end(seq, k, len(pairs))
        if end is not None:  # not a table sample: the grasp leaves the end's set of legal grasps
            kw[end][c, t] = False
            if log is not None:
                log.append(Removal("ik", _step_of(seq.kind, len(pairs), k), ((c, t), (j, f)),
                                   f"no IK branch at the {'pick-up' if end == 'start' else 'destination'} whose grasp, "
                                   f"approach and lifts are all free of collisions"))
            continue
        before = int(work.q.sum())
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
            ok = realiser.grasp_free(objs, objs @ classes[c].pose(work.theta[ts]), classes[c].opening)
            work.q[c, j, ts[~ok], fs[~ok]] = False
        elif realiser.ik is None and (c, j, t) not in rows_done:
            rows_done.add((c, j, t))
            for f2 in np.flatnonzero(work.q[c, j, t]):
                o2, tcp2, _ = conjunction_poses(work, classes, (c, t), (j, int(f2)))
                if realiser.configurations(o2, tcp2, None, opening=classes[c].opening) is None:
                    work.q[c, j, t, f2] = False
        work._matrix = None
        if log is not None:
            log.append(Removal("ik", _step_of(seq.kind, len(pairs), k), ((c, t), (j, f)),
                               "no IK branch whose grasp, approach and lifts are all free of collisions",
                               before - int(work.q.sum())))
    raise NoSequence(f"no executable regrasp sequence after {tries} attempts: the table's conjunctions fail their "
                     f"approach, retract or arm collision checks; try another table point or larger handx/worldz")


def _task_end(seq: Sequence, k: int, n: int) -> str | None:
    """"start" / "goal" when conjunction k of n is at the task's pick-up / destination (`task.task_query`)."""
    if "start_pose" not in seq.extra:
        return None
    return "start" if k == 0 else ("goal" if k == n - 1 else None)


def _step_of(kind: str, n: int, k: int) -> int:
    """The first plan step realising conjunction k of a sequence with n conjunctions."""
    return step_conjunctions(kind, n)[1].index(k) if n else 0


def branch_of(realiser: Realiser, cj: Conjunction) -> int | None:
    """The closed-form IK branch (0..7) of a conjunction's grasp configuration (None without a closed form)."""
    if realiser.ik is None:
        return None
    q, ok = solve(realiser.ik, cj.tcp[None])
    d = np.where(ok[0], np.abs(np.angle(np.exp(1j * (np.nan_to_num(q[0]) - cj.q[0])))).sum(axis=1), np.inf)
    return int(np.argmin(d)) if np.isfinite(d).any() else None


NEIGHBOURS = 2
"""Theta and phi samples either side of a failed conjunction removed with it when its motion failed without a
change of IK branch (the arm's motions vary slowly with the angles)."""


def _flood(work: GraspPlacementTable, classes: list[GraspClass], realiser: Realiser, cj: Conjunction, lose: int,
           need: int) -> None:
    """Remove cj's sample and the samples of its (class, placement) block connected to it (theta and phi neighbours,
    wrapping around) at which IK branch `lose` is not free (joint limits, collisions with the table, the resting part
    or itself) while `need` is."""
    (c, t), (j, f) = cj.grasp, cj.placement
    block = work.q[c, j]
    t_n, f_n = block.shape
    block[t, f] = False
    checker = realiser.motion_checker_default()
    g = classes[c]
    checker.set_jaw(realiser.pregrasp(g.opening))

    def needs_switch(ti: int, fi: int) -> bool:
        obj = work.object_pose(j, work.phi[fi])
        q, ok = solve(realiser.ik, (obj @ g.pose(work.theta[ti]))[None])
        checker.set_resting(obj, False)
        free = [bool(ok[0, b]) and checker.valid(q[0, b]) for b in (lose, need)]
        return not free[0] and free[1]

    seen, todo = {(t, f)}, [(t, f)]
    while todo:
        ti, fi = todo.pop()
        for nt, nf in (((ti + 1) % t_n, fi), ((ti - 1) % t_n, fi), (ti, (fi + 1) % f_n), (ti, (fi - 1) % f_n)):
            if (nt, nf) in seen or not block[nt, nf]:
                continue
            seen.add((nt, nf))
            if needs_switch(nt, nf):
                block[nt, nf] = False
                todo.append((nt, nf))


def _window(work: GraspPlacementTable, cj: tuple[tuple[int, int], tuple[int, int]]) -> None:
    """Remove a sample and its neighbours within `NEIGHBOURS` theta and phi samples of the same block."""
    (c, t), (j, f) = cj
    block = work.q[c, j]
    t_n, f_n = block.shape
    for dt in range(-NEIGHBOURS, NEIGHBOURS + 1):
        block[(t + dt) % t_n, [(f + d) % f_n for d in range(-NEIGHBOURS, NEIGHBOURS + 1)]] = False


def learn_removal(work: GraspPlacementTable, classes: list[GraspClass], realiser: Realiser, bad: Conjunction,
                  prev: Conjunction | None, both: bool = False) -> tuple[int, tuple[int, int] | None]:
    """Remove from `work` every sample that needs the same arm-configuration change as the failed motion
    prev -> bad, not only `bad` (the next sequences would otherwise try its neighbours one at a time): with the
    closed form, when the motion switches IK branch b_prev -> b_bad, the samples of bad's (class, placement) block
    connected to it at which b_prev is not free while b_bad is (`_flood`); with `both` (prev has failed before), also
    prev's connected samples at which b_bad is not free while b_prev is. Without a switch, or without a closed form,
    bad's samples within `NEIGHBOURS` in theta and phi. Returns (samples removed, (b_prev, b_bad))."""
    b_bad = branch_of(realiser, bad)
    b_prev = branch_of(realiser, prev) if prev is not None else None
    before = int(work.q.sum())
    if b_bad is None or b_prev is None or b_prev == b_bad:
        _window(work, (bad.grasp, bad.placement))
    else:
        _flood(work, classes, realiser, bad, b_prev, b_bad)
        if both:
            _flood(work, classes, realiser, prev, b_bad, b_prev)
    work._matrix = None
    return before - int(work.q.sum()), (b_prev, b_bad) if b_prev is not None and b_bad is not None else None


def explanation(table: GraspPlacementTable, own: Sequence | None, removals: list[Removal], seq: Sequence | None = None,
                own_dict: dict | None = None) -> list[str]:
    """Lines explaining how the executable answer differs from the table's own: each conjunction removed (which motion
    or collision, at which step, why), then the table's shortest sequence beside the shortest executable one (`seq`,
    None when there is none). `own` is the table's answer, or `own_dict` its `as_dict` (as `Sequence.extra["table"]`
    holds it)."""
    if own is not None:
        own_dict = own.as_dict(table)
    if own_dict is None:
        return []
    n = own_dict["regrasps"]
    if not removals:
        return [f"the table's shortest sequence has {n} regrasp(s); the arm executes it as it is"] if seq is not None else []
    lines = [f"  removed {x.text(table)}" for x in removals]
    own_pairs = set()
    g, p = own_dict["grasps"], own_dict["placements"]
    if own_dict["kind"] == "grasp":
        for k, pl in enumerate(p):
            own_pairs |= {(tuple(g[k]), tuple(pl)), (tuple(g[k + 1]), tuple(pl))}
    else:
        own_pairs = {(tuple(a), tuple(b)) for a, b in zip(g, p)} | {(tuple(a), tuple(b)) for a, b in zip(g, p[1:])}
    mine = sum(tuple(map(tuple, x.conjunction)) in own_pairs for x in removals)
    kinds = sorted({x.motion for x in removals})
    lines.append(f"the table's shortest sequence has {n} regrasp(s); {mine} of its conjunctions and "
                 f"{len(removals) - mine} of the later tries' fail with the arm ({', '.join(kinds)}); the shortest "
                 f"executable one has {'none' if seq is None else seq.regrasps}")
    return lines


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
        x, y = cj.position if cj.position is not None else (hx, hy)
        return PlanStep(kind=kind, idfreeairgrip=int(c * t_n + t), idfreetabletopplacement=int(j), position=np.array([x, y, 0.0]),
                        yaw=float(cj.phi), object_pose=cj.object_pose, tcp=cj.tcp, grasp=g,
                        jawwidth=float(classes[c].opening), q_approach=cj.q[1], q_grasp=cj.q[0], q_retract=cj.q[2],
                        q_worlda=cj.q[3], q_worldaworldz=cj.q[4], lift=cj.lift)

    kinds, which = step_conjunctions(seq.kind, len(conj))
    steps = [step(k, conj[i]) for k, i in zip(kinds, which)]
    first, last = steps[0], steps[-1]
    start = PoseQuery(first.idfreetabletopplacement, float(first.position[0]), float(first.position[1]), first.yaw)
    goal = PoseQuery(last.idfreetabletopplacement, float(last.position[0]), float(last.position[1]), last.yaw)
    return Plan(object=object_name, robot=robot.name, joint_names=list(robot.joint_names), start=start, goal=goal,
                start_pose=first.object_pose, goal_pose=last.object_pose, steps=steps, handx=handx, worldz=worldz,
                timings={"search": seq.seconds})


def add_motions(plan: Plan, realiser: Realiser, opts: ExecOptions) -> MotionResult:
    """Plan and time the motions of a plan with the roadmap planner's motion planner (`wan_harada.motions.plan_motion`,
    CONVENTIONS.md "Plans and motions"); on success they are attached to the plan (segments, the waypoints on the
    IK branch the motions use, acceleration limits and speed, time)."""
    robot = realiser.robot
    checker = realiser.motion_checker(opts)
    vlim = opts.velocity_limits(robot)
    t0 = time.perf_counter()
    res, lines = plan_motion(checker, plan.steps, vlim, opts.acc, opts.motion.seed, plan.worlda, plan.worldz,
                             plan.start_held, plan.end_held, pregrasp_margin=realiser.pregrasp_margin)
    if res.ok:
        attach_motions(plan, res, lines, plan.removed, time.perf_counter() - t0, opts, robot.nq)
    return res


def task_obstacles(pickup, destination) -> list[PlanObstacle]:
    """The obstacles of a task's two ends (`task.TaskEnd`) as the plan carries and the store keeps them."""
    return [PlanObstacle(o.name, end, np.asarray(o.mesh.vertices, dtype=np.float64), np.asarray(o.mesh.faces, dtype=np.int64),
                         o.pose.copy())
            for end, e in (("pickup", pickup), ("destination", destination)) for o in e.obstacles]


def _plan(query, table, classes, realiser: Realiser, robot: Robot, object_name: str, motions: ExecOptions | None,
          held: tuple[bool, bool] = (False, False), task: dict | None = None, **kw) -> tuple[Sequence, Plan | None]:
    """Answer, realise and plan a query; with `motions`, when a motion between two conjunctions fails (the step's
    lines, or the move into the next step), the failed conjunction and every sample needing the same change of arm
    configuration are removed from a working copy of the table (`learn_removal`) and the query answered again, at
    most `motions.max_removed` times (as the roadmap planner removes failing nodes).

    The returned sequence's `extra` carries the explanation: "table" the table's own answer (its shortest sequence
    before any removal, as a dict) and "removed" every removal (`Removal.as_dict`, in order); a NoSequence raised
    after removals carries them too (`removals`, `table_sequence`). `task`: the plan's `obstacles`, `insertion` and
    `insertion_depth` (a task query's)."""
    try:
        own = query(table, **kw)
    except NoSequence as exc:
        exc.removals, exc.table_sequence = [], None
        raise
    work = working_copy(table)
    kw = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in kw.items()}  # end masks lose grasps
    log: list[Removal] = []
    failures, last = 0, ""
    blamed: dict = {}  # how often each conjunction was the start of a failed motion

    def explained(seq: Sequence) -> Sequence:
        seq.extra["table"] = own.as_dict(table)
        seq.extra["removed"] = [r.as_dict() for r in log]
        seq.extra["removals"] = log
        return seq

    def give_up(text: str) -> NoSequence:
        err = NoSequence(text)
        err.removals, err.table_sequence = list(log), own
        return err

    while True:
        try:
            seq, conj = realise(query, work, classes, realiser, copy=False, log=log, **kw)
        except NoSequence as exc:
            if not log:
                exc.removals, exc.table_sequence = [], own
                raise
            raise give_up(f"after removing {len(log)} conjunction(s) the arm cannot execute "
                          f"({f'last motion failure: {last}; ' if last else ''}{exc})") from None
        if not conj:
            return explained(seq), None
        plan = to_plan(seq, conj, work, classes, robot, object_name, realiser.handx, realiser.worldz)
        plan.start_held, plan.end_held = held
        for k, v in (task or {}).items():
            setattr(plan, k, v)
        if motions is None:
            return explained(seq), plan
        res = add_motions(plan, realiser, motions)
        if res.ok:
            plan.removed = len(log)
            return explained(seq), plan
        last = res.reason
        if failures >= motions.max_removed:
            raise give_up(f"no executable regrasp sequence after {failures} motion failure(s), each removing the samples "
                          f"that need the same arm motion (limit --max-removed {motions.max_removed}); last failure: {last}")
        which = step_conjunctions(seq.kind, len(conj))[1]
        i = res.blame[1] if res.blame[0] == "step" else res.blame[2]
        bad = conj[which[i]]
        prev = None
        if res.blame[0] == "edge" and which[i - 1] != which[i]:
            prev = conj[which[i - 1]]
        end = _task_end(seq, which[i], len(conj))
        if end is not None:
            (c, t) = bad.grasp
            kw[end][c, t] = False
            n, branches = 1, None
        else:
            key = None if prev is None else (prev.grasp, prev.placement)
            blamed[key] = blamed.get(key, 0) + 1
            both = key is not None and blamed[key] > 1 and _task_end(seq, which[i - 1], len(conj)) is None
            n, branches = learn_removal(work, classes, realiser, bad, prev, both)
        kind = "lines" if res.blame[0] == "step" else ("transfer" if plan.steps[i - 1].kind in ("pick", "regrasp") else "transit")
        log.append(Removal(kind, i, (bad.grasp, bad.placement), res.reason.split(": ", 1)[-1], n,
                           None if prev is None else (prev.grasp, prev.placement), branches))
        failures += 1


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


def plan_task_query(table, classes, realiser: Realiser, robot: Robot, object_name: str, pickup, destination,
                    start: np.ndarray, goal: np.ndarray, motions: ExecOptions | None = None, start_held: bool = False,
                    end_held: bool = False) -> tuple[Sequence, Plan | None]:
    """Fig. 1's task (Section 5.1): the part picked up where it lies among the pick-up's obstacles with a grasp of
    `start` ((C, T), `task.end_mask`), regrasped on the table at H as often as needed, and put at the destination
    (inserted, the hand clear of its obstacles) with a grasp of `goal`. The plan's first step takes the part at the
    pick-up, its last puts it at the destination; the realiser should carry both ends' obstacles. With `start_held`
    the part is already in the hand at the pick-up (Fig. 1 (a)): the motions begin there, at the first grasp, and lift
    it out; with `end_held` they end with it still held at the destination (Fig. 1 (d)), after the insertion."""
    task = {"obstacles": task_obstacles(pickup, destination),
            "insertion": None if destination.lift() is None else destination.insertion.copy(),
            "insertion_depth": float(destination.depth) if destination.lift() is not None else 0.0}
    return _plan(task_query, table, classes, realiser, robot, object_name, motions, (start_held, end_held), task,
                 start=start, goal=goal, pickup=pickup, destination=destination)
