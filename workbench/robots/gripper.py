"""Parallel-jaw grippers in the TCP frame (CONVENTIONS.md, Gripper and Gripper spec).

The default is the Franka hand of example-robot-data's `panda.urdf`, read with pinocchio: the hand
body mesh, the finger collision boxes and the TCP frame `panda_hand_tcp`. Other grippers load from a URDF
(`gripper_from_urdf`), from a spec file (`gripper_from_spec`, JSON or YAML) or by name (`load_gripper`: the
bundled ones in `workbench/assets/grippers`). All geometry is expressed in the TCP frame: +z approach (palm
toward fingertips), fingers along +/-y, origin between the pads.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import trimesh

from workbench.errors import GripperError
from workbench.resources import ASSETS, erd_robots, erd_share

GRIPPERS_DIR = ASSETS / "grippers"
# Grippers known by name; a URDF here is read with the spec beside it (NAME.gripper.yaml).
BUNDLED = {"franka": None, "robotiq-2f85": GRIPPERS_DIR / "robotiq_2f85.yaml", "parallel60": GRIPPERS_DIR / "parallel60.urdf"}
STROKE_SAMPLES = 41          # finger poses sampled along a URDF gripper's stroke
PARALLEL_TOL = np.radians(1.0)  # a pad turning more than this over the stroke is not a parallel jaw
AXIS_TOL = 5e-4              # m a pad may drift across the jaw axis over the stroke


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
    the right finger mirrors them (y -> -y). `pad` is the index of the box that touches the object. A linkage's
    fingers change shape along the stroke: `stroke` then holds (widths (S,), extents (S, B, 3), poses (S, B, 4, 4))
    of the same boxes sampled along it, and the boxes at an opening are those of the nearest sample.
    `tcp_in_hand` is the TCP's pose in the hand frame (what bolts onto a robot's flange).
    """

    name: str
    body: trimesh.Trimesh
    finger_boxes: tuple[tuple[np.ndarray, np.ndarray], ...]
    pad: int
    jaw_min: float
    jaw_max: float
    visuals: tuple[Visual, ...] = ()
    urdf: str = ""
    tcp_in_hand: np.ndarray = field(default_factory=lambda: np.eye(4))
    extra: str = ""
    notes: tuple[str, ...] = ()
    stroke: tuple = ()

    @cached_property
    def digest(self) -> str:
        """Identifies the gripper's geometry: body mesh, finger boxes and jaw range, and a spec's every other field
        (`extra`: its canonical text and palm mesh bytes). It enters every digest that depends on the gripper: grasps,
        the robot, IK rows."""
        h = hashlib.sha256()
        h.update(np.round(self.body.vertices, 9).tobytes())
        for ext, pose in self.finger_boxes:
            h.update(np.round(ext, 9).tobytes() + np.round(pose, 9).tobytes())
        h.update(np.round(np.array([self.jaw_min, self.jaw_max]), 12).tobytes())
        if self.extra:
            h.update(self.extra.encode())
        for arr in self.stroke:
            h.update(np.round(arr, 9).tobytes())
        return h.hexdigest()[:24]

    @property
    def pad_length(self) -> float:
        """The pad's length along the approach axis (m)."""
        return float(self.finger_boxes[self.pad][0][2])

    def spec_value(self, key: str) -> float | None:
        """An optional field of the gripper's spec (`mass`, `max_force`, `friction`; CONVENTIONS.md, Gripper spec),
        or None when the gripper states none (a gripper from a URDF, the built-in Franka hand)."""
        if not self.extra.startswith("{"):
            return None
        try:  # a spec gripper keeps its spec as JSON followed by the palm mesh's sha256
            value = json.loads(self.extra[:-64]).get(key)
        except ValueError:
            return None
        return None if value is None else float(value)

    @property
    def finger_span(self) -> float:
        """How far the open fingers reach either side of the TCP along the jaw axis (m): half the stroke plus the
        thickest finger box."""
        return float(self.jaw_max / 2 + max(p[1, 3] + e[1] / 2 for e, p in self.finger_boxes))

    @property
    def fingertip_reach(self) -> float:
        """How far the fingertips reach past the TCP along the approach axis (m)."""
        return float(max(p[2, 3] + e[2] / 2 for e, p in self.finger_boxes))

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

    def boxes_at(self, width: float) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """The left finger's boxes (pad inner face at y = 0) at opening `width`."""
        if not self.stroke:
            return self.finger_boxes
        i = int(np.argmin(np.abs(self.stroke[0] - width)))
        return tuple(zip(self.stroke[1][i], self.stroke[2][i]))

    def width_groups(self, widths: np.ndarray) -> list[tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]]]:
        """Grasps grouped by the finger shape at their opening: (indices, `finger_poses(0)` of that shape)."""
        widths = np.asarray(widths, dtype=np.float64)
        if not self.stroke:
            return [(np.arange(len(widths)), self.finger_poses(0.0))]
        near = np.argmin(np.abs(widths[:, None] - self.stroke[0][None]), axis=1)
        return [(np.flatnonzero(near == i), self.finger_poses(0.0, self.stroke[0][i])) for i in np.unique(near)]

    def finger_poses(self, width: float, shape_at: float | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """(extents, pose) of every finger box of both fingers with the pads `width` apart (their shape at opening
        `shape_at`, default `width`)."""
        mirror = np.diag([1.0, -1.0, 1.0, 1.0])
        out = []
        for ext, pose in self.boxes_at(width if shape_at is None else shape_at):
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

    def pad_sweep(self, width: np.ndarray, opening: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
        """Level-1 swept volume of the left pad for grasps of `width`: (radius, y_start, y_end) along the TCP's y.

        The cylinder runs from just outside the contact (y = width/2 + 0.5 mm) to the pad's outer face at `opening`
        (the pre-grasp opening; default full opening); the right pad's cylinder is its mirror image.
        """
        y0 = np.asarray(width, dtype=np.float64) / 2 + 5e-4
        start = self.jaw_max if opening is None else np.asarray(opening, dtype=np.float64)
        y1 = np.maximum(start / 2 + self.pad_extents[1], y0 + 1e-4)
        return self.pad_radius, y0, y1


def _to_h(placement) -> np.ndarray:
    return np.asarray(placement.homogeneous, dtype=np.float64)


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _mimics(text: str) -> dict[str, tuple[str, float, float]]:
    """URDF `<mimic>` elements: joint -> (driving joint, multiplier, offset)."""
    out = {}
    for j in ElementTree.fromstring(text).findall("joint"):
        m = j.find("mimic")
        if m is not None:
            out[j.get("name", "")] = (m.get("joint", ""), float(m.get("multiplier", 1.0)), float(m.get("offset", 0.0)))
    return out


def _gripper_visuals_only(text: str, hand_link: str, finger_joints: tuple[str, ...]) -> str | None:
    """The URDF text without the `<visual>` elements of links outside the subtrees of `hand_link` and of the finger
    joints' links (a whole arm's visual meshes would be read only to be dropped: most of the parse), or None when
    there is nothing to drop or the hand link is not a link of the text."""
    root = ElementTree.fromstring(text)
    children: dict[str, list[str]] = {}
    tops = [hand_link]
    for j in root.findall("joint"):
        parent, child = j.find("parent"), j.find("child")
        if parent is not None and child is not None:
            children.setdefault(parent.get("link", ""), []).append(child.get("link", ""))
            if j.get("name") in finger_joints:
                tops.append(child.get("link", ""))
    links = root.findall("link")
    if not any(link.get("name") == hand_link for link in links):
        return None
    keep, stack = set(), tops
    while stack:
        name = stack.pop()
        if name not in keep:
            keep.add(name)
            stack.extend(children.get(name, ()))
    dropped = False
    for link in links:
        if link.get("name") not in keep:
            for v in link.findall("visual"):
                link.remove(v)
                dropped = True
    return ElementTree.tostring(root, encoding="unicode") if dropped else None


def _descends(model, joint: int, ancestor: int) -> bool:
    while joint > 0:
        if joint == ancestor:
            return True
        joint = model.parents[joint]
    return False


def _under_link(model, frame: int, link: int) -> bool:
    """Whether `frame` is `link` or hangs from it by fixed joints only (pinocchio merges those into one body)."""
    joint = model.frames[link].parentJoint
    while True:
        if frame == link:
            return True
        if frame == 0 or model.frames[frame].parentJoint != joint:
            return False
        frame = model.frames[frame].parentFrame


def _body_frame(model, name: str) -> int:
    import pinocchio as pin

    for kind in (pin.FrameType.BODY, pin.FrameType.OP_FRAME, pin.FrameType.FIXED_JOINT):
        if model.existFrame(name, kind):
            return model.getFrameId(name, kind)
    return model.getFrameId(name)


def _local_mesh(go) -> trimesh.Trimesh | None:
    """A collision geometry in its own frame: a box, cylinder, sphere or capsule primitive, or the scaled mesh file."""
    g = go.geometry
    if hasattr(g, "halfSide"):
        return trimesh.creation.box(extents=2 * np.asarray(g.halfSide))
    if hasattr(g, "halfLength") and hasattr(g, "radius"):  # URDF cylinders (coal's Cylinder; a Capsule likewise)
        make = trimesh.creation.capsule if type(g).__name__ == "Capsule" else trimesh.creation.cylinder
        return make(radius=float(g.radius), height=2 * float(g.halfLength))
    if hasattr(g, "radius"):
        return trimesh.creation.icosphere(subdivisions=2, radius=float(g.radius))
    if go.meshPath and go.meshPath not in ("BOX", "CYLINDER", "SPHERE", "CAPSULE"):
        part = trimesh.load(go.meshPath, force="mesh")
        part.apply_scale(np.asarray(go.meshScale))
        return part
    return None


def _local_points(go) -> np.ndarray:
    """Vertices of a collision geometry in its own frame (box corners, a primitive's mesh, a mesh's scaled vertices)."""
    part = _local_mesh(go)
    return np.zeros((0, 3)) if part is None else np.asarray(part.vertices, dtype=np.float64)


def _angle(r: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))


def gripper_from_urdf(urdf: str | Path, hand_link: str, tcp_frame: str | None, finger_joints: tuple[str, ...],
                      package_dirs: list[str] | None = None, name: str | None = None,
                      text: str | None = None) -> Gripper:
    """Load a parallel-jaw gripper from a URDF (CONVENTIONS.md, Gripper): the collision geometry on the hand link (and
    links fixed to it), the two fingers (the links moved by the left and right finger joints, with the joints that
    `<mimic>` them), the TCP frame and the stroke.

    The finger motion is sampled along the joints' range, so prismatic fingers, mimic joints and revolute linkages
    load alike; the pads must stay parallel and close along one axis, else the gripper is refused. Box collision
    geometry that only translates is kept exact; other finger geometry (meshes, linkage bars) becomes its bounding
    box in the TCP frame over the whole stroke, relative to the pad. Without `tcp_frame` the TCP is placed midway
    between the pads at mid-stroke, +y toward the left pad, +z away from the hand link's origin.

    `text`, when given, is the URDF itself (a stored robot's) and `urdf` only names it; its meshes are found in
    `package_dirs`."""
    import pinocchio as pin

    urdf = Path(urdf)
    if text is None and not urdf.is_file():
        raise GripperError(f"gripper URDF {urdf} does not exist")
    where = f"gripper URDF {urdf}"
    dirs = [str(erd_share())] + list(package_dirs or []) + [str(urdf.parent), str(urdf.parent.parent)]
    try:
        given = text
        text = urdf.read_text() if text is None else text
        lean = _gripper_visuals_only(text, hand_link, finger_joints)
        if given is None:
            model = pin.buildModelFromUrdf(str(urdf))  # from the file: relative mesh paths are the file's
            geom = pin.buildGeomFromUrdf(model, str(urdf), pin.COLLISION, package_dirs=dirs)
        else:
            model = pin.buildModelFromXML(text)
            geom = pin.buildGeomFromUrdfString(model, text, pin.COLLISION, package_dirs=dirs)
        if lean is not None:
            vis = pin.buildGeomFromUrdfString(model, lean, pin.VISUAL, package_dirs=dirs)
        elif given is None:
            vis = pin.buildGeomFromUrdf(model, str(urdf), pin.VISUAL, package_dirs=dirs)
        else:
            vis = pin.buildGeomFromUrdfString(model, text, pin.VISUAL, package_dirs=dirs)
        mimic = _mimics(text)
    except Exception as exc:
        raise GripperError(f"{where} could not be parsed: {_first_line(exc)}") from None
    for label, frame in (("hand link", hand_link), ("TCP frame", tcp_frame)):
        if frame is not None and not model.existFrame(frame):
            raise GripperError(f"{where} has no {label} {frame!r}")
    if len(finger_joints) != 2:
        raise GripperError(f"{where}: name two finger joints (left, right), got {', '.join(finger_joints) or 'none'}")
    hand = _body_frame(model, hand_link)
    jids = []
    for j in finger_joints:
        if not model.existJointName(j):
            raise GripperError(f"{where} has no finger joint {j!r}")
        jid = model.getJointId(j)
        if model.joints[jid].nq != 1:
            raise GripperError(f"finger joint {j!r} of {urdf} is {model.joints[jid].shortname()}; a finger joint is "
                               f"prismatic or revolute")
        if _descends(model, model.frames[hand].parentJoint, jid):
            raise GripperError(f"finger joint {j!r} of {urdf} moves the hand link {hand_link!r}; name the joints of the "
                               f"two fingers")
        jids.append(jid)
    # Drivers of the finger joints and every joint that mimics them move together along the stroke.
    drivers = list(dict.fromkeys(mimic.get(j, (j, 1.0, 0.0))[0] for j in finger_joints))
    moving: dict[int, tuple[int, float, float]] = {}
    for d in drivers:
        if not model.existJointName(d):
            raise GripperError(f"{where}: finger joint mimics {d!r}, which is not a joint of the URDF")
        moving[model.getJointId(d)] = (model.getJointId(d), 1.0, 0.0)
    for j, (d, m, o) in mimic.items():
        if d in drivers and model.existJointName(j):
            moving[model.getJointId(j)] = (model.getJointId(d), m, o)
    lo = {d: float(model.lowerPositionLimit[model.joints[d].idx_q]) for d in {v[0] for v in moving.values()}}
    hi = {d: float(model.upperPositionLimit[model.joints[d].idx_q]) for d in lo}
    if not all(np.isfinite(lo[d]) and np.isfinite(hi[d]) for d in lo):
        raise GripperError(f"{where}: finger joints {', '.join(drivers)} need finite <limit lower upper>")
    if all(hi[d] - lo[d] <= 0 for d in lo):
        raise GripperError(f"{where}: finger joints {', '.join(drivers)} have lower = upper, a stroke of zero")
    tcp_id = None if tcp_frame is None else _body_frame(model, tcp_frame)
    if tcp_id is not None and any(_descends(model, model.frames[tcp_id].parentJoint, j) for j in moving):
        raise GripperError(f"{where}: the TCP frame {tcp_frame!r} moves with the fingers; name a frame fixed to the hand")
    moved = [k for k, go in enumerate(geom.geometryObjects) if any(_descends(model, go.parentJoint, j) for j in moving)]
    body = [k for k, go in enumerate(geom.geometryObjects) if k not in moved and _under_link(model, go.parentFrame, hand)]
    side = {k: 1 if _descends(model, geom.geometryObjects[k].parentJoint, jids[0]) else
            (-1 if _descends(model, geom.geometryObjects[k].parentJoint, jids[1]) else 0) for k in moved}
    # Sample the stroke: world poses of the hand, the TCP and every moving collision object.
    steps = np.linspace(0.0, 1.0, STROKE_SAMPLES)
    data, gdata = model.createData(), geom.createData()
    hand_pose, tcp_pose, poses = None, None, {k: [] for k in moved}
    for s in steps:
        q = pin.neutral(model)
        for j, (d, m, o) in moving.items():
            q[model.joints[j].idx_q] = m * (lo[d] + s * (hi[d] - lo[d])) + o
        pin.forwardKinematics(model, data, q)
        pin.updateFramePlacements(model, data)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        if hand_pose is None:
            hand_pose = _to_h(data.oMf[hand])
            tcp_pose = None if tcp_id is None else _to_h(data.oMf[tcp_id])
            body_pose = {k: _to_h(gdata.oMg[k]) for k in body}
            vis_data = vis.createData()
            pin.updateGeometryPlacements(model, data, vis, vis_data)
            vis_pose = [_to_h(vis_data.oMg[k]) for k in range(len(vis.geometryObjects))]
        for k in moved:
            poses[k].append(_to_h(gdata.oMg[k]))
    points = {k: _local_points(geom.geometryObjects[k]) for k in moved}
    if not body or not any(len(points[k]) and side[k] == 1 for k in moved) or not any(side[k] == -1 for k in moved):
        raise GripperError(f"{where} lacks collision geometry on {hand_link!r} or on finger joints {', '.join(finger_joints)}")

    def world(k: int, i: int) -> np.ndarray:
        return points[k] @ poses[k][i][:3, :3].T + poses[k][i][:3, 3]

    centre = {k: np.array([world(k, i).mean(axis=0) for i in range(len(steps))]) for k in moved if len(points[k])}
    hand_origin = hand_pose[:3, 3]
    if tcp_pose is not None:
        approach = tcp_pose[:3, 2]
    else:
        tips = np.concatenate([centre[k][0][None] for k in centre])
        approach = tips.mean(axis=0) - hand_origin
    pads = {}
    for sgn in (1, -1):
        cands = [k for k in centre if side[k] == sgn]
        pads[sgn] = max(cands, key=lambda k: float((world(k, 0) @ approach).max()))
    mid = len(steps) // 2
    if tcp_pose is None:
        y = centre[pads[1]][-1] - centre[pads[-1]][-1]
        y /= np.linalg.norm(y)
        z = approach - (approach @ y) * y
        z /= np.linalg.norm(z)
        tcp_pose = np.eye(4)
        tcp_pose[:3, :3] = np.column_stack([np.cross(y, z), y, z])
        tcp_pose[:3, 3] = (centre[pads[1]][mid] + centre[pads[-1]][mid]) / 2
    tcp_inv = np.linalg.inv(tcp_pose)
    local = {k: [tcp_inv[:3, :3] @ world(k, i).T + tcp_inv[:3, 3:4] for i in range(len(steps))] for k in centre}
    jaw = centre[pads[1]][-1] - centre[pads[-1]][-1]
    off = np.degrees(np.arccos(np.clip(abs(jaw @ tcp_pose[:3, 1]) / np.linalg.norm(jaw), -1, 1)))
    if off > 2.0:
        raise GripperError(f"{where}: the fingers close {off:.1f} degrees off the TCP frame's y axis; the TCP's y must be "
                           f"the jaw axis")
    between = (local[pads[1]][mid].mean(axis=1) + local[pads[-1]][mid].mean(axis=1)) / 2  # pads' midpoint, TCP frame
    reach = np.ptp(local[pads[1]][mid], axis=1) / 2
    if abs(between[0]) > reach[0] or abs(between[2]) > reach[2] or abs(between[1]) > 1e-3:
        raise GripperError(f"{where}: the TCP frame {tcp_frame!r} lies outside the hand, {np.linalg.norm(between) * 1e3:.0f} "
                           f"mm from the midpoint between the pads; the TCP lies between them")
    notes, drift = [], {}
    for sgn in (1, -1):
        k = pads[sgn]
        turn = max(_angle(poses[k][0][:3, :3].T @ p[:3, :3]) for p in poses[k])
        if turn > PARALLEL_TOL:
            raise GripperError(f"{where}: the pad of finger joint {finger_joints[0 if sgn == 1 else 1]!r} turns "
                               f"{np.degrees(turn):.1f} degrees over the stroke; a parallel-jaw gripper needs pads that "
                               f"stay parallel")
        c = np.array([(tcp_inv @ np.append(p, 1.0))[:3] for p in centre[k]])
        if np.ptp(c[:, 0]) > AXIS_TOL:
            raise GripperError(f"{where}: the fingers do not close along one axis (a pad moves {np.ptp(c[:, 0]) * 1e3:.1f} "
                               f"mm across the jaw axis over the stroke)")
        pad_len = np.ptp(local[k][0][2])
        if np.ptp(c[:, 2]) > pad_len / 2:
            raise GripperError(f"{where}: the pads move {np.ptp(c[:, 2]) * 1e3:.1f} mm along the approach axis over the "
                               f"stroke, more than half their length; a parallel-jaw model cannot represent these fingers")
        drift[sgn] = c[-1] - c[0]
        if sgn == 1 and np.ptp(c[:, 2]) > 1e-4:
            notes.append(f"the pads move {np.ptp(c[:, 2]) * 1e3:.1f} mm along the approach axis over the stroke "
                         f"(modelled at mid-stroke)")
    if abs(drift[1][2] - drift[-1][2]) > AXIS_TOL or drift[1][1] * drift[-1][1] > 0:
        raise GripperError(f"{where}: the fingers do not close along one axis (over the stroke the left pad moves "
                           f"{np.round(drift[1] * 1e3, 1).tolist()} mm, the right {np.round(drift[-1] * 1e3, 1).tolist()} mm "
                           f"in the TCP frame)")
    inner = np.array([local[pads[1]][i][1].min() for i in range(len(steps))])    # left pad's inner face (y)
    outer = np.array([local[pads[-1]][i][1].max() for i in range(len(steps))])   # right pad's inner face
    widths = inner - outer
    jaw_min, jaw_max = max(0.0, float(widths.min())), float(widths.max())
    if jaw_max - jaw_min < 1e-4:
        raise GripperError(f"{where}: finger joints {', '.join(finger_joints)} give a stroke of zero")
    boxes, pad, shapes = [], 0, []
    for k in sorted(centre):
        if side[k] == -1 or (side[k] == 0 and local[k][mid][1].mean() < 0):
            continue
        go = geom.geometryObjects[k]
        rigid = all(_angle(poses[k][0][:3, :3].T @ p[:3, :3]) < 1e-9 for p in poses[k])
        if hasattr(go.geometry, "halfSide") and rigid:
            pose = tcp_inv @ poses[k][0]
            pose[1, 3] -= inner[0]
            boxes.append((2 * np.asarray(go.geometry.halfSide, dtype=np.float64), pose))
            shapes.append(None)
        else:  # at each sample, with the pad's inner face at y = 0, a box covering it and its neighbouring samples
            rel = [(local[k][i] - np.array([[0.0], [inner[i]], [0.0]])).T for i in range(len(steps))]
            lo, hi = points[k].min(axis=0), points[k].max(axis=0)
            centre = np.eye(4)
            centre[:3, 3] = (lo + hi) / 2
            per = []
            for i in range(len(steps)):
                reach = max(np.linalg.norm(rel[j] - rel[i], axis=1).max() for j in range(max(0, i - 1), min(len(steps), i + 2)))
                if k == pads[1]:  # the pad: a rectangle in the TCP frame's axes (it turns by under a degree)
                    pose = np.eye(4)
                    pose[:3, 3] = (rel[i].min(axis=0) + rel[i].max(axis=0)) / 2
                    per.append((np.ptp(rel[i], axis=0) + 2 * reach, pose))
                else:  # a linkage bar: its own bounding box, turning with it
                    pose = tcp_inv @ poses[k][i] @ centre
                    pose[1, 3] -= inner[i]
                    per.append((hi - lo + 2 * reach, pose))
            boxes.append(per[mid])
            shapes.append(per)
        if k == pads[1]:
            pad = len(boxes) - 1
    body_parts = []
    for k in body:
        part = _local_mesh(geom.geometryObjects[k])
        if part is not None:
            part.apply_transform(tcp_inv @ body_pose[k])
            body_parts.append(part)
    visuals = []
    for k, go in enumerate(vis.geometryObjects):
        s = 0 if _under_link(model, go.parentFrame, hand) else (1 if _descends(model, go.parentJoint, jids[0]) else
                                                               (-1 if _descends(model, go.parentJoint, jids[1]) else None))
        if s is None or not go.meshPath or (s and model.joints[jids[0 if s == 1 else 1]].shortname().startswith("JointModelR")):
            continue  # a linkage's meshes turn along the stroke: the view draws its collision boxes
        pose = tcp_inv @ vis_pose[k]
        if s:
            pose[1, 3] -= s * inner[0]
        visuals.append(Visual(go.meshPath, pose, np.asarray(go.meshScale, dtype=np.float64), s))
    stroke = ()
    if any(s is not None for s in shapes):  # a linkage: the boxes along the stroke
        per = [[boxes[b] if shapes[b] is None else shapes[b][i] for b in range(len(boxes))] for i in range(len(steps))]
        stroke = (np.maximum(widths, 0.0), np.array([[e for e, _ in row] for row in per]),
                  np.array([[p for _, p in row] for row in per]))
    return Gripper(name=name or hand_link, body=trimesh.util.concatenate(body_parts), finger_boxes=tuple(boxes), pad=pad,
                   jaw_min=jaw_min, jaw_max=jaw_max, visuals=tuple(visuals), urdf=str(urdf),
                   tcp_in_hand=np.linalg.inv(hand_pose) @ tcp_pose, notes=tuple(notes), stroke=stroke)


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


SPEC_LENGTH_MAX = 1.0  # m: no parallel-jaw gripper's stroke, pad, finger, palm or TCP offset reaches this
SPEC_FIELDS = ("name", "stroke", "tcp", "rpy", "pad", "finger", "palm", "mass", "max_force", "friction", "source")


def _spec_numbers(value, label: str, where: str, n: int | None = None, positive: bool = False,
                  nonneg: bool = False):
    """A number (or a list of `n`) from a spec field, or a GripperError naming the file and the field."""
    if n is not None and (not isinstance(value, (list, tuple)) or len(value) != n):
        raise GripperError(f"gripper spec {where}: field {label!r} must be a list of {n} numbers (m), got {value!r}")
    vals = list(value) if n is not None else [value]
    if any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in vals):
        raise GripperError(f"gripper spec {where}: field {label!r} must be numbers, got {value!r}")
    arr = np.asarray(vals, dtype=np.float64)
    if not np.isfinite(arr).all():
        raise GripperError(f"gripper spec {where}: field {label!r} must be finite, got {value!r}")
    if positive and (arr <= 0).any():
        raise GripperError(f"gripper spec {where}: field {label!r} must be positive, got {value!r}")
    if nonneg and (arr < 0).any():
        raise GripperError(f"gripper spec {where}: field {label!r} must not be negative, got {value!r}")
    return arr if n is not None else float(arr[0])


def _spec_get(spec: dict, dotted: str, where: str):
    cur = spec
    for key in dotted.split("."):
        if not isinstance(cur, dict) or key not in cur:
            raise GripperError(f"gripper spec {where}: missing field {dotted!r}")
        cur = cur[key]
    return cur


def read_spec(path: str | Path) -> dict:
    """The mapping in a JSON or YAML file (a gripper spec, or the spec beside a gripper URDF)."""
    import yaml

    path = Path(path)
    if not path.is_file():
        raise GripperError(f"gripper spec {path} does not exist")
    try:
        text = path.read_text()
        spec = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (OSError, UnicodeDecodeError) as exc:
        raise GripperError(f"gripper spec {path} cannot be read as text ({type(exc).__name__})") from None
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        raise GripperError(f"gripper spec {path} is not valid {'JSON' if path.suffix.lower() == '.json' else 'YAML'} "
                           f"({_first_line(exc)})") from None
    if not isinstance(spec, dict):
        raise GripperError(f"gripper spec {path} must be a mapping of fields (name, stroke, tcp, pad, finger, palm)")
    return spec


def _pose(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", rpy).as_matrix()  # URDF's fixed-axis roll, pitch, yaw
    out[:3, 3] = xyz
    return out


def gripper_from_spec(path: str | Path) -> Gripper:
    """A parallel-jaw gripper from a spec file (CONVENTIONS.md, Gripper spec), lengths in metres in the hand frame
    (origin at the palm's base, +z toward the fingertips, fingers along +/-y).

    Each finger is its pad (`pad.size` [x, z] by `pad.thickness`, its inner face the contact rectangle, centred on
    the TCP's height) and its finger box (`finger.size`), whose inner face holds the pad and whose tip is flush with
    the pad's; the palm is a box (`palm.size`, centred at `palm.offset`, default on the palm's base) or a mesh. The
    TCP (`tcp`, optional `rpy`) lies midway between the pads; it must lie in front of the palm, within its footprint,
    with the fingers reaching back to the palm."""
    path = Path(path)
    where = str(path)
    spec = read_spec(path)
    unknown = sorted(set(spec) - set(SPEC_FIELDS))
    if unknown:
        raise GripperError(f"gripper spec {where}: unknown field {unknown[0]!r} (fields: {', '.join(SPEC_FIELDS)})")
    name = _spec_get(spec, "name", where)
    if not isinstance(name, str) or not name.strip():
        raise GripperError(f"gripper spec {where}: field 'name' must be a short non-empty text, got {name!r}")
    stroke = _spec_numbers(_spec_get(spec, "stroke", where), "stroke", where, 2, nonneg=True)
    if stroke[1] <= stroke[0]:
        raise GripperError(f"gripper spec {where}: field 'stroke' {stroke.tolist()} must be [min, max] with max > min "
                           f"(a stroke of zero cannot open)")
    tcp = _spec_numbers(_spec_get(spec, "tcp", where), "tcp", where, 3)
    rpy = _spec_numbers(spec["rpy"], "rpy", where, 3) if "rpy" in spec else np.zeros(3)
    pad_size = _spec_numbers(_spec_get(spec, "pad.size", where), "pad.size", where, 2, positive=True)
    pad_t = _spec_numbers(_spec_get(spec, "pad.thickness", where), "pad.thickness", where, positive=True)
    finger = _spec_numbers(_spec_get(spec, "finger.size", where), "finger.size", where, 3, positive=True)
    for key in ("mass", "max_force", "friction"):
        if key in spec:
            _spec_numbers(spec[key], key, where, positive=True)
    if pad_size[0] > finger[0] + 1e-12 or pad_size[1] > finger[2] + 1e-12:
        raise GripperError(f"gripper spec {where}: field 'pad.size' {pad_size.tolist()} is larger than the finger's "
                           f"inner face (finger.size x {finger[0]:g}, z {finger[2]:g})")
    palm = _spec_get(spec, "palm", where)
    mesh_bytes = b""
    if isinstance(palm, dict) and "mesh" in palm:
        mesh_path = path.parent / str(palm["mesh"])
        if not mesh_path.is_file():
            raise GripperError(f"gripper spec {where}: field 'palm.mesh' names {mesh_path}, which does not exist")
        try:
            mesh_bytes = mesh_path.read_bytes()
            palm_mesh = trimesh.load(mesh_path, force="mesh")
        except Exception as exc:
            raise GripperError(f"gripper spec {where}: field 'palm.mesh' {mesh_path} cannot be loaded "
                               f"({_first_line(exc)})") from None
        if len(palm_mesh.faces) == 0 or not np.isfinite(palm_mesh.vertices).all():
            raise GripperError(f"gripper spec {where}: field 'palm.mesh' {mesh_path} has no faces or non-finite vertices")
    else:
        size = _spec_numbers(_spec_get(spec, "palm.size", where), "palm.size", where, 3, positive=True)
        offset = _spec_numbers(palm.get("offset", [0.0, 0.0, size[2] / 2]), "palm.offset", where, 3)
        palm_mesh = trimesh.creation.box(extents=size, transform=_pose(offset, np.zeros(3)))
    lo, hi = palm_mesh.bounds
    lengths = {"stroke": stroke.max(), "tcp": np.abs(tcp).max(), "pad.size": pad_size.max(), "pad.thickness": pad_t,
               "finger.size": finger.max(), "palm": float((hi - lo).max())}
    field, big = max(lengths.items(), key=lambda kv: kv[1])
    if big > SPEC_LENGTH_MAX:
        raise GripperError(f"gripper spec {where}: field {field!r} reaches {big:g} m, implausible for a gripper (over "
                           f"{SPEC_LENGTH_MAX:g} m); a spec's lengths are in metres (50 mm is 0.05): divide "
                           f"millimetres by 1000")
    tcp_in_hand = _pose(tcp, rpy)
    if not (lo[0] - 1e-9 <= tcp[0] <= hi[0] + 1e-9 and lo[1] - 1e-9 <= tcp[1] <= hi[1] + 1e-9):
        raise GripperError(f"gripper spec {where}: field 'tcp' {tcp.tolist()} lies outside the hand (beside the palm, "
                           f"which spans x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g})")
    pad_pose, finger_pose = np.eye(4), np.eye(4)
    pad_pose[:3, 3] = (0.0, pad_t / 2, 0.0)
    finger_pose[:3, 3] = (0.0, finger[1] / 2, pad_size[1] / 2 - finger[2] / 2)
    boxes = ((np.array([pad_size[0], pad_t, pad_size[1]]), pad_pose), (finger.copy(), finger_pose))
    # Where the open fingers lie in the hand frame: the pads in front of the palm, the fingers reaching back to it.
    hand_z = []
    for ext, pose in boxes:
        for sgn in (-1, 1):
            c = tcp_in_hand @ pose @ np.array([0.0, 0.0, sgn * ext[2] / 2, 1.0])
            hand_z.append(c[2])
    pad_back, finger_back = min(hand_z[0:2]), min(hand_z[2:4])
    if pad_back < hi[2] - 1e-9:
        raise GripperError(f"gripper spec {where}: field 'tcp' {tcp.tolist()} lies outside the hand (the pads reach "
                           f"back to z {pad_back:g} m, inside the palm, whose top is at z {hi[2]:g} m)")
    if finger_back > hi[2] + 1e-6:
        raise GripperError(f"gripper spec {where}: field 'finger.size' z {finger[2]:g} m is too short to reach the "
                           f"palm (the fingers end {finger_back - hi[2]:.4g} m in front of it)")
    body = palm_mesh.copy()
    body.apply_transform(np.linalg.inv(tcp_in_hand))
    extra = json.dumps(spec, sort_keys=True, default=str) + hashlib.sha256(mesh_bytes).hexdigest()
    return Gripper(name=name.strip(), body=body, finger_boxes=boxes, pad=0, jaw_min=float(stroke[0]),
                   jaw_max=float(stroke[1]), urdf="", tcp_in_hand=tcp_in_hand, extra=extra)


def _urdf_beside(urdf: Path) -> dict:
    """The small spec beside a gripper URDF (`NAME.gripper.yaml`/`.json`): hand_link, finger_joints, tcp_frame."""
    for suffix in (".gripper.yaml", ".gripper.yml", ".gripper.json"):
        p = urdf.with_name(urdf.stem + suffix)
        if p.is_file():
            spec = read_spec(p)
            unknown = sorted(set(spec) - {"name", "hand_link", "finger_joints", "tcp_frame", "source"})
            if unknown:
                raise GripperError(f"gripper spec {p}: unknown field {unknown[0]!r} (fields: name, hand_link, "
                                   f"finger_joints, tcp_frame)")
            return spec
    return {}


def load_gripper(choice: str = "franka", hand_link: str | None = None, finger_joints: tuple[str, ...] = (),
                 tcp_frame: str | None = None, robot_urdf: str | Path | None = None, tip: str | None = None,
                 package_dirs: list[str] | None = None, robot_text: str | None = None) -> Gripper:
    """The gripper a user names: `franka`, a bundled name (`robotiq-2f85`, `parallel60`), a spec file (.json, .yaml),
    a URDF file (hand link, finger joints and TCP frame given, or read from `NAME.gripper.yaml` beside it), or `own`:
    the robot's own hand in `robot_urdf`, mounted at `tip` (the hand link, default the tip; the finger joints named;
    `robot_text` the URDF itself when `robot_urdf` only names it, as for a stored robot)."""
    if choice == "franka":
        return franka_hand()
    if choice == "own":
        if robot_urdf is None or tip is None:
            raise GripperError("--gripper own takes the robot's own hand from --robot URDF and --tip; where there is no "
                               "robot (grasps, placements) give its URDF itself: --gripper ROBOT.urdf --gripper-hand TIP "
                               "--gripper-fingers LEFT,RIGHT")
        if len(finger_joints) != 2:
            raise GripperError(f"--gripper own needs --gripper-fingers LEFT,RIGHT: the two finger joints of the hand in "
                               f"{robot_urdf}")
        if robot_text is None and not Path(robot_urdf).is_file():
            raise GripperError(f"robot URDF {robot_urdf} does not exist (--gripper own takes the hand from it); give "
                               f"the path of a .urdf file")
        return gripper_from_urdf(robot_urdf, hand_link or tip, tcp_frame, tuple(finger_joints), package_dirs,
                                 name=f"{Path(robot_urdf).stem}-hand", text=robot_text)
    path = BUNDLED.get(choice) or Path(choice)
    suffix = path.suffix.lower()
    if suffix in (".json", ".yaml", ".yml"):
        return gripper_from_spec(path)
    if suffix == ".urdf":
        if not path.is_file():
            raise GripperError(f"gripper URDF {path} does not exist")
        beside = _urdf_beside(path)
        hand = hand_link or beside.get("hand_link")
        fingers = tuple(finger_joints) or tuple(beside.get("finger_joints") or ())
        if not hand or not fingers:
            raise GripperError(f"gripper URDF {path}: name its hand link and two finger joints (--gripper-hand, "
                               f"--gripper-fingers) or put them in {path.stem}.gripper.yaml beside it")
        return gripper_from_urdf(path, str(hand), tcp_frame or beside.get("tcp_frame"), tuple(str(f) for f in fingers),
                                 package_dirs, name=beside.get("name") or path.stem)
    raise GripperError(f"gripper {choice!r} is not one of {', '.join(BUNDLED)}, own, or a .urdf, .json or .yaml file")
