"""Scenes that answer a slider at once: geometry is sent when it is computed, and a view-only change (which facet is
highlighted, how many hands, which placement or step) only shows, hides or moves what was sent.

`Switches` remembers what it set so that each change sends only the properties that differ; `HandOutlines` draws
hands as thin outlines, one object each or, as `FirstHands`, a few objects of which the first k are shown; `send_group` sends
several objects as one, hidden until shown; `OneAtATime` sends many small parts of which one is shown at a time
(the highlighted facet) as one object; `SolidHand` is the selected hand, body and fingers moved by transforms to any
pose and opening.
"""

from __future__ import annotations

from collections.abc import Callable

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

    def placed(self, poses: np.ndarray, widths: np.ndarray) -> list[np.ndarray]:
        """Each hand's (2K, 3) outline segment ends at its TCP pose and jaw opening."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        return [trimesh.transform_points(self.at(w), pose) for pose, w in zip(poses, np.asarray(widths))]

    def send(self, vis: meshcat.Visualizer, path: str, poses: np.ndarray, widths: np.ndarray, color: int,
             opacity: float = 0.7) -> int:
        """One outline object per hand under `path/i`; returns how many were sent."""
        vis[path].delete()
        outlines = self.placed(poses, widths)
        for i, ends in enumerate(outlines):
            vis[f"{path}/{i}"].set_object(lines_object(ends, color, opacity))
        return len(outlines)


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


def far_offsets(n: int, spacing: float = 200.0) -> np.ndarray:
    """(n, 3) distinct offsets on a cubic grid of `spacing` (metres) around the origin, the origin itself left out:
    a part displaced by one lies beyond meshcat's far clipping plane (100 m) wherever the camera looks from near the
    work, and stays within float32's sub-0.1 mm precision for thousands of parts."""
    k = 0
    while (2 * k + 1) ** 3 - 1 < n:
        k += 1
    r = np.arange(-k, k + 1)
    grid = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    grid = grid[np.abs(grid).sum(axis=1) > 0]
    return spacing * grid[np.argsort(np.abs(grid).max(axis=1), kind="stable")][:n].astype(np.float64)


class OneAtATime:
    """Many small parts of which at most one is shown (the highlighted facet and its samples, a partial block of
    hands), sent as one object: part i is stored displaced far away by `far_offsets` and shown by moving the object
    back by its offset, so that choosing another part is one transform and no geometry."""

    def __init__(self, vis: meshcat.Visualizer, path: str, n: int, pieces: list[tuple[np.ndarray, np.ndarray, Callable]]):
        """`pieces`: (vertices (V, 3) in place, the part of each vertex, a function making a meshcat object of the
        displaced vertices), e.g. triangle corners for a mesh, segment ends for lines, points for a cloud."""
        self.vis, self.path, self.n = vis, path, n
        self.offsets = far_offsets(n)
        self.switches = Switches(vis)
        children = [make(np.asarray(v, dtype=np.float64).reshape(-1, 3) + self.offsets[np.asarray(part, dtype=int)])
                    for v, part, make in pieces if len(v)]
        self.shown = send_group(vis, path, children) if children else None

    def choose(self, i: int | None) -> None:
        """Show part `i` in place (none when `i` is None or out of range)."""
        if self.shown is None:
            return
        on = i is not None and 0 <= i < self.n
        self.switches.show(self.shown, on)
        if on:
            pose = np.eye(4)
            pose[:3, 3] = -self.offsets[i]
            self.switches.move(self.path, pose)


def triangles_object(corners: np.ndarray, color: int) -> g.Mesh:
    """A meshcat mesh of (3M, 3) triangle corners (three rows per triangle, unshared) in one colour (0xRRGGBB)."""
    corners = np.asarray(corners, dtype=np.float32).reshape(-1, 3)
    return g.Mesh(g.TriangularMeshGeometry(corners, np.arange(len(corners)).reshape(-1, 3)),
                  g.MeshLambertMaterial(color=int(color)))


def lines_object(ends: np.ndarray, color: int, opacity: float = 1.0) -> g.LineSegments:
    """Meshcat line segments from (2K, 3) end points (two rows per segment) in one colour, translucent below 1."""
    pts = np.asarray(ends, dtype=np.float32).reshape(-1, 3)
    return g.LineSegments(g.PointsGeometry(pts.T),
                          g.LineBasicMaterial(color=int(color), opacity=opacity, transparent=opacity < 1))


def spread_order(n: int) -> np.ndarray:
    """0..n-1 ordered so that every prefix is spread evenly over the range (van der Corput's sequence)."""
    order, seen, k = [], set(), 0
    while len(order) < n:
        x, base, v = 0.0, 0.5, k
        while v:
            x, v, base = x + base * (v & 1), v >> 1, base / 2
        j = int(x * n)
        if j not in seen:
            seen.add(j)
            order.append(j)
        k += 1
    return np.asarray(order, dtype=int)


class FirstHands:
    """Hand outlines of which the first k are shown, sent as a few objects whatever k: whole blocks of about sqrt(n)
    hands, one object each, and the block being filled as a `OneAtATime` of its partial prefixes, so that changing k
    is visibility and one transform."""

    def __init__(self, vis: meshcat.Visualizer, path: str, outlines: list[np.ndarray], color: int, opacity: float = 0.7):
        """`outlines`: each hand's (2K, 3) segment ends in the scene frame, in the order they are shown."""
        vis[path].delete()
        self.switches = Switches(vis)
        n = len(outlines)
        self.n, self.block = n, max(1, int(np.ceil(np.sqrt(n))))
        self.blocks = []
        for q in range(0, n, self.block):
            name = f"{path}/block{q // self.block}"
            vis[name].set_object(lines_object(np.vstack(outlines[q:q + self.block]), color, opacity))
            self.switches.show(name, False)
            self.blocks.append(name)
        ends, part = [], []  # part (q, r): the first r hands of block q, r < block
        for q in range(len(self.blocks)):
            for r in range(1, self.block):
                hands = outlines[q * self.block:q * self.block + r]
                ends += hands
                part += [q * (self.block - 1) + r - 1] * sum(len(h) for h in hands)
        self.partial = OneAtATime(vis, f"{path}/partial", len(self.blocks) * (self.block - 1),
                                  [(np.vstack(ends) if ends else np.zeros((0, 3)), part,
                                    lambda v: lines_object(v, color, opacity))])

    def show(self, k: int) -> int:
        """Show the first `k` hands (all of them when k >= n); returns how many are shown."""
        k = max(0, min(int(k), self.n))
        full, r = divmod(k, self.block)
        for q, name in enumerate(self.blocks):
            self.switches.show(name, q < full)
        self.partial.choose(full * (self.block - 1) + r - 1 if r else None)
        return k


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
