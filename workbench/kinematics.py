"""IK feasibility of tabletop grips (Wan & Harada Section IV: the `ik` and `ikret` tables).

For every tabletop grip (a TCP pose in the world) three poses are solved: the grasp, the grasp retracted
by `handx` along the TCP's -z (the paper's hand x axis is our approach axis), and that pose raised by
`worldz` along world +z. A pose is feasible when IK converges (position within `tol_pos`, orientation
within `tol_rot`) inside the joint limits and the arm and the gripper at that configuration do not collide
with the table, nor the arm with the object (python-fcl on the URDF's collision geometry; the gripper's
contact with the object is the grasp planner's business).

Speed (Section VI, Table I's t-tpgik): a reachability pre-filter (the shoulder's reach sphere and the
workspace box); grips sorted so neighbours are the same grasp at the next position, then rotation; each
chunk of the sorted grips split into lanes solved in lock-step, so one batched Levenberg-Marquardt
iteration (numpy forward kinematics and Jacobians of the serial chain) serves hundreds of poses while
each lane warm-starts from its previous grip; the retracted poses start from the grasp's solution;
fall-back seeds come from a deterministic library of sampled configurations nearest to the target;
chunks run on all cores (joblib) with a progress bar. Chunk boundaries depend only on the sorted input,
so a resumed run produces the same rows as an uninterrupted one.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import asdict, dataclass, field
from typing import Callable, Iterator

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from .errors import RobotError
from .robots import Robot, RobotSpec, robot_from_spec

KINDS = ("grasp", "handx", "handxworldz")
STALL_WINDOW = 6  # LM iterations between progress checks
STALL_RATIO = 0.8  # a row whose error did not drop below this fraction over the window is given up


@dataclass(frozen=True)
class Scene:
    """The table in the world (its top is z = 0) and the workspace box for the pre-filter, in metres.

    `table_min`/`table_max` are the table top's x-y corners; the slab is `table_thickness` thick.
    `workspace_min`/`workspace_max` bound the TCP position of poses worth solving."""

    table_min: tuple[float, float] = (-0.3, -0.8)
    table_max: tuple[float, float] = (1.0, 0.8)
    table_thickness: float = 0.05
    workspace_min: tuple[float, float, float] = (-1.5, -1.5, 0.0)
    workspace_max: tuple[float, float, float] = (1.5, 1.5, 1.5)

    def __post_init__(self) -> None:
        vals = np.array([*self.table_min, *self.table_max, self.table_thickness, *self.workspace_min, *self.workspace_max], dtype=float)
        if not np.isfinite(vals).all():
            raise RobotError(f"scene has NaN or infinite values: {self}")
        if self.table_max[0] <= self.table_min[0] or self.table_max[1] <= self.table_min[1] or self.table_thickness <= 0:
            raise RobotError(f"scene table is empty: min {self.table_min}, max {self.table_max}, thickness {self.table_thickness}")

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


@dataclass(frozen=True)
class IKOptions:
    """Solver settings (they change the rows, so they are stored with the scene).

    tol_pos (m) and tol_rot (rad): convergence; iters_warm/iters_seed: LM iterations from a warm start and
    from a library seed; seeds: library seeds tried after the warm start; library: size of the seed
    library; chunk: grips per parallel task (resume unit); lane: grips per warm-start lane; seed: RNG seed."""

    tol_pos: float = 1e-4
    tol_rot: float = 1e-3
    iters_warm: int = 30
    iters_seed: int = 60
    seeds: int = 5
    library: int = 32768
    chunk: int = 4096
    lane: int = 16
    seed: int = 0
    collide: bool = True

    def as_dict(self) -> dict:
        return asdict(self)


@dataclass
class IKResult:
    """Per grip (in input order): feasibility (N, 3) for grasp, handx, handxworldz; joints (N, 3, nq), NaN where infeasible."""

    feasible: np.ndarray
    joints: np.ndarray
    order: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


# ----------------------------------------------------------------------------------------------------------------
# Batched kinematics of a serial chain (numpy).


def _joint_terms(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per joint, constant matrices with placement_R @ Rot(axis, q) = M0 + sin(q) Ms + cos(q) Mc (Rodrigues)."""
    cached = getattr(robot, "_joint_terms", None)
    if cached is None:
        m0, ms, mc = [], [], []
        for pl, (x, y, z), pr in zip(robot.chain_placement, robot.chain_axis, robot.chain_prismatic):
            r = pl[:3, :3]
            if pr:
                m0.append(r)
                ms.append(np.zeros((3, 3)))
                mc.append(np.zeros((3, 3)))
                continue
            k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
            m0.append(r @ (np.eye(3) + k @ k))
            ms.append(r @ k)
            mc.append(-r @ k @ k)
        cached = (np.array(m0), np.array(ms), np.array(mc))
        robot._joint_terms = cached
    return cached


def forward(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched forward kinematics in the world: joint rotations (B, n, 3, 3), joint origins (B, n, 3), TCP rotation
    (B, 3, 3) and TCP position (B, 3) for joint vectors q (B, n)."""
    q = np.asarray(q, dtype=np.float64)
    b, n = q.shape
    m0, ms, mc = _joint_terms(robot)
    sq, cq = np.sin(q), np.cos(q)
    rot = np.empty((b, n, 3, 3))
    pos = np.empty((b, n, 3))
    r = robot.base[:3, :3]
    t = robot.base[:3, 3]
    for i in range(n):
        pl = robot.chain_placement[i]
        t = t + r @ pl[:3, 3]
        if robot.chain_prismatic[i]:
            r = r @ m0[i]
            t = t + (r @ robot.chain_axis[i]) * q[:, i:i + 1]
        else:
            local = m0[i] + sq[:, i, None, None] * ms[i] + cq[:, i, None, None] * mc[i]
            r = np.matmul(r, local)
        rot[:, i], pos[:, i] = r, t
    tip = robot.tip_in_joint
    tcp_t = t + r @ tip[:3, 3]
    tcp_r = r @ tip[:3, :3]
    return rot, pos, tcp_r, tcp_t


def jacobian(robot: Robot, rot: np.ndarray, pos: np.ndarray, tcp_t: np.ndarray) -> np.ndarray:
    """World-frame geometric Jacobian (B, 6, n) of the TCP (linear rows first) from `forward`'s output."""
    axes = np.einsum("bnij,nj->bni", rot, robot.chain_axis)
    lin = np.cross(axes, tcp_t[:, None, :] - pos)
    pr = robot.chain_prismatic
    if pr.any():
        lin[:, pr] = axes[:, pr]
        axes = axes.copy()
        axes[:, pr] = 0.0
    return np.concatenate([lin, axes], axis=2).transpose(0, 2, 1)


def rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation vectors (B, 3) of rotation matrices (B, 3, 3) (SO(3) log; near pi through scipy)."""
    v = 0.5 * np.stack([m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]], axis=1)
    c = np.clip(0.5 * (m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2] - 1.0), -1.0, 1.0)
    s = np.linalg.norm(v, axis=1)
    theta = np.arctan2(s, c)
    scale = np.where(s > 1e-9, theta / np.maximum(s, 1e-300), 1.0 + theta * theta / 6.0)
    out = v * scale[:, None]
    far = c < -0.95
    if far.any():
        out[far] = Rotation.from_matrix(m[far]).as_rotvec()
    return out


def _pose_error(target: np.ndarray, tcp_r: np.ndarray, tcp_t: np.ndarray) -> np.ndarray:
    """(B, 6): position error and rotation vector of target * current^-1, both in the world frame."""
    ep = target[:, :3, 3] - tcp_t
    er = rotvec(target[:, :3, :3] @ tcp_r.transpose(0, 2, 1))
    return np.concatenate([ep, er], axis=1)


_STATS = {'rowiters': 0, 'iters': 0}  # DEVSTATS


def solve_ik(robot: Robot, targets: np.ndarray, q0: np.ndarray, iters: int, tol_pos: float = 1e-4,
             tol_rot: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Batched Levenberg-Marquardt IK (Sugihara's damping E + 1e-3) with joint-limit clamping.

    Converged rows leave the active set; rows whose error stalls for STALL_WINDOW iterations are given up. Returns the
    joint vectors (M, n) and which converged (M,)."""
    q = np.clip(np.array(q0, dtype=np.float64), robot.lower, robot.upper)
    m, n = q.shape
    ok = np.zeros(m, dtype=bool)
    active = np.arange(m)
    last = np.full(m, np.inf)
    eye = np.eye(n)
    for it in range(iters + 1):
        if len(active) == 0:
            break
        qa = q[active]
        _STATS["rowiters"] += len(active); _STATS["iters"] += 1  # DEVSTATS
        rot, pos, tcp_r, tcp_t = forward(robot, qa)
        e = _pose_error(targets[active], tcp_r, tcp_t)
        ep = np.linalg.norm(e[:, :3], axis=1)
        er = np.linalg.norm(e[:, 3:], axis=1)
        conv = (ep < tol_pos) & (er < tol_rot)
        ok[active[conv]] = True
        keep = ~conv
        err = ep + 0.2 * er
        if it % STALL_WINDOW == 0 and it > 0:
            stalled = err > STALL_RATIO * last[active]
            keep &= ~stalled
            last[active] = err
        elif it == 0:
            last[active] = err
        if it == iters:
            break
        active, qa, e = active[keep], qa[keep], e[keep]
        if len(active) == 0:
            break
        rot, pos, tcp_t = rot[keep], pos[keep], tcp_t[keep]
        jac = jacobian(robot, rot, pos, tcp_t)
        jt = jac.transpose(0, 2, 1)
        energy = 0.5 * np.einsum("bi,bi->b", e, e)
        h = jt @ jac + (energy + 1e-3)[:, None, None] * eye
        g = np.einsum("bij,bj->bi", jt, e)
        dq = np.linalg.solve(h, g[..., None])[..., 0]
        step = np.abs(dq).max(axis=1, keepdims=True)
        dq *= np.minimum(1.0, 0.6 / np.maximum(step, 1e-12))
        q[active] = np.clip(qa + dq, robot.lower, robot.upper)
    return q, ok


class SeedLibrary:
    """Deterministic sampled configurations and their TCP poses; `nearest` picks the seeds whose TCP pose is
    closest to each target (k-d tree over position and `rho`-weighted rotation matrix entries)."""

    def __init__(self, robot: Robot, size: int, seed: int, rho: float = 0.1):
        from scipy.spatial import cKDTree

        rng = np.random.default_rng(seed)
        self.q = rng.uniform(robot.lower, robot.upper, size=(size, robot.nq))
        self.q[0] = robot.neutral()
        _, _, r, t = forward(robot, self.q)
        self.rho = rho
        self.tree = cKDTree(np.concatenate([t, rho * r.reshape(size, 9)], axis=1))

    def nearest(self, targets: np.ndarray, k: int) -> np.ndarray:
        """(M, k) library indices, nearest first."""
        k = max(1, min(k, len(self.q)))
        emb = np.concatenate([targets[:, :3, 3], self.rho * targets[:, :3, :3].reshape(len(targets), 9)], axis=1)
        _, ix = self.tree.query(emb, k=k)
        return np.asarray(ix, dtype=np.int64).reshape(len(targets), k)


# ----------------------------------------------------------------------------------------------------------------
# Collision (python-fcl on the URDF's collision geometry, numpy bounding-box broad phase).


def _geometry_mesh(go, fcl_mod) -> tuple[object, trimesh.Trimesh]:
    """An fcl geometry and a trimesh of one pinocchio GeometryObject (in the geometry's own frame)."""
    geom = go.geometry
    kind = type(geom).__name__
    if kind == "Box" or hasattr(geom, "halfSide"):
        ext = 2 * np.asarray(geom.halfSide, dtype=np.float64)
        return fcl_mod.Box(*ext), trimesh.creation.box(extents=ext)
    if kind == "Cylinder":
        r, h = float(geom.radius), 2 * float(geom.halfLength)
        return fcl_mod.Cylinder(r, h), trimesh.creation.cylinder(radius=r, height=h, sections=24)
    if kind == "Sphere":
        r = float(geom.radius)
        return fcl_mod.Sphere(r), trimesh.creation.icosphere(radius=r, subdivisions=2)
    if kind == "Capsule":
        r, h = float(geom.radius), 2 * float(geom.halfLength)
        return fcl_mod.Capsule(r, h), trimesh.creation.capsule(radius=r, height=h)
    if go.meshPath:
        mesh = trimesh.load(go.meshPath, force="mesh")
        mesh.apply_scale(np.asarray(go.meshScale, dtype=np.float64))
        return _bvh(mesh, fcl_mod), mesh
    raise RobotError(f"collision geometry {go.name} has unsupported type {kind}")


def _bvh(mesh: trimesh.Trimesh, fcl_mod):
    model = fcl_mod.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


def _hull(mesh: trimesh.Trimesh) -> np.ndarray:
    try:
        return np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
    except Exception:  # degenerate (flat) meshes: all vertices bound it as well
        return np.asarray(mesh.vertices, dtype=np.float64)


class Collider:
    """Arm (without its own hand) and planning gripper against the table slab and the object.

    Broad phase: axis-aligned boxes of the convex hulls' vertices in the world (numpy, batched); narrow phase:
    python-fcl for the overlapping (configuration, part) pairs only."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None):
        import fcl

        self.fcl = fcl
        self.robot = robot
        parts = []  # (joint index 0-based, placement in joint frame, hull vertices in joint frame, fcl object, vs object)
        for k in robot.arm_geometry():
            go = robot.geom.geometryObjects[k]
            g, mesh = _geometry_mesh(go, fcl)
            pl = np.asarray(go.placement.homogeneous)
            hull = _hull(mesh) @ pl[:3, :3].T + pl[:3, 3]
            parts.append((go.parentJoint - 1, pl, hull, fcl.CollisionObject(g, fcl.Transform()), True))
        grip = robot.gripper.collision_mesh()
        pl = robot.tip_in_joint
        parts.append((robot.nq - 1, pl, _hull(grip) @ pl[:3, :3].T + pl[:3, 3],
                      fcl.CollisionObject(_bvh(grip, fcl), fcl.Transform()), False))
        self.parts = parts
        self.names = [robot.geom.geometryObjects[k].name for k in robot.arm_geometry()] + ["gripper"]
        self.joint = np.array([p[0] for p in parts])
        self.hull_sizes = np.array([len(p[2]) for p in parts])
        self.hull = np.concatenate([p[2] for p in parts])
        self.hull_joint = np.repeat(self.joint, self.hull_sizes)
        self.hull_part = np.repeat(np.arange(len(parts)), self.hull_sizes)
        self.vs_object = np.array([p[4] for p in parts])
        tmin = np.array([scene.table_min[0], scene.table_min[1], -scene.table_thickness])
        tmax = np.array([scene.table_max[0], scene.table_max[1], 0.0])
        self.table_box = (tmin, tmax)
        self.table = fcl.CollisionObject(fcl.Box(*(tmax - tmin)), fcl.Transform(0.5 * (tmin + tmax)))
        self.obj = None
        if obj_mesh is not None:
            self.obj = fcl.CollisionObject(_bvh(obj_mesh, fcl), fcl.Transform())
            self.obj_hull = _hull(obj_mesh)
        self.request = fcl.CollisionRequest()

    def fixed_parts_hit_table(self) -> list[str]:
        """Names of the robot's fixed collision objects (base, locked legs) that cut into the table's top 5 mm."""
        fcl = self.fcl
        robot = self.robot
        tmin, tmax = self.table_box
        top = fcl.CollisionObject(fcl.Box(tmax[0] - tmin[0], tmax[1] - tmin[1], max(tmax[2] - tmin[2] - 0.005, 1e-3)),
                                  fcl.Transform(0.5 * (tmin + tmax) - np.array([0, 0, 0.0025])))
        out = []
        for k in robot.fixed_geometry():
            go = robot.geom.geometryObjects[k]
            g, _ = _geometry_mesh(go, fcl)
            pose = robot.base @ np.asarray(go.placement.homogeneous)
            obj = fcl.CollisionObject(g, fcl.Transform(pose[:3, :3], pose[:3, 3]))
            if fcl.collide(obj, top, self.request, fcl.CollisionResult()):
                out.append(go.name)
        return out

    def _world_hulls(self, rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
        r = rot[:, self.hull_joint]  # (B, V, 3, 3)
        return np.einsum("bvij,vj->bvi", r, self.hull) + pos[:, self.hull_joint]

    def _boxes(self, rot: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per configuration and part: world AABB min and max (B, P, 3)."""
        w = self._world_hulls(rot, pos)
        starts = np.concatenate([[0], np.cumsum(self.hull_sizes)[:-1]])
        return np.minimum.reduceat(w, starts, axis=1), np.maximum.reduceat(w, starts, axis=1)

    def collides(self, rot: np.ndarray, pos: np.ndarray, placements: np.ndarray | None) -> np.ndarray:
        """(B,) True where a configuration's arm or gripper hits the table or its arm hits the object placed at
        `placements` (B, 4, 4)."""
        fcl = self.fcl
        b = len(rot)
        if b == 0:
            return np.zeros(0, dtype=bool)
        lo, hi = self._boxes(rot, pos)
        tmin, tmax = self.table_box
        cand_table = (lo <= tmax).all(-1) & (hi >= tmin).all(-1)
        cand_obj = np.zeros_like(cand_table)
        if self.obj is not None and placements is not None:
            ow = np.einsum("bij,vj->bvi", placements[:, :3, :3], self.obj_hull) + placements[:, None, :3, 3]
            omin, omax = ow.min(1), ow.max(1)
            cand_obj = (lo <= omax[:, None]).all(-1) & (hi >= omin[:, None]).all(-1) & self.vs_object[None]
        hit = np.zeros(b, dtype=bool)
        for bi, pi in zip(*np.nonzero(cand_table | cand_obj)):
            if hit[bi]:
                continue
            j, pl, _, cobj, _ = self.parts[pi]
            r = rot[bi, j] @ pl[:3, :3]
            t = rot[bi, j] @ pl[:3, 3] + pos[bi, j]
            cobj.setRotation(r)
            cobj.setTranslation(t)
            if cand_table[bi, pi] and fcl.collide(cobj, self.table, self.request, fcl.CollisionResult()):
                hit[bi] = True
                continue
            if cand_obj[bi, pi]:
                p = placements[bi]
                self.obj.setRotation(p[:3, :3])
                self.obj.setTranslation(p[:3, 3])
                if fcl.collide(cobj, self.obj, self.request, fcl.CollisionResult()):
                    hit[bi] = True
        return hit

    def collides_q(self, q: np.ndarray, placements: np.ndarray | None) -> np.ndarray:
        """`collides` for joint vectors (B, n)."""
        rot, pos, _, _ = forward(self.robot, np.atleast_2d(q))
        return self.collides(rot, pos, None if placements is None else np.asarray(placements).reshape(-1, 4, 4))


# ----------------------------------------------------------------------------------------------------------------
# The stage.


def retract(poses: np.ndarray, handx: float, worldz: float) -> np.ndarray:
    """(N, 3, 4, 4): the grasp, the pose moved back by `handx` along the TCP's -z, and that pose raised by `worldz`
    along world +z (Section IV, ikret)."""
    poses = np.asarray(poses, dtype=np.float64)
    out = np.repeat(poses[:, None], 3, axis=1)
    out[:, 1, :3, 3] -= handx * poses[:, :3, 2]
    out[:, 2, :3, 3] = out[:, 1, :3, 3]
    out[:, 2, 2, 3] += worldz
    return out


def check_poses(poses: np.ndarray, label: str = "TCP pose") -> np.ndarray:
    """(N, 4, 4) finite rigid transforms, or a RobotError naming the first bad one."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise RobotError(f"{label}s must be an (N, 4, 4) array, got shape {poses.shape}")
    bad = ~np.isfinite(poses).all(axis=(1, 2))
    if bad.any():
        raise RobotError(f"{label} {int(np.argmax(bad))} (of {len(poses)}) has NaN or infinite entries; rebuild the tabletop grips")
    r = poses[:, :3, :3]
    dev = np.abs(r @ r.transpose(0, 2, 1) - np.eye(3)).max(axis=(1, 2))
    if (dev > 1e-5).any():
        raise RobotError(f"{label} {int(np.argmax(dev > 1e-5))} (of {len(poses)}) is not a rigid transform; rebuild the tabletop grips")
    return poses


def neighbour_order(grips: dict[str, np.ndarray]) -> np.ndarray:
    """Indices sorting grips so consecutive ones are close: by free-air grasp, then placement orientation (which
    includes the rotation angle), then position in a serpentine over the grid (x rows, y alternating)."""
    n = len(grips["rotmat"])
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    prot = np.round(np.asarray(grips["placement_rotmat"])[:, :3, :3].reshape(n, 9), 6)
    _, orient = np.unique(prot, axis=0, return_inverse=True)
    pos = np.asarray(grips["tabletopposition"], dtype=np.float64)
    ix = np.unique(np.round(pos[:, 0], 4), return_inverse=True)[1].ravel()
    iy = np.unique(np.round(pos[:, 1], 4), return_inverse=True)[1].ravel()
    iy_s = np.where(ix % 2 == 0, iy, -iy)
    return np.lexsort((np.asarray(grips["idtabletopgrips"]), iy_s, ix, orient.ravel(), np.asarray(grips["idfreeairgrip"])))


def chunk_bounds(n: int, chunk: int) -> list[tuple[int, int]]:
    """Fixed chunk boundaries over the sorted grips (they depend only on n, so resumed runs match)."""
    return [(s, min(s + chunk, n)) for s in range(0, n, chunk)]


class _Solver:
    """Per-process state: robot, seed library, collider, pre-filter (built once per worker)."""

    def __init__(self, spec: RobotSpec, scene: Scene, opts: IKOptions, obj_mesh: trimesh.Trimesh | None):
        self.robot = robot_from_spec(spec)
        self.scene, self.opts = scene, opts
        self.library = SeedLibrary(self.robot, opts.library, opts.seed)
        self.collider = Collider(self.robot, scene, obj_mesh) if opts.collide else None
        self.centre, self.radius = self.robot.reach()
        self.wmin = np.asarray(scene.workspace_min)
        self.wmax = np.asarray(scene.workspace_max)

    def prefilter(self, poses: np.ndarray) -> np.ndarray:
        """Poses whose TCP is inside the reach sphere and the workspace box."""
        p = poses[..., :3, 3]
        inside = np.linalg.norm(p - self.centre, axis=-1) <= self.radius
        return inside & (p >= self.wmin).all(-1) & (p <= self.wmax).all(-1)

    def _feasible(self, rows: np.ndarray, q: np.ndarray, ok: np.ndarray, placements: np.ndarray) -> np.ndarray:
        """Converged rows whose configuration is collision-free."""
        good = ok.copy()
        if self.collider is not None and ok.any():
            sel = np.nonzero(ok)[0]
            good[sel] = ~self.collider.collides_q(q[sel], placements[rows[sel]])
        return good

    def chunk(self, targets: np.ndarray, placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One chunk of sorted grips: targets (C, 3, 4, 4) -> feasible (C, 3), joints (C, 3, n).

        Pass 1 walks the lanes in lock-step: every (lane, kind) starts from its previous feasible solution, or from
        the library seed nearest to the target; pass 2 retries the failures from `seeds` library seeds at once."""
        o, robot = self.opts, self.robot
        c, n = len(targets), robot.nq
        flat = targets.transpose(1, 0, 2, 3).reshape(3 * c, 4, 4)  # row = kind * c + grip
        place = np.tile(placements, (3, 1, 1))
        pre = self.prefilter(flat)
        q_out = np.full((3 * c, n), np.nan)
        good = np.zeros(3 * c, dtype=bool)
        lane = max(1, o.lane)
        nl = -(-c // lane)
        starts = np.arange(nl) * lane
        prev = np.full((3 * nl, n), np.nan)
        tried = np.zeros(3 * c, dtype=bool)
        for step in range(lane):
            idx = starts + step
            live = idx < c
            lanes = np.concatenate([np.nonzero(live)[0] + k * nl for k in range(3)])
            rows = np.concatenate([idx[live] + k * c for k in range(3)])
            keep = pre[rows]
            rows, lanes = rows[keep], lanes[keep]
            if len(rows) == 0:
                continue
            q0 = prev[lanes].copy()
            cold = np.isnan(q0).any(axis=1)
            if cold.any():
                q0[cold] = self.library.q[self.library.nearest(flat[rows[cold]], 1)[:, 0]]
            q, ok = solve_ik(robot, flat[rows], q0, o.iters_warm, o.tol_pos, o.tol_rot)
            ok = self._feasible(rows, q, ok, place)
            tried[rows] = True
            q_out[rows[ok]] = q[ok]
            good[rows[ok]] = True
            prev[lanes[ok]] = q[ok]
        pool = np.nonzero(pre & ~good)[0]
        if len(pool) and o.seeds > 0:
            near = self.library.nearest(flat[pool], o.seeds)
            k = near.shape[1]
            rows = np.repeat(pool, k)
            q, ok = solve_ik(robot, flat[rows], self.library.q[near.ravel()], o.iters_seed, o.tol_pos, o.tol_rot)
            ok = self._feasible(rows, q, ok, place)
            okm = ok.reshape(len(pool), k)
            has = okm.any(axis=1)
            first = okm.argmax(axis=1)
            pick = np.arange(len(pool)) * k + first
            q_out[pool[has]] = q[pick[has]]
            good[pool[has]] = True
        feas = good.reshape(3, c).T.copy()
        joints = q_out.reshape(3, c, n).transpose(1, 0, 2).copy()
        return feas, joints


_SOLVERS: dict[tuple, _Solver] = {}


def _solver(spec: RobotSpec, scene: Scene, opts: IKOptions, obj_key: str, obj_mesh: trimesh.Trimesh | None) -> _Solver:
    key = (spec.digest, scene, opts, obj_key)
    if key not in _SOLVERS:
        _SOLVERS.clear()
        _SOLVERS[key] = _Solver(spec, scene, opts, obj_mesh)
    return _SOLVERS[key]


def _run_chunk(spec: RobotSpec, scene: Scene, opts: IKOptions, obj_key: str, obj_arrays: tuple | None,
               targets: np.ndarray, placements: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    mesh = None if obj_arrays is None else trimesh.Trimesh(obj_arrays[0], obj_arrays[1], process=False)
    return _solver(spec, scene, opts, obj_key, mesh).chunk(targets, placements)


def iter_ik(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, handx: float, worldz: float,
            obj_mesh: trimesh.Trimesh | None = None, opts: IKOptions = IKOptions(), workers: int | None = None,
            skip: Callable[[np.ndarray], bool] | None = None, progress: bool = True
            ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """IK feasibility chunk by chunk (Section IV): yields (grip indices, feasible (C, 3), joints (C, 3, n)).

    `grips` follows the placements contract (rotmat: TCP poses in the world, placement_rotmat: object poses,
    idfreeairgrip, tabletopposition, idtabletopgrips). Chunks for which `skip(indices)` is True are not computed
    (already stored). Workers default to all cores; 1 runs in this process."""
    from tqdm.auto import tqdm

    poses = check_poses(grips["rotmat"])
    placements = check_poses(grips["placement_rotmat"], "object placement")
    for label, value in (("handx", handx), ("worldz", worldz)):
        if not np.isfinite(value) or value < 0:
            raise RobotError(f"retraction {label} must be a finite distance >= 0 m, got {value}")
    order = neighbour_order(grips)
    bounds = chunk_bounds(len(order), opts.chunk)
    todo = [(s, e) for s, e in bounds if skip is None or not skip(order[s:e])]
    if not todo:
        return
    targets = retract(poses, handx, worldz)
    obj_arrays, obj_key = None, ""
    if obj_mesh is not None:
        obj_arrays = (np.asarray(obj_mesh.vertices, dtype=np.float64), np.asarray(obj_mesh.faces, dtype=np.int64))
        obj_key = hashlib.sha256(obj_arrays[0].tobytes() + obj_arrays[1].tobytes()).hexdigest()[:16]
    workers = workers or os.cpu_count() or 1
    workers = max(1, min(workers, len(todo)))
    bar = tqdm(total=int(sum(e - s for s, e in todo)), desc=f"ik {robot.name}", unit="grip", disable=not progress, leave=False)
    args = [order[s:e] for s, e in todo]
    try:
        if workers == 1:
            gen = (_run_chunk(robot.spec, scene, opts, obj_key, obj_arrays, targets[ix], placements[ix]) for ix in args)
        else:
            from joblib import Parallel, delayed

            gen = Parallel(n_jobs=workers, return_as="generator")(
                delayed(_run_chunk)(robot.spec, scene, opts, obj_key, obj_arrays, targets[ix], placements[ix]) for ix in args)
        for ix, (feas, joints) in zip(args, gen):
            bar.update(len(ix))
            yield ix, feas, joints
    finally:
        bar.close()


def ik_feasibility(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, handx: float, worldz: float,
                   obj_mesh: trimesh.Trimesh | None = None, opts: IKOptions = IKOptions(), workers: int | None = None,
                   progress: bool = True) -> IKResult:
    """IK feasibility of every grip at the grasp, handx and handxworldz poses (Section IV), in input order."""
    n = len(grips["rotmat"])
    feas = np.zeros((n, 3), dtype=bool)
    joints = np.full((n, 3, robot.nq), np.nan)
    for ix, f, j in iter_ik(robot, grips, scene, handx, worldz, obj_mesh, opts, workers, progress=progress):
        feas[ix], joints[ix] = f, j
    return IKResult(feasible=feas, joints=joints, order=neighbour_order(grips))
