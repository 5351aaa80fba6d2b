"""meshcat animation of a regrasp plan: robot, gripper and object through every step (Wan & Harada, Section V,
Figs. 11-12), exported as static HTML that opens without a server.

The robot and the planning gripper (at the step's jaw opening) are drawn by `workbench.viewer.robot.RobotView`
from the URDF's visual (or collision) meshes, the robot's own hand replaced by the planning gripper.
A plan with motions plays its timed trajectory at its real speed (`timed_frames`: frames at `fps` per
second of plan time), with a caption naming the current step (pick, transfer, release, regrasp, place) and a colour
key; a plan without motions plays its waypoints joined by straight joint lines (`keyframes`, not a motion a robot
could execute). The object rests at its pose or follows the TCP while held. Start (yellow) and goal (blue) poses
stay as ghosts, intermediate placements as faint outlines.
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import meshcat
import meshcat.animation as manim
import numpy as np
import trimesh

from workbench.planners.wan_harada.plans import inverse_pose
from workbench.robots.chain import forward
from workbench.robots.timing import TimedSegment
from workbench.viewer.captions import add_overlays, overlay_corners
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
CAMERA_DIR = np.array([0.8, -0.8, 0.0]) / np.hypot(0.8, 0.8)
"""Horizontal direction from the scene toward `frame_camera`'s default camera (captions face it)."""


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
    out = []
    k = 0
    jaw_before = jaw_open
    for t in times:
        while k + 1 < len(segments) and t > segments[k].t0 + segments[k].duration + 1e-9:
            if segments[k].kind == "gripper":
                jaw_before = segments[k].jaw
            k += 1
        seg = segments[k]
        local = min(max(t - seg.t0, 0.0), seg.duration)
        q = seg.traj.sample(np.array([local]))[0][0]
        if seg.kind == "gripper":
            f = local / seg.duration if seg.duration > 0 else 1.0
            jaw = (1 - f) * jaw_before + f * seg.jaw
        else:
            jaw = seg.jaw
        step = plan.steps[seg.step]
        if seg.holding:
            obj = tcp_pose(q) @ inverse_pose(np.asarray(step.grasp, dtype=np.float64))
        else:
            obj = np.asarray(step.object_pose, dtype=np.float64)
        out.append({"t": float(t), "q": q, "jaw": float(jaw), "held": bool(seg.holding), "object": obj, "caption": seg.caption,
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


def show_plan(vis: meshcat.Visualizer, plan, robot, obj_mesh: trimesh.Trimesh, table: tuple | None = None, fps: int = 30,
              path: str = "plan", kind: str = "visual", frames: list[dict] | None = None) -> manim.Animation:
    """Draw the plan's scene under `path` and attach its animation to `vis` (looped). The robot and the planning
    gripper are drawn by `workbench.viewer.robot.RobotView` (`kind`: the URDF's visual or collision meshes);
    `frames`: `plan_frames(plan, robot, fps)` when the caller has them already."""

    vis[path].delete()
    vis["/Grid"].set_property("visible", False)  # the table stands for the plane z = 0
    if table is not None:
        (x0, y0), (x1, y1), thick = table
        box = trimesh.creation.box(extents=(x1 - x0, y1 - y0, thick))
        box.apply_translation(((x0 + x1) / 2, (y0 + y1) / 2, -thick / 2))
        show_mesh(vis, f"{path}/table", box, color=TABLE_COLOR, opacity=0.5)
    show_mesh(vis, f"{path}/start", obj_mesh, color=START_COLOR, opacity=0.35, pose=plan.start_pose)
    show_mesh(vis, f"{path}/goal", obj_mesh, color=GOAL_COLOR, opacity=0.35, pose=plan.goal_pose)
    for i, s in enumerate(plan.steps[1:-1:2]):
        show_mesh(vis, f"{path}/placements/{i}", obj_mesh, color=0x999999, opacity=0.15, pose=s.object_pose)
    show_mesh(vis, f"{path}/object", obj_mesh, color=OBJECT_COLOR)
    view = RobotView(vis, robot, f"{path}/robot", kind)
    frames = plan_frames(plan, robot, fps) if frames is None else frames
    anim = manim.Animation(default_framerate=fps)
    if plan.segments:
        key = [("part", OBJECT_COLOR), ("start pose", START_COLOR), ("goal pose", GOAL_COLOR),
               ("put down to regrasp", 0x999999), ("table", TABLE_COLOR)]
        add_overlays(vis, anim, frames, f"{path}/captions", caption_anchor(plan, arm_reach(plan, robot)), CAMERA_DIR, key)
    for i, fr in enumerate(frames):
        poses = view.poses(fr["q"], fr["jaw"])
        obj_pose = fr["object"]
        with anim.at_frame(vis, i) as f:
            for name, m in poses.items():
                f[name].set_transform(m)
            f[f"{path}/object"].set_transform(obj_pose)
    if frames:  # the first frame as the scene's static state (shown before playing)
        view.show(frames[0]["q"], frames[0]["jaw"])
        vis[f"{path}/object"].set_transform(plan.start_pose)
    vis.set_animation(anim, play=True, repetitions=1000)
    return anim


def frame_plan(vis: meshcat.Visualizer, plan, robot) -> None:
    """Camera on every pose the part takes (start, placements, goal), the robot's base and its joints at every
    waypoint (so that a large arm stays in view as well as a small one) and the captions above them."""
    reach = arm_reach(plan, robot)
    parts = [plan.start_pose[:3, 3], plan.goal_pose[:3, 3], robot.base[:3, 3]]
    parts += [np.asarray(s.object_pose)[:3, 3] for s in plan.steps]
    frame_points(vis, np.vstack([parts, reach, overlay_corners(caption_anchor(plan, reach), CAMERA_DIR)]))


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


def caption_anchor(plan, reach: np.ndarray) -> np.ndarray:
    """Where `show_plan` stands the captions: behind the part's start and goal as the camera sees them, 0.25 m above
    the highest the arm reaches (`arm_reach`), so that the arm never hides them, and at least 0.62 m up."""
    anchor = 0.5 * (plan.start_pose[:3, 3] + plan.goal_pose[:3, 3]) + CAMERA_DIR * -0.3
    anchor[2] = max(0.62, float(reach[:, 2].max()) + 0.25)
    return anchor


def scene_table(planner) -> tuple:
    """(table_min, table_max, thickness) of the planner's scene."""
    s = planner.scene
    return tuple(s.table_min), tuple(s.table_max), float(s.table_thickness)


def plan_scene(plan, planner, out: str | Path | None = None, vis: meshcat.Visualizer | None = None,
               kind: str = "collision") -> Path | meshcat.Visualizer:
    """The plan's animation in a meshcat scene (a new one unless `vis`); written as static HTML when `out` is given
    (returns its path), else the visualizer is returned. `kind`: the robot's collision meshes (a file of a few MB)
    or its visual meshes (nicer, about 15 MB for the Panda)."""
    if vis is None:
        vis = new_scene()
    frames = plan_frames(plan, planner.robot)  # the animation's, and the page caption's clock
    show_plan(vis, plan, planner.robot, planner.object.mesh, scene_table(planner), kind=kind, frames=frames)
    frame_plan(vis, plan, planner.robot)
    if out is None:
        return vis
    path = static_html(vis, out)
    page = path.read_text()
    path.write_text(page.replace("</body>", plan_overlay(plan, [f["step"] for f in frames]) + "</body>", 1))
    return path


def plan_overlay(plan, frame_steps: list[int], fps: int = 30) -> str:
    """HTML for a static plan page: a colour key (top left) and a caption naming the step playing (bottom), read
    from the meshcat animation's clock (`viewer.animator`)."""
    legend = "".join(f"<span style='margin-right:12px;white-space:nowrap'><span style='display:inline-block;width:11px;"
                     f"height:11px;margin-right:4px;border:1px solid #555;background:#{c:06x}'></span>{t}</span>"
                     for c, t in ((OBJECT_COLOR, "the part"), (START_COLOR, "start pose"), (GOAL_COLOR, "goal pose"),
                                  (0x999999, "intermediate placements"), (TABLE_COLOR, "table")))
    captions = ["start: the part at its start pose, the robot at its first retract configuration"] + [
        f"step {i + 1} of {len(plan.steps)}: {' '.join(line.split('. ', 1)[-1].split())}"
        for i, line in enumerate(plan.lines()[:len(plan.steps)])]
    data = json.dumps({"steps": [s + 1 for s in frame_steps], "captions": captions, "fps": fps})
    box = "position:fixed;left:0;background:rgba(255,255,255,.88);font:14px sans-serif;padding:6px 12px;z-index:10"
    return (f"<div id='wb-legend' style='{box};top:0'>{legend}</div>"
            f"<div id='wb-caption' style='{box};bottom:0;right:0;font-size:15px'>{html.escape(captions[0])}</div>"
            "<script>(function () { var d = " + data + ", el = document.getElementById('wb-caption');"
            " function tick() { var a = window.viewer && viewer.animator && viewer.animator.actions[0];"
            " var f = a ? Math.min(Math.floor(a.time * d.fps + 1e-6), d.steps.length - 1) : 0;"
            " var t = d.captions[d.steps[Math.max(f, 0)]]; if (el.textContent !== t) el.textContent = t;"
            " requestAnimationFrame(tick); } tick(); })();</script>")


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
