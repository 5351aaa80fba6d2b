"""Scenes that answer a slider at once: geometry is sent when it is computed, and a view-only change (which facet is
highlighted, how many hands, which placement or step) only shows, hides or moves what was sent.

`Switches` remembers what it set so that each change sends only the properties that differ; `HandOutlines` sends
many hands as thin outlines, one object each, so that their number is a visibility change; `send_group` sends
several objects as one, hidden until shown; `SolidHand` is
the selected hand, body and fingers moved by transforms to any pose and opening.
"""

from __future__ import annotations

import meshcat
import meshcat.geometry as g
from meshcat.animation import Animation, AnimationClip, AnimationTrack
import numpy as np
import trimesh

from workbench.robots.gripper import Gripper
from workbench.viewer.scenes import _rgb


class Switches:
    """Visibility and transforms of objects already in a scene, sent only when they change."""

    def __init__(self, vis: meshcat.Visualizer):
        self.vis = vis
        self.visible: dict = {}  # path (or (path, property)) -> value
        self.poses: dict[str, bytes] = {}

    def show(self, path: str, on: bool) -> None:
        on = bool(on)
        if self.visible.get(path) != on:
            self.vis[path].set_property("visible", on)
            self.visible[path] = on

    def set(self, path: str, key: str, value) -> None:
        """Any other property (meshcat's "color" takes [r, g, b, opacity] and recolours the children too)."""
        if self.visible.get((path, key)) != value:
            self.vis[path].set_property(key, value)
            self.visible[(path, key)] = value

    def move(self, path: str, pose: np.ndarray) -> None:
        pose = np.asarray(pose, dtype=np.float64)
        key = pose.tobytes()
        if self.poses.get(path) != key:
            self.vis[path].set_transform(pose)
            self.poses[path] = key

    def forget(self, prefix: str) -> None:
        """Drop what is remembered under `prefix` (its objects were deleted or replaced)."""
        for d in (self.visible, self.poses):
            for k in [k for k in d if (k if isinstance(k, str) else k[0]).startswith(prefix)]:
                del d[k]


class HandOutlines:
    """A gripper drawn as thin outlines: its feature edges (creases sharper than 25 degrees) at each jaw opening,
    kept per opening (0.1 mm), so that many hands hide nothing behind them."""

    def __init__(self, gripper: Gripper):
        self.gripper = gripper
        self.edges: dict[float, np.ndarray] = {}

    def at(self, width: float) -> np.ndarray:
        """(2K, 3) segment end points in the TCP frame at `width`."""
        key = round(float(width), 4)
        if key not in self.edges:
            mesh = self.gripper.collision_mesh(key)
            sharp = mesh.face_adjacency_edges[mesh.face_adjacency_angles > np.radians(25)]
            self.edges[key] = mesh.vertices[sharp].reshape(-1, 3)
        return self.edges[key]

    def send(self, vis: meshcat.Visualizer, path: str, poses: np.ndarray, widths: np.ndarray, color: int,
             opacity: float = 0.7) -> int:
        """One outline object per hand under `path/i`; returns how many were sent."""
        vis[path].delete()
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        material = g.LineBasicMaterial(color=int(color), opacity=opacity, transparent=opacity < 1)
        for i, (pose, width) in enumerate(zip(poses, np.asarray(widths))):
            pts = trimesh.transform_points(self.at(width), pose).astype(np.float32)
            vis[f"{path}/{i}"].set_object(g.LineSegments(g.PointsGeometry(pts.T), material))
        return len(poses)


def pick_evenly(n: int, k: int) -> np.ndarray:
    """`k` indices spread evenly over `n` items (all of them when k >= n)."""
    return np.unique(np.linspace(0, n - 1, min(k, n)).astype(int)) if n and k else np.zeros(0, dtype=int)


def finger_corners(gripper: Gripper, pose: np.ndarray, width: float) -> np.ndarray:
    """(16, 3) corners of both finger boxes of the hand at a TCP pose and jaw opening: what a camera framed on a
    grasp keeps in view (the hand's body may leave the frame; the part and the jaw stay)."""
    unit = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    return np.vstack([trimesh.transform_points(unit * ext, np.asarray(pose) @ local)
                      for ext, local in gripper.finger_poses(float(width))])


class SolidHand:
    """The selected hand drawn solid (its body a little translucent, so that the part behind it stays readable):
    body and finger boxes are sent once and placed by transforms."""

    def __init__(self, vis: meshcat.Visualizer, path: str, gripper: Gripper, color: int, body_opacity: float = 0.55):
        self.vis, self.path, self.gripper = vis, path, gripper
        self.switches = Switches(vis)
        material = g.MeshLambertMaterial(color=int(color))
        body = gripper.body
        vis[f"{path}/body"].set_object(g.TriangularMeshGeometry(body.vertices, body.faces), g.MeshLambertMaterial(
            color=int(color), opacity=body_opacity, transparent=body_opacity < 1))
        self.fingers = []
        for k, (ext, _) in enumerate(gripper.finger_poses(gripper.jaw_max)):
            vis[f"{path}/finger{k}"].set_object(g.Box(list(map(float, ext))), material)
            self.fingers.append(f"{path}/finger{k}")

    def place(self, pose: np.ndarray | None, width: float | None = None) -> None:
        """The hand at a TCP pose with its jaw at `width` (hidden when `pose` is None)."""
        self.switches.show(self.path, pose is not None)
        if pose is None:
            return
        pose = np.asarray(pose, dtype=np.float64)
        self.switches.move(f"{self.path}/body", pose)
        width = self.gripper.jaw_max if width is None else float(width)
        for name, (_, local) in zip(self.fingers, self.gripper.finger_poses(width)):
            self.switches.move(name, pose @ local)


class _Group(g.Object):
    """Several meshcat objects sent as one three.js group in one message, hidden or shown from the start."""

    def __init__(self, children: list[g.Object], visible: bool):
        super().__init__(None, None)
        self.children, self.visible = children, visible

    def lower(self) -> dict:
        parts = [c.lower() for c in self.children]
        return {"metadata": {"version": 4.5, "type": "Object"},
                "geometries": [x for p in parts for x in p["geometries"]],
                "materials": [x for p in parts for x in p["materials"]],
                "object": {"uuid": self.uuid, "type": "Group", "visible": self.visible,
                           "matrix": np.eye(4).flatten().tolist(), "children": [p["object"] for p in parts]}}


def send_group(vis: meshcat.Visualizer, path: str, children: list[g.Object], visible: bool = False) -> str:
    """Send `children` (meshcat objects) as one object at `path`, hidden unless `visible`; returns the path whose
    "visible" property shows or hides it (`Switches.show`)."""
    vis[path].set_object(_Group(children, visible))
    return f"{path}/<object>"


def mesh_object(mesh: trimesh.Trimesh, color: int, opacity: float = 1.0) -> g.Mesh:
    """A meshcat mesh object of `mesh` in one colour (0xRRGGBB), translucent below opacity 1."""
    return g.Mesh(g.TriangularMeshGeometry(mesh.vertices, mesh.faces),
                  g.MeshLambertMaterial(color=int(color), opacity=opacity, transparent=opacity < 1))


def points_object(points: np.ndarray, colors: np.ndarray, size: float) -> g.Points:
    """A meshcat point cloud of (N, 3) `points`, one colour or one per point, `size` in metres."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    return g.Points(g.PointsGeometry(pts.T, color=_rgb(colors, len(pts)).T), g.PointsMaterial(size=size))


def transform_animation(vis: meshcat.Visualizer, poses: dict[str, np.ndarray], fps: float = 30.0) -> Animation:
    """A meshcat animation moving each scene path through its (F, 4, 4) poses, one per frame at `fps`, built from
    whole arrays (meshcat's frame-by-frame builder converts every matrix on its own)."""
    from scipy.spatial.transform import Rotation

    anim = Animation(default_framerate=fps)
    for path, m in poses.items():
        m = np.asarray(m, dtype=np.float64).reshape(-1, 4, 4)
        frames = list(range(len(m)))
        quat = Rotation.from_matrix(m[:, :3, :3]).as_quat()  # x, y, z, w: three.js's order
        anim.clips[vis[path].path] = AnimationClip(fps=fps, tracks={
            "position": AnimationTrack("position", "vector3", frames, m[:, :3, 3].tolist()),
            "quaternion": AnimationTrack("quaternion", "quaternion", frames, quat.tolist())})
    return anim
