"""A robot in meshcat at joint configurations (Wan & Harada Section IV, Fig. 6(e)-(g): feasible IKs).

The URDF's visual meshes (DAE/STL/OBJ files are sent as they are; boxes and cylinders as primitives) or its
collision geometry, placed by pinocchio's forward kinematics of the robot's reduced model, plus the planning
gripper's visual meshes at the TCP with the jaw at a given width. `RobotView.show(q)` moves it; `animate(qs)`
plays a list of configurations; `show_table` draws a scene's table slab.
"""

from __future__ import annotations

from pathlib import Path

import meshcat
import meshcat.geometry as g
import numpy as np

from ..kinematics import Scene
from ..robots import Robot
from . import GREY, ORANGE

_FILES = {".dae": g.DaeMeshGeometry, ".stl": g.StlMeshGeometry, ".obj": g.ObjMeshGeometry}
_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # meshcat cylinders run along y


def _geometry(go) -> tuple[object, np.ndarray] | None:
    """A meshcat geometry for a pinocchio GeometryObject and the local transform it needs (scale, axis)."""
    path = go.meshPath or ""
    ext = Path(path).suffix.lower()
    scale = np.diag([*np.asarray(go.meshScale, dtype=np.float64), 1.0])
    if ext in _FILES and Path(path).is_file():
        return _FILES[ext].from_file(path), scale
    geom = go.geometry
    if hasattr(geom, "halfSide"):
        return g.Box(list(2 * np.asarray(geom.halfSide, dtype=np.float64))), np.eye(4)
    if type(geom).__name__ == "Cylinder":
        return g.Cylinder(2 * float(geom.halfLength), float(geom.radius)), _Y_TO_Z
    if type(geom).__name__ == "Sphere":
        return g.Sphere(float(geom.radius)), np.eye(4)
    return None


class RobotView:
    """A robot drawn under `path` in a meshcat visualizer; `kind` is "visual" or "collision" geometry."""

    def __init__(self, vis: meshcat.Visualizer, robot: Robot, path: str = "robot", kind: str = "visual",
                 color: int | None = None, opacity: float = 1.0):
        import pinocchio as pin

        self.vis, self.robot, self.path = vis, robot, path
        self.geom = robot.visual_model() if kind == "visual" else robot.geom
        self.gdata = self.geom.createData()
        self.data = robot.model.createData()
        self.nodes: list[tuple[int, str, np.ndarray]] = []
        vis[path].delete()
        for k, go in enumerate(self.geom.geometryObjects):
            if robot.dropped(go):
                continue
            made = _geometry(go)
            if made is None:
                continue
            obj, local = made
            name = f"{path}/links/{k:03d}_{go.name}"
            if color is None and isinstance(obj, (g.DaeMeshGeometry,)):
                vis[name].set_object(obj)
            else:
                vis[name].set_object(obj, g.MeshLambertMaterial(color=GREY if color is None else color, opacity=opacity,
                                                                transparent=opacity < 1))
            self.nodes.append((k, name, local))
        self.fingers: list[tuple[str, np.ndarray, int]] = []
        for i, v in enumerate(robot.gripper.visuals):
            ext = Path(v.path).suffix.lower()
            if ext not in _FILES or not Path(v.path).is_file():
                continue
            name = f"{path}/gripper/{i}"
            local = v.pose @ np.diag([*v.scale, 1.0])
            if color is None and ext == ".dae":
                vis[name].set_object(_FILES[ext].from_file(v.path))
            else:
                vis[name].set_object(_FILES[ext].from_file(v.path),
                                     g.MeshLambertMaterial(color=ORANGE if color is None else color, opacity=opacity, transparent=opacity < 1))
            self.fingers.append((name, local, v.side))
        self._pin = pin

    def poses(self, q: np.ndarray, width: float | None = None) -> dict[str, np.ndarray]:
        """World transforms of every drawn node at joint vector `q` with the jaw at `width` (default: full opening)."""
        pin, robot = self._pin, self.robot
        q = np.asarray(q, dtype=np.float64)
        pin.forwardKinematics(robot.model, self.data, q)
        pin.updateFramePlacements(robot.model, self.data)
        pin.updateGeometryPlacements(robot.model, self.data, self.geom, self.gdata)
        out = {}
        for k, name, local in self.nodes:
            out[name] = robot.base @ np.asarray(self.gdata.oMg[k].homogeneous) @ local
        tcp = robot.base @ np.asarray(self.data.oMf[robot.tcp_id].homogeneous)
        w = robot.gripper.jaw_max if width is None else float(width)
        for name, local, side in self.fingers:
            shift = np.eye(4)
            shift[1, 3] = side * w / 2
            out[name] = tcp @ shift @ local
        return out

    def show(self, q: np.ndarray, width: float | None = None) -> None:
        """Move the robot to joint vector `q` (robot.joint_names order)."""
        for name, pose in self.poses(q, width).items():
            self.vis[name].set_transform(pose)

    def animate(self, qs: np.ndarray, fps: float = 10.0, widths: np.ndarray | None = None) -> None:
        """Play joint vectors `qs` (T, n) as a meshcat animation (`widths` (T,) jaw openings)."""
        from meshcat.animation import Animation

        anim = Animation(default_framerate=fps)
        for t, q in enumerate(np.asarray(qs, dtype=np.float64)):
            with anim.at_frame(self.vis, t) as frame:
                for name, pose in self.poses(q, None if widths is None else widths[t]).items():
                    frame[name].set_transform(pose)
        self.vis.set_animation(anim)


def show_table(vis: meshcat.Visualizer, scene: Scene, path: str = "table", color: int = 0xC8A878, opacity: float = 0.6) -> None:
    """The scene's table slab (its top at z = 0)."""
    lo = np.array([scene.table_min[0], scene.table_min[1], -scene.table_thickness])
    hi = np.array([scene.table_max[0], scene.table_max[1], 0.0])
    pose = np.eye(4)
    pose[:3, 3] = 0.5 * (lo + hi)
    vis[path].set_object(g.Box(list(hi - lo)), g.MeshLambertMaterial(color=color, opacity=opacity, transparent=opacity < 1))
    vis[path].set_transform(pose)


def show_robot(vis: meshcat.Visualizer, robot: Robot, q: np.ndarray, path: str = "robot", kind: str = "visual",
               width: float | None = None) -> RobotView:
    """Draw `robot` at joint vector `q` and return the view (call `.show(q)` to move it)."""
    view = RobotView(vis, robot, path, kind)
    view.show(q, width)
    return view


# ----------------------------------------------------------------------------------------------------------------
# Reachability views for notebooks/03_reachability.ipynb.

FEASIBLE_ALL, FEASIBLE_GRASP, INFEASIBLE = 0x33AA55, 0xE8B400, 0xDD3333


def feasibility_colors(feasible: np.ndarray) -> np.ndarray:
    """Per grip: green when grasp, handx and handxworldz are feasible, yellow for the grasp only, red otherwise."""
    f = np.asarray(feasible, dtype=bool).reshape(-1, 3)
    return np.where(f.all(1), FEASIBLE_ALL, np.where(f[:, 0], FEASIBLE_GRASP, INFEASIBLE))


def show_roadmap(vis: meshcat.Visualizer, rows: dict[str, np.ndarray], path: str = "roadmap", size: float = 0.006) -> None:
    """The tabletop grips' TCP positions coloured by IK feasibility (Section IV's ik flags over Fig. 7's roadmap)."""
    from . import show_points

    show_points(vis, path, rows["rotmat"][:, :3, 3], feasibility_colors(rows["feasible"]), size=size)


class IKBrowser:
    """The robot at the feasible tabletop grips: a slider over them, a choice of grasp / handx / handxworldz, and the
    object at the grip's placement. `widget` holds the ipywidgets."""

    def __init__(self, vis: meshcat.Visualizer, robot: Robot, rows: dict[str, np.ndarray], obj_mesh, kind: str = "visual"):
        import ipywidgets as w

        from . import show_mesh

        self.vis, self.robot, self.rows, self.mesh = vis, robot, rows, obj_mesh
        self.view = RobotView(vis, robot, "robot", kind)
        self.feasible = np.flatnonzero(np.asarray(rows["feasible"])[:, 0])
        self.slider = w.IntSlider(min=0, max=max(len(self.feasible) - 1, 0), value=0, description="feasible grip",
                                  continuous_update=False, layout=w.Layout(width="520px"))
        self.kind = w.ToggleButtons(options=["grasp", "handx", "handxworldz"], value="grasp")
        self.label = w.HTML()
        self.slider.observe(lambda _: self.update(), names="value")
        self.kind.observe(lambda _: self.update(), names="value")
        self.widget = w.VBox([w.HBox([self.slider, self.kind]), self.label])
        self._show_mesh = show_mesh
        self.update()

    def update(self) -> int | None:
        """Show the selected grip; returns its row index (None when no grip is feasible)."""
        if len(self.feasible) == 0:
            self.label.value = "no feasible grip"
            return None
        i = int(self.feasible[self.slider.value])
        k = ["grasp", "handx", "handxworldz"].index(self.kind.value)
        q = self.rows["joints"][i, k]
        ok = bool(self.rows["feasible"][i, k])
        if not ok:
            q = self.rows["joints"][i, 0]
        self.view.show(q, float(self.rows["jawwidth"][i]) if k == 0 else None)
        self._show_mesh(self.vis, "object", self.mesh, color=0x4477CC, pose=self.rows["placement_rotmat"][i])
        self.label.value = (f"tabletop grip {int(self.rows['idtabletopgrips'][i])}, free-air grasp {int(self.rows['idfreeairgrip'][i])}, "
                            f"position {np.round(self.rows['tabletopposition'][i][:2], 3).tolist()} m; {self.kind.value}: "
                            f"{'feasible' if ok else 'infeasible (showing the grasp)'}; q = {np.round(q, 3).tolist()}")
        return i


def plot_feasibility(rows: dict[str, np.ndarray], title: str = ""):
    """Feasible counts per placement (tabletop placement's free placement and angle) and per grid position."""
    import matplotlib.pyplot as plt

    f = np.asarray(rows["feasible"], dtype=bool)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    key = np.asarray(rows["idtabletopplacements"])
    pos = np.round(np.asarray(rows["tabletopposition"])[:, :2], 4)
    # per free placement and angle: the tabletop placements share the placement's rotation
    rot = np.round(np.asarray(rows["placement_rotmat"])[:, :3, :3].reshape(len(key), 9), 5)
    _, group = np.unique(rot, axis=0, return_inverse=True)
    group = group.ravel()
    n = group.max() + 1 if len(group) else 0
    total = np.bincount(group, minlength=n)
    grasp = np.bincount(group, weights=f[:, 0], minlength=n)
    both = np.bincount(group, weights=f.all(1), minlength=n)
    ax[0].bar(np.arange(n), total, color="#dddddd", label="tabletop grips")
    ax[0].bar(np.arange(n), grasp, color="#e8b400", label="IK feasible (grasp)")
    ax[0].bar(np.arange(n), both, color="#33aa55", label="with handx and handxworldz")
    ax[0].set(xlabel="placement x rotation", ylabel="grips", title="per placement and angle (summed over positions)")
    ax[0].legend(fontsize=8)
    xs, ix = np.unique(pos[:, 0], return_inverse=True)
    ys, iy = np.unique(pos[:, 1], return_inverse=True)
    cnt = np.zeros((len(xs), len(ys)))
    tot = np.zeros((len(xs), len(ys)))
    np.add.at(cnt, (ix.ravel(), iy.ravel()), f.all(1))
    np.add.at(tot, (ix.ravel(), iy.ravel()), 1)
    dx = np.diff(xs).min() / 2 if len(xs) > 1 else 0.025
    dy = np.diff(ys).min() / 2 if len(ys) > 1 else 0.025
    im = ax[1].imshow(np.divide(cnt, tot, out=np.zeros_like(cnt), where=tot > 0).T, origin="lower", vmin=0, vmax=1,
                      cmap="RdYlGn", extent=[xs[0] - dx, xs[-1] + dx, ys[0] - dy, ys[-1] + dy], aspect="auto")
    fig.colorbar(im, ax=ax[1], label="feasible share (all three)")
    ax[1].set(xlabel="x (m)", ylabel="y (m)", title="per position")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
