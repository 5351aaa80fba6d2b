"""Grippers side by side: one part with the grasps of each gripper, as a meshcat scene and as a picture
(CONVENTIONS.md, Gripper; Wan & Harada Section III's grasps for any parallel-jaw hand)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import meshcat
import numpy as np

from workbench.geometry.objects import ObjectModel
from workbench.robots.gripper import Gripper
from workbench.viewer.scenes import GREEN, GREY, frame_points, show_grippers, show_mesh


def _offsets(obj: ObjectModel, n: int) -> np.ndarray:
    """x offsets that set `n` copies of the part side by side with room for the hands between them."""
    span = float(np.ptp(obj.mesh.bounds[:, 0])) + 0.25
    return (np.arange(n) - (n - 1) / 2) * span


def compare_scene(vis: meshcat.Visualizer, obj: ObjectModel, sets: list[tuple[Gripper, np.ndarray, np.ndarray]],
                  hands: int = 8) -> None:
    """The part once per gripper, side by side along x, each with up to `hands` of its grasps (TCP poses, widths)."""
    vis["compare"].delete()
    corners = []
    for k, ((gripper, poses, widths), dx) in enumerate(zip(sets, _offsets(obj, len(sets)))):
        at = np.eye(4)
        at[0, 3] = dx
        show_mesh(vis, f"compare/{k}/part", obj.mesh, color=GREY, pose=at)
        show_grippers(vis, f"compare/{k}/hands", gripper, at @ np.asarray(poses).reshape(-1, 4, 4), widths,
                      colors=GREEN, opacity=0.35, limit=hands)
        corners.append(obj.mesh.bounds + [dx, 0.0, 0.0])
    frame_points(vis, np.concatenate(corners))


def _surface(ax, mesh, color: str, alpha: float) -> None:
    v = mesh.vertices
    ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=mesh.faces, color=color, alpha=alpha, linewidth=0, shade=True)


def compare_figure(obj: ObjectModel, sets: list[tuple[Gripper, np.ndarray, np.ndarray]], hands: int = 4,
                   size: tuple[float, float] = (10.0, 4.6)):
    """A matplotlib figure, one panel per gripper: the part (grey) and a few of its grasps (the gripper's own
    palm and fingers at the grasp's opening), titled with the gripper's name, stroke and grasp count."""
    fig = plt.figure(figsize=size)
    for k, (gripper, poses, widths) in enumerate(sets):
        ax = fig.add_subplot(1, len(sets), k + 1, projection="3d")
        _surface(ax, obj.mesh, "0.7", 0.9)
        poses = np.asarray(poses).reshape(-1, 4, 4)
        pick = np.unique(np.linspace(0, len(poses) - 1, min(hands, len(poses))).astype(int)) if len(poses) else []
        pts = [obj.mesh.vertices]
        for i in pick:
            hand = gripper.collision_mesh(float(widths[i]))
            hand.apply_transform(poses[i])
            _surface(ax, hand, "#33aa55", 0.25)
            pts.append(hand.vertices)
        allp = np.concatenate(pts)
        c, r = allp.mean(axis=0), np.ptp(allp, axis=0).max() / 2
        ax.set_xlim(c[0] - r, c[0] + r)
        ax.set_ylim(c[1] - r, c[1] + r)
        ax.set_zlim(c[2] - r, c[2] + r)
        ax.set_box_aspect((1, 1, 1))
        ax.set_axis_off()
        ax.set_title(f"{gripper.name}: stroke {gripper.jaw_max * 1e3:.0f} mm, {len(poses):,} grasps", fontsize=10)
    fig.tight_layout()
    return fig

