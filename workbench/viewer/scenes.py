"""meshcat helpers: meshes, facets, points, normals, the gripper at poses, the table, and static HTML export.

Everything takes a `meshcat.Visualizer` and a scene path; colours are 0xRRGGBB integers. `static_html` writes a
file that opens in a browser without a running server; `grasp_scene` is a ready-made scene for the command line.
"""

from __future__ import annotations

from pathlib import Path

import meshcat
import meshcat.geometry as g
import meshcat.transformations as tf
import numpy as np
import trimesh

from workbench.geometry.objects import ObjectModel
from workbench.robots.gripper import Gripper

GREEN, RED, GREY, BLUE, ORANGE, WHITE = 0x33AA55, 0xDD3333, 0xB0B0B0, 0x3366DD, 0xFF9922, 0xFFFFFF


def new_scene() -> meshcat.Visualizer:
    """A meshcat visualizer with its own server (closed with the kernel); starts empty."""
    vis = meshcat.Visualizer()
    vis.delete()
    return vis


def palette(n: int, seed: int = 0) -> np.ndarray:
    """`n` distinct colours as 0xRRGGBB ints (deterministic)."""
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    rgb = np.array([cmap(i % 20)[:3] for i in range(n)])
    if n > 20:
        rng = np.random.default_rng(seed)
        rgb = np.clip(rgb * rng.uniform(0.6, 1.2, size=(n, 1)), 0, 1)
    return (np.round(rgb * 255).astype(int) @ np.array([1 << 16, 1 << 8, 1])).astype(int)


def _rgb(colors: np.ndarray | int, n: int) -> np.ndarray:
    c = np.broadcast_to(np.asarray(colors, dtype=np.int64), (n,))
    return np.stack([(c >> 16) & 255, (c >> 8) & 255, c & 255], axis=1).astype(np.float32) / 255.0


def show_mesh(vis: meshcat.Visualizer, path: str, mesh: trimesh.Trimesh, color: int = GREY, opacity: float = 1.0,
              pose: np.ndarray | None = None, wireframe: bool = False) -> None:
    """A triangle mesh with one colour."""
    material = g.MeshLambertMaterial(color=color, opacity=opacity, transparent=opacity < 1.0, wireframe=wireframe)
    vis[path].set_object(g.TriangularMeshGeometry(mesh.vertices, mesh.faces), material)
    if pose is not None:
        vis[path].set_transform(np.asarray(pose, dtype=np.float64))


def show_face_colors(vis: meshcat.Visualizer, path: str, mesh: trimesh.Trimesh, face_colors: np.ndarray,
                     pose: np.ndarray | None = None) -> None:
    """A mesh with a colour per face (for facets): faces are unshared so each keeps its colour."""
    tris = mesh.triangles.reshape(-1, 3)
    faces = np.arange(len(tris)).reshape(-1, 3)
    colors = np.repeat(_rgb(face_colors, len(mesh.faces)), 3, axis=0)
    geom = g.TriangularMeshGeometry(tris, faces, color=colors)
    vis[path].set_object(geom, g.MeshLambertMaterial(vertexColors=True))
    if pose is not None:
        vis[path].set_transform(np.asarray(pose, dtype=np.float64))


def show_points(vis: meshcat.Visualizer, path: str, points: np.ndarray, color: int | np.ndarray = BLUE,
                size: float = 0.003) -> None:
    """Points with one colour or one colour each."""
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    if len(pts) == 0:
        vis[path].delete()
        return
    vis[path].set_object(g.PointsGeometry(pts.T, color=_rgb(color, len(pts)).T), g.PointsMaterial(size=size))


def show_segments(vis: meshcat.Visualizer, path: str, starts: np.ndarray, ends: np.ndarray, color: int = ORANGE) -> None:
    """Line segments from `starts` to `ends` (normals, contact axes, graph edges)."""
    s = np.asarray(starts, dtype=np.float32).reshape(-1, 3)
    e = np.asarray(ends, dtype=np.float32).reshape(-1, 3)
    if len(s) == 0:
        vis[path].delete()
        return
    pts = np.empty((2 * len(s), 3), dtype=np.float32)
    pts[0::2], pts[1::2] = s, e
    vis[path].set_object(g.LineSegments(g.PointsGeometry(pts.T), g.LineBasicMaterial(color=color)))


def show_normals(vis: meshcat.Visualizer, path: str, points: np.ndarray, normals: np.ndarray, length: float = 0.01,
                 color: int = ORANGE) -> None:
    """Normals as segments of `length` from each point."""
    points = np.asarray(points).reshape(-1, 3)
    show_segments(vis, path, points, points + length * np.asarray(normals).reshape(-1, 3), color)


def show_spheres(vis: meshcat.Visualizer, path: str, centers: np.ndarray, radius: float, color: int = RED,
                 opacity: float = 1.0) -> None:
    """One sphere per centre under `path/i`."""
    vis[path].delete()
    for i, c in enumerate(np.asarray(centers).reshape(-1, 3)):
        vis[f"{path}/{i}"].set_object(g.Sphere(radius), g.MeshLambertMaterial(color=color, opacity=opacity, transparent=opacity < 1))
        vis[f"{path}/{i}"].set_transform(tf.translation_matrix(c))


def gripper_mesh(gripper: Gripper, width: float | None = None) -> trimesh.Trimesh:
    """The gripper's collision geometry (body and both fingers at `width`) as one mesh in the TCP frame."""
    return gripper.collision_mesh(width)


def show_gripper(vis: meshcat.Visualizer, path: str, gripper: Gripper, pose: np.ndarray, width: float | None = None,
                 color: int = GREEN, opacity: float = 0.6) -> None:
    """The gripper at a TCP pose with its jaw at `width` (default: full opening)."""
    show_mesh(vis, path, gripper_mesh(gripper, width), color=color, opacity=opacity, pose=pose)


def show_grippers(vis: meshcat.Visualizer, path: str, gripper: Gripper, poses: np.ndarray, widths: np.ndarray | None = None,
                  colors: np.ndarray | int = GREEN, opacity: float = 0.4, limit: int = 400) -> None:
    """Many grippers merged into one mesh per colour (fast to send); at most `limit`, evenly picked."""
    poses = np.asarray(poses).reshape(-1, 4, 4)
    vis[path].delete()
    if len(poses) == 0:
        return
    pick = np.unique(np.linspace(0, len(poses) - 1, min(limit, len(poses))).astype(int))
    colors = np.broadcast_to(np.asarray(colors), (len(poses),))[pick]
    widths = np.full(len(poses), gripper.jaw_max) if widths is None else np.asarray(widths)
    base = {}
    for c in np.unique(colors):
        parts = []
        for i in pick[colors == c]:
            key = round(float(widths[i]), 4)
            if key not in base:
                base[key] = gripper_mesh(gripper, key)
            m = base[key].copy()
            m.apply_transform(poses[i])
            parts.append(m)
        show_mesh(vis, f"{path}/{int(c):06x}", trimesh.util.concatenate(parts), color=int(c), opacity=opacity)


def show_frame(vis: meshcat.Visualizer, path: str, pose: np.ndarray, length: float = 0.05) -> None:
    """An RGB triad for x, y, z at a pose."""
    vis[path].set_object(g.triad(length))
    vis[path].set_transform(np.asarray(pose, dtype=np.float64))


def frame_camera(vis: meshcat.Visualizer, center: np.ndarray, radius: float) -> None:
    """Aim the default camera at `center` from about 3 radii away (meshcat's camera frame is y-up)."""
    c = np.asarray(center, dtype=np.float64)
    vis["/Cameras/default"].set_transform(tf.translation_matrix(c))
    d = 3.0 * max(float(radius), 0.01)
    vis["/Cameras/default/rotated/<object>"].set_property("position", [0.8 * d, 0.6 * d, 0.8 * d])


def static_html(vis: meshcat.Visualizer, out: str | Path) -> Path:
    """Write the scene (with any animation) as one HTML file that opens without a server."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(vis.static_html())
    return out


def grasp_scene(obj: ObjectModel, gripper: Gripper, poses: np.ndarray, widths: np.ndarray, out: str | Path,
                limit: int = 200) -> Path:
    """The object with up to `limit` of its grasps (green hands at their jaw widths) as an HTML file."""
    vis = new_scene()
    show_mesh(vis, "object", obj.mesh, color=GREY)
    show_points(vis, "com", obj.com[None], color=0xFF0000, size=0.006)
    show_grippers(vis, "grasps", gripper, poses, widths, colors=GREEN, opacity=0.25, limit=limit)
    frame_camera(vis, obj.mesh.bounds.mean(axis=0), float(obj.mesh.scale) + 0.1)
    return static_html(vis, out)


def table_mesh(size: tuple[float, float] = (1.2, 1.0), thickness: float = 0.02, center: tuple[float, float] = (0.5, 0.0)) -> trimesh.Trimesh:
    """A thin table box whose top is z = 0."""
    return trimesh.creation.box((size[0], size[1], thickness), transform=trimesh.transformations.translation_matrix(
        (center[0], center[1], -thickness / 2)))


def save_scene(vis, out: str | Path) -> Path:
    """The current scene as static HTML (opens without a server)."""
    return static_html(vis, out)
