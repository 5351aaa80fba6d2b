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
from workbench.planners.tournassoud.table import GraspPlacementTable
from workbench.planners.wan_harada.plans import Plan, PlanStep
from workbench.planners.wan_harada.query import PoseQuery
from workbench.robots.analytic import analytic_ik, solve, spherical_wrist_reason
from workbench.robots.collider import Scene
from workbench.robots.ik import WORLDA, IKOptions, IKSolver, held_placements, retract
from workbench.robots.model import Robot


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
        self.opts = IKOptions(closed_form=self.closed, library=8192, seed=seed)
        self.solver = IKSolver(robot, scene, self.opts, obj_mesh)
        self.ik = analytic_ik(robot) if self.closed else None

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


def realise(query, table: GraspPlacementTable, classes: list[GraspClass], realiser: Realiser, attempts: int = 40,
            **kw) -> tuple[Sequence, list[Conjunction]]:
    """Answer `query` (grasp_query or placement_query with keyword arguments `kw`) and give every conjunction its
    joint vectors; failing conjunctions are removed from a copy of the table and the query re-run."""
    work = GraspPlacementTable(theta=table.theta, phi=table.phi, hand_object=table.hand_object, hand_table=table.hand_table,
                               q=table.q.copy(), placements=table.placements, frame=table.frame, timings=table.timings)
    for _ in range(attempts):
        seq = query(work, **kw)
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
        work._matrix = None
    raise NoSequence(f"no executable regrasp sequence after {attempts} attempts: the table's conjunctions fail their approach, "
                        f"retract or arm collision checks; try another table point or larger handx/worldz")


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

    if seq.kind == "placement":
        kinds = ["pick"] + ["transfer", "regrasp"] * ((len(conj) - 2) // 2) + ["place"]
        steps = [step(k, cj) for k, cj in zip(kinds, conj)]
    else:
        steps = [step("pick", conj[0]), step("transfer", conj[0])]
        for k in range(1, len(conj) - 1, 2):
            steps += [step("regrasp", conj[k]), step("transfer", conj[k + 1])]
        steps += [step("regrasp", conj[-1]), step("place", conj[-1])]
    first, last = steps[0], steps[-1]
    start = PoseQuery(first.idfreetabletopplacement, float(hx), float(hy), first.yaw)
    goal = PoseQuery(last.idfreetabletopplacement, float(hx), float(hy), last.yaw)
    return Plan(object=object_name, robot=robot.name, joint_names=list(robot.joint_names), start=start, goal=goal,
                start_pose=first.object_pose, goal_pose=last.object_pose, steps=steps, handx=handx, worldz=worldz,
                timings={"search": seq.seconds})


def plan_grasp_query(table, classes, realiser: Realiser, robot: Robot, object_name: str, initial: tuple[int, float],
                     goal_class: int, goal_range: tuple[float, float]) -> tuple[Sequence, Plan | None]:
    """Section 6's query, realised and turned into a plan (None when no regrasp is needed)."""
    seq, conj = realise(grasp_query, table, classes, realiser, initial=initial, goal_class=goal_class, goal_range=goal_range)
    plan = to_plan(seq, conj, table, classes, robot, object_name, realiser.handx, realiser.worldz) if conj else None
    return seq, plan


def plan_placement_query(table, classes, realiser: Realiser, robot: Robot, object_name: str, start: tuple[int, float],
                         goal: tuple[int, float]) -> tuple[Sequence, Plan]:
    """The placement-to-placement query, realised and turned into a plan."""
    seq, conj = realise(placement_query, table, classes, realiser, start=start, goal=goal)
    return seq, to_plan(seq, conj, table, classes, robot, object_name, realiser.handx, realiser.worldz)
