"""meshcat views of the grasp-placement table planner (Tournassoud, Lozano-Perez & Mazer 1987, Figs. 1-4):
a grasp class's features on the object with the hand at (G_i, theta); the object at (P_j, phi) on the table with
the hand; a task's pick-up, destination and obstacles; and a returned sequence animated with the robot (the roadmap
planner's plan animation)."""

from __future__ import annotations

from pathlib import Path

import meshcat
import numpy as np
import trimesh

from workbench.planners.tournassoud.classes import ClassParams, GraspClass
from workbench.planners.tournassoud.features import faces_of
from workbench.planners.tournassoud.table import GraspPlacementTable
from workbench.robots.gripper import Gripper
from workbench.viewer.scenes import (
    BLUE,
    GREEN,
    GREY,
    ORANGE,
    RED,
    legend,
    new_scene,
    show_gripper,
    show_mesh,
    show_segments,
    show_spheres,
    static_html,
)
from workbench.viewer.live import Switches
from workbench.viewer.wan_harada import (
    PlanView,
    caption_track,
    frame_plan,
    plan_frames,
    plan_overlay,
    plan_title,
    show_plan,
)

FEATURE_COLOR = 0xDD3333
PART_AT_H = 0xE0A030
"""The part's colour at (P_j, phi) on the table (`TableView`)."""


def feature_meshes(mesh: trimesh.Trimesh, cls: GraspClass, params: ClassParams = ClassParams()) -> list[trimesh.Trimesh]:
    """The class's faces as meshes (the faces of Section 2.1 recomputed with `params`)."""
    faces = faces_of(mesh, params.min_face_area)
    out = []
    for k in cls.features.get("faces", []):
        if k < len(faces):
            tris = faces[k].triangles
            out.append(trimesh.Trimesh(tris.reshape(-1, 3), np.arange(len(tris) * 3).reshape(-1, 3), process=False))
    return out


BESIDE = np.array([[1, 0, 0, 0.0], [0, 1, 0, -0.3], [0, 0, 1, 0.2], [0, 0, 0, 1]])
"""Where the class's part stands in the explorer's scene: beside the table point H, clear of the part there."""


def _rgba(color: int, opacity: float) -> list[float]:
    return [((color >> s) & 255) / 255 for s in (16, 8, 0)] + [opacity]


class TableView:
    """Notebook 06's scene (Sections 2-4): on the left the class's part (at `BESIDE`) with its features highlighted,
    the grasp point, the grasp-plane normal and the hand at angle theta (green legal on the part, red not); on the
    right the part at (P_j, phi) at the table point H with the hand at (G_i, theta) (green when the sampled table
    holds the pair, orange when not). Geometry is sent when the class changes (`set_class`); a change of theta,
    placement or phi only moves and recolours what is there (`pose`)."""

    def __init__(self, vis: meshcat.Visualizer, mesh: trimesh.Trimesh, table: GraspPlacementTable,
                 classes: list[GraspClass], gripper: Gripper, params: ClassParams = ClassParams()):
        self.vis, self.mesh, self.table, self.classes, self.gripper, self.params = vis, mesh, table, classes, gripper, params
        self.switches = Switches(vis)
        self.index: int | None = None
        for path in ("class", "conjunction"):
            vis[path].delete()

    def set_class(self, index: int) -> None:
        """Send the class's part, features, grasp point, normal and both hands (at its opening), unless shown."""
        if index == self.index:
            return
        vis, cls, pose = self.vis, self.classes[index], BESIDE
        for path in ("class", "conjunction"):
            vis[path].delete()
            self.switches.forget(path)
        show_mesh(vis, "class/object", self.mesh, color=GREY, opacity=0.5, pose=pose)
        for i, m in enumerate(feature_meshes(self.mesh, cls, self.params)):
            m = m.copy()
            m.apply_transform(pose)
            m.vertices += m.face_normals.mean(axis=0) * 2e-4  # just above the surface
            show_mesh(vis, f"class/features/face{i}", m, color=FEATURE_COLOR)
        R, t = pose[:3, :3], pose[:3, 3]
        if "edge" in cls.features:
            a, b = (np.asarray(p) @ R.T + t for p in cls.features["edge"])
            show_segments(vis, "class/features/edge", a[None], b[None], color=FEATURE_COLOR)
        if "vertex" in cls.features:
            show_spheres(vis, "class/features/vertex", (np.asarray(cls.features["vertex"]) @ R.T + t)[None], 0.003,
                         color=FEATURE_COLOR)
        c = cls.point @ R.T + t
        show_spheres(vis, "class/point", c[None], 0.002, color=BLUE)
        show_segments(vis, "class/normal", c[None], (c + 0.04 * (R @ cls.normal))[None], color=BLUE)
        width = min(cls.opening + 1e-3, self.gripper.jaw_max)
        show_gripper(vis, "class/hand", self.gripper, np.eye(4), width=width)
        show_spheres(vis, "conjunction/H", self.table.frame[:3, 3][None], 0.004, color=BLUE)
        show_mesh(vis, "conjunction/object", self.mesh, color=PART_AT_H)
        show_gripper(vis, "conjunction/hand", self.gripper, np.eye(4), width=width)
        self.index = index

    def pose(self, index: int, theta: float, placement: int, phi: float) -> bool:
        """The hand at (G_index, theta) on the class's part, and the part at (P_placement, phi) at H with the hand;
        returns whether the sampled table holds the pair at the nearest samples (Section 4.1)."""
        self.set_class(index)
        cls, table, sw = self.classes[index], self.table, self.switches
        sw.move("class/hand", BESIDE @ cls.pose(theta))
        sw.set("class/hand", "color", _rgba(GREEN if cls.legal(np.array([theta]))[0] else RED, 0.6))
        obj = table.object_pose(placement, phi)
        t = int(np.round(np.mod(theta, 2 * np.pi) / (2 * np.pi / len(table.theta)))) % len(table.theta)
        f = int(np.round(np.mod(phi, 2 * np.pi) / (2 * np.pi / len(table.phi)))) % len(table.phi)
        legal = bool(table.q[index, placement, t, f])
        sw.move("conjunction/object", obj)
        sw.move("conjunction/hand", obj @ cls.pose(theta))
        sw.set("conjunction/hand", "color", _rgba(GREEN if legal else ORANGE, 0.6))
        return legal


def show_sequence(vis: meshcat.Visualizer, plan, robot, mesh: trimesh.Trimesh, table: tuple | None = None, fps: int = 30):
    """A realised sequence animated with the robot (the roadmap planner's plan animation), with the plan's task
    obstacles (grey, half transparent) and its insertion (an orange segment ending where the part goes)."""
    anim = show_plan(vis, plan, robot, mesh, table, fps=fps)
    show_plan_task(vis, plan, mesh)
    return anim


def show_plan_task(vis: meshcat.Visualizer, plan, mesh: trimesh.Trimesh, path: str = "plan_task") -> None:
    """The obstacles a plan's motions were checked against and its final insertion, as the plan carries them (a
    plan reloaded from the store included)."""
    vis[path].delete()
    for k, o in enumerate(plan.obstacles):
        show_mesh(vis, f"{path}/obstacle_{k}", o.mesh(), color=GREY, opacity=0.5, pose=o.pose)
    if plan.insertion is not None and plan.insertion_depth > 0:
        end = mesh.copy().apply_transform(plan.goal_pose).bounds.mean(axis=0)
        show_segments(vis, f"{path}/insertion", (end - plan.insertion_depth * np.asarray(plan.insertion))[None], end[None],
                      color=ORANGE)


def plan_page(plan, robot, mesh: trimesh.Trimesh, table: tuple, out) -> Path:
    """A plan's animation with its obstacles and insertion as a static HTML page, framed on the work, with the
    plan views' key, caption and footer overlays."""
    vis = new_scene()
    frames = plan_frames(plan, robot)
    PlanView(vis, robot, mesh, table, kind="collision").play(plan, frames=frames)
    show_plan_task(vis, plan, mesh)
    frame_plan(vis, plan, robot)
    title = plan_title(plan.object, robot)
    path = static_html(vis, out, title)
    page = path.read_text()
    path.write_text(page.replace("</body>", plan_overlay(caption_track(plan, frames), title=title) + "</body>", 1))
    return path


def show_task(vis: meshcat.Visualizer, mesh: trimesh.Trimesh, pickup_pose: np.ndarray, destination_pose: np.ndarray,
              obstacles, insertion: np.ndarray | None = None, depth: float = 0.0) -> str:
    """Fig. 1's task (Section 5.1): the part where it is picked up (blue) and where it goes (green), the obstacles
    there (grey, half transparent) and the insertion as an orange segment ending at the destination; returns a
    legend (HTML) for the colours."""
    show_mesh(vis, "task/pickup", mesh.copy().apply_transform(pickup_pose), color=BLUE)
    show_mesh(vis, "task/destination", mesh.copy().apply_transform(destination_pose), color=GREEN, opacity=0.6)
    for k, o in enumerate(obstacles):
        show_mesh(vis, f"task/obstacle_{k}", o.world_mesh(), color=GREY, opacity=0.5)
    if insertion is not None and depth > 0:
        end = mesh.copy().apply_transform(destination_pose).bounds.mean(axis=0)
        show_segments(vis, "task/insertion", (end - depth * np.asarray(insertion))[None], end[None], color=ORANGE)
    return legend([(BLUE, "part at the pick-up"), (GREEN, "part at the destination"), (GREY, "obstacles"),
                   (ORANGE, "insertion")], "Fig. 1's task")
