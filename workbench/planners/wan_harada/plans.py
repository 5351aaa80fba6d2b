"""Regrasp plans: the steps a robot executes, from a route through the regrasp graph (Wan & Harada, Section V, Fig. 8).

A plan with k regrasps has 2k + 2 steps: `pick` at the start pose with the first grasp; for each regrasp a
`transfer` (carry the object with the current grasp to a placement on the table at a position and yaw, put it
down and release it) and a `regrasp` (grasp it again at that placement with another grasp and lift it); and
`place` at the goal pose with the last grasp. Every step carries the object pose in the world, the grasp (TCP in
the object frame and in the world), the jaw width and five joint configurations, one per pose of the `ik` table
(the paper's ikret retractions): `q_approach` (handx: the TCP backed off along its approach axis), `q_grasp`,
`q_retract` (handxworldz: backed off, then raised by `worldz`), `q_worlda` (the grasp raised by `worlda` along
world z: the held part lifted straight off the table) and `q_worldaworldz` (raised by `worldz` more).

`PlanStep.waypoints()` orders them, as the reference implementation moves (the part only ever moves vertically
while it is near the table, whatever the grasp's approach direction):
- taking the part (pick, regrasp): handxworldz -> handx -> grasp (open) -> grasp (close) -> worlda -> worldaworldz;
- putting it down (transfer, place): worldaworldz -> worlda -> grasp (holding, lowered straight down) -> grasp
  (open) -> handx (backed off along the TCP's -z) -> handxworldz.

A plan is executable only with its motions (CONVENTIONS.md, Plans and motions): `segments` are its
timed motions in order (`robots.timing.TimedSegment`: kind, the step it serves, whether the object is held, start
time, knots t / q / qd; in the JSON and the store the knot times are plan time, from the plan's start), planned by
`planners.wan_harada.motions`; `removed` counts the roadmap nodes or query grips removed because their motions
failed, `acc` the acceleration limits used. The JSON carries them under "motion"; the store in the `plansegment`
table.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import trimesh

from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.search import Route, SearchResult
from workbench.robots.ik import WORLDA
from workbench.robots.timing import TimedSegment

KINDS = ("pick", "transfer", "regrasp", "place")
TAKE = ("pick", "regrasp")  # steps that close the hand on the resting part and lift it; the others put it down


@dataclass(frozen=True)
class Waypoint:
    """One configuration of a step: the `ik` pose it reaches (robots.ik.KINDS name), the joint vector, and whether the
    hand holds the part there (closed on it; the part moves with the hand)."""

    name: str
    q: np.ndarray
    holding: bool


@dataclass
class PlanStep:
    """One step: kind, grasp id, the stable placement and where it is (position, yaw), object pose (4, 4) in the world,
    TCP pose (4, 4) in the world at the grasp, grasp (4, 4) TCP in the object frame, jaw width, and joint vectors
    for the five `ik` poses (robot.joint_names order; see `waypoints`). `idtabletopgrips` is the roadmap row (None at
    the start and goal poses)."""

    kind: str
    idfreeairgrip: int
    idfreetabletopplacement: int
    position: np.ndarray
    yaw: float
    object_pose: np.ndarray
    tcp: np.ndarray
    grasp: np.ndarray
    jawwidth: float
    q_approach: np.ndarray
    q_grasp: np.ndarray
    q_retract: np.ndarray
    idtabletopgrips: int | None = None
    idtabletopplacements: int | None = None
    q_worlda: np.ndarray | None = None
    q_worldaworldz: np.ndarray | None = None
    lift: np.ndarray | None = None  # world TCP displacement grasp -> worlda; None: straight up by the plan's worlda

    def lift_vector(self, worlda: float) -> np.ndarray:
        """(3,) the TCP's move from the grasp to the worlda pose: `lift` (an insertion run backwards), else up by worlda."""
        return np.array([0.0, 0.0, worlda]) if self.lift is None else np.asarray(self.lift, dtype=np.float64).reshape(3)

    def as_dict(self) -> dict[str, Any]:
        out = {"kind": self.kind, "idfreeairgrip": int(self.idfreeairgrip), "idfreetabletopplacement": int(self.idfreetabletopplacement),
               "idtabletopgrips": None if self.idtabletopgrips is None else int(self.idtabletopgrips),
               "idtabletopplacements": None if self.idtabletopplacements is None else int(self.idtabletopplacements),
               "position": _list(self.position), "yaw": float(self.yaw), "object_pose": _list(self.object_pose),
               "tcp": _list(self.tcp), "grasp": _list(self.grasp), "jawwidth": float(self.jawwidth),
               "q_approach": _list(self.q_approach), "q_grasp": _list(self.q_grasp), "q_retract": _list(self.q_retract),
               "q_worlda": _list(self.q_worlda), "q_worldaworldz": _list(self.q_worldaworldz)}
        if self.lift is not None:
            out["lift"] = _list(self.lift)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "PlanStep":
        arr = lambda k, shape=None: np.asarray(d[k], dtype=np.float64) if shape is None else np.asarray(d[k], dtype=np.float64).reshape(shape)  # noqa: E731
        return cls(kind=d["kind"], idfreeairgrip=int(d["idfreeairgrip"]), idfreetabletopplacement=int(d["idfreetabletopplacement"]),
                   position=arr("position", (3,)), yaw=float(d["yaw"]), object_pose=arr("object_pose", (4, 4)), tcp=arr("tcp", (4, 4)),
                   grasp=arr("grasp", (4, 4)), jawwidth=float(d["jawwidth"]), q_approach=arr("q_approach"), q_grasp=arr("q_grasp"),
                   q_retract=arr("q_retract"), idtabletopgrips=d.get("idtabletopgrips"), idtabletopplacements=d.get("idtabletopplacements"),
                   q_worlda=arr("q_worlda") if d.get("q_worlda") is not None else None,
                   q_worldaworldz=arr("q_worldaworldz") if d.get("q_worldaworldz") is not None else None,
                   lift=arr("lift", (3,)) if d.get("lift") is not None else None)

    def configurations(self) -> dict[str, np.ndarray]:
        return {"approach": self.q_approach, "grasp": self.q_grasp, "retract": self.q_retract,
                "worlda": self.q_worlda, "worldaworldz": self.q_worldaworldz}

    def waypoints(self) -> list[Waypoint]:
        """The step's configurations in the order the hand visits them (module docstring): a pick or regrasp closes
        on the resting part, then lifts it straight up; a transfer or place lowers it straight down, opens, then
        backs off along the TCP's -z. The grasp appears twice: before and after the hand closes (or opens)."""
        empty = [Waypoint("handxworldz", self.q_retract, False), Waypoint("handx", self.q_approach, False),
                 Waypoint("grasp", self.q_grasp, False)]
        held = [Waypoint("grasp", self.q_grasp, True), Waypoint("worlda", self.q_worlda, True),
                Waypoint("worldaworldz", self.q_worldaworldz, True)]
        return empty + held if self.kind in TAKE else held[::-1] + empty[::-1]


@dataclass
class PlanObstacle:
    """A fixed obstacle of a plan's task (Tournassoud et al. 1987, Section 5.1): a mesh (metres, its own frame) at a
    world pose, at the task's `end` ("pickup" or "destination"); stored in `planobstacle`."""

    name: str
    end: str
    vertices: np.ndarray
    faces: np.ndarray
    pose: np.ndarray

    def mesh(self) -> trimesh.Trimesh:
        """The mesh in its own frame (not processed)."""
        return trimesh.Trimesh(np.asarray(self.vertices, dtype=np.float64), np.asarray(self.faces, dtype=np.int64), process=False)

    def as_dict(self) -> dict[str, Any]:
        return {"name": self.name, "end": self.end, "vertices": _list(self.vertices),
                "faces": np.asarray(self.faces, dtype=np.int64).tolist(), "pose": _list(self.pose)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "PlanObstacle":
        return cls(str(d["name"]), str(d["end"]), np.asarray(d["vertices"], dtype=np.float64).reshape(-1, 3),
                   np.asarray(d["faces"], dtype=np.int64).reshape(-1, 3), np.asarray(d["pose"], dtype=np.float64).reshape(4, 4))


@dataclass
class Plan:
    """A regrasp plan for one object and robot from a start to a goal pose (Section V); `rank` 0 is the best of a
    search, higher ranks its alternatives. `timings` holds the search's connect and search times and the motion
    planning time (s); `segments`, `removed`, `acc` and `speed` its timed motions (see the module docstring)."""

    object: str
    robot: str
    joint_names: list[str]
    start: PoseQuery
    goal: PoseQuery
    start_pose: np.ndarray
    goal_pose: np.ndarray
    steps: list[PlanStep]
    handx: float
    worldz: float
    rank: int = 0
    worlda: float = WORLDA
    timings: dict = field(default_factory=dict)
    ids: dict = field(default_factory=dict)
    segments: list[TimedSegment] = field(default_factory=list)
    removed: int = 0
    acc: list[float] = field(default_factory=list)
    speed: float = 1.0  # the share of the URDF's joint velocity limits the motions were timed under
    planner: str = "wan_harada"
    start_held: bool = False  # the motions begin with the part already in the hand at the first step's grasp
    end_held: bool = False  # they end with it still in the hand at the last step's grasp (Tournassoud Fig. 1 (a), (d))
    obstacles: list[PlanObstacle] = field(default_factory=list)  # the task's, fixed in the world
    insertion: np.ndarray | None = None  # the final insertion's direction (world, unit); its move is the last step's lift
    insertion_depth: float = 0.0

    def obstacle_pairs(self) -> tuple:
        """The obstacles as (mesh, world pose) pairs, as the motion checker and the validators take them."""
        return tuple((o.mesh(), np.asarray(o.pose, dtype=np.float64)) for o in self.obstacles)

    @property
    def duration(self) -> float:
        """Length of the timed trajectory (s); 0 without motions."""
        return (self.segments[-1].t0 + self.segments[-1].duration) if self.segments else 0.0

    @property
    def regrasps(self) -> int:
        return sum(s.kind == "regrasp" for s in self.steps)

    @property
    def transfers(self) -> int:
        return sum(s.kind in ("transfer", "place") for s in self.steps)

    @property
    def grasps(self) -> list[int]:
        """The free-air grasp ids used, in order."""
        return [s.idfreeairgrip for s in self.steps if s.kind in ("pick", "regrasp")]

    def as_dict(self) -> dict[str, Any]:
        return {"planner": self.planner, "object": self.object, "robot": self.robot, "joint_names": list(self.joint_names),
                "start": self.start.as_dict(), "goal": self.goal.as_dict(), "start_pose": _list(self.start_pose),
                "goal_pose": _list(self.goal_pose), "handx": self.handx, "worldz": self.worldz, "worlda": self.worlda, "rank": self.rank,
                "regrasps": self.regrasps, "transfers": self.transfers, "timings": {k: float(v) for k, v in self.timings.items()},
                "ids": {k: int(v) for k, v in self.ids.items()}, "steps": [s.as_dict() for s in self.steps],
                "motion": {"duration": self.duration, "removed": self.removed, "acc": [float(a) for a in self.acc],
                           "speed": float(self.speed), "segments": [s.as_dict() for s in self.segments]},
                "start_held": self.start_held, "end_held": self.end_held, "obstacles": [o.as_dict() for o in self.obstacles],
                "insertion": _list(self.insertion), "insertion_depth": float(self.insertion_depth)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Plan":
        q = lambda v: PoseQuery(int(v["placement"]), float(v["x"]), float(v["y"]), float(v["yaw"]))  # noqa: E731
        return cls(object=d["object"], robot=d["robot"], joint_names=list(d["joint_names"]), start=q(d["start"]), goal=q(d["goal"]),
                   start_pose=np.asarray(d["start_pose"], dtype=np.float64).reshape(4, 4),
                   goal_pose=np.asarray(d["goal_pose"], dtype=np.float64).reshape(4, 4),
                   steps=[PlanStep.from_dict(s) for s in d["steps"]], handx=float(d["handx"]), worldz=float(d["worldz"]),
                   worlda=float(d.get("worlda", WORLDA)),
                   rank=int(d.get("rank", 0)), timings=dict(d.get("timings", {})), ids=dict(d.get("ids", {})),
                   segments=[TimedSegment.from_dict(s) for s in (d.get("motion") or {}).get("segments", [])],
                   removed=int((d.get("motion") or {}).get("removed", 0)), acc=list((d.get("motion") or {}).get("acc", [])),
                   speed=float((d.get("motion") or {}).get("speed", 1.0)),
                   planner=str(d.get("planner", "wan_harada")), start_held=bool(d.get("start_held", False)),
                   end_held=bool(d.get("end_held", False)),
                   obstacles=[PlanObstacle.from_dict(o) for o in d.get("obstacles") or []],
                   insertion=None if d.get("insertion") is None else np.asarray(d["insertion"], dtype=np.float64).reshape(3),
                   insertion_depth=float(d.get("insertion_depth") or 0.0))

    def to_json(self, path: str | Path | None = None) -> str:
        """The plan as JSON (written to `path` when given)."""
        text = json.dumps(self.as_dict(), indent=1)
        if path is not None:
            out = Path(path)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.write_text(text)
        return text

    @classmethod
    def from_json(cls, path_or_text: str | Path) -> "Plan":
        text = str(path_or_text)
        if not text.lstrip().startswith("{"):
            text = Path(path_or_text).read_text()
        return cls.from_dict(json.loads(text))

    def lines(self) -> list[str]:
        """Human-readable steps."""
        out = []
        for i, s in enumerate(self.steps):
            where = "start" if i == 0 else ("goal" if i == len(self.steps) - 1 else f"placement {s.idfreetabletopplacement}")
            out.append(f"{i + 1:2d}. {s.kind:8s} grasp {s.idfreeairgrip:<6d} {where:14s} at x {s.position[0]:+.3f} y {s.position[1]:+.3f} "
                       f"yaw {np.degrees(s.yaw):+7.1f} deg  jaw {s.jawwidth * 1000:5.1f} mm")
        return out

    def summary(self) -> str:
        t = self.timings
        gs = t.get("connect", 0.0) + t.get("search", 0.0)
        motion = (f"; motions {t.get('motion', 0.0):.2f} s, trajectory {self.duration:.1f} s, {self.removed} removed"
                  if self.segments else "; no motions")
        return (f"{self.object} with {self.robot}: {self.regrasps} regrasp(s), {self.transfers} transfer(s), {len(self.steps)} steps; "
                f"connect {t.get('connect', 0.0) * 1000:.1f} ms + search {t.get('search', 0.0) * 1000:.1f} ms = {gs * 1000:.1f} ms{motion}")


def _list(a: Any) -> Any:
    return None if a is None else np.asarray(a, dtype=np.float64).tolist()


def inverse_pose(m: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform."""
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def step_from_side(kind: str, side, k: int) -> PlanStep:
    """A pick (start) or place (goal) step from grip `k` of a query side."""
    q = side.joints[k]
    return PlanStep(kind=kind, idfreeairgrip=int(side.grasp[k]), idfreetabletopplacement=int(side.query.idfreetabletopplacement),
                    position=np.array([side.query.x, side.query.y, 0.0]), yaw=float(side.query.yaw), object_pose=side.pose.copy(),
                    tcp=side.tcp[k].copy(), grasp=inverse_pose(side.pose) @ side.tcp[k], jawwidth=float(side.jawwidth[k]),
                    q_approach=q[1].copy(), q_grasp=q[0].copy(), q_retract=q[2].copy(), q_worlda=q[3].copy(),
                    q_worldaworldz=q[4].copy())


def step_from_node(kind: str, roadmap, a: int) -> PlanStep:
    """A transfer or regrasp step at roadmap node `a`."""
    q = roadmap.joints[a]
    return PlanStep(kind=kind, idfreeairgrip=int(roadmap.idfreeairgrip[a]), idfreetabletopplacement=int(roadmap.idfreetabletopplacement[a]),
                    position=roadmap.position[a].copy(), yaw=float(roadmap.yaw[a]), object_pose=roadmap.placement[a].copy(),
                    tcp=roadmap.tcp[a].copy(), grasp=inverse_pose(roadmap.placement[a]) @ roadmap.tcp[a], jawwidth=float(roadmap.jawwidth[a]),
                    q_approach=q[1].copy(), q_grasp=q[0].copy(), q_retract=q[2].copy(), q_worlda=q[3].copy(),
                    q_worldaworldz=q[4].copy(), idtabletopgrips=int(roadmap.idtabletopgrips[a]), idtabletopplacements=int(roadmap.idtabletopplacements[a]))


def make_plan(planner, result: SearchResult, route: Route, rank: int = 0) -> Plan:
    """The steps of one route of a search (pick, transfer / regrasp per regrasp, place)."""
    steps = [step_from_side("pick", result.start, route.start_grip)]
    for a, b in route.regrasps:
        steps.append(step_from_node("transfer", planner.roadmap, a))
        steps.append(step_from_node("regrasp", planner.roadmap, b))
    steps.append(step_from_side("place", result.goal, route.goal_grip))
    return Plan(object=planner.object.name, robot=planner.robot.name, joint_names=list(planner.robot.joint_names),
                start=result.start.query, goal=result.goal.query, start_pose=result.start.pose.copy(), goal_pose=result.goal.pose.copy(),
                steps=steps, handx=planner.handx, worldz=planner.worldz, worlda=planner.worlda, rank=rank, timings=dict(result.timings), ids=dict(planner.ids))


def obstacles_digest(obstacles: list[PlanObstacle]) -> str | None:
    """A digest of a plan's obstacles (ends, names, meshes, poses), None without any: plans answering the same
    query among other obstacles are other plans."""
    if not obstacles:
        return None
    h = hashlib.sha256()
    for o in obstacles:
        h.update(f"{o.end}\0{o.name}\0".encode())
        for a, t in ((o.vertices, np.float64), (o.faces, np.int64), (o.pose, np.float64)):
            h.update(np.ascontiguousarray(a, dtype=t).tobytes())
    return h.hexdigest()


def obstacle_rows(plan: Plan) -> dict[str, Any]:
    """The `planobstacle` columns of a plan's obstacles (empty lists without any)."""
    o = plan.obstacles
    return {"seq": np.arange(len(o), dtype=np.int32), "task_end": np.array([x.end for x in o], dtype=object),
            "name": np.array([x.name for x in o], dtype=object),
            "vertices": pa.array([np.asarray(x.vertices, dtype=np.float64).tolist() for x in o],
                                 type=pa.list_(pa.list_(pa.float64(), 3))),
            "faces": pa.array([np.asarray(x.faces, dtype=np.int64).tolist() for x in o], type=pa.list_(pa.list_(pa.int32(), 3))),
            "pose": np.array([np.asarray(x.pose, dtype=np.float64).ravel() for x in o]).reshape(len(o), 16)}


def plan_rows(plan: Plan) -> tuple[dict, dict, dict]:
    """The `plan` row, the `planstep` columns and the `plansegment` columns of a plan (written by `stages.save_plan`)."""

    ids = plan.ids
    row = {"idobject": ids["idobject"], "idrobot": ids["idrobot"], "idscene": ids["idscene"], "idikret": ids["idikret"],
           "idtabletop": ids["idtabletop"], "start_placement": plan.start.idfreetabletopplacement,
           "start_xyyaw": [plan.start.x, plan.start.y, plan.start.yaw], "goal_placement": plan.goal.idfreetabletopplacement,
           "goal_xyyaw": [plan.goal.x, plan.goal.y, plan.goal.yaw], "rank": plan.rank, "regrasps": plan.regrasps,
           "transfers": plan.transfers, "t_connect": plan.timings.get("connect"), "t_search": plan.timings.get("search"),
           "duration": plan.duration if plan.segments else None, "removed": plan.removed,
           "t_motion": plan.timings.get("motion"), "acc": [float(a) for a in plan.acc] or None,
           "speed": float(plan.speed) if plan.segments else None, "planner": plan.planner,
           "start_held": bool(plan.start_held), "end_held": bool(plan.end_held), "insertion": _list(plan.insertion),
           "insertion_depth": float(plan.insertion_depth) if plan.insertion is not None else None,
           "obstacles": obstacles_digest(plan.obstacles)}
    s = plan.steps

    steps = {"seq": np.arange(len(s), dtype=np.int32), "kind": np.array([x.kind for x in s], dtype=object),
             "idfreeairgrip": np.array([x.idfreeairgrip for x in s], dtype=np.int64),
             "idfreetabletopplacement": np.array([x.idfreetabletopplacement for x in s], dtype=np.int64),
             "idtabletopgrips": pa.array([x.idtabletopgrips for x in s], type=pa.int64()),
             "position": np.array([x.position for x in s]), "yaw": np.array([x.yaw for x in s]),
             "object": np.array([x.object_pose.ravel() for x in s]), "tcp": np.array([x.tcp.ravel() for x in s]),
             "jawwidth": np.array([x.jawwidth for x in s]),
             "jnt_approach": pa.array([x.q_approach.tolist() for x in s], type=pa.list_(pa.float64())),
             "jnt_grasp": pa.array([x.q_grasp.tolist() for x in s], type=pa.list_(pa.float64())),
             "jnt_retract": pa.array([x.q_retract.tolist() for x in s], type=pa.list_(pa.float64())),
             "jnt_worlda": pa.array([None if x.q_worlda is None else x.q_worlda.tolist() for x in s], type=pa.list_(pa.float64())),
             "jnt_worldaworldz": pa.array([None if x.q_worldaworldz is None else x.q_worldaworldz.tolist() for x in s],
                                         type=pa.list_(pa.float64())),
             "lift": pa.array([None if x.lift is None else np.asarray(x.lift, dtype=np.float64).ravel().tolist() for x in s],
                              type=pa.list_(pa.float64()))}
    g = plan.segments
    flat = lambda a: pa.array([np.asarray(a(x), dtype=np.float64).ravel().tolist() for x in g], type=pa.list_(pa.float64()))  # noqa: E731
    segments = {"seq": np.arange(len(g), dtype=np.int32), "kind": np.array([x.kind for x in g], dtype=object),
                "caption": np.array([x.caption for x in g], dtype=object), "step": np.array([x.step for x in g], dtype=np.int32),
                "holding": np.array([x.holding for x in g], dtype=bool), "t0": np.array([x.t0 for x in g], dtype=np.float64),
                "duration": np.array([x.duration for x in g], dtype=np.float64),
                "method": np.array([x.method for x in g], dtype=object), "jaw": np.array([x.jaw for x in g], dtype=np.float64),
                "t": flat(lambda x: x.t0 + x.traj.t), "q": flat(lambda x: x.traj.q), "qd": flat(lambda x: x.traj.qd)}
    return row, steps, segments
