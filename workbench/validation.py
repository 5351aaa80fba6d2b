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
table only vertically, except where a step names its own `lift`, an insertion run backwards: worlda is then the
grasp moved by it); no arm-table, gripper-table or arm-object collision (the object at the
step's pose); every object pose rests on the table and is stable; the object stays put between a transfer and
its regrasp; the grasp (object in the TCP frame, from forward kinematics) is unchanged along each transfer;
the object starts at the start pose and ends at the goal pose.

Motions (CONVENTIONS.md, Plans and motions), `TrajectoryValidator`: a plan is executable only with its
timed trajectory, checked at every knot (knots at most 1 degree apart in every joint and 5 mm of TCP travel):
times increase and segments join without jumps, rest at both ends; positions, velocities (URDF) and
accelerations (the plan's limits, from knot velocity differences) within limits, positions consistent with
velocities; no self-collision of the arm and gripper (the gripper's body and fingers apart, the allowed link pairs
of the robot row, extended with the links joined by one URDF joint and links that never move relative to each
other); arm, gripper and held object clear of the table (the held object may touch it within 1 mm); with an empty
hand, arm and gripper clear of the object where it rests (the fingers may touch it on the segments that reach or
leave the step's grasp pose, as CONVENTIONS.md allows), the fingers at each segment's jaw width (the empty hand's
pre-grasp opening, never narrower than the grasp's); the object is held exactly between a pick / regrasp and
the next transfer / place (or from the first knot, at the first grasp, when the plan says it starts holding the
part, and to the last knot, at the last grasp, when it says it ends holding it); the jaw acts at the step's grasp
pose. The only planner output it takes as data is the
robot row's allowed pairs.
"""

from __future__ import annotations

import json
import math
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
    joints outside the plan's that are not at their neutral value (a humanoid's other arm tucked away); `jaw`: the
    gripper's (min, max) opening, which every step's jaw width must lie within."""

    def __init__(self, urdf: str, tip_frame: str, mount: np.ndarray, base: np.ndarray, joint_names: list[str],
                 table: tuple, object_vertices: np.ndarray, object_faces: np.ndarray, object_com: np.ndarray,
                 gripper_mesh: trimesh.Trimesh, hand_links: tuple[str, ...] = (), free_poses: dict | None = None,
                 package_dirs: tuple[str, ...] = (), locked: dict | None = None, tol_pos: float = 5e-4, tol_rot: float = 5e-3,
                 tol_grasp: float = 2e-3, jaw: tuple[float, float] | None = None):
        import fcl
        import pinocchio as pin

        self.pin, self.fcl = pin, fcl
        self.jaw = jaw
        self.model = pin.buildModelFromXML(urdf)
        self.data = self.model.createData()
        if not self.model.existFrame(tip_frame):
            raise PlanningError(f"validator: the robot URDF has no frame {tip_frame!r}")
        kinds = (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT, pin.FrameType.JOINT)
        self.tip = next(self.model.getFrameId(tip_frame, k) for k in kinds if self.model.existFrame(tip_frame, k))
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
            # the held part lifted straight up by worlda (or back along the step's insertion, `lift`), then by worldz
            move = np.array([0.0, 0.0, plan.worlda]) if getattr(s, "lift", None) is None else np.asarray(s.lift, dtype=np.float64)
            lift, lift2 = np.eye(4), np.eye(4)
            lift[:3, 3] = move
            lift2[:3, 3] = move + [0.0, 0.0, plan.worldz]
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
            if self.jaw is not None:
                need(self.jaw[0] - 1e-9 <= s.jawwidth <= self.jaw[1] + 1e-9,
                     f"{tag}: jaw width {s.jawwidth * 1000:.1f} mm is outside the gripper's stroke "
                     f"{self.jaw[0] * 1000:.1f}-{self.jaw[1] * 1000:.1f} mm")
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


ONE_DEGREE = math.radians(1.0)
TCP_STEP = 0.005  # m


class TrajectoryValidator:
    """Checks timed segments against a `PlanValidator` (URDF model, table, object) plus the gripper's body and
    fingers (meshes in the TCP frame at full opening `jaw_max`; each segment's fingers are moved to its jaw width,
    the left one (+y) and the right one apart), the allowed self-collision link pairs, and the acceleration limits
    (rad/s^2) the plan was timed with."""

    GRIPPER_HAND = "gripper_hand"
    GRIPPER_FINGERS = "gripper_fingers"

    def __init__(self, pv, hand_mesh: trimesh.Trimesh, finger_mesh: trimesh.Trimesh, allowed: list[tuple[str, str]],
                 acc_limits: np.ndarray | float, table_tol: float = 1e-3, urdf: str | None = None, obstacles: tuple = (),
                 jaw_max: float | None = None):
        """`obstacles`: (mesh, world pose) pairs fixed in the world (a task's pick-up and destination), which the
        arm, the hand and the held object must not touch."""
        import fcl

        self.pv, self.fcl = pv, fcl
        model = pv.model
        self.vlim = np.asarray(model.velocityLimit)[pv.idx_q]
        self.alim = np.broadcast_to(np.asarray(acc_limits, dtype=np.float64), (len(pv.joint_names),)).copy()
        self.table_tol = float(table_tol)
        arm = {model.getJointId(j) for j in pv.joint_names}
        # every collision object of the URDF except the robot's own hand: moving (some arm joint supports it) or fixed
        self.parts = []  # (geometry index, link, moving joint id or 0, fcl object)
        moving_of = {}
        for k, go in enumerate(pv.geom.geometryObjects):
            link = model.frames[go.parentFrame].name
            if any(k == kk for kk, _, _ in pv.parts):
                j = max(set(model.supports[go.parentJoint]) & arm)
            else:
                support = set(model.supports[go.parentJoint]) if go.parentJoint > 0 else set()
                if support & arm:
                    continue  # the robot's own hand (moved by the arm but not among the validator's arm parts)
                j = 0
            moving_of[link] = j
            obj = next((c for kk, _, c in pv.parts if kk == k), None)
            if obj is None:
                obj = fcl.CollisionObject(_fcl_geometry(go), fcl.Transform())
            self.parts.append((k, link, j, obj))
        tip_joint = max(set(model.supports[model.frames[pv.tip].parentJoint]) & arm)
        self.hand = fcl.CollisionObject(_fcl_mesh(hand_mesh.vertices, hand_mesh.faces), fcl.Transform())
        faces = np.asarray(finger_mesh.faces)
        left = np.asarray(finger_mesh.vertices)[faces].mean(axis=1)[:, 1] > 0
        halves = [(sign, part) for sign, part in ((1.0, left), (-1.0, ~left)) if part.any()]
        self.finger_side = [sign for sign, _ in halves]
        self.fingers = [fcl.CollisionObject(_fcl_mesh(finger_mesh.vertices, faces[part]), fcl.Transform())
                        for _, part in halves]
        self.jaw_max = jaw_max
        moving_of[self.GRIPPER_HAND] = moving_of[self.GRIPPER_FINGERS] = tip_joint
        # adjacency from the URDF XML: links joined by one joint (fixed joints merged into their parent)
        root = ET.fromstring(urdf) if urdf else None
        parent = {}
        if root is not None:
            for j in root.iter("joint"):
                p, c = j.find("parent"), j.find("child")
                if p is not None and c is not None:
                    parent[c.get("link")] = (p.get("link"), j.get("type"))
        tip_link = model.frames[pv.tip].name

        def body(link: str) -> str:
            n = 0
            while link in parent and parent[link][1] == "fixed" and n < 1000:
                link, n = parent[link][0], n + 1
            return link

        bodies = {lk: body(lk) for lk in moving_of}
        bodies[self.GRIPPER_HAND] = bodies[self.GRIPPER_FINGERS] = body(tip_link)
        joint_parent = {}
        for child, (par, kind) in parent.items():
            if kind != "fixed":
                joint_parent[body(child)] = body(par)
        allowed_set = {frozenset(p) for p in allowed}
        links = sorted(moving_of)
        self.pairs = set()
        for i, a in enumerate(links):
            for b in links[i + 1:]:
                ja, jb = moving_of[a], moving_of[b]
                ba, bb = bodies[a], bodies[b]
                if ja == jb or ba == bb or joint_parent.get(ba) == bb or joint_parent.get(bb) == ba:
                    continue
                if frozenset((a, b)) in allowed_set:
                    continue
                self.pairs.add(frozenset((a, b)))
        (x0, y0), (x1, y1), thick = pv.table_box[0][:2], pv.table_box[1][:2], pv.table_box[1][2] - pv.table_box[0][2]
        self.table_low = fcl.CollisionObject(fcl.Box(x1 - x0, y1 - y0, thick - table_tol),
                                             fcl.Transform(np.array([(x0 + x1) / 2, (y0 + y1) / 2, -table_tol - (thick - table_tol) / 2])))
        self.request = fcl.CollisionRequest()
        self.obstacles = []
        for mesh, pose in obstacles:
            pose = np.asarray(pose, dtype=np.float64)
            self.obstacles.append(fcl.CollisionObject(_fcl_mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
                                                      fcl.Transform(pose[:3, :3], pose[:3, 3])))

    # -- one configuration ---------------------------------------------------------------------------------------------

    def _place(self, q: np.ndarray, jaw: float | None = None) -> np.ndarray:
        """Place every part at joint vector `q`, the fingers `jaw` apart (None or 0: full opening); the TCP pose."""
        pv, pin, fcl = self.pv, self.pv.pin, self.fcl
        full = pv.full_q(q)
        pin.forwardKinematics(pv.model, pv.data, full)
        pin.updateFramePlacements(pv.model, pv.data)
        pin.updateGeometryPlacements(pv.model, pv.data, pv.geom, pv.gdata)
        for k, _, _, obj in self.parts:
            m = pv.base @ np.asarray(pv.gdata.oMg[k].homogeneous)
            obj.setTransform(fcl.Transform(m[:3, :3], m[:3, 3]))
        tcp = pv.base @ np.asarray(pv.data.oMf[pv.tip].homogeneous) @ pv.mount
        self.hand.setTransform(fcl.Transform(tcp[:3, :3], tcp[:3, 3]))
        shut = 0.0 if not jaw or self.jaw_max is None else (self.jaw_max - float(jaw)) / 2  # each finger's move inward
        for side, finger in zip(self.finger_side, self.fingers):
            at = tcp[:3, 3] - side * shut * tcp[:3, 1]
            finger.setTransform(fcl.Transform(tcp[:3, :3], at))
        return tcp

    def _hit(self, a, b) -> bool:
        return self.fcl.collide(a, b, self.request, self.fcl.CollisionResult())

    def problems(self, tcp: np.ndarray, holding: bool, object_pose: np.ndarray | None, grasp: np.ndarray | None,
                 fingers: bool = True) -> list[str]:
        """What is wrong at the configuration last placed by `_place` (its TCP pose `tcp`; empty when nothing); with
        `fingers` False the fingers may touch the resting object (on the way to or from the grasp)."""
        pv = self.pv
        out = []
        objs = [(lk, j, o) for _, lk, j, o in self.parts] + [(self.GRIPPER_HAND, -1, self.hand)] + \
            [(self.GRIPPER_FINGERS, -1, f) for f in self.fingers]
        for i, (a, _, oa) in enumerate(objs):
            for b, _, ob in objs[i + 1:]:
                if frozenset((a, b)) in self.pairs and self._hit(oa, ob):
                    out.append(f"self-collision {a} / {b}")
        for lk, j, o in objs:
            if j != 0 and self._hit(o, pv.table):
                out.append(f"{lk} hits the table")
            for i, ob in enumerate(self.obstacles):
                if j != 0 and self._hit(o, ob):
                    out.append(f"{lk} hits obstacle {i}")
        obj = pv.obj
        if holding:
            pose = tcp @ np.linalg.inv(grasp)
            obj.setTransform(self.fcl.Transform(pose[:3, :3], pose[:3, 3]))
            low = float((pv.obj_vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].min())
            if low < -self.table_tol:
                out.append(f"the held object is {-low * 1000:.1f} mm below the table top")
            elif self._hit(obj, self.table_low):
                out.append("the held object hits the table")
            out += [f"the held object hits obstacle {i}" for i, ob in enumerate(self.obstacles) if self._hit(obj, ob)]
            for lk, j, o in objs:
                if lk not in (self.GRIPPER_HAND, self.GRIPPER_FINGERS) and self._hit(o, obj):
                    out.append(f"{lk} hits the held object")
        elif object_pose is not None:
            obj.setTransform(self.fcl.Transform(object_pose[:3, :3], object_pose[:3, 3]))
            for lk, j, o in objs:
                if j != 0 and (fingers or lk != self.GRIPPER_FINGERS) and self._hit(o, obj):
                    out.append(f"{lk} hits the object")
        return out

    # -- the whole trajectory ----------------------------------------------------------------------------------------

    def check(self, plan, segments, max_errors: int = 20) -> tuple[list[str], int]:
        """(problems, number of knots checked) for a plan's timed segments (see the module docstring)."""
        pv = self.pv
        errs: list[str] = []
        steps = plan.steps
        n = len(pv.joint_names)
        knots = 0
        prev_end_t, prev_end_q = None, None
        jaw_before = None
        start_held, end_held = bool(getattr(plan, "start_held", False)), bool(getattr(plan, "end_held", False))
        holding = start_held  # a plan may begin with the part already in the hand at its first grasp
        if start_held and segments and steps:
            q0 = np.asarray(segments[0].traj.q)[0]
            d = float(np.linalg.norm(self._place(q0)[:3, 3] - np.asarray(steps[0].tcp)[:3, 3]))
            if d > pv.tol_pos:
                errs.append(f"the plan starts holding the part but its first knot is {d * 1000:.1f} mm from the first grasp")
        for si, seg in enumerate(segments):
            tag = f"segment {si + 1} ({seg.kind}, {seg.caption})"
            t, q, qd = np.asarray(seg.traj.t), np.asarray(seg.traj.q), np.asarray(seg.traj.qd)
            if q.ndim != 2 or q.shape[1] != n or len(t) != len(q) or qd.shape != q.shape or not np.isfinite(q).all():
                errs.append(f"{tag}: knots have the wrong shape or NaN")
                continue
            if not (0 <= seg.step < len(steps)):
                errs.append(f"{tag}: step {seg.step} is not a step of the plan")
                continue
            if len(t) > 1 and (np.diff(t) <= 0).any():
                errs.append(f"{tag}: knot times do not increase")
            if prev_end_t is not None and (abs(seg.t0 - prev_end_t) > 1e-6 or np.abs(q[0] - prev_end_q).max() > 1e-6):
                errs.append(f"{tag}: does not start where the previous segment ends (time or configuration jumps)")
            prev_end_t, prev_end_q = seg.t0 + (t[-1] - t[0]), q[-1]
            if np.abs(qd[0]).max() > 1e-9 or np.abs(qd[-1]).max() > 1e-9:
                errs.append(f"{tag}: does not start and end at rest")
            if (q < pv.lower - 1e-9).any() or (q > pv.upper + 1e-9).any():
                errs.append(f"{tag}: joint positions outside the URDF limits")
            if (np.abs(qd) > self.vlim * (1 + 1e-3) + 1e-9).any():
                errs.append(f"{tag}: joint velocities above the URDF limits (max {float((np.abs(qd) / self.vlim).max()):.3f} of the limit)")
            if len(t) > 1:
                dt = np.diff(t)[:, None]
                acc = np.diff(qd, axis=0) / dt
                if (np.abs(acc) > self.alim * 1.02 + 1e-9).any():
                    errs.append(f"{tag}: joint accelerations above the limits (max {float((np.abs(acc) / self.alim).max()):.3f} of the limit)")
                # trapezoid rule: with |acceleration| <= a, |dq - (v0 + v1) dt / 2| <= a dt^2 / 4 (twice that allowed)
                drift = np.abs(np.diff(q, axis=0) - 0.5 * (qd[1:] + qd[:-1]) * dt) - 0.5 * self.alim * dt ** 2
                if drift.max() > 1e-4:
                    errs.append(f"{tag}: positions and velocities disagree (by {math.degrees(drift.max()):.2f} deg more than the "
                                f"acceleration limit allows between knots)")
            s = steps[seg.step]
            taking = s.kind in ("pick", "regrasp")
            if seg.kind == "gripper":
                if np.abs(q - q[0]).max() > 1e-9:
                    errs.append(f"{tag}: the arm moves while the jaw acts")
                d = float(np.linalg.norm(self._place(q[0])[:3, 3] - np.asarray(s.tcp)[:3, 3]))
                if d > pv.tol_pos:
                    errs.append(f"{tag}: the jaw acts {d * 1000:.1f} mm from the step's grasp pose")
                holding = taking
                if bool(seg.holding) != holding:
                    errs.append(f"{tag}: says the object is {'held' if seg.holding else 'not held'} after the jaw acts")
            elif bool(seg.holding) != holding:
                errs.append(f"{tag}: says the object is {'held' if seg.holding else 'resting'} but it is "
                            f"{'held' if holding else 'resting'} there")
            pose = np.asarray(s.object_pose, dtype=np.float64)
            grasp = np.asarray(s.grasp, dtype=np.float64)
            # the fingers may touch the resting part on the segment that reaches or leaves the step's grasp pose
            at_grasp = seg.kind in ("approach", "retract", "gripper") and min(
                float(np.linalg.norm(self._place(q[e])[:3, 3] - np.asarray(s.tcp)[:3, 3])) for e in (0, -1)) <= pv.tol_pos
            # the empty hand approaches and leaves at its pre-grasp opening, at least the grasp's; while the jaw acts
            # the fingers are checked at the wider of its two openings
            if seg.kind in ("approach", "retract") and seg.jaw and seg.jaw < float(s.jawwidth) - 1e-9:
                errs.append(f"{tag}: the jaw is open {seg.jaw * 1000:.1f} mm, narrower than the grasp's "
                            f"{float(s.jawwidth) * 1000:.1f} mm")
            jaw = max(seg.jaw, jaw_before) if seg.kind == "gripper" and seg.jaw and jaw_before else seg.jaw
            jaw_before = seg.jaw
            tcp_at = np.zeros((len(q), 3))  # every knot is placed once: its TCP for the spacing, its parts for collisions
            found = False
            for k, x in enumerate(q):
                tcp = self._place(x, jaw)
                tcp_at[k] = tcp[:3, 3]
                if found:
                    continue
                knots += 1
                p = self.problems(tcp, holding, None if holding else pose, grasp if holding else None, not at_grasp)
                if p:
                    errs.append(f"{tag} at t = {seg.t0 + t[k] - t[0]:.2f} s: {'; '.join(sorted(set(p)))}")
                    found = True
            if len(q) > 1:
                step = float(np.abs(np.diff(q, axis=0)).max())
                travel = float(np.linalg.norm(np.diff(tcp_at, axis=0), axis=1).max())
                if step > ONE_DEGREE + 1e-9 or travel > TCP_STEP + 1e-6:
                    errs.append(f"{tag}: knots up to {math.degrees(step):.2f} deg and {travel * 1000:.1f} mm of TCP travel "
                                f"apart, beyond the check resolution (1 degree and 5 mm)")
            if len(errs) >= max_errors:
                break
        if holding and not end_held:
            errs.append("the trajectory ends with the object still in the hand")
        elif end_held and not holding:
            errs.append("the plan says it ends holding the part, but the trajectory releases it")
        elif end_held and segments and steps:
            d = float(np.linalg.norm(self._place(np.asarray(segments[-1].traj.q)[-1])[:3, 3] - np.asarray(steps[-1].tcp)[:3, 3]))
            if d > pv.tol_pos:
                errs.append(f"the plan ends holding the part {d * 1000:.1f} mm from its last grasp")
        return errs, knots


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


def trajectory_validator_from_rows(rows: dict, pv: PlanValidator, acc: np.ndarray | float,
                                   obstacles: tuple = ()) -> TrajectoryValidator:
    """The trajectory validator of stored rows: the gripper's collision mesh split into body and fingers at its
    stored `body_faces`, the robot row's allowed self-collision pairs (JSON), `acc` the plan's acceleration limits,
    and the task's `obstacles` ((mesh, world pose) pairs)."""
    r, grip = rows["robot"], rows.get("gripper") or {}
    nb = grip.get("body_faces")
    if nb is None or grip.get("collision_vertices") is None or not r.get("allowed_pairs"):
        raise PlanningError("validator: the store lacks the gripper's body/finger split or the robot's allowed self-collision "
                            "pairs (a store written by an older version); rebuild the IK stage in a new store")
    mesh = trimesh.Trimesh(grip["collision_vertices"], grip["collision_faces"], process=False)
    body = trimesh.Trimesh(mesh.vertices, mesh.faces[:nb], process=False)
    fingers = trimesh.Trimesh(mesh.vertices, mesh.faces[nb:], process=False)
    allowed = [(a, b) for a, b, _ in json.loads(r["allowed_pairs"])["allowed"]]
    return TrajectoryValidator(pv, body, fingers, allowed, acc, urdf=r["urdf"], obstacles=obstacles,
                               jaw_max=grip.get("jaw_max"))


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
                         locked=dict(r.get("locked") or {}), jaw=(float(grip["jaw_min"]), float(grip["jaw_max"])))
