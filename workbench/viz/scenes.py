"""Ready-made meshcat scenes written as static HTML (for the command line and `make demo`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..gripper import Gripper
from ..objects import ObjectModel
from . import GREEN, GREY, frame_camera, new_scene, show_grippers, show_mesh, show_points, static_html


def grasp_scene(obj: ObjectModel, gripper: Gripper, poses: np.ndarray, widths: np.ndarray, out: str | Path,
                limit: int = 200) -> Path:
    """The object with up to `limit` of its grasps (green hands at their jaw widths) as an HTML file."""
    vis = new_scene()
    show_mesh(vis, "object", obj.mesh, color=GREY)
    show_points(vis, "com", obj.com[None], color=0xFF0000, size=0.006)
    show_grippers(vis, "grasps", gripper, poses, widths, colors=GREEN, opacity=0.25, limit=limit)
    frame_camera(vis, obj.mesh.bounds.mean(axis=0), float(obj.mesh.scale) + 0.1)
    return static_html(vis, out)
