"""meshcat animation of a regrasp plan: robot, gripper and object through every step (Wan & Harada, Section V,
Figs. 11-12), exported as static HTML that opens without a server.

The robot and the planning gripper (at the step's jaw opening) are drawn by `workbench.viewer.robot.RobotView`
from the URDF's visual (or collision) meshes, the robot's own hand replaced by the planning gripper.
A plan with motions plays its timed trajectory at its real speed (`timed_frames`: frames at `fps` per
second of plan time); a plan without motions plays its waypoints joined by straight joint lines (`keyframes`, not a
motion a robot could execute). The object rests at its pose or follows the TCP while held. Start (yellow) and goal
(blue) poses stay as ghosts, intermediate placements as faint outlines. `PlanView` sends that scene once and plays
any plan in it by transforms. The caption naming the step playing and its footer come from one track
(`caption_track`) and are HTML over the canvas (`plan_overlay` in a static page, `view(vis, captions=True)` live),
never panels in the scene.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import meshcat
import meshcat.animation as manim
import numpy as np
import trimesh

from workbench.grasping.naming import per_part_numbers
from workbench.planners.wan_harada.plans import inverse_pose
from workbench.robots.chain import forward
from workbench.robots.timing import TimedSegment
from workbench.viewer.captions import CAPTION_SCRIPT, CAPTION_TEXT
from workbench.viewer.live import Switches, transform_animation
from workbench.viewer.robot import RobotView
from workbench.viewer.scenes import (
    frame_points,
    new_scene,
    palette,
    show_mesh,
    show_points,
    static_html,
)

OBJECT_COLOR, START_COLOR, GOAL_COLOR, TABLE_COLOR = 0xE0A030, 0xF0D040, 0x3366DD, 0x8B6B4A
SIMULATED_COLOR = 0xD03060  # the part as MuJoCo moved it (`workbench simulate`), beside the planned one


def keyframes(plan, frames_move: int = 14, frames_line: int = 7, frames_jaw: int = 5,
              jaw_open: float | None = None) -> list[dict]:
    """The animation as a list of frames: joint vector `q`, jaw opening (`jaw_open` when open: the planned gripper's
    full opening, default the widest grasp), whether the object is held, its pose when resting, the grasp (TCP in the
    object frame) when held, and the plan step playing (-1 before the first)."""
    out: list[dict] = []
    steps = plan.steps
    if not steps:
        return out
    jaw_open = max(s.jawwidth for s in steps) if jaw_open is None else jaw_open
    q = np.asarray(steps[0].waypoints()[0].q, dtype=np.float64)
    held, rest, grasp = False, np.asarray(plan.start_pose, dtype=np.float64), np.eye(4)

    def line(q0: np.ndarray, q1: np.ndarray, n: int, jaw: float) -> None:
        for t in np.linspace(0.0, 1.0, n + 1)[1:]:
            out.append({"q": (1 - t) * q0 + t * q1, "jaw": jaw, "held": held, "rest": rest, "grasp": grasp, "step": k})

    k = -1  # the plan step playing, recorded in every frame
    out.append({"q": q, "jaw": jaw_open, "held": False, "rest": rest, "grasp": grasp, "step": k})
    for k, s in enumerate(steps):  # waypoints in order (PlanStep.waypoints): the part moves vertically near the table
        wps = s.waypoints()
        for n_wp, wp in enumerate(wps):
            qw = np.asarray(wp.q, dtype=np.float64)
            if wp.holding != held:  # the hand closes on the part (or opens) at the grasp configuration
                if wp.holding:
                    held, grasp = True, np.asarray(s.grasp, dtype=np.float64)
                    jaws = np.linspace(jaw_open, s.jawwidth, frames_jaw)
                else:
                    held, rest = False, np.asarray(s.object_pose, dtype=np.float64)
                    jaws = np.linspace(s.jawwidth, jaw_open, frames_jaw)
                for w in jaws:
                    out.append({"q": qw, "jaw": float(w), "held": held, "rest": rest, "grasp": grasp, "step": k})
                continue
            line(q, qw, frames_move if n_wp == 0 else frames_line, s.jawwidth if held else jaw_open)
            q = qw
    return out


MOVES_TO_NEXT = ("transfer", "transit")  # motions from one step's pose to the next step's: they serve the next step


def timed_frames(plan, segments: list[TimedSegment], tcp_pose, fps: float = 30.0, jaw_open: float | None = None) -> list[dict]:
    """Frames of a timed plan at `fps` frames per second of plan time (a player at `fps` plays the motion at its real
    speed): t, q, jaw, held, object (4x4 world pose), caption (the step: pick, transfer, release, regrasp, place) and
    segment index. `tcp_pose(q)` gives the TCP pose in the world (the robot's forward kinematics)."""
    if not segments:
        return []
    jaw_open = max((s.jawwidth for s in plan.steps), default=0.0) if jaw_open is None else jaw_open
    total = segments[-1].t0 + segments[-1].duration
    times = np.arange(0.0, total + 0.5 / fps, 1.0 / fps)
    times[-1] = min(times[-1], total)
    ends = np.array([sg.t0 + sg.duration for sg in segments])
    # each frame's segment: the first one not yet over at its time (segments of no frame are passed over)
    which = np.minimum(np.searchsorted(ends + 1e-9, times, side="left"), len(segments) - 1)
    local = np.empty(len(times))
    q = np.empty((len(times), len(segments[0].traj.q[0])))
    for k in np.unique(which):
        at = which == k
        seg = segments[k]
        local[at] = np.clip(times[at] - seg.t0, 0.0, seg.duration)
        q[at] = seg.traj.sample(local[at])[0]
    out = []
    for i, t in enumerate(times):
        k = int(which[i])
        seg = segments[k]
        if seg.kind == "gripper":  # the jaw acts from the opening of the move before it (the pre-grasp one)
            jaw_before = segments[k - 1].jaw if k > 0 else jaw_open
            f = local[i] / seg.duration if seg.duration > 0 else 1.0
            jaw = (1 - f) * jaw_before + f * seg.jaw
        else:
            jaw = seg.jaw
        step = plan.steps[seg.step]
        if seg.holding:
            obj = tcp_pose(q[i]) @ inverse_pose(np.asarray(step.grasp, dtype=np.float64))
        else:
            obj = np.asarray(step.object_pose, dtype=np.float64)
        out.append({"t": float(t), "q": q[i], "jaw": float(jaw), "held": bool(seg.holding), "object": obj, "caption": seg.caption,
                    "segment": k, "step": min(int(seg.step) + (seg.kind in MOVES_TO_NEXT), len(plan.steps) - 1)})
    return out


def plan_frames(plan, robot, fps: int = 30) -> list[dict]:
    """The frames `show_plan` animates, one per 1/fps s of plan time when the plan has timed motions (`timed_frames`),
    else its waypoint keyframes; each with q, jaw, held, object (4x4 world pose) and step (index in plan.steps of the
    step it serves: a transfer or transit serves the step it goes to)."""
    if plan.segments:
        return timed_frames(plan, plan.segments, robot.tcp_pose, fps, jaw_open=robot.gripper.jaw_max)
    frames = keyframes(plan, jaw_open=robot.gripper.jaw_max)
    for fr in frames:
        fr["object"] = robot.tcp_pose(fr["q"]) @ inverse_pose(fr["grasp"]) if fr["held"] else fr["rest"]
    return frames


PLAN_VIEW = np.array([0.35, -0.9, 0.6])
"""World direction toward the camera of a plan: from the side of the arm's reach, so that the arm stands beside the
part rather than in front of it."""


class PlanView:
    """A plan's scene, sent once per robot and part: the table, the robot, the part, its start and goal ghosts and
    ghosts for intermediate placements (more are sent only when a plan needs more). `play(plan)` then only moves
    them and sets the animation, so a new search or another alternative sends no geometry."""

    def __init__(self, vis: meshcat.Visualizer, robot, obj_mesh: trimesh.Trimesh, table: tuple | None = None,
                 path: str = "plan", kind: str = "visual", ghosts: int = 4):
        self.vis, self.robot, self.mesh, self.path = vis, robot, obj_mesh, path
        self.switches = Switches(vis)
        vis[path].delete()
        if table is not None:
            (x0, y0), (x1, y1), thick = table
            box = trimesh.creation.box(extents=(x1 - x0, y1 - y0, thick))
            box.apply_translation(((x0 + x1) / 2, (y0 + y1) / 2, -thick / 2))
            show_mesh(vis, f"{path}/table", box, color=TABLE_COLOR, opacity=0.5)
        show_mesh(vis, f"{path}/start", obj_mesh, color=START_COLOR, opacity=0.35)
        show_mesh(vis, f"{path}/goal", obj_mesh, color=GOAL_COLOR, opacity=0.35)
        show_mesh(vis, f"{path}/object", obj_mesh, color=OBJECT_COLOR)
        self.ghosts, self.simulated = 0, False
        self._more_ghosts(ghosts)
        self.robot_view = RobotView(vis, robot, f"{path}/robot", kind)

    def _more_ghosts(self, n: int) -> None:
        while self.ghosts < n:
            show_mesh(self.vis, f"{self.path}/placements/{self.ghosts}", self.mesh, color=0x999999, opacity=0.15)
            self.switches.show(f"{self.path}/placements/{self.ghosts}", False)
            self.ghosts += 1

    def play(self, plan, fps: int = 30, frames: list[dict] | None = None, numbers: dict[int, int] | None = None,
             simulated: tuple[np.ndarray, np.ndarray] | None = None) -> manim.Animation:
        """Move the ghosts to the plan's poses and attach its animation (looped); `frames`: `plan_frames(plan, robot,
        fps)` when the caller has them already; `simulated`: (t, poses (K, 4, 4)), the part as a physics replay moved
        it, played beside the planned part (a timed plan only). The caption track (`caption_track`, placements named
        by `numbers`) rides along as a property of the scene's /Captions node, for the live view's overlay."""
        path, vis, sw = self.path, self.vis, self.switches
        sw.move(f"{path}/start", plan.start_pose)
        sw.move(f"{path}/goal", plan.goal_pose)
        between = plan.steps[1:-1:2]
        self._more_ghosts(len(between))
        for i in range(self.ghosts):
            if i < len(between):
                sw.move(f"{path}/placements/{i}", between[i].object_pose)
            sw.show(f"{path}/placements/{i}", i < len(between))
        frames = plan_frames(plan, self.robot, fps) if frames is None else frames
        tracks: dict[str, list] = {f"{path}/object": [fr["object"] for fr in frames]}
        if simulated is not None and plan.segments:
            if not self.simulated:
                show_mesh(vis, f"{path}/simulated", self.mesh, color=SIMULATED_COLOR, opacity=0.6)
                self.simulated = True
            t_sim, p_sim = simulated
            at = np.clip(np.searchsorted(t_sim, np.arange(len(frames)) / fps), 0, len(t_sim) - 1)
            tracks[f"{path}/simulated"] = list(np.asarray(p_sim)[at])
        if self.simulated:
            sw.show(f"{path}/simulated", simulated is not None and bool(plan.segments))
        for fr in frames:
            for name, m in self.robot_view.poses(fr["q"], fr["jaw"]).items():
                tracks.setdefault(name, []).append(m)
        anim = transform_animation(vis, {k: np.array(v) for k, v in tracks.items()}, fps)
        if frames:  # the first frame as the scene's static state (shown before playing)
            self.robot_view.show(frames[0]["q"], frames[0]["jaw"])
            vis[f"{path}/object"].set_transform(plan.start_pose)
        vis["/Captions"].set_property("workbench_captions", caption_track(plan, frames, fps, numbers))
        vis.set_animation(anim, play=True, repetitions=1000)
        return anim


def show_plan(vis: meshcat.Visualizer, plan, robot, obj_mesh: trimesh.Trimesh, table: tuple | None = None, fps: int = 30,
              path: str = "plan", kind: str = "visual", frames: list[dict] | None = None,
              simulated: tuple[np.ndarray, np.ndarray] | None = None) -> manim.Animation:
    """Draw the plan's scene under `path` and attach its animation to `vis` (looped). The robot and the planning
    gripper are drawn by `workbench.viewer.robot.RobotView` (`kind`: the URDF's visual or collision meshes);
    `frames`: `plan_frames(plan, robot, fps)` when the caller has them already. `simulated`: (t, poses (K, 4, 4)),
    the part as a physics replay moved it, played beside the planned part (a timed plan only)."""
    return PlanView(vis, robot, obj_mesh, table, path, kind).play(plan, fps, frames, simulated=simulated)


def frame_plan(vis: meshcat.Visualizer, plan, robot) -> None:
    """Camera on the work: every pose the part takes (start, placements, goal), the table patch around them and the
    arm's joints along the plan (so that a large arm stays in view as well as a small one)."""
    parts = [plan.start_pose[:3, 3], plan.goal_pose[:3, 3], robot.base[:3, 3]]
    parts += [np.asarray(s.object_pose)[:3, 3] for s in plan.steps]
    parts = np.vstack(parts)
    patch = np.vstack([parts[:, :2].min(0) - 0.1, parts[:, :2].max(0) + 0.1])
    patch = np.column_stack([patch, np.zeros(2)])
    frame_points(vis, np.vstack([parts, patch, arm_reach(plan, robot)]), PLAN_VIEW)


def arm_reach(plan, robot) -> np.ndarray:
    """(K, 3) world positions of the arm's joints and TCP along the plan: at its trajectories' knots, or at its
    waypoints when it has no timed motion (batched forward kinematics)."""
    if plan.segments:
        qs = np.vstack([s.traj.q for s in plan.segments])
    else:
        qs = np.array([fr["q"] for fr in keyframes(plan, frames_move=1, frames_line=1, frames_jaw=1)])
    if len(qs) == 0:  # a plan without steps: the arm is not drawn moving
        return robot.base[None, :3, 3]
    _, joints, _, tcp = forward(robot, qs)
    return np.vstack([joints.reshape(-1, 3), tcp])


STEP_NAMES = {"pick": "pick", "transfer": "release", "regrasp": "regrasp", "place": "place"}
"""A plan step by what the hand does there (a "transfer" step puts the part down at an intermediate placement)."""


def caption_track(plan, frames: list[dict], fps: int = 30, numbers: dict[int, int] | None = None) -> dict:
    """The one source of every caption of a plan's animation: per frame, the index of the text naming its step
    (`steps`: 0 before the first step, k for step k), the texts (`captions`: "step k of n: what the hand does"),
    the footers (`footers`: the same step's grasp, pose and jaw; placements by their number within the part,
    `numbers`: store id -> number, else by store id), and the frame rate."""
    n = len(plan.steps)
    numbers = numbers or {}
    captions = ["start: the part at its start pose, the robot at its first retract configuration"]
    footers = ["start"]
    for i, s in enumerate(plan.steps):
        where = "start" if i == 0 else ("goal" if i == n - 1 else f"placement {numbers.get(int(s.idfreetabletopplacement), s.idfreetabletopplacement)}")
        what = CAPTION_TEXT[STEP_NAMES.get(s.kind, s.kind)] if STEP_NAMES.get(s.kind, s.kind) in CAPTION_TEXT else s.kind
        captions.append(f"step {i + 1} of {n}: {what}")
        footers.append(f"step {i + 1} of {n}: {STEP_NAMES.get(s.kind, s.kind)} with grasp {s.idfreeairgrip} at {where}, "
                       f"x {s.position[0]:+.3f} m, y {s.position[1]:+.3f} m, yaw {np.degrees(s.yaw):+.1f} deg, "
                       f"jaw {s.jawwidth * 1000:.1f} mm")
    return {"steps": [int(f["step"]) + 1 for f in frames], "captions": captions, "footers": footers, "fps": fps}


def scene_table(planner) -> tuple:
    """(table_min, table_max, thickness) of the planner's scene."""
    s = planner.scene
    return tuple(s.table_min), tuple(s.table_max), float(s.table_thickness)


def plan_scene(plan, planner, out: str | Path | None = None, vis: meshcat.Visualizer | None = None,
               kind: str = "collision", simulated: tuple[np.ndarray, np.ndarray] | None = None) -> Path | meshcat.Visualizer:
    """The plan's animation in a meshcat scene (a new one unless `vis`); written as static HTML when `out` is given
    (returns its path), else the visualizer is returned. `kind`: the robot's collision meshes (a file of a few MB)
    or its visual meshes (nicer, about 15 MB for the Panda). `simulated`: the part's poses in a physics replay
    (t, poses), played beside the planned part."""
    if vis is None:
        vis = new_scene()
    frames = plan_frames(plan, planner.robot)  # the animation's, and the page caption's clock
    numbers = per_part_numbers(planner.free["idfreetabletopplacement"])
    PlanView(vis, planner.robot, planner.object.mesh, scene_table(planner), kind=kind).play(
        plan, frames=frames, numbers=numbers, simulated=simulated)
    frame_plan(vis, plan, planner.robot)
    if out is None:
        return vis
    title = plan_title(plan.object, planner.robot)
    path = static_html(vis, out, title)
    page = path.read_text()
    path.write_text(page.replace("</body>", plan_overlay(caption_track(plan, frames, numbers=numbers),
                                                         simulated=simulated is not None, title=title) + "</body>", 1))
    return path


def plan_title(part: str, robot) -> str:
    """What a plan page shows: the part, the robot and its planning gripper."""
    return f"{part} · {robot.name} · {robot.gripper.name}"


def plan_overlay(track: dict, simulated: bool = False, title: str | None = None) -> str:
    """HTML for a static plan page: the `title` (part, robot, gripper) over a colour key (top left; `simulated`: it
    names the part in physics), the caption naming the step playing (under the key) and its footer (bottom), both
    read from `caption_track` at the meshcat animation's clock."""
    keys = KEY[:1] + (((SIMULATED_COLOR, "the part in physics"),) if simulated else ()) + KEY[1:]
    legend = "".join(f"<span style='margin-right:12px;white-space:nowrap'><span style='display:inline-block;width:11px;"
                     f"height:11px;margin-right:4px;border:1px solid #555;background:#{c:06x}'></span>{t}</span>"
                     for c, t in keys)
    box = "position:fixed;left:0;background:rgba(255,255,255,.88);font:14px sans-serif;padding:6px 12px;z-index:10"
    head = f"<b id='wb-title' style='font-size:15px'>{html.escape(title)}</b><br>" if title else ""
    return (f"<div id='wb-legend' style='{box};top:0'>{head}{legend}<br><b id='wb-caption' style='font-size:16px'>"
            f"{html.escape(track['captions'][0])}</b></div>"
            f"<div id='wb-footer' style='{box};bottom:0;right:0;font-size:13px'>{html.escape(track['footers'][0])}</div>"
            f"<script>{CAPTION_SCRIPT.replace('TRACK', json.dumps(track))}</script>")


KEY = ((OBJECT_COLOR, "the part"), (START_COLOR, "start pose"), (GOAL_COLOR, "goal pose"),
       (0x999999, "intermediate placements"), (TABLE_COLOR, "table"))


def show_roadmap(vis: meshcat.Visualizer, planner, result=None, path: str = "roadmap", limit: int = 20000) -> dict:
    """The regrasp graph's nodes as points at their object positions, lifted by component (grey shades, one layer
    per component), with the roadmap nodes the start grips attach to (transfer edges) in yellow and the goal's in
    blue; returns the attach summaries."""

    rm = planner.roadmap
    vis[path].delete()
    if rm.n_nodes == 0:
        return {}
    pick = np.unique(np.linspace(0, rm.n_nodes - 1, min(limit, rm.n_nodes)).astype(int))
    pts = rm.tcp[pick, :3, 3]
    colors = palette(max(rm.n_components, 1))[rm.component[pick] % max(rm.n_components, 1)]
    show_points(vis, f"{path}/nodes", pts, colors, size=0.004)
    out = {}
    if result is not None:
        for side, color in ((result.start, START_COLOR), (result.goal, GOAL_COLOR)):
            att = planner.attach(side)
            out[side.label] = att
            nodes = att["nodes"]
            show_points(vis, f"{path}/{side.label}", rm.tcp[nodes, :3, 3] + [0, 0, 0.002], color, size=0.007)
    return out
