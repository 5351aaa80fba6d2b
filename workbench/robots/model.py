"""Robot models for IK feasibility (Wan & Harada Section IV, the `robot` table; CONVENTIONS.md, Store).

A robot is a URDF, the base pose of its root link in the world, the arm's tip frame, and the mount
transform from the tip frame to the planning gripper's TCP (CONVENTIONS.md, Gripper). The arm is the
serial chain of joints from the root to the tip frame (optionally restricted to named joints); every
other joint is locked at its reference value (zero) with pinocchio's `buildReducedModel`.

The TCP pose of a stored joint vector is, without this library::

    model = pinocchio.buildModelFromXML(robot.urdf)          # every joint not in joint_names at 0
    q[idx_q(name)] = value for name in robot.joint_names
    TCP = robot.base @ oMf(robot.tip_frame) @ robot.mount

Built-in robots (all from example-robot-data, all carrying the Franka hand as planning gripper):

- `panda`: the Franka Panda arm with its own hand, TCP `panda_hand_tcp` (tip = TCP, mount = identity),
  mounted at the world origin on the table.
- `ur5`: UR5 (`ur5_robot.urdf`) with the Franka hand on its flange `tool0` (TCP 0.1034 m along the
  flange's z), at the world origin on the table.
- `talos`: Talos's left arm with its two torso joints (9 DoF, like the paper's 8-DoF HRP5P arm that
  includes the waist), the Franka hand on the wrist tool flange `wrist_left_ft_tool_link`; the robot
  stands in front of the table (pelvis at x = 0.05 m, 0.25 m above the table top, the table's edge at x = 0.2 m),
  its legs, head and own gripper locked, the right arm locked tucked away (`TALOS_RIGHT_ARM_TUCKED`).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import pinocchio as pin

from workbench.errors import RobotError
from workbench.resources import erd_robots, erd_share
from workbench.robots.gripper import Gripper, franka_hand

TCP_OFFSET = 0.1034  # panda_hand -> panda_hand_tcp along the hand's z (CONVENTIONS.md, Gripper)
ROBOTS = ("panda", "ur5", "talos")


def pose_xyz_yaw(x: float = 0.0, y: float = 0.0, z: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    """A 4x4 pose from a position and a rotation about world z (radians)."""
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.eye(4)
    out[:2, :2] = [[c, -s], [s, c]]
    out[:3, 3] = (x, y, z)
    return out


def _rot_x(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    out = np.eye(4)
    out[1:3, 1:3] = [[c, -s], [s, c]]
    return out


def _trans(x: float, y: float, z: float) -> np.ndarray:
    out = np.eye(4)
    out[:3, 3] = (x, y, z)
    return out


def check_pose(pose: np.ndarray, label: str) -> np.ndarray:
    """A finite rigid 4x4 transform, or a RobotError naming `label`."""
    p = np.asarray(pose, dtype=np.float64)
    if p.shape != (4, 4):
        raise RobotError(f"{label} must be a 4x4 transform, got shape {p.shape}")
    if not np.isfinite(p).all():
        raise RobotError(f"{label} has NaN or infinite entries; give a finite pose")
    r = p[:3, :3]
    if np.abs(r @ r.T - np.eye(3)).max() > 1e-6 or np.linalg.det(r) < 0 or np.abs(p[3] - (0, 0, 0, 1)).max() > 1e-9:
        raise RobotError(f"{label} is not a rigid transform (rotation not orthonormal or last row not 0 0 0 1)")
    return p


@dataclass(frozen=True)
class RobotSpec:
    """Everything that defines a robot for IK (picklable; rebuilt in worker processes).

    `drop_geometry` lists link-name prefixes whose collision geometry is replaced by the planning gripper
    (a robot's own hand or tool); `joints` restricts the arm to these joints of the chain (None: all);
    `locked` gives values of locked joints other than 0 (a humanoid's other arm tucked away).
    """

    name: str
    urdf: str
    urdf_path: str
    tip_frame: str
    tcp_frame: str
    mount: np.ndarray = field(default_factory=lambda: np.eye(4))
    base: np.ndarray = field(default_factory=lambda: np.eye(4))
    joints: tuple[str, ...] | None = None
    drop_geometry: tuple[str, ...] = ()
    package_dirs: tuple[str, ...] = ()
    locked: tuple[tuple[str, float], ...] = ()
    gripper: Gripper | None = None

    @cached_property
    def hand(self) -> Gripper:
        """The planning gripper (the Franka hand unless the spec names another)."""
        return self.gripper if self.gripper is not None else franka_hand()

    @cached_property
    def digest(self) -> str:
        """Identifies the kinematics and the hand: URDF text, frames, mount, base, joints, dropped geometry and the
        planning gripper's geometry (its digest), so caches, worker processes and `ik` rows follow the gripper."""
        h = hashlib.sha256()
        h.update(self.hand.digest.encode())
        h.update(self.urdf.encode())
        h.update(json.dumps([self.tip_frame, self.tcp_frame, list(self.joints or ()), list(self.drop_geometry),
                             [[k, float(v)] for k, v in self.locked]]).encode())
        h.update(np.round(np.asarray(self.mount, dtype=np.float64), 12).tobytes())
        h.update(np.round(np.asarray(self.base, dtype=np.float64), 12).tobytes())
        return h.hexdigest()[:24]




class Robot:
    """A loaded robot: the reduced pinocchio model of the arm, its collision geometry and the gripper.

    `joint_names` is the order of joint vectors; `lower`/`upper` their limits. `chain_*` arrays describe the
    serial chain for batched numpy kinematics (kinematics.py): joint i's placement in its parent joint,
    its axis in its own frame and whether it is prismatic; `tip` is the TCP in the last joint's frame.
    """

    def __init__(self, spec: RobotSpec):
        self.spec = spec
        self.gripper = spec.hand
        self.base = check_pose(spec.base, f"base pose of robot {spec.name!r}")
        self.mount = check_pose(spec.mount, f"mount transform of robot {spec.name!r}")
        dirs = [str(erd_share()), *spec.package_dirs]
        if spec.urdf_path:
            dirs.append(str(Path(spec.urdf_path).parent))
        try:
            full = pin.buildModelFromXML(spec.urdf)
            geom = pin.buildGeomFromUrdfString(full, spec.urdf, pin.COLLISION, package_dirs=dirs)
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise RobotError(f"robot URDF {spec.urdf_path or spec.name!r} could not be loaded ({first}); check the file and its mesh paths") from None
        if not full.existFrame(spec.tip_frame):
            names = [f.name for f in full.frames if f.type in (pin.FrameType.BODY, pin.FrameType.OP_FRAME)]
            raise RobotError(f"robot URDF {spec.urdf_path or spec.name!r} has no tip frame {spec.tip_frame!r} "
                             f"(links: {', '.join(names[-8:])}, ...); pass --tip with one of its links")
        tip = full.frames[full.getFrameId(spec.tip_frame)]
        chain = []
        j = tip.parentJoint
        while j > 0:
            chain.append(j)
            j = full.parents[j]
        chain = chain[::-1]
        if spec.joints is not None:
            missing = [n for n in spec.joints if not full.existJointName(n) or full.getJointId(n) not in chain]
            if missing:
                raise RobotError(f"joints {missing} of robot {spec.name!r} are not on the chain from the root to {spec.tip_frame!r}")
            chain = [j for j in chain if full.names[j] in spec.joints]
        if not chain:
            raise RobotError(f"tip frame {spec.tip_frame!r} of robot {spec.name!r} is not moved by any joint; choose a frame of the arm")
        for j in chain:
            if full.joints[j].nq != 1 or full.joints[j].nv != 1:
                raise RobotError(f"joint {full.names[j]!r} of robot {spec.name!r} is {full.joints[j].shortname()}; "
                                 f"only revolute and prismatic joints with limits are supported")
        lock = [j for j in range(1, full.njoints) if j not in chain]
        q_ref = pin.neutral(full)
        for jname, value in spec.locked:
            if not full.existJointName(jname) or full.getJointId(jname) in chain:
                raise RobotError(f"locked joint {jname!r} of robot {spec.name!r} is not a joint of the URDF outside the arm")
            jid = full.getJointId(jname)
            q_ref[full.joints[jid].idx_q] = float(value)
        model, rgeom = pin.buildReducedModel(full, geom, lock, q_ref)
        self.model, self.geom = model, rgeom
        self._lock, self._q_ref, self._dirs, self._visual = lock, q_ref, dirs, None
        self.joint_names = tuple(model.names[j] for j in range(1, model.njoints))
        self.lower = np.asarray(model.lowerPositionLimit, dtype=np.float64).copy()
        self.upper = np.asarray(model.upperPositionLimit, dtype=np.float64).copy()
        if not (np.isfinite(self.lower).all() and np.isfinite(self.upper).all()) or (self.upper - self.lower < 0).any():
            raise RobotError(f"robot {spec.name!r} has joints without finite limits; add <limit> to its URDF")
        fid = model.getFrameId(spec.tip_frame)
        self.last_joint = model.frames[fid].parentJoint
        if self.last_joint != model.njoints - 1:
            raise RobotError(f"tip frame {spec.tip_frame!r} of robot {spec.name!r} is not after the last arm joint")
        self.tip_in_joint = np.asarray(model.frames[fid].placement.homogeneous) @ self.mount
        if spec.tcp_frame == spec.tip_frame:
            if np.abs(self.mount - np.eye(4)).max() > 1e-12:
                raise RobotError(f"robot {spec.name!r}: the TCP frame equals the tip frame {spec.tip_frame!r} but the mount is not identity")
        elif model.existFrame(spec.tcp_frame):
            raise RobotError(f"robot {spec.name!r}: TCP frame name {spec.tcp_frame!r} already exists in the URDF; choose another")
        else:
            model.addFrame(pin.Frame(spec.tcp_frame, self.last_joint, fid,
                                     pin.SE3(self.tip_in_joint[:3, :3], self.tip_in_joint[:3, 3]), pin.FrameType.OP_FRAME))
        self.tcp_id = model.getFrameId(spec.tcp_frame)
        # Chain description for batched kinematics.
        n = model.nq
        self.chain_placement = np.stack([np.asarray(model.jointPlacements[j].homogeneous) for j in range(1, n + 1)])
        axes, prismatic = [], []
        for j in range(1, n + 1):
            kind = model.joints[j].shortname()
            if kind in ("JointModelRX", "JointModelPX"):
                ax = np.array([1.0, 0, 0])
            elif kind in ("JointModelRY", "JointModelPY"):
                ax = np.array([0, 1.0, 0])
            elif kind in ("JointModelRZ", "JointModelPZ"):
                ax = np.array([0, 0, 1.0])
            elif kind in ("JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"):
                ax = np.asarray(model.joints[j].extract().axis, dtype=np.float64)
            else:
                raise RobotError(f"joint {model.names[j]!r} of robot {spec.name!r} has unsupported type {kind}")
            axes.append(ax / np.linalg.norm(ax))
            prismatic.append(kind.startswith("JointModelP"))
        self.chain_axis = np.stack(axes)
        self.chain_prismatic = np.array(prismatic)

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    def tcp_pose(self, q: np.ndarray) -> np.ndarray:
        """The TCP pose in the world at joint vector `q` (pinocchio, one configuration)."""

        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q, dtype=np.float64))
        return self.base @ np.asarray(data.oMf[self.tcp_id].homogeneous)

    def visual_model(self):
        """The reduced pinocchio VISUAL geometry model (meshes of the URDF, same locked joints as the arm)."""

        if self._visual is None:
            full = pin.buildModelFromXML(self.spec.urdf)
            vis = pin.buildGeomFromUrdfString(full, self.spec.urdf, pin.VISUAL, package_dirs=self._dirs)
            _, self._visual = pin.buildReducedModel(full, vis, self._lock, self._q_ref)
        return self._visual

    def dropped(self, go) -> bool:
        """Whether a geometry object belongs to the links replaced by the planning gripper."""
        link = self.model.frames[go.parentFrame].name
        return any(link.startswith(p) for p in self.spec.drop_geometry)

    def fixed_geometry(self) -> list[int]:
        """Indices of collision objects that do not move with the arm (base, locked legs...)."""
        return [k for k, go in enumerate(self.geom.geometryObjects) if go.parentJoint == 0]

    def arm_geometry(self) -> list[int]:
        """Indices of collision objects moved by the arm, without the robot's own hand (`drop_geometry`)."""
        out = []
        for k, go in enumerate(self.geom.geometryObjects):
            if go.parentJoint == 0 or self.dropped(go):
                continue
            out.append(k)
        return out

    def shoulder(self) -> tuple[int, np.ndarray]:
        """The deepest arm joint whose origin no earlier joint moves, and that origin in the base frame.

        Distances from it to the TCP are bounded by the chain's length (reachability pre-filter)."""

        rng = np.random.default_rng(0)
        data = self.model.createData()
        qs = [pin.neutral(self.model)] + [rng.uniform(self.lower, self.upper) for _ in range(8)]
        best = 1
        for j in range(1, self.model.njoints):
            pts = []
            for q in qs:
                pin.forwardKinematics(self.model, data, q)
                pts.append(np.asarray(data.oMi[j].translation).copy())
            if np.ptp(np.array(pts), axis=0).max() < 1e-9:
                best = j
            else:
                break
        pin.forwardKinematics(self.model, data, pin.neutral(self.model))
        return best, np.asarray(data.oMi[best].translation).copy()


    def neutral(self) -> np.ndarray:
        """The zero configuration clipped into the joint limits."""
        q = np.clip(np.zeros(self.nq), self.lower, self.upper)
        return q


def robot_from_urdf(urdf: str | Path, tip_frame: str, base: np.ndarray | None = None, mount: np.ndarray | None = None,
                    tcp_frame: str | None = None, name: str | None = None, joints: tuple[str, ...] | None = None,
                    drop_geometry: tuple[str, ...] = (), package_dirs: tuple[str, ...] = (),
                    locked: tuple[tuple[str, float], ...] = (), gripper: Gripper | None = None) -> Robot:
    """Any robot: a URDF path, its base pose in the world, the arm's tip frame, the gripper mount (tip to TCP) and
    the planning gripper (default: the Franka hand)."""
    path = Path(urdf)
    if not path.is_file():
        raise RobotError(f"robot URDF {path} does not exist; give the path of a .urdf file or one of {', '.join(ROBOTS)}")
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RobotError(f"robot URDF {path} cannot be read as text ({type(exc).__name__})") from None
    if "<robot" not in text:
        raise RobotError(f"robot URDF {path} is not a URDF (no <robot> element)")
    if tcp_frame is None:
        tcp_frame = tip_frame if mount is None else f"{tip_frame}_tcp"
    spec = RobotSpec(name=name or path.stem, urdf=text, urdf_path=str(path), tip_frame=tip_frame, tcp_frame=tcp_frame,
                     mount=np.eye(4) if mount is None else np.asarray(mount, dtype=np.float64),
                     base=np.eye(4) if base is None else np.asarray(base, dtype=np.float64),
                     joints=joints, drop_geometry=tuple(drop_geometry), package_dirs=tuple(package_dirs),
                     locked=tuple((str(k), float(v)) for k, v in locked), gripper=gripper)
    return Robot(spec)


# Talos's right arm bent with its forearm pointing outwards, clear of the table (radians).
TALOS_RIGHT_ARM_TUCKED = (("arm_right_2_joint", -0.3), ("arm_right_3_joint", -1.5), ("arm_right_4_joint", -2.0))

DEFAULT_BASES = {
    "panda": pose_xyz_yaw(0.0, 0.0, 0.0, 0.0),
    "ur5": pose_xyz_yaw(0.0, 0.0, 0.0, 0.0),
    "talos": pose_xyz_yaw(0.05, 0.0, 0.25, 0.0),
}


def builtin_robot(name: str, base: np.ndarray | None = None, tip_frame: str | None = None,
                  mount: np.ndarray | None = None, gripper: Gripper | None = None) -> Robot:
    """One of the built-in robots (`panda`, `ur5`, `talos`), optionally at another base, tip or mount."""
    root = erd_robots()
    base = DEFAULT_BASES[name] if base is None else base
    if name == "panda":
        return robot_from_urdf(root / "panda_description" / "urdf" / "panda.urdf", tip_frame or "panda_hand_tcp", base=base,
                               mount=mount, tcp_frame="panda_hand_tcp" if mount is None else None, name="panda",
                               drop_geometry=("panda_hand", "panda_leftfinger", "panda_rightfinger"), gripper=gripper)
    if name == "ur5":
        return robot_from_urdf(root / "ur_description" / "urdf" / "ur5_robot.urdf", tip_frame or "tool0", base=base,
                               mount=_trans(0, 0, TCP_OFFSET) if mount is None else mount, tcp_frame="franka_hand_tcp",
                               name="ur5", gripper=gripper)
    if name == "talos":
        return robot_from_urdf(root / "talos_data" / "robots" / "talos_reduced.urdf", tip_frame or "wrist_left_ft_tool_link",
                               base=base, mount=(_rot_x(np.pi) @ _trans(0, 0, TCP_OFFSET)) if mount is None else mount,
                               tcp_frame="franka_hand_tcp", name="talos", drop_geometry=("gripper_left_",),
                               locked=TALOS_RIGHT_ARM_TUCKED, gripper=gripper)
    raise RobotError(f"unknown robot {name!r}: use one of {', '.join(ROBOTS)} or the path of a URDF")


def get_robot(name_or_path: str, base: np.ndarray | None = None, tip_frame: str | None = None,
              mount: np.ndarray | None = None, gripper: Gripper | None = None) -> Robot:
    """A built-in robot by name, or a robot from a URDF path (then `tip_frame` is required)."""
    if name_or_path in ROBOTS:
        return builtin_robot(name_or_path, base=base, tip_frame=tip_frame, mount=mount, gripper=gripper)
    if tip_frame is None:
        raise RobotError(f"robot {name_or_path!r} is not one of {', '.join(ROBOTS)}; for a URDF path also give --tip FRAME")
    return robot_from_urdf(name_or_path, tip_frame, base=base, mount=mount, gripper=gripper)


def robot_from_spec(spec: RobotSpec) -> Robot:
    """Rebuild a robot from its spec (in worker processes, from the pickled spec)."""
    return Robot(spec)
