"""An independent check of regrasp plans (Wan & Harada, Section V: what a returned plan must satisfy).

Nothing here goes through the planner's kinematics or collision code: forward kinematics comes from the robot's
URDF text with pinocchio directly (every joint not named in the plan at its neutral value or its stored locked
value, TCP = base @ tip frame @ mount, as the `robot` table documents); joint limits from the same URDF; collisions from its own python-fcl
objects built from the URDF's collision meshes and primitives, the table slab of the scene, the object mesh and
the gripper's collision mesh at full opening; stability from the object's convex hull in the world (the centre
of mass must project inside the support polygon of the hull vertices within 0.1 mm of the table).

Checks, per plan: the step sequence (pick, then transfer / regrasp pairs, then place); each joint vector is
finite, within limits and reproduces its TCP pose (grasp, approach = backed off by handx along the TCP's -z,
retract = approach raised by worldz, worlda = the grasp raised by worlda along world z with the part held,
worldaworldz = that raised by worldz; the part moves with the hand at the last two, so it leaves and reaches the
table only vertically); no arm-table, gripper-table or arm-object collision (the object at the
step's pose); every object pose rests on the table and is stable; the object stays put between a transfer and
its regrasp; the grasp (object in the TCP frame, from forward kinematics) is unchanged along each transfer;
the object starts at the start pose and ends at the goal pose.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from workbench.errors import PlanningError
from workbench.resources import erd_share


@dataclass
class ValidationReport:
    """The outcome of `PlanValidator.check`: ok, the failed checks (one line each) and how many checks ran."""

    ok: bool
    errors: list[str] = field(default_factory=list)
    checks: int = 0

    def raise_if_failed(self) -> None:
        if not self.ok:
            raise PlanningError(f"plan fails validation ({len(self.errors)} problem(s)): {self.errors[0]}")


def _inv(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = (np.trace(a[:3, :3].T @ b[:3, :3]) - 1.0) / 2.0
    return float(np.arccos(np.clip(c, -1.0, 1.0)))


def _fcl_mesh(vertices: np.ndarray, faces: np.ndarray):
    import fcl

    m = fcl.BVHModel()
    m.beginModel(len(vertices), len(faces))
    m.addSubModel(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int32))
    m.endModel()
    return m


def _fcl_geometry(go) -> Any:
    """A python-fcl geometry for a pinocchio GeometryObject (mesh file or primitive)."""
    import fcl

    path = getattr(go, "meshPath", "")
    if path and not path.startswith("BOX") and not path.startswith("SPHERE"):
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception:
            mesh = None
        if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces):
            mesh = mesh.copy()
            mesh.apply_scale(np.asarray(go.meshScale, dtype=np.float64))
            return _fcl_mesh(mesh.vertices, mesh.faces)
    g = go.geometry
    kind = type(g).__name__
    if hasattr(g, "halfSide"):
        return fcl.Box(*(2 * np.asarray(g.halfSide, dtype=np.float64)))
    if kind == "Sphere":
        return fcl.Sphere(float(g.radius))
    if kind == "Cylinder":
        return fcl.Cylinder(float(g.radius), 2 * float(g.halfLength))
    if kind == "Capsule":
        return fcl.Capsule(float(g.radius), 2 * float(g.halfLength))
    raise PlanningError(f"validator: collision geometry {go.name} of type {kind} is not supported")


class PlanValidator:
    """Checks plans for one robot (URDF text, tip frame, mount, base, joint names), table, object and gripper.

    `hand_links`: link-name prefixes of the robot's own hand, replaced by the planning gripper (their geometry is
    not checked); `table`: (x_min, y_min), (x_max, y_max) of the table top (z = 0) and its thickness;
    `free_poses`: {idfreetabletopplacement: rotmat} to recompute start and goal poses; `locked`: {joint: value} of
    joints outside the plan's that are not at their neutral value (a humanoid's other arm tucked away)."""

    def __init__(self, urdf: str, tip_frame: str, mount: np.ndarray, base: np.ndarray, joint_names: list[str],
                 table: tuple, object_vertices: np.ndarray, object_faces: np.ndarray, object_com: np.ndarray,
                 gripper_mesh: trimesh.Trimesh, hand_links: tuple[str, ...] = (), free_poses: dict | None = None,
                 package_dirs: tuple[str, ...] = (), locked: dict | None = None, tol_pos: float = 5e-4, tol_rot: float = 5e-3,
                 tol_grasp: float = 2e-3):
        import fcl
        import pinocchio as pin

        self.pin, self.fcl = pin, fcl
        self.model = pin.buildModelFromXML(urdf)
        self.data = self.model.createData()
        if not self.model.existFrame(tip_frame):
            raise PlanningError(f"validator: the robot URDF has no frame {tip_frame!r}")
        self.tip = self.model.getFrameId(tip_frame)
        self.mount = np.asarray(mount, dtype=np.float64).reshape(4, 4)
        self.base = np.asarray(base, dtype=np.float64).reshape(4, 4)
        self.joint_names = list(joint_names)
        missing = [j for j in self.joint_names if not self.model.existJointName(j)]
        if missing:
            raise PlanningError(f"validator: joints {missing} are not in the robot URDF")
        jids = [self.model.getJointId(j) for j in self.joint_names]
        self.idx_q = np.array([self.model.joints[j].idx_q for j in jids])
        self.lower = np.asarray(self.model.lowerPositionLimit)[self.idx_q]
        self.upper = np.asarray(self.model.upperPositionLimit)[self.idx_q]
        self.q_ref = pin.neutral(self.model)
        for name, value in (locked or {}).items():
            if not self.model.existJointName(name):
                raise PlanningError(f"validator: locked joint {name!r} is not in the robot URDF")
            self.q_ref[self.model.joints[self.model.getJointId(name)].idx_q] = float(value)
        self.tol_pos, self.tol_rot, self.tol_grasp = tol_pos, tol_rot, tol_grasp
        # geometry moved by the arm's joints, without the robot's own hand
        geom = pin.buildGeomFromUrdfString(self.model, urdf, pin.COLLISION, package_dirs=list(package_dirs))
        self.geom, self.gdata = geom, pin.GeometryData(geom)
        arm = set(jids)
        parents = _link_parents(urdf)
        self.parts = []
        for k, go in enumerate(geom.geometryObjects):
            support = set(self.model.supports[go.parentJoint]) if go.parentJoint > 0 else set()
            if not (support & arm):
                continue
            link = self.model.frames[go.parentFrame].name
            if any(_in_subtree(link, p, parents) for p in hand_links):
                continue
            self.parts.append((k, go.name, fcl.CollisionObject(_fcl_geometry(go), fcl.Transform())))
        gm = gripper_mesh
        self.gripper = fcl.CollisionObject(_fcl_mesh(gm.vertices, gm.faces), fcl.Transform())
        (x0, y0), (x1, y1), thick = table
        self.table = fcl.CollisionObject(fcl.Box(x1 - x0, y1 - y0, thick), fcl.Transform(np.array([(x0 + x1) / 2, (y0 + y1) / 2, -thick / 2])))
        self.table_box = (np.array([x0, y0, -thick]), np.array([x1, y1, 0.0]))
        self.obj_vertices = np.asarray(object_vertices, dtype=np.float64)
        self.obj = fcl.CollisionObject(_fcl_mesh(self.obj_vertices, object_faces), fcl.Transform())
        self.com = np.asarray(object_com, dtype=np.float64)
        self.hull = self.obj_vertices[ConvexHull(self.obj_vertices).vertices]
        self.free_poses = {int(k): np.asarray(v, dtype=np.float64).reshape(4, 4) for k, v in (free_poses or {}).items()}

    # -- primitives ------------------------------------------------------------------------------------------------

    def full_q(self, q: np.ndarray) -> np.ndarray:
        full = self.q_ref.copy()
        full[self.idx_q] = q
        return full

    def fk(self, q: np.ndarray) -> np.ndarray:
        """TCP pose in the world of a joint vector (pinocchio on the URDF)."""
        pin = self.pin
        pin.framesForwardKinematics(self.model, self.data, self.full_q(q))
        return self.base @ np.asarray(self.data.oMf[self.tip].homogeneous) @ self.mount

    def collisions(self, q: np.ndarray, object_pose: np.ndarray | None) -> list[str]:
        """Names of what collides at `q`: arm links with the table or the object, the gripper with the table."""
        pin, fcl = self.pin, self.fcl
        full = self.full_q(q)
        pin.forwardKinematics(self.model, self.data, full)
        pin.updateFramePlacements(self.model, self.data)
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata)
        req = fcl.CollisionRequest()
        out = []
        if object_pose is not None:
            self.obj.setTransform(fcl.Transform(object_pose[:3, :3], object_pose[:3, 3]))
        for k, name, cobj in self.parts:
            m = self.base @ np.asarray(self.gdata.oMg[k].homogeneous)
            cobj.setTransform(fcl.Transform(m[:3, :3], m[:3, 3]))
            if fcl.collide(cobj, self.table, req, fcl.CollisionResult()):
                out.append(f"{name} hits the table")
            if object_pose is not None and fcl.collide(cobj, self.obj, req, fcl.CollisionResult()):
                out.append(f"{name} hits the object")
        tcp = self.base @ np.asarray(self.data.oMf[self.tip].homogeneous) @ self.mount
        self.gripper.setTransform(fcl.Transform(tcp[:3, :3], tcp[:3, 3]))
        if fcl.collide(self.gripper, self.table, req, fcl.CollisionResult()):
            out.append("the gripper hits the table")
        return out

    def stability(self, pose: np.ndarray, tol: float = 1e-4) -> tuple[bool, str]:
        """Whether the object at `pose` rests on the table (its lowest point within `tol` of z = 0) with its centre
        of mass strictly over the support polygon: the convex hull of the hull vertices within `tol` (0.1 mm, a
        flatness tolerance: a slightly curved face rests on its near-touching vertices) of the table. Returns the
        reason when not."""
        pts = self.hull @ pose[:3, :3].T + pose[:3, 3]
        zmin = float(pts[:, 2].min())
        if abs(zmin) > tol:
            return False, f"its lowest point is at z = {zmin * 1000:.2f} mm, not on the table"
        contact = pts[pts[:, 2] <= zmin + tol][:, :2]
        com = pose[:3, :3] @ self.com + pose[:3, 3]
        if len(contact) < 3:
            return False, f"it touches the table at {len(contact)} point(s), no support polygon"
        try:
            hull = ConvexHull(contact)
        except Exception:
            return False, "its support points are collinear, no support polygon"
        margin = float(np.min(-(hull.equations[:, :2] @ com[:2] + hull.equations[:, 2])))
        if margin <= 1e-6:
            return False, f"its centre of mass is {-margin * 1000:.1f} mm outside the support polygon"
        return True, ""

    # -- the plan ----------------------------------------------------------------------------------------------------

    def check(self, plan) -> ValidationReport:
        """Every check of the module docstring on one plan (a `workbench.plans.Plan`)."""
        errors: list[str] = []
        n = 0

        def need(cond: bool, msg: str) -> None:
            nonlocal n
            n += 1
            if not cond:
                errors.append(msg)

        steps = plan.steps
        kinds = [s.kind for s in steps]
        ok_seq = (len(kinds) >= 2 and kinds[0] == "pick" and kinds[-1] == "place" and len(kinds) % 2 == 0
                  and all(kinds[i] == "transfer" and kinds[i + 1] == "regrasp" for i in range(1, len(kinds) - 1, 2)))
        need(ok_seq, f"step sequence {kinds} is not pick, (transfer, regrasp)*, place")
        if list(plan.joint_names) != self.joint_names:
            need(False, f"plan joints {plan.joint_names} differ from the robot's {self.joint_names}")
            return ValidationReport(False, errors, n)
        for i, s in enumerate(steps):
            tag = f"step {i + 1} ({s.kind})"
            tcp = np.asarray(s.tcp, dtype=np.float64)
            obj = np.asarray(s.object_pose, dtype=np.float64)
            need(np.allclose(obj @ s.grasp, tcp, atol=1e-6), f"{tag}: its TCP pose is not the object pose times its grasp")
            back = tcp.copy()
            back[:3, 3] -= plan.handx * tcp[:3, 2]
            up = back.copy()
            up[2, 3] += plan.worldz
            lift = np.eye(4)
            lift[2, 3] = plan.worlda            # the held part lifted straight up, then by worldz more
            lift2 = np.eye(4)
            lift2[2, 3] = plan.worlda + plan.worldz
            for label, q, target, at in (("grasp", s.q_grasp, tcp, obj), ("approach", s.q_approach, back, obj),
                                         ("retract", s.q_retract, up, obj), ("worlda", s.q_worlda, lift @ tcp, lift @ obj),
                                         ("worldaworldz", s.q_worldaworldz, lift2 @ tcp, lift2 @ obj)):
                q = np.asarray(np.nan if q is None else q, dtype=np.float64)
                if q.shape != (len(self.joint_names),) or not np.isfinite(q).all():
                    need(False, f"{tag}: the {label} joint vector is missing, has NaN or the wrong length")
                    continue
                low, high = q < self.lower - 1e-9, q > self.upper + 1e-9
                need(not (low | high).any(), f"{tag}: {label} joints {[self.joint_names[j] for j in np.flatnonzero(low | high)]} "
                     f"are outside their limits")
                f = self.fk(q)
                dp, dr = float(np.linalg.norm(f[:3, 3] - target[:3, 3])), _angle(f, target)
                need(dp <= self.tol_pos and dr <= self.tol_rot,
                     f"{tag}: the {label} configuration reaches a TCP {dp * 1000:.2f} mm / {np.degrees(dr):.2f} deg from its pose")
                hits = self.collisions(q, at)
                need(not hits, f"{tag}: at the {label} configuration {', '.join(hits)}")
            stable, why = self.stability(obj)
            need(stable, f"{tag}: the object pose is not a stable placement: {why}")
        # the object stays put while released, the grasp is constant while carried
        for i in range(1, len(steps) - 1, 2):
            a, b = steps[i], steps[i + 1]
            need(np.allclose(a.object_pose, b.object_pose, atol=1e-6),
                 f"step {i + 2} (regrasp): the object moved while released at step {i + 1}")
        for i in range(0, len(steps) - 1, 2):
            a, b = steps[i], steps[i + 1]  # picked at a (pick / regrasp), put down at b (transfer / place)
            need(a.idfreeairgrip == b.idfreeairgrip and np.allclose(a.grasp, b.grasp, atol=1e-6),
                 f"steps {i + 1}-{i + 2}: the grasp changes along the transfer ({a.idfreeairgrip} -> {b.idfreeairgrip})")
            qa, qb = np.asarray(a.q_grasp, dtype=np.float64), np.asarray(b.q_grasp, dtype=np.float64)
            if np.isfinite(qa).all() and np.isfinite(qb).all() and qa.shape == qb.shape == (len(self.joint_names),):
                ga = _inv(self.fk(qa)) @ np.asarray(a.object_pose)
                gb = _inv(self.fk(qb)) @ np.asarray(b.object_pose)
                dp, dr = float(np.linalg.norm(ga[:3, 3] - gb[:3, 3])), _angle(ga, gb)
                need(dp <= self.tol_grasp and dr <= 5 * self.tol_rot,
                     f"steps {i + 1}-{i + 2}: the object moves in the hand along the transfer ({dp * 1000:.1f} mm, {np.degrees(dr):.1f} deg)")
        # start and goal
        for label, query, pose, step in (("start", plan.start, plan.start_pose, steps[0] if steps else None),
                                         ("goal", plan.goal, plan.goal_pose, steps[-1] if steps else None)):
            if step is None:
                continue
            expect = np.asarray(pose, dtype=np.float64)
            free = self.free_poses.get(int(query.idfreetabletopplacement))
            if free is not None:
                c, s_ = np.cos(query.yaw), np.sin(query.yaw)
                move = np.array([[c, -s_, 0, query.x], [s_, c, 0, query.y], [0, 0, 1, 0], [0, 0, 0, 1.0]])
                expect = move @ free
                need(np.allclose(expect, pose, atol=1e-6), f"the plan's {label} pose is not its query {query.text()}")
            else:
                need(not self.free_poses, f"the {label} placement {query.idfreetabletopplacement} is not a stable placement")
            need(np.allclose(step.object_pose, expect, atol=1e-6),
                 f"the object is not at the {label} pose at the {'first' if label == 'start' else 'last'} step")
        return ValidationReport(not errors, errors, n)


def _link_parents(urdf: str) -> dict[str, str]:
    """child link -> parent link of every URDF joint."""
    root = ET.fromstring(urdf)
    out = {}
    for j in root.iter("joint"):
        p, c = j.find("parent"), j.find("child")
        if p is not None and c is not None:
            out[c.get("link")] = p.get("link")
    return out


def _in_subtree(link: str, prefix: str, parents: dict[str, str]) -> bool:
    """Whether `link` or one of its ancestors starts with `prefix`."""
    seen = 0
    while link is not None and seen < 1000:
        if link.startswith(prefix):
            return True
        link = parents.get(link)
        seen += 1
    return False


def validator_from_rows(rows: dict, free_poses: dict | None = None) -> PlanValidator:
    """A validator rebuilt from stored rows only (`robot`, `scene`, `object`, `gripper` as the store returns them:
    URDF text, frames, mount, base, joint names, locked joints, dropped hand links, mesh folders; the table; the
    object's mesh and centre of mass; the gripper's collision mesh), so it shares no code or object with the
    planner. `free_poses`: {idfreetabletopplacement: rotmat} of the stable placements."""
    r, sc, obj, grip = rows["robot"], rows["scene"], rows["object"], rows.get("gripper")
    if grip is None or grip.get("collision_vertices") is None:
        raise PlanningError("validator: the store has no collision mesh of the robot's gripper (a store written by an "
                            "older version); rebuild the IK stage in a new store")
    scene = sc.scene
    table = (tuple(scene.table_min), tuple(scene.table_max), float(scene.table_thickness))
    gripper = trimesh.Trimesh(grip["collision_vertices"], grip["collision_faces"], process=False)
    return PlanValidator(r["urdf"], r["tip_frame"], r["mount"], r["base"], r["joint_names"], table,
                         np.asarray(obj["vertices"], dtype=np.float64), np.asarray(obj["faces"], dtype=np.int64),
                         np.asarray(obj["com"], dtype=np.float64), gripper, hand_links=tuple(r.get("drop_geometry") or ()),
                         free_poses=free_poses, package_dirs=(str(erd_share()), *(r.get("package_dirs") or ())),
                         locked=dict(r.get("locked") or {}))
