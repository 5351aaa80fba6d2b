"""From a chaining sequence to joint vectors and a plan in the roadmap planner's format (Tournassoud et al. 1987,
Section 6: "a sequence of grasps and placements"; the plan format of `workbench.plans`).

Every conjunction (grasp G_i at theta, placement P_j at phi) of a sequence gets three joint vectors, as in the roadmap
planner's plans: `grasp` (TCP at the grasp), `approach` (backed off by `handx` along the TCP's -z) and `retract`
(the approach raised by `worldz`). Each is an IK branch within the joint limits whose arm and hand clear the table and
whose arm clears the object (`Collider`); approach and retract take the branch nearest to the grasp's.

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
from workbench.planners.tournassoud.chaining import NoSequence, Sequence, grasp_query, placement_query
from workbench.planners.tournassoud.classes import GraspClass
from workbench.planners.tournassoud.table import GraspPlacementTable
from workbench.planners.wan_harada.plans import Plan, PlanStep
from workbench.planners.wan_harada.query import PoseQuery
from workbench.robots.analytic import analytic_ik, nearest_branch, solve, spherical_wrist_reason
from workbench.robots.chain import solve_ik
from workbench.robots.collider import Collider, Scene
from workbench.robots.ik import IKOptions, SeedLibrary, retract
from workbench.robots.model import Robot


@dataclass
class Conjunction:
    """A grasp (class, theta sample) with a placement (placement, phi sample) and its three joint vectors."""

    grasp: tuple[int, int]
    placement: tuple[int, int]
    object_pose: np.ndarray
    tcp: np.ndarray
    q: np.ndarray  # (3, n): grasp, approach, retract


class Realiser:
    """IK branches and collision checks for conjunctions (see the module docstring)."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh, handx: float = 0.05, worldz: float = 0.05, seed: int = 0):
        self.robot, self.handx, self.worldz = robot, handx, worldz
        self.collider = Collider(robot, scene, obj_mesh)
        self.closed = not spherical_wrist_reason(robot)
        if self.closed:
            self.ik = analytic_ik(robot)
        else:
            self.lib = SeedLibrary(robot, 8192, seed)

    def branches(self, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, B, n) candidate joint vectors and (N, B) validity for TCP poses (N, 4, 4)."""
        if self.closed:
            return solve(self.ik, poses)
        k = 8
        seeds = self.lib.nearest(poses, k, pool=32, spread=1.0)
        target = np.repeat(poses, k, axis=0)
        q, ok = solve_ik(self.robot, target, self.lib.q[seeds.reshape(-1)], IKOptions().iters_seed)
        return q.reshape(len(poses), k, -1), ok.reshape(len(poses), k)

    def configurations(self, object_pose: np.ndarray, tcp: np.ndarray, q_prev: np.ndarray | None) -> np.ndarray | None:
        """(3, n) grasp/approach/retract joint vectors, or None when no branch works."""
        poses = retract(tcp[None], self.handx, self.worldz)[0]  # (3, 4, 4)
        q, ok = self.branches(poses)
        lo, hi = self.robot.lower, self.robot.upper
        cand = np.flatnonzero(ok[0])
        if q_prev is not None and len(cand):
            cand = cand[np.argsort(np.abs(q[0, cand] - q_prev).sum(axis=1))]
        for b in cand:
            qg = q[0, b]
            qa, fa = nearest_branch(q[1:2], ok[1:2], qg, lo, hi)
            qr, fr = nearest_branch(q[2:3], ok[2:3], qg, lo, hi)
            if not (fa[0] and fr[0]):
                continue
            trio = np.stack([qg, qa[0], qr[0]])
            if not self.collider.collides_q(trio, np.repeat(object_pose[None], 3, axis=0)).any():
                return trio
        return None


def conjunction_poses(table: GraspPlacementTable, classes: list[GraspClass], grasp: tuple[int, int], placement: tuple[int, int],
                      theta: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(object pose in the world, TCP in the world, grasp = TCP in the object frame) of a conjunction (Section 4.1)."""
    c, t = grasp
    j, f = placement
    obj = table.object_pose(j, table.phi[f])
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
        for g, p in pairs:
            theta = seq.theta_ini if (seq.kind == "grasp" and g == seq.grasps[0]) else None
            obj, tcp, _ = conjunction_poses(work, classes, g, p, theta)
            q = realiser.configurations(obj, tcp, q_prev)
            if q is None:
                bad = (g, p)
                break
            out.append(Conjunction(g, p, obj, tcp, q))
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
        (c, t), (j, f) = cj.grasp, cj.placement
        g = np.linalg.solve(cj.object_pose, cj.tcp)
        return PlanStep(kind=kind, idfreeairgrip=int(c * t_n + t), idfreetabletopplacement=int(j), position=np.array([hx, hy, 0.0]),
                        yaw=float(table.phi[f]), object_pose=cj.object_pose, tcp=cj.tcp, grasp=g,
                        jawwidth=float(classes[c].opening), q_approach=cj.q[1], q_grasp=cj.q[0], q_retract=cj.q[2])

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
