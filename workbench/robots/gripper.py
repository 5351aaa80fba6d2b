"""Parallel-jaw grippers in the TCP frame (CONVENTIONS.md, Gripper).

The default is the Franka hand of example-robot-data's `panda.urdf`, read with pinocchio: the hand
body mesh, the finger collision boxes and the TCP frame `panda_hand_tcp`. All geometry is expressed in
the TCP frame: +z approach (palm toward fingertips), fingers along +/-y, origin between the pads.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path

import numpy as np
import trimesh

from workbench.errors import GripperError
from workbench.resources import erd_robots, erd_share


@dataclass(frozen=True)
class Visual:
    """A visual mesh file and its pose in the TCP frame at zero opening; `side` is 0 (body), +1 (left), -1 (right)."""

    path: str
    pose: np.ndarray
    scale: np.ndarray
    side: int


@dataclass(frozen=True)
class Gripper:
    """A parallel-jaw gripper in its TCP frame.

    `finger_boxes` are (extents, pose) pairs of the left finger (+y) when its pad's inner face is at y=0;
    the right finger mirrors them (y -> -y). `pad` is the index of the box that touches the object.
    """

    name: str
    body: trimesh.Trimesh
    finger_boxes: tuple[tuple[np.ndarray, np.ndarray], ...]
    pad: int
    jaw_min: float
    jaw_max: float
    visuals: tuple[Visual, ...] = ()
    urdf: str = ""

    @cached_property
    def digest(self) -> str:
        """Identifies the gripper's geometry: body mesh, finger boxes and jaw range (enters every digest that
        depends on the gripper: grasps, the robot, IK rows)."""
        h = hashlib.sha256()
        h.update(np.round(self.body.vertices, 9).tobytes())
        for ext, pose in self.finger_boxes:
            h.update(np.round(ext, 9).tobytes() + np.round(pose, 9).tobytes())
        h.update(np.array([self.jaw_min, self.jaw_max]).tobytes())
        return h.hexdigest()[:24]

    @property
    def pad_extents(self) -> np.ndarray:
        return self.finger_boxes[self.pad][0]

    @property
    def pad_center(self) -> np.ndarray:
        """Centre of the left pad box when its inner face is at y = 0 (in the TCP frame)."""
        return self.finger_boxes[self.pad][1][:3, 3]

    @property
    def pad_radius(self) -> float:
        """Radius of the pad's swept cylinder about the TCP's y axis: it covers the pad's contact face wherever the
        hand rotates (half the diagonal, plus the face's offset from the axis)."""
        ext, c = self.pad_extents, self.pad_center
        return float(np.hypot(ext[0] / 2 + abs(c[0]), ext[2] / 2 + abs(c[2])))

    def finger_poses(self, width: float) -> list[tuple[np.ndarray, np.ndarray]]:
        """(extents, pose) of every finger box of both fingers with the pads `width` apart."""
        mirror = np.diag([1.0, -1.0, 1.0, 1.0])
        out = []
        for ext, pose in self.finger_boxes:
            left = pose.copy()
            left[1, 3] += width / 2
            out.append((ext, left))
            right = mirror @ pose @ mirror
            right[1, 3] -= width / 2
            out.append((ext, right))
        return out

    def collision_mesh(self, width: float | None = None) -> trimesh.Trimesh:
        """Hand body plus both fingers at `width` (default: full opening) as one mesh in the TCP frame."""
        width = self.jaw_max if width is None else width
        parts = [self.body]
        for ext, pose in self.finger_poses(width):
            parts.append(trimesh.creation.box(extents=ext, transform=pose))
        return trimesh.util.concatenate(parts)

    def pad_sweep(self, width: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Level-1 swept volume of the left pad for grasps of `width`: (radius, y_start, y_end) along the TCP's y.

        The cylinder runs from just outside the contact (y = width/2 + 0.5 mm) to the pad's outer face at full
        opening; the right pad's cylinder is its mirror image.
        """
        y0 = np.asarray(width, dtype=np.float64) / 2 + 5e-4
        y1 = np.maximum(self.jaw_max / 2 + self.pad_extents[1], y0 + 1e-4)
        return self.pad_radius, y0, y1


def _to_h(placement) -> np.ndarray:
    return np.asarray(placement.homogeneous, dtype=np.float64)


def gripper_from_urdf(urdf: str | Path, hand_link: str, tcp_frame: str, finger_joints: tuple[str, str],
                      package_dirs: list[str] | None = None, name: str | None = None) -> Gripper:
    """Load a parallel-jaw gripper from a URDF: the hand link's collision meshes, the two prismatic fingers' boxes,
    the TCP frame and the jaw range (twice the finger joints' upper limit)."""
    import pinocchio as pin

    urdf = Path(urdf)
    if not urdf.is_file():
        raise GripperError(f"gripper URDF {urdf} does not exist")
    dirs = [str(erd_share())] + list(package_dirs or [])
    try:
        model = pin.buildModelFromUrdf(str(urdf))
        geom = pin.buildGeomFromUrdf(model, str(urdf), pin.COLLISION, package_dirs=dirs)
        vis = pin.buildGeomFromUrdf(model, str(urdf), pin.VISUAL, package_dirs=dirs)
    except Exception as exc:
        raise GripperError(f"gripper URDF {urdf} could not be parsed: {exc}") from None
    for label, frame in (("hand link", hand_link), ("TCP frame", tcp_frame)):
        if not model.existFrame(frame):
            raise GripperError(f"gripper URDF {urdf} has no {label} {frame!r}")
    jids = []
    for j in finger_joints:
        if not model.existJointName(j):
            raise GripperError(f"gripper URDF {urdf} has no finger joint {j!r}")
        jid = model.getJointId(j)
        if model.joints[jid].shortname() not in ("JointModelPY", "JointModelPrismaticUnaligned", "JointModelPX", "JointModelPZ"):
            raise GripperError(f"finger joint {j!r} of {urdf} is not prismatic")
        jids.append(jid)
    data = model.createData()
    q = pin.neutral(model)
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    gdata = geom.createData()
    pin.updateGeometryPlacements(model, data, geom, gdata)
    tcp_inv = np.linalg.inv(_to_h(data.oMf[model.getFrameId(tcp_frame)]))
    body_parts, left_boxes = [], []
    for k, go in enumerate(geom.geometryObjects):
        pose = tcp_inv @ _to_h(gdata.oMg[k])
        if model.frames[go.parentFrame].name == hand_link:
            part = trimesh.load(go.meshPath, force="mesh") if go.meshPath and go.meshPath != "BOX" else None
            if part is None and hasattr(go.geometry, "halfSide"):
                part = trimesh.creation.box(extents=2 * np.asarray(go.geometry.halfSide))
            if part is None:
                continue
            part.apply_scale(np.asarray(go.meshScale))
            part.apply_transform(pose)
            body_parts.append(part)
        elif go.parentJoint == jids[0]:
            if not hasattr(go.geometry, "halfSide"):
                raise GripperError(f"finger collision geometry {go.name} of {urdf} is not a box; only box fingers are supported")
            left_boxes.append((2 * np.asarray(go.geometry.halfSide, dtype=np.float64), pose))
    if not body_parts or not left_boxes:
        raise GripperError(f"gripper URDF {urdf} lacks collision geometry on {hand_link!r} or on finger joint {finger_joints[0]!r}")
    # The pad is the finger box that reaches farthest along the approach axis; shift boxes so its inner face is at y=0.
    pad = int(np.argmax([p[2, 3] + e[2] / 2 for e, p in left_boxes]))
    inner = left_boxes[pad][1][1, 3] - left_boxes[pad][0][1] / 2
    boxes = []
    for e, p in left_boxes:
        p = p.copy()
        p[1, 3] -= inner
        boxes.append((e, p))
    upper = float(model.upperPositionLimit[model.joints[jids[0]].idx_q])
    visuals = []
    vdata = vis.createData()
    pin.updateGeometryPlacements(model, data, vis, vdata)
    for k, go in enumerate(vis.geometryObjects):
        side = 0 if model.frames[go.parentFrame].name == hand_link else (1 if go.parentJoint == jids[0] else (-1 if go.parentJoint == jids[1] else None))
        if side is None or not go.meshPath:
            continue
        pose = tcp_inv @ _to_h(vdata.oMg[k])
        if side:
            pose[1, 3] -= side * inner
        visuals.append(Visual(go.meshPath, pose, np.asarray(go.meshScale, dtype=np.float64), side))
    return Gripper(name=name or hand_link, body=trimesh.util.concatenate(body_parts), finger_boxes=tuple(boxes), pad=pad,
                   jaw_min=0.0, jaw_max=2 * (upper + inner), visuals=tuple(visuals), urdf=str(urdf))


@lru_cache(maxsize=1)
def franka_hand() -> Gripper:
    """The Franka hand of example-robot-data's panda.urdf (jaw 0 to 0.08 m, TCP `panda_hand_tcp`)."""
    urdf = erd_robots() / "panda_description" / "urdf" / "panda.urdf"
    return gripper_from_urdf(urdf, "panda_hand", "panda_hand_tcp", ("panda_finger_joint1", "panda_finger_joint2"),
                             name="franka_hand")


def parametric_gripper(pad_size: tuple[float, float] = (0.02, 0.02), pad_thickness: float = 0.008,
                       jaw_range: tuple[float, float] = (0.0, 0.1), palm_box: tuple[float, float, float] = (0.04, 0.16, 0.05),
                       finger_length: float = 0.06, name: str = "parametric") -> Gripper:
    """A box gripper: pads (width along x, length along z), a finger of `finger_length` above each pad, a palm box."""
    pw, pl = pad_size
    if min(pw, pl, pad_thickness, finger_length) <= 0 or jaw_range[1] <= jaw_range[0] or jaw_range[0] < 0:
        raise GripperError(f"parametric gripper needs positive sizes and 0 <= jaw_min < jaw_max, got pad {pad_size}, jaw {jaw_range}")
    if palm_box[1] < jaw_range[1] + 2 * pad_thickness:
        raise GripperError(f"palm box width {palm_box[1]} m is narrower than the open jaw ({jaw_range[1] + 2 * pad_thickness} m)")
    pad_pose = np.eye(4)
    pad_pose[:3, 3] = (0.0, pad_thickness / 2, 0.0)
    finger_pose = np.eye(4)
    finger_pose[:3, 3] = (0.0, pad_thickness / 2, -(pl / 2 + finger_length / 2))
    palm_pose = np.eye(4)
    palm_pose[:3, 3] = (0.0, 0.0, -(pl / 2 + finger_length + palm_box[2] / 2))
    body = trimesh.creation.box(extents=palm_box, transform=palm_pose)
    boxes = ((np.array([pw, pad_thickness, pl]), pad_pose), (np.array([pw, pad_thickness, finger_length]), finger_pose))
    return Gripper(name=name, body=body, finger_boxes=boxes, pad=0, jaw_min=jaw_range[0], jaw_max=jaw_range[1])
