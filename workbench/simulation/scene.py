"""The MuJoCo scene of a plan (CONVENTIONS.md, Simulation): the arm, the planning gripper, the table and the part.

- The arm is the robot's serial chain as the stored URDF gives it (the library's reduced pinocchio model: joint
  placements, axes, limits, link masses and inertias), one position actuator per joint plus a velocity term that
  follows the trajectory's velocities; the links are gravity-compensated, as an arm's own controller does. Each
  link collides through the URDF's collision shapes (primitives as they are, meshes as their convex hulls, as
  MuJoCo convexifies every mesh), without the robot's own hand: against the table and the part, and against the
  other links and the gripper in the pairs the self-collision check tests (`robots.selfcollision`; never
  adjacent links, never pairs that cannot move relative to each other, never a link whose hull is much larger than
  its mesh: that hull would touch where the mesh keeps clear, and the kinematic check tests its exact mesh).
- The gripper is the planning gripper's own geometry in its TCP frame (hand body mesh, finger boxes), its fingers
  on two slide joints coupled to move together (as a parallel-jaw gripper's mechanism does), each driven by a
  force-limited position actuator: closing squeezes with the grip force whatever the opening.
- The table is a box whose top is z = 0 over the scene's table rectangle, standing on a floor (a plane at
  z = FLOOR_Z, a table's height below its top): a part that leaves the table lands there (the replay calls it a drop).
- The part is a free body with the mass, centre of mass and inertia of its mesh at a density, colliding through
  its convex decomposition (simulation.decomposition).
Friction: the pads with the part use the plan's grasp friction, the table with the part the table friction
(MuJoCo's geom priority picks the pad's or the table's coefficient in each pair).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from workbench.errors import RobotWarning, SimulationError
from workbench.geometry.collision import pinocchio_geometry

ARM_KP = 4000.0  # N m / rad: position gain of every arm joint (tracking error I a / kp, under 0.1 mm at the TCP here)
ARM_KV = 100.0  # N m s / rad: velocity gain toward the trajectory velocity (higher gains chatter the hand at 2 ms)
FLOOR_Z = -0.75  # m: the floor, a table's height below the table top
ARM_ARMATURE = 0.1  # kg m^2: reflected rotor inertia, keeps stiff joints stable at a 2 ms step
FINGER_KP = 20000.0  # N / m: finger position gain; closing aims past the closed stop so the force limit holds
FINGER_DAMPING = 150.0  # N s / m
FINGER_ARMATURE = 0.5  # kg: reflected inertia of the finger drive
FINGER_MASS = 0.05  # kg per finger
HAND_MASS = 0.7  # kg when the gripper states none
TORSION = 0.004  # m: torsional friction of the soft pads (MuJoCo condim 4)
SOLREF = (0.005, 1.0)  # contact time constant (s, >= 2 timesteps) and damping ratio
NOSLIP = 0  # no-slip solver iterations: off (with it the soft pad contacts of a held part drift more, and it costs a third of the step)
SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
# contype / conaffinity: the table and the part raise contacts with everything, the robot's geoms only with them;
# robot-robot contacts are the explicit self-collision pairs
ENV_TYPE, ENV_AFFINITY, ROBOT_TYPE, ROBOT_AFFINITY = 1, 1, 0, 1
CONVEX_RATIO = 1.1  # a link mesh whose hull exceeds its volume this much takes no part in self-collision here


@dataclass
class SimScene:
    """A compiled MuJoCo model and the indices the replay needs: arm joint and finger qpos addresses, the part's
    free joint, the arm's position and velocity actuators, the finger actuators, the hand (TCP) body and the part;
    the robot's geoms (id -> the link they belong to, `gripper_hand` and `gripper_fingers` for the gripper's),
    which of them are the gripper's, the self-collision geom pairs, the table's geom and the floor's."""

    model: object
    arm_qpos: np.ndarray
    finger_qpos: np.ndarray
    part_qpos: int
    arm_act: np.ndarray
    vel_act: np.ndarray
    finger_act: np.ndarray
    hand_body: int
    part_body: int
    part_com: np.ndarray
    robot_geoms: dict[int, str] = field(default_factory=dict)
    gripper_geoms: frozenset[int] = frozenset()
    self_pairs: frozenset[tuple[int, int]] = frozenset()
    table_geom: int = -1
    floor_geom: int = -1


def mujoco_module():
    """The mujoco package, or a SimulationError saying how to install it."""
    try:
        import mujoco
    except ImportError:
        raise SimulationError("simulating plans needs MuJoCo: pip install 'regrasp-workbench[physics]' "
                              "(mujoco and coacd)") from None
    return mujoco


def mass_properties(mesh: trimesh.Trimesh, density: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass (kg), centre of mass (3,) and inertia about it (3, 3) in the part's frame: of the solid when the mesh
    is watertight, else of its convex hull."""
    solid = mesh if mesh.is_volume else mesh.convex_hull
    m = solid.copy()
    m.density = float(density)
    return float(m.mass), np.asarray(m.center_mass, dtype=np.float64), np.asarray(m.moment_inertia, dtype=np.float64)


def _quat(rot: np.ndarray) -> np.ndarray:
    mujoco = mujoco_module()
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=np.float64).ravel())
    return q


def _full_inertia(i: np.ndarray) -> list[float]:
    return [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]


def physical_inertia(inertia: np.ndarray, mass: float) -> tuple[np.ndarray, bool]:
    """A link's inertia tensor (3, 3) as physics accepts it, and whether it had to change: a tensor that is not
    positive definite becomes a small sphere's (1e-4 m^2 times the mass); one whose principal moments break the
    triangle inequality (A + B >= C, which every rigid body's moments meet and a hand-written URDF's may not) gets its two
    smaller moments raised by the same amount until they meet it, its axes kept (MuJoCo refuses it otherwise)."""
    ii = np.asarray(inertia, dtype=np.float64)
    ii = 0.5 * (ii + ii.T)
    e, v = np.linalg.eigh(ii)  # ascending
    if e[0] <= 1e-8:
        return np.eye(3) * 1e-4 * mass, True
    short = e[2] - e[0] - e[1]
    if short <= 1e-9 * e[2]:
        return ii, False
    e = e + np.array([1.0, 1.0, 0.0]) * (0.5 * short + 1e-6 * e[2])
    return (v * e) @ v.T, True


def build_scene(robot, gripper, scene, mesh: trimesh.Trimesh, hulls: list[tuple[np.ndarray, np.ndarray]],
                density: float, grip_force: float, pad_friction: float, table_friction: float,
                timestep: float, hand_mass: float | None = None, self_pairs: list[tuple[str, str]] | None = None,
                impratio: float = 1.0) -> SimScene:
    """Compile the scene of the module docstring for `robot` (a workbench Robot), `gripper` (its planning
    Gripper), `scene` (the table), the part's `mesh` and convex `hulls` (part frame); `hand_mass` from the
    gripper's spec, else 0.7 kg (it only loads the gravity-compensated arm); `self_pairs`: the link pairs that
    may collide with each other (`AllowedPairs.checked`; None: every pair of links two or more joints apart)."""
    mujoco = mujoco_module()
    spec = _spec(timestep, impratio)

    _add_table(spec, scene, table_friction)

    base = robot.base
    parent = spec.worldbody.add_body(name="robot_base", pos=base[:3, 3], quat=_quat(base[:3, :3]))
    model = robot.model
    arm_joints, balanced = [], []
    bodies = {0: parent}
    for j in range(1, model.njoints):
        placement = robot.chain_placement[j - 1]
        inertia = model.inertias[j]
        body = parent.add_body(name=f"link{j}", pos=placement[:3, 3], quat=_quat(placement[:3, :3]), gravcomp=1.0)
        mass = max(float(inertia.mass), 1e-3)
        body.explicitinertial = True
        body.mass = mass
        body.ipos = np.asarray(inertia.lever, dtype=np.float64)
        ii, changed = physical_inertia(inertia.inertia, mass)
        body.fullinertia = _full_inertia(ii)
        if changed:
            balanced.append(robot.joint_names[j - 1])
        kind = mujoco.mjtJoint.mjJNT_SLIDE if robot.chain_prismatic[j - 1] else mujoco.mjtJoint.mjJNT_HINGE
        name = robot.joint_names[j - 1]
        body.add_joint(name=name, type=kind, axis=robot.chain_axis[j - 1], range=[robot.lower[j - 1], robot.upper[j - 1]],
                       armature=ARM_ARMATURE, limited=mujoco.mjtLimited.mjLIMITED_TRUE)
        arm_joints.append(name)
        bodies[j] = body
        parent = body

    if balanced:
        warnings.warn(f"robot {robot.name!r}: the URDF inertias of the links moved by {', '.join(balanced)} are not a "
                      f"rigid body's (not positive definite, or principal moments with A + B < C); simulated with the "
                      f"nearest valid ones", RobotWarning, stacklevel=2)
    tip = robot.tip_in_joint
    hand_mass = float(hand_mass or HAND_MASS)
    hand = parent.add_body(name="hand", pos=tip[:3, 3], quat=_quat(tip[:3, :3]), gravcomp=1.0)
    body_mesh = gripper.body
    hand.explicitinertial = True
    hand.mass = hand_mass
    hand.ipos = np.asarray(body_mesh.bounds.mean(axis=0), dtype=np.float64)
    hand.fullinertia = _full_inertia(np.eye(3) * hand_mass * 0.05 ** 2 / 6)
    spec.add_mesh(name="hand_body", uservert=np.asarray(body_mesh.vertices, dtype=np.float32).ravel(),
                  userface=np.asarray(body_mesh.faces, dtype=np.int32).ravel())
    hand.add_geom(name="hand_body", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="hand_body", condim=3,
                  solref=SOLREF, solimp=SOLIMP, contype=ROBOT_TYPE, conaffinity=ROBOT_AFFINITY)
    links = {"hand_body": "gripper_hand"}
    mirror = np.diag([1.0, -1.0, 1.0, 1.0])
    fingers = []
    for side, sign in (("left", 1.0), ("right", -1.0)):
        finger = hand.add_body(name=f"finger_{side}", gravcomp=1.0)
        finger.explicitinertial = True
        finger.mass = FINGER_MASS
        finger.fullinertia = _full_inertia(np.eye(3) * 1e-5)
        finger.add_joint(name=f"finger_{side}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0.0, sign, 0.0],
                         range=[gripper.jaw_min / 2, gripper.jaw_max / 2], armature=FINGER_ARMATURE, damping=FINGER_DAMPING,
                         limited=mujoco.mjtLimited.mjLIMITED_TRUE)
        for k, (ext, pose) in enumerate(gripper.finger_boxes):
            p = pose if sign > 0 else mirror @ pose @ mirror
            pad = k == gripper.pad
            finger.add_geom(name=f"{side}_{'pad' if pad else f'box{k}'}", type=mujoco.mjtGeom.mjGEOM_BOX,
                            size=np.asarray(ext, dtype=np.float64) / 2, pos=p[:3, 3], quat=_quat(p[:3, :3]),
                            friction=[pad_friction, TORSION, 0.0], priority=1, condim=4 if pad else 3,
                            solref=SOLREF, solimp=SOLIMP, contype=ROBOT_TYPE, conaffinity=ROBOT_AFFINITY)
            links[f"{side}_{'pad' if pad else f'box{k}'}"] = "gripper_fingers"
        fingers.append(f"finger_{side}")
    spec.add_equality(type=mujoco.mjtEq.mjEQ_JOINT, name1="finger_left", name2="finger_right",
                      data=[0.0, 1.0, 0.0, 0.0, 0.0] + [0.0] * 7)
    spec.add_exclude(bodyname1="finger_left", bodyname2="finger_right")

    arm, bent = _add_link_geoms(spec, robot, bodies)
    links.update(arm)
    pairs = _self_pairs(robot, links, self_pairs, bent)
    for a, b in pairs:
        spec.add_pair(geomname1=a, geomname2=b, condim=3, solref=SOLREF, solimp=SOLIMP)

    _, com = _add_part(spec, mesh, hulls, density, min(pad_friction, table_friction))

    for name in arm_joints:
        a = spec.add_actuator(name=f"pos_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.set_to_position(kp=ARM_KP)
        v = spec.add_actuator(name=f"vel_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        v.set_to_velocity(kv=ARM_KV)
    for name in fingers:
        a = spec.add_actuator(name=f"grip_{name}", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        a.set_to_position(kp=FINGER_KP)
        a.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        a.forcerange = [-float(grip_force), float(grip_force)]
    try:
        m = spec.compile()
    except Exception as exc:  # MuJoCo's compiler names the element it refuses
        raise SimulationError(f"the physics scene of robot {robot.name!r} does not compile "
                              f"({str(exc).strip().splitlines()[0]})") from None
    jid = [m.joint(n).id for n in arm_joints]
    return SimScene(model=m, arm_qpos=np.array([m.jnt_qposadr[j] for j in jid]),
                    finger_qpos=np.array([m.jnt_qposadr[m.joint(n).id] for n in fingers]),
                    part_qpos=int(m.jnt_qposadr[m.joint("part").id]),
                    arm_act=np.array([m.actuator(f"pos_{n}").id for n in arm_joints]),
                    vel_act=np.array([m.actuator(f"vel_{n}").id for n in arm_joints]),
                    finger_act=np.array([m.actuator(f"grip_{n}").id for n in fingers]),
                    hand_body=m.body("hand").id, part_body=m.body("part").id, part_com=com,
                    robot_geoms={m.geom(g).id: lk for g, lk in links.items()},
                    gripper_geoms=frozenset(m.geom(g).id for g, lk in links.items() if lk.startswith("gripper_")),
                    self_pairs=frozenset(tuple(sorted((m.geom(a).id, m.geom(b).id))) for a, b in pairs),
                    table_geom=m.geom("table").id, floor_geom=m.geom("floor").id)


def _add_link_geoms(spec, robot, bodies: dict[int, object]) -> tuple[dict[str, str], set[str]]:
    """The URDF's collision shapes of the arm (without the robot's own hand) and of its fixed base on their bodies
    (`bodies`: reduced-model joint -> MjsBody, 0 the base); returns geom name -> link name, and the links with a
    mesh far from convex (its hull more than `CONVEX_RATIO` times its volume)."""
    mujoco = mujoco_module()
    out, bent = {}, set()
    for k in robot.fixed_geometry() + robot.arm_geometry():
        go = robot.geom.geometryObjects[k]
        body = bodies.get(int(go.parentJoint))
        if body is None:
            continue
        pl = np.asarray(go.placement.homogeneous, dtype=np.float64)
        name = f"arm{k}"
        kw = dict(name=name, pos=pl[:3, 3], quat=_quat(pl[:3, :3]), contype=ROBOT_TYPE, conaffinity=ROBOT_AFFINITY,
                  condim=3, solref=SOLREF, solimp=SOLIMP)
        geom, kind = go.geometry, type(go.geometry).__name__
        if kind == "Box" or hasattr(geom, "halfSide"):
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=np.asarray(geom.halfSide, dtype=np.float64), **kw)
        elif kind in ("Cylinder", "Capsule"):
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_CYLINDER if kind == "Cylinder" else mujoco.mjtGeom.mjGEOM_CAPSULE,
                          size=[float(geom.radius), float(geom.halfLength), 0.0], **kw)
        elif kind == "Sphere":
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[float(geom.radius), 0.0, 0.0], **kw)
        else:
            _, tm = pinocchio_geometry(go)
            hull = tm.convex_hull  # MuJoCo collides a mesh as its convex hull; handing it the hull compiles faster
            if not tm.is_volume or hull.volume > CONVEX_RATIO * tm.volume:
                bent.add(robot.model.frames[go.parentFrame].name)
            spec.add_mesh(name=name, uservert=np.asarray(hull.vertices, dtype=np.float32).ravel(),
                          userface=np.asarray(hull.faces, dtype=np.int32).ravel())
            body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name, **kw)
        out[name] = robot.model.frames[go.parentFrame].name
    return out, bent


def _self_pairs(robot, links: dict[str, str], checked: list[tuple[str, str]] | None,
                bent: set[str]) -> list[tuple[str, str]]:
    """Geom pairs (names) of the link pairs that may collide: `checked` link pairs, else every pair of links whose
    joints are neither the same nor adjacent (the gripper's two pseudo-links ride the last joint); never with a
    `bent` link, whose hull touches its neighbours where its mesh keeps clear (a UR5's forearm and the hand: 2 mm
    apart, hulls touching), and whose exact mesh the kinematic self-collision check tests at every knot."""
    if checked is None:
        joint = {robot.model.frames[go.parentFrame].name: int(go.parentJoint) for go in robot.geom.geometryObjects}
        joint["gripper_hand"] = joint["gripper_fingers"] = robot.nq
        parents = np.asarray(robot.model.parents)
        names = sorted(joint)
        checked = [(a, b) for i, a in enumerate(names) for b in names[i + 1:]
                   if joint[a] != joint[b] and parents[max(joint[a], joint[b])] != min(joint[a], joint[b])]
    want = {tuple(sorted(p)) for p in checked if not bent & set(p)}
    geoms = sorted(links)
    return [(a, b) for i, a in enumerate(geoms) for b in geoms[i + 1:] if tuple(sorted((links[a], links[b]))) in want]


def _spec(timestep: float, impratio: float = 1.0):
    """An empty MjSpec with the scene's options: gravity, timestep, implicit integration, elliptic friction cones
    (`impratio`: frictional to normal impedance)."""
    mujoco = mujoco_module()
    spec = mujoco.MjSpec()
    spec.option.timestep = float(timestep)
    spec.option.impratio = float(impratio)
    spec.option.gravity = [0.0, 0.0, -9.81]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.noslip_iterations = NOSLIP
    if hasattr(mujoco.mjtEnableBit, "mjENBL_MULTICCD"):  # several contacts per flat face pair (default from MuJoCo 3.3)
        spec.option.enableflags |= int(mujoco.mjtEnableBit.mjENBL_MULTICCD)
    spec.compiler.autolimits = True
    spec.compiler.degree = False  # joint ranges in radians
    return spec


def _add_table(spec, scene, friction: float) -> None:
    """The table slab and the floor under it."""
    mujoco = mujoco_module()
    lo, hi, th = np.asarray(scene.table_min), np.asarray(scene.table_max), float(scene.table_thickness)
    spec.worldbody.add_geom(name="table", type=mujoco.mjtGeom.mjGEOM_BOX, size=[*(0.5 * (hi - lo)), th / 2],
                            pos=[*(0.5 * (lo + hi)), -th / 2], friction=[friction, 0.0, 0.0], priority=1,
                            condim=3, solref=SOLREF, solimp=SOLIMP, contype=ENV_TYPE, conaffinity=ENV_AFFINITY)
    spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0.0, 0.0, 1.0], pos=[0.0, 0.0, FLOOR_Z],
                            friction=[friction, 0.0, 0.0], priority=1, condim=3, solref=SOLREF, solimp=SOLIMP,
                            contype=ENV_TYPE, conaffinity=ENV_AFFINITY)


def _add_part(spec, mesh: trimesh.Trimesh, hulls, density: float, friction: float) -> tuple[float, np.ndarray]:
    """The part as a free body with its mesh's mass properties and one geom per convex hull. The body's frame is the
    part's moved to its centre of mass (`part_qpos`, `body_poses`): a free joint integrates about its frame's
    origin, and an origin far from the mass (a CAD part exported in assembly coordinates) makes each step's small
    turn a large, unstable move."""
    mujoco = mujoco_module()
    mass, com, inertia = mass_properties(mesh, density)
    part = spec.worldbody.add_body(name="part")
    part.add_freejoint(name="part")
    part.explicitinertial = True
    part.mass = mass
    part.ipos = np.zeros(3)
    part.fullinertia = _full_inertia(inertia)
    for k, (v, f) in enumerate(hulls):
        spec.add_mesh(name=f"hull{k}", uservert=(np.asarray(v, dtype=np.float64) - com).astype(np.float32).ravel(),
                      userface=np.asarray(f, dtype=np.int32).ravel())
        part.add_geom(name=f"hull{k}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"hull{k}", condim=4,
                      friction=[friction, TORSION, 0.0], solref=SOLREF, solimp=SOLIMP, contype=ENV_TYPE,
                      conaffinity=ENV_AFFINITY)
    return mass, com


def part_qpos(pose: np.ndarray, com: np.ndarray) -> np.ndarray:
    """(7,) the part body's free-joint position and quaternion (w, x, y, z) for the part at `pose` (4, 4)."""
    out = np.zeros(7)
    out[:3] = pose[:3, :3] @ com + pose[:3, 3]
    mujoco_module().mju_mat2Quat(out[3:], np.ascontiguousarray(pose[:3, :3]).ravel())
    return out


def body_poses(pos: np.ndarray, quat_wxyz: np.ndarray, com: np.ndarray | None = None) -> np.ndarray:
    """(N, 4, 4) poses from a body's positions (N, 3) and quaternions (N, 4; w, x, y, z); with `com`, the part's
    poses from its body's (`_add_part`)."""
    out = np.tile(np.eye(4), (len(pos), 1, 1))
    out[:, :3, :3] = Rotation.from_quat(quat_wxyz[:, [1, 2, 3, 0]]).as_matrix()
    out[:, :3, 3] = pos if com is None else pos - out[:, :3, :3] @ com
    return out


def part_scene(mesh: trimesh.Trimesh, hulls, scene, density: float, friction: float, timestep: float,
               impratio: float = 1.0) -> tuple[object, int]:
    """The table and the part alone (no robot): the compiled model and the part's body id."""
    spec = _spec(timestep, impratio)
    _add_table(spec, scene, friction)
    _add_part(spec, mesh, hulls, density, friction)
    m = spec.compile()
    return m, m.body("part").id
