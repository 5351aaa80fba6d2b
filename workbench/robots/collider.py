"""Collision checks of a robot at joint configurations (Section IV's IK feasibility): the arm and the planning
gripper against the table slab of a `Scene`, the arm against the object at its placement, with python-fcl on the
URDF's collision geometry (the robot's own hand replaced by the planning gripper). A compiled broad phase
(`robots._collidekernel`) settles most configurations from the parts' boxes and hull vertices; fcl tests the rest.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import trimesh

from workbench.geometry.collision import (
    box,
    bvh,
    collide,
    collision_object,
    pinocchio_geometry,
    set_pose,
)
from workbench.params import Params, param
from workbench.robots._collidekernel import HIT, OPEN, classify_rows
from workbench.robots.chain import _kernel_chain, forward
from workbench.robots.model import Robot


@dataclass(frozen=True)
class Scene(Params):
    """The table in the world (its top is z = 0) and the workspace box for the pre-filter, in metres.

    `table_min`/`table_max` are the table top's x-y corners; the slab is `table_thickness` thick.
    `workspace_min`/`workspace_max` bound the TCP position of poses worth solving."""

    table_min: tuple[float, float] = param((-0.3, -0.8), ge=-10, le=10, unit="m", help="table corner (x, y)", flag="--table")
    table_max: tuple[float, float] = param((1.0, 0.8), ge=-10, le=10, unit="m", help="table corner (x, y)", flag="--table")
    table_thickness: float = param(0.05, gt=0, le=1, unit="m", help="table slab thickness")
    workspace_min: tuple[float, float, float] = param((-1.5, -1.5, 0.0), ge=-10, le=10, unit="m", help="workspace box corner")
    workspace_max: tuple[float, float, float] = param((1.5, 1.5, 1.5), ge=-10, le=10, unit="m", help="workspace box corner")

    def check(self) -> None:
        self.require(len(self.table_min) == 2 and len(self.table_max) == 2 and self.table_max[0] > self.table_min[0]
                     and self.table_max[1] > self.table_min[1], ("table_min", "table_max"),
                     "the table is empty; give XMIN,YMIN,XMAX,YMAX with min < max")

    def as_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}


DEFAULT_SCENES = {
    "panda": Scene(),
    "ur5": Scene(),
    # Talos stands in front of the table: the table starts 0.2 m in front of its pelvis.
    "talos": Scene(table_min=(0.2, -0.8), table_max=(1.2, 0.8)),
}


def default_scene(robot_name: str) -> Scene:
    """The default table for a built-in robot (a table under and in front of it); other robots get `Scene()`."""
    return DEFAULT_SCENES.get(robot_name, Scene())


MARGIN = 1e-5  # m: hull vertices this far inside the table are a contact, this far clear of a box none; fcl between


def _hull_vertices(mesh: trimesh.Trimesh) -> np.ndarray:
    """The vertices of the mesh's convex hull (all its vertices where qhull fails on a flat or tiny mesh)."""
    try:
        return np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
    except Exception:  # noqa: BLE001 - qhull's errors on degenerate input have no common type
        return np.asarray(mesh.vertices, dtype=np.float64)


def _obb(mesh: trimesh.Trimesh, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounding box of `mesh` (axis-aligned in the mesh's frame) placed at `pose`: rotation (3, 3), centre (3,),
    half extents (3,) (plus 0.1 mm)."""
    lo, hi = np.asarray(mesh.bounds, dtype=np.float64)
    centre = pose[:3, :3] @ (0.5 * (lo + hi)) + pose[:3, 3]
    return pose[:3, :3].copy(), centre, 0.5 * (hi - lo) + 1e-4


class Collider:
    """Arm (without its own hand) and planning gripper against the table slab and the object.

    Broad phase: world axis-aligned boxes of each part's oriented bounding box, then for the pairs whose boxes meet,
    the part's convex-hull vertices (compiled, one configuration at a time; `_collidekernel.classify_rows`); narrow
    phase: python-fcl on the URDF's collision geometry for the pairs the vertices leave open. `collides` is the
    same test with the numpy box broad phase and fcl alone."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None):
        self.robot = robot
        joints, obbs, objs, vs_obj, names, verts, exact = [], [], [], [], [], [], []
        for k in robot.arm_geometry():
            go = robot.geom.geometryObjects[k]
            g, mesh = pinocchio_geometry(go)
            pl = np.asarray(go.placement.homogeneous)
            joints.append(go.parentJoint - 1)
            obbs.append(_obb(mesh, pl))
            objs.append((pl, collision_object(g)))
            vs_obj.append(True)
            names.append(go.name)
            # a cylinder's, sphere's or capsule's mesh is inscribed in the shape: its vertices bound nothing
            exact.append(type(g).__name__ in ("BVHModel", "Box"))
            verts.append(_hull_vertices(mesh) @ pl[:3, :3].T + pl[:3, 3])
        grip = robot.gripper.collision_mesh()
        joints.append(robot.nq - 1)
        obbs.append(_obb(grip, robot.tip_in_joint))
        objs.append((robot.tip_in_joint, collision_object(bvh(grip))))
        vs_obj.append(False)
        names.append("gripper")
        exact.append(True)
        tip = robot.tip_in_joint
        verts.append(_hull_vertices(grip) @ tip[:3, :3].T + tip[:3, 3])
        self.verts = np.ascontiguousarray(np.concatenate(verts))
        self.vstart = np.cumsum([0] + [len(v) for v in verts]).astype(np.int64)
        self.exact = np.array(exact)
        self.names = names
        self.joint = np.array(joints)
        self.parts = objs
        self.obb_r = np.array([o[0] for o in obbs])
        self.obb_c = np.array([o[1] for o in obbs])
        self.obb_h = np.array([o[2] for o in obbs])
        self.vs_object = np.array(vs_obj)
        tmin = np.array([scene.table_min[0], scene.table_min[1], -scene.table_thickness])
        tmax = np.array([scene.table_max[0], scene.table_max[1], 0.0])
        self.table_box = (tmin, tmax)
        at = np.eye(4)
        at[:3, 3] = 0.5 * (tmin + tmax)
        self.table = collision_object(box(tmax - tmin), at)
        self.obj = None
        self.obj_obb = (np.eye(3), np.zeros(3), np.zeros(3))
        if obj_mesh is not None:
            self.obj = collision_object(bvh(obj_mesh))
            self.obj_obb = _obb(obj_mesh, np.eye(4))

    def fixed_parts_hit_table(self) -> list[str]:
        """Names of the robot's fixed collision objects (base, locked legs) that cut into the table below its top 5 mm."""
        robot = self.robot
        tmin, tmax = self.table_box
        depth = max(tmax[2] - tmin[2] - 0.005, 1e-3)
        at = np.eye(4)
        at[:3, 3] = (0.5 * (tmin[0] + tmax[0]), 0.5 * (tmin[1] + tmax[1]), -0.005 - depth / 2)
        top = collision_object(box(np.array([tmax[0] - tmin[0], tmax[1] - tmin[1], depth])), at)
        out = []
        for k in robot.fixed_geometry():
            go = robot.geom.geometryObjects[k]
            g, _ = pinocchio_geometry(go)
            if collide(collision_object(g, robot.base @ np.asarray(go.placement.homogeneous)), top):
                out.append(go.name)
        return out

    def boxes(self, rot: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per configuration and part: world axis-aligned box (min, max), each (B, P, 3)."""
        rj = rot[:, self.joint]  # (B, P, 3, 3)
        rw = np.einsum("bpij,pjk->bpik", rj, self.obb_r)
        cw = np.einsum("bpij,pj->bpi", rj, self.obb_c) + pos[:, self.joint]
        hw = np.einsum("bpij,pj->bpi", np.abs(rw), self.obb_h)
        return cw - hw, cw + hw

    def collides(self, rot: np.ndarray, pos: np.ndarray, placements: np.ndarray | None,
                 table_only: bool = False) -> np.ndarray:
        """(B,) True where a configuration's arm or gripper hits the table or its arm hits the object placed at
        `placements` (B, 4, 4)."""
        b = len(rot)
        if b == 0:
            return np.zeros(0, dtype=bool)
        lo, hi = self.boxes(rot, pos)
        tmin, tmax = self.table_box
        cand_table = (lo <= tmax).all(-1) & (hi >= tmin).all(-1)
        cand_obj = np.zeros_like(cand_table)
        if self.obj is not None and placements is not None and not table_only:
            orr, oc, oh = self.obj_obb
            rw = placements[:, :3, :3] @ orr
            cw = placements[:, :3, :3] @ oc + placements[:, :3, 3]
            hw = np.einsum("bij,j->bi", np.abs(rw), oh)
            cand_obj = (lo <= (cw + hw)[:, None]).all(-1) & (hi >= (cw - hw)[:, None]).all(-1) & self.vs_object[None]
        return self._narrow(rot, pos, placements, cand_table, cand_obj)

    def _narrow(self, rot: np.ndarray, pos: np.ndarray, placements: np.ndarray | None, cand_table: np.ndarray,
                cand_obj: np.ndarray) -> np.ndarray:
        """(B,) whether fcl finds a contact among the candidate (configuration, part) pairs with the table
        (cand_table (B, P)) and with the object (cand_obj (B, P))."""
        hit = np.zeros(len(rot), dtype=bool)
        for bi, pi in zip(*np.nonzero(cand_table | cand_obj)):
            if hit[bi]:
                continue
            j = self.joint[pi]
            pl, cobj = self.parts[pi]
            set_pose(cobj, rot[bi, j] @ pl[:3, :3], rot[bi, j] @ pl[:3, 3] + pos[bi, j])
            if cand_table[bi, pi] and collide(cobj, self.table):
                hit[bi] = True
                continue
            if cand_obj[bi, pi]:
                p = placements[bi]
                set_pose(self.obj, p[:3, :3], p[:3, 3])
                if collide(cobj, self.obj):
                    hit[bi] = True
        return hit

    def hit_parts(self, q: np.ndarray, placement: np.ndarray | None) -> list[tuple[str, str]]:
        """(part, "table" or "object") for every part that one joint vector `q` (n,) puts into the table or, with the
        object at `placement` (4, 4), into the object (the gripper is never tested against the object it grasps)."""
        rot, pos, _, _ = forward(self.robot, np.atleast_2d(q))
        out = []
        if placement is not None and self.obj is not None:
            set_pose(self.obj, placement[:3, :3], placement[:3, 3])
        for pi, (pl, cobj) in enumerate(self.parts):
            j = self.joint[pi]
            set_pose(cobj, rot[0, j] @ pl[:3, :3], rot[0, j] @ pl[:3, 3] + pos[0, j])
            if collide(cobj, self.table):
                out.append((self.names[pi], "table"))
            if placement is not None and self.obj is not None and self.vs_object[pi] and collide(cobj, self.obj):
                out.append((self.names[pi], "object"))
        return out

    def collides_q(self, q: np.ndarray, placements: np.ndarray | None, table_only: bool = False) -> np.ndarray:
        """`collides` for joint vectors (B, n): the compiled broad phase, then fcl on the pairs it leaves open."""
        q = np.ascontiguousarray(np.atleast_2d(np.asarray(q, dtype=np.float64)))
        pl = None if placements is None else np.ascontiguousarray(np.asarray(placements, dtype=np.float64).reshape(-1, 4, 4))
        with_obj = self.obj is not None and pl is not None and not table_only
        places = pl if with_obj else np.empty((0, 4, 4))
        status = np.empty(len(q), dtype=np.int8)
        open_table = np.empty((len(q), len(self.parts)), dtype=bool)
        open_obj = np.empty_like(open_table)
        base, chain_pl, axis, prism, _ = _kernel_chain(self.robot)
        tmin, tmax = self.table_box
        orr, oc, oh = self.obj_obb
        classify_rows(q, base, chain_pl, axis, prism, self.joint, self.obb_r, self.obb_c, self.obb_h, self.vstart,
                      self.verts, self.exact, self.vs_object, tmin, tmax, places, orr, oc, oh, MARGIN, status,
                      open_table, open_obj)
        hit = status == HIT
        rows = np.flatnonzero(status == OPEN)
        if len(rows):
            rot, pos, _, _ = forward(self.robot, q[rows])
            hit[rows] = self._narrow(rot, pos, pl[rows] if with_obj else None, open_table[rows], open_obj[rows])
        return hit
