"""meshcat helpers: meshes, facets, points, normals, the gripper at poses, the table, and static HTML export.

Everything takes a `meshcat.Visualizer` and a scene path; colours are 0xRRGGBB integers. `static_html` writes a
file that opens in a browser without a running server; `grasp_scene` is a ready-made scene for the command line.
"""

from __future__ import annotations

import atexit
import collections
import ctypes
import html
import json
import os
import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace
from urllib.parse import urlparse

import meshcat
import meshcat.visualizer
import msgpack
import meshcat.geometry as g
import meshcat.transformations as tf
import numpy as np
import trimesh
from IPython.display import HTML

from workbench.geometry.objects import ObjectModel
from workbench.robots.gripper import Gripper
from workbench.viewer.captions import CAPTION_SCRIPT

GREEN, RED, GREY, BLUE, ORANGE, WHITE = 0x33AA55, 0xDD3333, 0xB0B0B0, 0x3366DD, 0xFF9922, 0xFFFFFF
HIGHLIGHT = 0xFF00CC  # not in the tab20 palette the facets use


class SceneWindow(meshcat.visualizer.ViewerWindow):
    """meshcat's link to its own server, started so that it ends with this process (on Linux the kernel stops it
    when its parent dies, so a shut-down notebook kernel leaves no server behind); it counts the commands it sends
    by type (`sent["set_object"]`: geometry, `sent["set_transform"]`, `sent["set_property"]`: view-only changes)."""

    def __init__(self) -> None:
        self.server_proc, self.zmq_url, self.web_url = _start_server()
        self.connect_zmq()
        self.sent: collections.Counter = collections.Counter()

    def send(self, command) -> None:
        self.sent[type(command).__name__] += 1
        data = command.lower()
        self.zmq_socket.send_multipart([data["type"].encode("utf-8"), data["path"].encode("utf-8"), _pack(data)])
        self.zmq_socket.recv()

    def close(self) -> None:
        """Stop the server (the scene cannot be used afterwards)."""
        if self.server_proc is not None and self.server_proc.poll() is None:
            self.server_proc.kill()
            self.server_proc.wait()


def _ext(obj):
    if type(obj).__name__ == "Ext" and isinstance(getattr(obj, "type", None), int):  # meshcat's arrays (umsgpack.Ext)
        return msgpack.ExtType(obj.type, obj.data)
    raise TypeError(f"cannot pack {type(obj).__name__} for meshcat")


def _pack(data: dict) -> bytes:
    """meshcat's message bytes, packed by msgpack's compiled packer (meshcat's own is pure Python: a long animation
    took seconds to pack)."""
    return msgpack.packb(data, default=_ext)


def _die_with_parent() -> None:  # runs in the child between fork and exec
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _start_server() -> tuple[subprocess.Popen, str, str]:
    """meshcat's zmq server as a child process bound to 127.0.0.1 (as `meshcat.servers.zmqserver` starts it, plus
    the parent-death signal)."""
    from meshcat.servers.zmqserver import match_web_url, match_zmq_url

    env = dict(os.environ, PYTHONPATH=str(Path(meshcat.__file__).resolve().parents[1]))
    proc = subprocess.Popen([sys.executable, "-u", "-m", "meshcat.servers.zmqserver"], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, env=env, start_new_session=True,
                            preexec_fn=_die_with_parent if sys.platform.startswith("linux") else None)
    line = ""
    while "zmq_url" not in line:
        line = proc.stdout.readline().strip().decode("utf-8")
        if proc.poll() is not None:
            raise RuntimeError(f"the meshcat server exited with status {proc.returncode}")
    zmq_url = match_zmq_url(line)
    web_url = match_web_url(proc.stdout.readline().strip().decode("utf-8"))
    proc.stdout.close()
    atexit.register(SceneWindow.close, SimpleNamespace(server_proc=proc))
    return proc, zmq_url, web_url


def new_scene(grid: bool = False, axes: bool = False) -> meshcat.Visualizer:
    """A meshcat visualizer with its own server (bound to 127.0.0.1, ended with the kernel); starts empty, without
    meshcat's grid and axes unless asked for. `view(vis)` shows the scene."""
    vis = meshcat.Visualizer(window=SceneWindow())
    vis.delete()
    vis["/Grid"].set_property("visible", bool(grid))
    vis["/Axes"].set_property("visible", bool(axes))
    return vis


def geometry_sent(vis) -> int:
    """How many geometry messages (set_object) the scene's window has sent (0 for a window that does not count)."""
    return int(getattr(vis.window, "sent", {}).get("SetObject", 0))


# The page shown in a notebook output: meshcat's viewer script and websocket reached through the Jupyter server
# (jupyter-server-proxy's /proxy/PORT/), so a JupyterLab opened from another machine shows the scene while the
# kernel's meshcat server stays bound to 127.0.0.1. Outside JupyterLab (no page config) it connects directly.
_VIEW_PAGE = """<!DOCTYPE html><html><head><meta charset="utf-8"><style>body{margin:0}#pane{width:100vw;height:100vh;
overflow:hidden}</style></head><body><div id="pane"></div><script>
(function () {
  var port = PORT, base = null, loc = window.location;
  try {
    var cfg = parent.document.getElementById("jupyter-config-data");
    if (cfg) { base = JSON.parse(cfg.textContent).baseUrl || "/"; loc = parent.location; }
  } catch (e) {}
  var http = base !== null ? base + "proxy/" + port + "/" : "http://127.0.0.1:" + port + "/";
  var ws = base !== null ? (loc.protocol === "https:" ? "wss://" : "ws://") + loc.host + http : "ws://127.0.0.1:" + port + "/";
  var script = document.createElement("script");
  script.src = http + "static/main.min.js";
  script.onload = function () {
    window.viewer = new MeshCat.Viewer(document.getElementById("pane"));
    window.viewer.gui.domElement.style.display = "none";  // meshcat's "Open Controls" bar would cover a corner
    window.viewer.connect(ws);
  };
  script.onerror = function () {
    document.body.innerHTML = "<p style='font-family:sans-serif;padding:1em'>The 3D view cannot reach the kernel's " +
      "meshcat server: " + http + " (is jupyter-server-proxy installed and enabled?)</p>";
  };
  document.head.appendChild(script);
})();
</script>OVERLAY</body></html>"""
_CAPTION_BOXES = ("<div style='position:fixed;left:0;top:0;background:rgba(255,255,255,.88);font:15px sans-serif;"
                  "padding:5px 10px'><b id='wb-caption'></b></div><div id='wb-footer' style='position:fixed;right:0;"
                  "bottom:0;background:rgba(255,255,255,.88);font:13px sans-serif;padding:4px 10px'></div>")


def view(vis: meshcat.Visualizer, height: int = 460, captions: bool = False) -> HTML:
    """The live scene as a notebook output (an IPython HTML object): works on a remote JupyterLab through the Jupyter
    server's proxy; the meshcat server itself listens on 127.0.0.1 only. With `captions`, the caption and footer of
    the animation playing (the track a plan view sets on the scene) are shown over the canvas's corners."""
    port = urlparse(vis.url()).port
    overlay = _CAPTION_BOXES + f"<script>{CAPTION_SCRIPT.replace('TRACK', 'null')}</script>" if captions else ""
    page = _VIEW_PAGE.replace("PORT", json.dumps(int(port))).replace("OVERLAY", overlay)
    return HTML(f'<div class="workbench-view"><iframe srcdoc="{html.escape(page, quote=True)}" '
                f'style="width:100%;height:{int(height)}px;border:1px solid #ddd;resize:vertical"></iframe></div>')


def legend(items: list[tuple[int, str]], title: str = "") -> str:
    """A colour key as HTML: one swatch and label per (0xRRGGBB, label)."""
    chips = "".join(f"<span style='display:inline-block;margin-right:14px;white-space:nowrap'><span style='display:inline-block;"
                    f"width:12px;height:12px;margin-right:5px;vertical-align:-1px;border:1px solid #555;"
                    f"background:#{int(c):06x}'></span>{html.escape(label)}</span>" for c, label in items)
    head = f"<b>{html.escape(title)}</b> " if title else ""
    return f"<div style='line-height:1.8'>{head}{chips}</div>"


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


VIEW_DIRECTION = np.array([0.75, -0.65, 0.55])
"""World direction from the framed work toward the default camera: front right and above."""


def frame_camera(vis: meshcat.Visualizer, center: np.ndarray, radius: float, direction: np.ndarray | None = None) -> None:
    """Aim the default camera at `center` so a sphere of `radius` fills the view (meshcat's 75 degree vertical field
    of view), seen from `direction` (world; default `VIEW_DIRECTION`, from the front right and above)."""
    c = np.asarray(center, dtype=np.float64)
    vis["/Cameras/default"].set_transform(tf.translation_matrix(c))
    d = 1.1 * max(float(radius), 1e-3) / np.sin(np.radians(37.5))
    w = np.asarray(VIEW_DIRECTION if direction is None else direction, dtype=np.float64)
    w = w / max(np.linalg.norm(w), 1e-12)
    pos = d * np.array([w[0], w[2], -w[1]])  # meshcat's rotated camera frame is y-up: world (x, y, z) -> (x, z, -y)
    vis["/Cameras/default/rotated/<object>"].set_property("position", pos.tolist())


def frame_points(vis: meshcat.Visualizer, points: np.ndarray, direction: np.ndarray | None = None) -> None:
    """Frame the camera on everything in `points` (vertices, positions): their bounding sphere fills the view."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lo, hi = p.min(axis=0), p.max(axis=0)
    frame_camera(vis, (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2, direction)


def beside_hand(approach: np.ndarray) -> np.ndarray:
    """A camera direction near the default that looks at a grasp from the fingers' side, not through the hand's
    body (which lies behind the TCP along -`approach`)."""
    a = np.asarray(approach, dtype=np.float64)
    a = a / max(np.linalg.norm(a), 1e-12)
    d = VIEW_DIRECTION / np.linalg.norm(VIEW_DIRECTION)
    side = d - (d @ a) * a
    if np.linalg.norm(side) < 1e-6:
        side = np.cross(a, [0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.cross(a, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    return side + 0.6 * a  # from the side, a little ahead of the jaw


def static_html(vis: meshcat.Visualizer, out: str | Path, title: str | None = None) -> Path:
    """Write the scene (with any animation) as one HTML file that opens without a server; `title` names the page
    (its browser tab) instead of meshcat's "MeshCat"."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    page = vis.static_html()
    if title:
        page = page.replace("<title>MeshCat</title>", f"<title>{html.escape(title)}</title>", 1)
    out.write_text(page)
    return out


def grasp_scene(obj: ObjectModel, gripper: Gripper, poses: np.ndarray, widths: np.ndarray, out: str | Path,
                limit: int = 200) -> Path:
    """The object with up to `limit` of its grasps (green hands at their jaw widths) as an HTML file."""
    vis = new_scene()
    show_mesh(vis, "object", obj.mesh, color=GREY)
    show_points(vis, "com", obj.com[None], color=0xFF0000, size=0.006)
    show_grippers(vis, "grasps", gripper, poses, widths, colors=GREEN, opacity=0.25, limit=limit)
    frame_points(vis, obj.mesh.bounds)
    return static_html(vis, out)


def table_mesh(size: tuple[float, float] = (1.2, 1.0), thickness: float = 0.02, center: tuple[float, float] = (0.5, 0.0)) -> trimesh.Trimesh:
    """A thin table box whose top is z = 0."""
    return trimesh.creation.box((size[0], size[1], thickness), transform=trimesh.transformations.translation_matrix(
        (center[0], center[1], -thickness / 2)))


def save_scene(vis, out: str | Path) -> Path:
    """The current scene as static HTML (opens without a server)."""
    return static_html(vis, out)
