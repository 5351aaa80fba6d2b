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
import trimesh

from workbench.robots.collider import Scene
from workbench.robots.model import Robot
from workbench.viewer.scenes import GREY, ORANGE, show_points

_FILES = {".dae": g.DaeMeshGeometry, ".stl": g.StlMeshGeometry, ".obj": g.ObjMeshGeometry}


_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # meshcat cylinders run along y


def _geometry(go) -> tuple[object, np.ndarray] | None:
    """A meshcat geometry for a pinocchio GeometryObject and the local transform it needs (scale, axis)."""
    path = go.meshPath or ""
    ext = Path(path).suffix.lower()
    scale = np.diag([*np.asarray(go.meshScale, dtype=np.float64), 1.0])
    if ext in _FILES and Path(path).is_file():
        if np.linalg.det(scale) < 0:  # a mirrored mesh (Tiago's): into the vertices, as no rotation can mirror
            mesh = trimesh.load(path, force="mesh")
            mesh.apply_transform(scale)
            return g.TriangularMeshGeometry(mesh.vertices, mesh.faces), np.eye(4)
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
        self._draw_gripper_boxes(path, color, opacity)
        self._pin = pin

    def _draw_gripper_boxes(self, path: str, color: int | None, opacity: float) -> None:
        """The planned gripper's own collision geometry where it has no visual meshes (a spec gripper, a linkage's
        fingers): its palm mesh and its finger boxes, moving with the jaw."""
        gripper = self.robot.gripper
        sides = {side for _, _, side in self.fingers}
        mat = g.MeshLambertMaterial(color=ORANGE if color is None else color, opacity=opacity, transparent=opacity < 1)
        if 0 not in sides:
            name = f"{path}/gripper/body"
            self.vis[name].set_object(g.TriangularMeshGeometry(gripper.body.vertices, gripper.body.faces), mat)
            self.fingers.append((name, np.eye(4), 0))
        if not sides & {1, -1}:
            for i, (ext, pose) in enumerate(gripper.finger_poses(0.0)):
                name = f"{path}/gripper/finger{i}"
                self.vis[name].set_object(g.Box(ext.tolist()), mat)
                self.fingers.append((name, pose, 1 if pose[1, 3] > 0 else -1))

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


FEASIBLE_ALL, FEASIBLE_GRASP, INFEASIBLE = 0x33AA55, 0xE8B400, 0xDD3333


def feasibility_colors(feasible: np.ndarray) -> np.ndarray:
    """Per grip: green when all poses (grasp, retractions, lifts) are feasible, yellow for the grasp only, red otherwise."""
    f = np.asarray(feasible, dtype=bool)
    f = f.reshape(len(f), -1)
    return np.where(f.all(1), FEASIBLE_ALL, np.where(f[:, 0], FEASIBLE_GRASP, INFEASIBLE))


def show_roadmap(vis: meshcat.Visualizer, rows: dict[str, np.ndarray], path: str = "roadmap", size: float = 0.006) -> None:
    """The tabletop grips' TCP positions coloured by IK feasibility (Section IV's ik flags over Fig. 7's roadmap)."""

    show_points(vis, path, rows["rotmat"][:, :3, 3], feasibility_colors(rows["feasible"]), size=size)
