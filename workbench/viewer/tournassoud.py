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
from workbench.viewer.wan_harada import PlanView, caption_track, frame_plan, plan_frames, plan_overlay, show_plan

FEATURE_COLOR = 0xDD3333
PART_AT_H = 0xE0A030
"""The part's colour at (P_j, phi) on the table (`show_conjunction`)."""


def feature_meshes(mesh: trimesh.Trimesh, cls: GraspClass, params: ClassParams = ClassParams()) -> list[trimesh.Trimesh]:
    """The class's faces as meshes (the faces of Section 2.1 recomputed with `params`)."""
    faces = faces_of(mesh, params.min_face_area)
    out = []
    for k in cls.features.get("faces", []):
        if k < len(faces):
            tris = faces[k].triangles
            out.append(trimesh.Trimesh(tris.reshape(-1, 3), np.arange(len(tris) * 3).reshape(-1, 3), process=False))
    return out


def show_class(vis: meshcat.Visualizer, mesh: trimesh.Trimesh, cls: GraspClass, gripper: Gripper, theta: float,
               pose: np.ndarray | None = None, path: str = "class", params: ClassParams = ClassParams()) -> None:
    """The object (at `pose`, default its own frame), the class's features highlighted, the grasp point, the grasp
    plane normal and the hand at angle `theta` (Sections 2.1-2.3)."""
    pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
    vis[path].delete()
    show_mesh(vis, f"{path}/object", mesh, color=GREY, opacity=0.5, pose=pose)
    for i, m in enumerate(feature_meshes(mesh, cls, params)):
        m = m.copy()
        m.apply_transform(pose)
        m.vertices += m.face_normals.mean(axis=0) * 2e-4  # just above the surface
        show_mesh(vis, f"{path}/features/face{i}", m, color=FEATURE_COLOR)
    R, t = pose[:3, :3], pose[:3, 3]
    if "edge" in cls.features:
        a, b = (np.asarray(p) @ R.T + t for p in cls.features["edge"])
        show_segments(vis, f"{path}/features/edge", a[None], b[None], color=FEATURE_COLOR)
    if "vertex" in cls.features:
        show_spheres(vis, f"{path}/features/vertex", (np.asarray(cls.features["vertex"]) @ R.T + t)[None], 0.003, color=FEATURE_COLOR)
    c = cls.point @ R.T + t
    show_spheres(vis, f"{path}/point", c[None], 0.002, color=BLUE)
    show_segments(vis, f"{path}/normal", c[None], (c + 0.04 * (R @ cls.normal))[None], color=BLUE)
    show_gripper(vis, f"{path}/hand", gripper, pose @ cls.pose(theta), width=min(cls.opening + 1e-3, gripper.jaw_max),
                 color=GREEN if cls.legal(np.array([theta]))[0] else RED)


def show_conjunction(vis: meshcat.Visualizer, mesh: trimesh.Trimesh, table: GraspPlacementTable, classes: list[GraspClass],
                     index: int, gripper: Gripper, placement: int, theta: float, phi: float, path: str = "conjunction") -> bool:
    """The object at (P_j, phi) on the table and the hand at (G_index, theta) (Section 4.1); returns whether the
    sampled table holds the pair at the nearest samples (green hand) or not (orange)."""
    cls = classes[index]
    obj = table.object_pose(placement, phi)
    t = int(np.round(np.mod(theta, 2 * np.pi) / (2 * np.pi / len(table.theta)))) % len(table.theta)
    f = int(np.round(np.mod(phi, 2 * np.pi) / (2 * np.pi / len(table.phi)))) % len(table.phi)
    vis[path].delete()
    show_spheres(vis, f"{path}/H", table.frame[:3, 3][None], 0.004, color=BLUE)
    show_mesh(vis, f"{path}/object", mesh, color=PART_AT_H, pose=obj)
    legal = bool(table.q[index, placement, t, f])
    show_gripper(vis, f"{path}/hand", gripper, obj @ cls.pose(theta), width=min(cls.opening + 1e-3, gripper.jaw_max),
                 color=GREEN if legal else ORANGE)
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
    path = static_html(vis, out)
    page = path.read_text()
    path.write_text(page.replace("</body>", plan_overlay(caption_track(plan, frames)) + "</body>", 1))
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
