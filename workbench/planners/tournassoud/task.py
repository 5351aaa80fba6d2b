"""The task's two ends: where the part is picked up and where it goes (Tournassoud, Lozano-Perez & Mazer 1987,
Section 5.1: "for the first grasp we must consider any obstacles at the pick-up point and for the last grasp ... at
the destination"; Fig. 1 (a) and (d)).

An end is the part resting in one of its placement classes P_j at a position (x, y) and angle phi on the table (a
part in a tray's pocket, or seated in a fixture's slot), with obstacles around it: meshes with poses in the world
(the neighbouring parts, the tray's walls, the fixture). The destination may also name the final insertion: the
direction (world, unit) in which the held part moves into place, over `depth` metres, so the hand is swept back
along it from the final pose.

A grasp (G_i, theta) is legal at an end (`end_mask`) when it is legal on the part (Section 5.1's hand-object range),
the open fingers clear the table at P_j (the table's hand-table stage), the arm reaches the TCP pose within its
joint limits (Section 5.2, closed form; the numerical IK otherwise), and the hand clears every obstacle:

- at the grasp and along the approach (the pick-up) or the retract (the destination), `approach` metres back along
  the TCP's -z, checked every 5 mm;
- along the insertion (the destination), at every 2 mm of the sweep from `depth` back along the insertion
  direction to the final pose;

the hand body and both fingers at the pre-grasp opening (the class's opening plus `pregrasp_margin`, capped at the
stroke; None: full opening) at the grasp and along the approach or retract, and at the grasp's opening along the
insertion (the part in the hand), as the motion checker places the fingers (`robots.motion`), so that a grasp legal
here is one its motions can use.

The chaining then starts from the (C, T) set of legal grasps at the pick-up and ends in the set legal at the
destination (`task_query`): the theta ranges of the first and last grasps come from the obstacles, not from the user.
The plan's motions take the part out of the pick-up straight up (the roadmap planner's lift, `worlda` then
`worldz`) and put it into the destination along the insertion: the held part comes down by `worldz` to the start of
the insertion, `depth` back along its direction, then moves along it in a straight TCP line into place (without an
insertion, straight down by `worlda`), every motion checked against the obstacles; so a slot entered sideways or at
a slant is executed as it is checked.
The paper leaves the obstacle test's details open; this is the workbench's choice.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import trimesh

from workbench.errors import WorkbenchError
from workbench.geometry.collision import bvh, collide_at_poses, object_collider
from workbench.grasping.grasps import PREGRASP_MARGIN, pregrasp_widths
from workbench.planners.tournassoud.chaining import NoSequence, Sequence, _pick2, _through, chain, nearest_sample
from workbench.planners.tournassoud.classes import GraspClass
from workbench.planners.tournassoud.table import GraspPlacementTable, reachable, rz
from workbench.robots.gripper import Gripper
from workbench.robots.model import Robot

APPROACH_STEP = 0.005
INSERT_STEP = 0.002


@dataclass
class Obstacle:
    """A mesh (metres, its own frame) at a pose in the world."""

    mesh: trimesh.Trimesh
    pose: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = "obstacle"

    def __post_init__(self) -> None:
        self.pose = np.asarray(self.pose, dtype=np.float64).reshape(4, 4)
        if len(self.mesh.faces) == 0 or not np.isfinite(self.mesh.vertices).all() or not np.isfinite(self.pose).all():
            raise WorkbenchError(f"obstacle {self.name}: the mesh is empty or its vertices or pose are not finite")

    def world_mesh(self) -> trimesh.Trimesh:
        """The mesh moved to its pose."""
        return self.mesh.copy().apply_transform(self.pose)


@dataclass
class TaskEnd:
    """One end of the task: the part resting in placement class `placement` at (x, y) with angle `phi` (radians)
    about the vertical, the obstacles there, and for the destination the insertion direction and depth."""

    placement: int
    x: float
    y: float
    phi: float = 0.0
    obstacles: list[Obstacle] = field(default_factory=list)
    insertion: np.ndarray | None = None
    depth: float = 0.0
    approach: float = 0.05

    def __post_init__(self) -> None:
        if not np.isfinite([self.x, self.y, self.phi, self.depth, self.approach]).all() or self.depth < 0 or self.approach < 0:
            raise WorkbenchError(f"task end at ({self.x}, {self.y}): position, angle, depth and approach must be finite, "
                                 f"depth and approach non-negative")
        if self.insertion is not None:
            d = np.asarray(self.insertion, dtype=np.float64).reshape(3)
            n = float(np.linalg.norm(d))
            if not np.isfinite(n) or n < 1e-9:
                raise WorkbenchError(f"insertion direction {self.insertion} must be a non-zero vector DX,DY,DZ")
            self.insertion = d / n

    def lift(self) -> np.ndarray | None:
        """(3,) the hand's move from the final pose back to the start of the insertion (world), None without one: the
        plan's last straight line runs it forwards, along the insertion direction for `depth`."""
        return None if self.insertion is None or self.depth <= 0 else -self.depth * self.insertion

    def as_dict(self) -> dict:
        """The end as JSON-ready values (angles in radians, obstacle poses row-major)."""
        return {"placement": int(self.placement), "x": float(self.x), "y": float(self.y), "phi": float(self.phi),
                "obstacles": [{"name": o.name, "pose": o.pose.reshape(-1).tolist()} for o in self.obstacles],
                "insertion": None if self.insertion is None else [float(v) for v in self.insertion],
                "depth": float(self.depth), "approach": float(self.approach)}

    def object_pose(self, table: GraspPlacementTable) -> np.ndarray:
        """The part in the world: translate(x, y) Rz(phi) P_j (as the table's placements at H)."""
        if not 0 <= self.placement < len(table.placements):
            raise WorkbenchError(f"placement {self.placement} does not exist: the table has placements "
                                 f"0..{len(table.placements) - 1}")
        frame = np.eye(4)
        frame[:2, 3] = self.x, self.y
        return frame @ rz(self.phi)[0] @ table.placements[self.placement]


def _sweeps(grasps: np.ndarray, end: TaskEnd) -> tuple[np.ndarray, np.ndarray]:
    """(approach poses (K, A, 4, 4), insertion poses (K, S, 4, 4)) of TCP poses (K, 4, 4) in the world."""
    n_a = int(np.ceil(end.approach / APPROACH_STEP - 1e-9)) + 1 if end.approach > 0 else 1
    back = np.linspace(0.0, end.approach, n_a)
    app = np.repeat(grasps[:, None], n_a, axis=1)
    app[..., :3, 3] -= back[None, :, None] * grasps[:, None, :3, 2]
    if end.insertion is None or end.depth <= 0:
        return app, grasps[:, None]
    n_s = int(np.ceil(end.depth / INSERT_STEP - 1e-9)) + 1
    ins = np.repeat(grasps[:, None], n_s, axis=1)
    ins[..., :3, 3] -= np.linspace(0.0, end.depth, n_s)[None, :, None] * end.insertion
    return app, ins


def end_mask(table: GraspPlacementTable, classes: list[GraspClass], end: TaskEnd, robot: Robot, gripper: Gripper,
             pregrasp_margin: float | None = PREGRASP_MARGIN) -> tuple[np.ndarray, dict[str, int]]:
    """(C, T) bool: the grasps legal at this end (see the module docstring), and how many legal-on-the-part samples
    each test refused ("table", "ik", "obstacles")."""
    c_n, t_n = table.hand_object.shape
    obj = end.object_pose(table)
    ok = table.hand_object & table.hand_table[:, end.placement, :]
    counts = {"table": int((table.hand_object & ~ok).sum())}
    ci, ti = np.nonzero(ok)
    tcp = np.array([obj @ classes[c].pose(table.theta[t]) for c, t in zip(ci, ti)]).reshape(-1, 4, 4)
    reach = reachable(robot, np.eye(4)[None], tcp, 20000, False).reshape(-1) if len(tcp) else np.zeros(0, dtype=bool)
    counts["ik"] = int((~reach).sum())
    ci, ti, tcp = ci[reach], ti[reach], tcp[reach]
    free = np.ones(len(ci), dtype=bool)
    if end.obstacles and len(ci):
        targets = [object_collider(o.mesh, o.pose) for o in end.obstacles]
        app, ins = _sweeps(tcp, end)
        hands: dict[int, tuple] = {}  # per class: the hand at the pre-grasp opening and at the grasp's
        for k in range(len(ci)):
            c = int(ci[k])
            if c not in hands:
                w = classes[c].opening
                pre = float(pregrasp_widths(np.array([w]), gripper.jaw_max, pregrasp_margin)[0])
                hands[c] = (bvh(gripper.collision_mesh(pre)), bvh(gripper.collision_mesh(min(w, gripper.jaw_max))))
            free[k] = not any(collide_at_poses(hands[c][0], app[k], target).any() or
                              collide_at_poses(hands[c][1], ins[k], target).any() for target in targets)
    counts["obstacles"] = int((~free).sum())
    out = np.zeros((c_n, t_n), dtype=bool)
    out[ci[free], ti[free]] = True
    return out, counts


def task_query(table: GraspPlacementTable, start: np.ndarray, goal: np.ndarray, pickup: TaskEnd,
               destination: TaskEnd) -> Sequence:
    """Fewest placements from the part held at the pick-up to the part held at the destination (Sections 5.1, 6):
    the first grasp in `start` ((C, T), legal at the pick-up), the last in `goal` (legal at the destination), the
    intermediate placements at the table point H. A placement-kind sequence whose first and last placements are the
    two ends (their nearest phi samples; `extra` holds their exact poses, "start_pose" and "goal_pose")."""
    t0 = time.perf_counter()
    if not start.any():
        raise NoSequence("no grasp is legal at the pick-up")
    if not goal.any():
        raise NoSequence("no grasp is legal at the destination")
    levels = chain(table, start, goal)
    if levels is None:
        raise NoSequence(f"no regrasp sequence from the {int(start.sum())} grasp sample(s) legal at the pick-up to the "
                         f"{int(goal.sum())} legal at the destination: the grasp-placement table does not connect them "
                         f"(try another table point, finer steps or --points)")
    cur = _pick2(levels[-1] & start)
    grasps, placements = [cur], [(pickup.placement, nearest_sample(table.phi, pickup.phi))]
    for prev in reversed(levels[:-1]):
        pl, cur = _through(table, cur, prev)
        placements.append(pl)
        grasps.append(cur)
    placements.append((destination.placement, nearest_sample(table.phi, destination.phi)))
    return Sequence("placement", grasps, placements, len(levels) - 1, time.perf_counter() - t0,
                    extra={"phi_start": float(pickup.phi), "phi_goal": float(destination.phi),
                           "start_pose": pickup.object_pose(table), "goal_pose": destination.object_pose(table),
                           "start_xy": (float(pickup.x), float(pickup.y)),
                           "goal_xy": (float(destination.x), float(destination.y)),
                           "goal_lift": destination.lift()})


def walls_around(part: trimesh.Trimesh, pose: np.ndarray, gap: float = 0.01, height: float | None = None,
                 thickness: float = 0.01, sides: str = "xy", name: str = "wall") -> list[Obstacle]:
    """Boxes standing on the table `gap` metres beside the part's bounding box at `pose` (world), along world x
    (sides containing "x": two walls facing it along x) and y: a tray's pocket ("xy") or a slot ("x" or "y"), the
    walls `height` tall (default: the part's height)."""
    lo, hi = part.copy().apply_transform(pose).bounds
    h = float(hi[2]) if height is None else float(height)
    out = []
    for axis in (0, 1):
        if "xy"[axis] not in sides:
            continue
        other = 1 - axis
        span = hi[other] - lo[other] + 2 * (gap + thickness)
        for sign, edge in ((-1, lo[axis] - gap - thickness / 2), (1, hi[axis] + gap + thickness / 2)):
            ext = np.zeros(3)
            ext[axis], ext[other], ext[2] = thickness, span, h
            centre = np.zeros(3)
            centre[axis], centre[other], centre[2] = edge, (lo[other] + hi[other]) / 2, h / 2
            box = trimesh.creation.box(ext)
            p = np.eye(4)
            p[:3, 3] = centre
            out.append(Obstacle(box, p, f"{name} {'-+'[sign > 0]}{'xy'[axis]}"))
    return out
