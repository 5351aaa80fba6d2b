"""An independent check of a plan's timed trajectory (CONVENTIONS.md, Plans and motions; issue 12).

Nothing here uses the planner's kinematics, collision or timing code: forward kinematics and joint limits come
from the URDF text through pinocchio (the `PlanValidator`'s model), collisions from python-fcl objects built from
the URDF's collision meshes, the table slab, the object mesh and the gripper's body and finger meshes. The only
planner output it trusts as data is the robot row's allowed self-collision pairs (SRDF / sampled), which it
extends with the pairs it finds itself: links joined by one URDF joint and links that never move relative to
each other.

Checks, over every knot of every segment (knots must be at most 1 degree apart in every joint, the stated
resolution, or at most 5 mm of TCP travel):
- times increase, segments follow each other without a jump in time or configuration, rest at both ends;
- positions within the URDF limits, velocities within the URDF velocity limits, accelerations (differences of
  knot velocities) within the plan's acceleration limits, positions consistent with velocities;
- no self-collision of the arm and the gripper;
- arm, gripper and held object clear of the table (the held object may touch it within `table_tol`);
- empty hand: arm and gripper clear of the object where it rests (the step's object pose);
- the object is held exactly between a pick / regrasp and the next transfer / place, and the jaw acts at the
  step's grasp configuration.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np
import trimesh

from ..validate import _fcl_geometry

ONE_DEGREE = math.radians(1.0)


def _fcl_mesh(mesh: trimesh.Trimesh):
    import fcl

    m = fcl.BVHModel()
    m.beginModel(len(mesh.vertices), len(mesh.faces))
    m.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    m.endModel()
    return m


class TrajectoryValidator:
    """Checks timed segments against a `PlanValidator` (URDF model, table, object) plus the gripper's body and
    fingers (meshes in the TCP frame at full opening), the allowed self-collision link pairs, and the acceleration
    limits (rad/s^2) the plan was timed with."""

    GRIPPER_HAND = "gripper_hand"
    GRIPPER_FINGERS = "gripper_fingers"

    def __init__(self, pv, hand_mesh: trimesh.Trimesh, finger_mesh: trimesh.Trimesh, allowed: list[tuple[str, str]],
                 acc_limits: np.ndarray | float, table_tol: float = 1e-3, urdf: str | None = None):
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
        self.hand = fcl.CollisionObject(_fcl_mesh(hand_mesh), fcl.Transform())
        self.fingers = fcl.CollisionObject(_fcl_mesh(finger_mesh), fcl.Transform())
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

    # -- one configuration ---------------------------------------------------------------------------------------------

    def _place(self, q: np.ndarray) -> np.ndarray:
        pv, pin, fcl = self.pv, self.pv.pin, self.fcl
        full = pv.full_q(q)
        pin.forwardKinematics(pv.model, pv.data, full)
        pin.updateFramePlacements(pv.model, pv.data)
        pin.updateGeometryPlacements(pv.model, pv.data, pv.geom, pv.gdata)
        for k, _, _, obj in self.parts:
            m = pv.base @ np.asarray(pv.gdata.oMg[k].homogeneous)
            obj.setTransform(fcl.Transform(m[:3, :3], m[:3, 3]))
        tcp = pv.base @ np.asarray(pv.data.oMf[pv.tip].homogeneous) @ pv.mount
        t = fcl.Transform(tcp[:3, :3], tcp[:3, 3])
        self.hand.setTransform(t)
        self.fingers.setTransform(t)
        return tcp

    def _hit(self, a, b) -> bool:
        return self.fcl.collide(a, b, self.request, self.fcl.CollisionResult())

    def problems(self, q: np.ndarray, holding: bool, object_pose: np.ndarray | None, grasp: np.ndarray | None) -> list[str]:
        """What is wrong at one configuration (empty when nothing)."""
        pv = self.pv
        out = []
        tcp = self._place(q)
        objs = [(lk, j, o) for _, lk, j, o in self.parts] + [(self.GRIPPER_HAND, -1, self.hand), (self.GRIPPER_FINGERS, -1, self.fingers)]
        for i, (a, _, oa) in enumerate(objs):
            for b, _, ob in objs[i + 1:]:
                if frozenset((a, b)) in self.pairs and self._hit(oa, ob):
                    out.append(f"self-collision {a} / {b}")
        for lk, j, o in objs:
            if j != 0 and self._hit(o, pv.table):
                out.append(f"{lk} hits the table")
        obj = pv.obj
        if holding:
            pose = tcp @ np.linalg.inv(grasp)
            obj.setTransform(self.fcl.Transform(pose[:3, :3], pose[:3, 3]))
            low = float((pv.obj_vertices @ pose[:3, :3].T + pose[:3, 3])[:, 2].min())
            if low < -self.table_tol:
                out.append(f"the held object is {-low * 1000:.1f} mm below the table top")
            elif self._hit(obj, self.table_low):
                out.append("the held object hits the table")
            for lk, j, o in objs:
                if lk not in (self.GRIPPER_HAND, self.GRIPPER_FINGERS) and self._hit(o, obj):
                    out.append(f"{lk} hits the held object")
        elif object_pose is not None:
            obj.setTransform(self.fcl.Transform(object_pose[:3, :3], object_pose[:3, 3]))
            for lk, j, o in objs:
                if j != 0 and self._hit(o, obj):
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
        holding = False
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
                step = np.abs(np.diff(q, axis=0)).max(axis=1)
                far = step > ONE_DEGREE + 1e-9
                if far.any():
                    pos = np.array([self._place(x)[:3, 3] for x in q[np.r_[far, False] | np.r_[False, far]]]).reshape(-1, 2, 3)
                    if (np.linalg.norm(pos[:, 1] - pos[:, 0], axis=1) > 0.005 + 1e-9).any():
                        errs.append(f"{tag}: knots more than 1 degree and 5 mm apart (the check resolution)")
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
            for k, x in enumerate(q):
                knots += 1
                p = self.problems(x, holding, None if holding else pose, grasp if holding else None)
                if p:
                    errs.append(f"{tag} at t = {seg.t0 + t[k] - t[0]:.2f} s: {'; '.join(sorted(set(p)))}")
                    break
            if len(errs) >= max_errors:
                break
        if holding:
            errs.append("the trajectory ends with the object still in the hand")
        return errs, knots


def trajectory_validator_for(planner, acc: np.ndarray | float, allowed: list[tuple[str, str]] | None = None) -> TrajectoryValidator:
    """The trajectory validator of a planner's store rows (robot URDF, scene, object) and gripper; `allowed`: the
    robot row's allowed self-collision link pairs (data; computed from the SRDF or by sampling when not given)."""
    from ..validate import validator_for

    pv = validator_for(planner)
    g = planner.robot.gripper
    fingers = trimesh.util.concatenate([trimesh.creation.box(extents=e, transform=p) for e, p in g.finger_poses(g.jaw_max)])
    if allowed is None:
        from .selfcollision import allowed_pairs

        allowed = list(allowed_pairs(planner.robot).allowed)
    return TrajectoryValidator(pv, g.body, fingers, allowed, acc, urdf=planner.rows["robot"]["urdf"])
