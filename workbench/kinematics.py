"""IK feasibility of tabletop grips (Wan & Harada Section IV: the `ik` and `ikret` tables).

For every tabletop grip (a TCP pose in the world) three poses are solved: the grasp, the grasp retracted
by `handx` along the TCP's -z (the paper's hand x axis is our approach axis), and that pose raised by
`worldz` along world +z. A pose is feasible when IK converges (position within `tol_pos`, orientation
within `tol_rot`) inside the joint limits and the arm and the gripper at that configuration do not collide
with the table, nor the arm with the object (python-fcl on the URDF's collision geometry; the gripper's
contact with the object is the grasp planner's business).

Speed (Section VI, Table I's t-tpgik): a reachability pre-filter (`ReachFilter`: distance from the
shoulder, also over a humanoid's waist, and the workspace box); grips sorted so neighbours are the same
grasp at the next position, then rotation; each chunk of the sorted grips split into lanes solved in
lock-step, so one batched Levenberg-Marquardt iteration (numpy forward kinematics and Jacobians of the
serial chain, entry-major arrays) serves hundreds of poses while each lane warm-starts from its previous
grip's solution (per pose kind); fall-back seeds come from a deterministic library of table-clear sampled configurations nearest to the
target; chunks run on all cores (forked concurrent.futures workers that inherit the solver) with a tqdm
progress bar. Chunk boundaries depend only on the sorted input, so a resumed run produces the same rows as
an uninterrupted one, whatever the number of workers.
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
    from a library seed; seeds: library seeds tried after the warm start, picked among the seed_pool nearest
    library poses at least seed_spread rad apart; library: size of the seed
    library; chunk: grips per parallel task (resume unit); lane: grips per warm-start lane; seed: RNG seed."""

    tol_pos: float = 1e-4
    tol_rot: float = 1e-3
    iters_warm: int = 60
    iters_seed: int = 300
    seeds: int = 5
    seed_pool: int = 24
    seed_spread: float = 1.0
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


def _mm(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Batched 3x3 products in entry-major layout: (3, 3, B) x (3, 3, B) -> (3, 3, B)."""
    return np.einsum("ikb,kjb->ijb", a, b)


def _aligned(robot: Robot) -> list[tuple[int, float, bool]]:
    """Per joint: (axis index, sign) when its axis is a coordinate axis (else index -1), and whether its placement
    rotation is the identity."""
    cached = getattr(robot, "_aligned", None)
    if cached is None:
        cached = []
        for pl, ax in zip(robot.chain_placement, robot.chain_axis):
            k = int(np.argmax(np.abs(ax)))
            aligned = abs(abs(ax[k]) - 1.0) < 1e-12
            cached.append((k if aligned else -1, float(np.sign(ax[k])), bool(np.abs(pl[:3, :3] - np.eye(3)).max() < 1e-15)))
        robot._aligned = cached
    return cached


def _fk(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """`forward_soa` plus the joints' world axes (n, 3, B). Joints about a coordinate axis rotate two columns of the
    running rotation (no 3x3 product); others use Rodrigues' constant terms."""
    n, b = q.shape
    m0, ms, mc = _joint_terms(robot)
    info = _aligned(robot)
    sq, cq = np.sin(q), np.cos(q)
    rot = np.empty((n, 3, 3, b))
    pos = np.empty((n, 3, b))
    axes = np.empty((n, 3, b))
    r = np.repeat(robot.base[:3, :3, None], b, axis=2)
    t = np.repeat(robot.base[:3, 3, None], b, axis=1)
    for i in range(n):
        pl = robot.chain_placement[i]
        t = t + np.einsum("ikb,k->ib", r, pl[:3, 3])
        k, sign, identity = info[i]
        if robot.chain_prismatic[i]:
            r = np.einsum("ikb,kj->ijb", r, m0[i])
            axes[i] = np.einsum("ikb,k->ib", r, robot.chain_axis[i])
            t = t + axes[i] * q[i]
            rot[i] = r
        elif k >= 0:
            if not identity:
                r = np.einsum("ikb,kj->ijb", r, pl[:3, :3])
            u, v = (k + 1) % 3, (k + 2) % 3
            c, s_ = cq[i], sq[i] * sign
            out = rot[i]
            out[:, u] = c * r[:, u] + s_ * r[:, v]
            out[:, v] = c * r[:, v] - s_ * r[:, u]
            out[:, k] = r[:, k]
            r = out
            axes[i] = r[:, k] * sign
        else:
            local = m0[i][:, :, None] + ms[i][:, :, None] * sq[i] + mc[i][:, :, None] * cq[i]
            r = _mm(r, local)
            rot[i] = r
            axes[i] = np.einsum("ikb,k->ib", r, robot.chain_axis[i])
        pos[i] = t
    tip = robot.tip_in_joint
    tcp_t = t + np.einsum("ikb,k->ib", r, tip[:3, 3])
    tcp_r = np.einsum("ikb,kj->ijb", r, tip[:3, :3])
    return rot, pos, axes, tcp_r, tcp_t


def forward_soa(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched forward kinematics in entry-major layout (the batch is the last, contiguous axis): joint rotations
    (n, 3, 3, B), joint origins (n, 3, B), TCP rotation (3, 3, B) and position (3, B) for joint vectors q (n, B)."""
    rot, pos, _, tcp_r, tcp_t = _fk(robot, q)
    return rot, pos, tcp_r, tcp_t


def forward(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched forward kinematics in the world: joint rotations (B, n, 3, 3), joint origins (B, n, 3), TCP rotation
    (B, 3, 3) and TCP position (B, 3) for joint vectors q (B, n)."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    rot, pos, tcp_r, tcp_t = forward_soa(robot, np.ascontiguousarray(q.T))
    return rot.transpose(3, 0, 1, 2), pos.transpose(2, 0, 1), tcp_r.transpose(2, 0, 1), tcp_t.T


def _jacobian_soa(robot: Robot, axes: np.ndarray, pos: np.ndarray, tcp_t: np.ndarray) -> np.ndarray:
    """World-frame geometric Jacobian of the TCP, (6, n, B), linear rows first, from the joints' world axes."""
    d = tcp_t[None] - pos
    lin = np.stack([axes[:, 1] * d[:, 2] - axes[:, 2] * d[:, 1],
                    axes[:, 2] * d[:, 0] - axes[:, 0] * d[:, 2],
                    axes[:, 0] * d[:, 1] - axes[:, 1] * d[:, 0]], axis=0)  # (3, n, B)
    ang = axes.transpose(1, 0, 2)
    pr = robot.chain_prismatic
    if pr.any():
        lin[:, pr] = ang[:, pr]
        ang = ang.copy()
        ang[:, pr] = 0.0
    return np.concatenate([lin, ang], axis=0)


def jacobian(robot: Robot, q: np.ndarray) -> np.ndarray:
    """World-frame geometric Jacobian (B, 6, n) of the TCP at joint vectors q (B, n), linear rows first."""
    q = np.atleast_2d(np.asarray(q, dtype=np.float64))
    _, pos, axes, _, tcp_t = _fk(robot, np.ascontiguousarray(q.T))
    return _jacobian_soa(robot, axes, pos, tcp_t).transpose(2, 0, 1)


def _rotvec_soa(m: np.ndarray) -> np.ndarray:
    """Rotation vectors (3, B) of rotations (3, 3, B) (SO(3) log; near pi through scipy)."""
    v = 0.5 * np.stack([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]])
    c = np.clip(0.5 * (m[0, 0] + m[1, 1] + m[2, 2] - 1.0), -1.0, 1.0)
    s = np.sqrt((v * v).sum(0))
    theta = np.arctan2(s, c)
    out = v * np.where(s > 1e-9, theta / np.maximum(s, 1e-300), 1.0)
    far = c < -0.95
    if far.any():
        out[:, far] = Rotation.from_matrix(m[:, :, far].transpose(2, 0, 1)).as_rotvec().T
    return out


def rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation vectors (B, 3) of rotation matrices (B, 3, 3) (the SO(3) log map)."""
    return _rotvec_soa(np.ascontiguousarray(np.asarray(m, dtype=np.float64).transpose(1, 2, 0))).T


def _spd_solve(a: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve a x = rhs for symmetric positive definite a (m, m, B), rhs (m, B), by Cholesky in entry-major layout."""
    m = a.shape[0]
    low = np.zeros_like(a)
    for j in range(m):
        d = a[j, j] - (low[j, :j] ** 2).sum(0)
        low[j, j] = np.sqrt(np.maximum(d, 1e-300))
        if j + 1 < m:
            low[j + 1:, j] = (a[j + 1:, j] - (low[j + 1:, :j] * low[j, :j][None]).sum(1)) / low[j, j]
    y = np.empty_like(rhs)
    for i in range(m):
        y[i] = (rhs[i] - (low[i, :i] * y[:i]).sum(0)) / low[i, i]
    x = np.empty_like(rhs)
    for i in range(m - 1, -1, -1):
        x[i] = (y[i] - (low[i + 1:, i] * x[i + 1:]).sum(0)) / low[i, i]
    return x




def solve_ik(robot: Robot, targets: np.ndarray, q0: np.ndarray, iters: int, tol_pos: float = 1e-4,
             tol_rot: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    """Batched Levenberg-Marquardt IK (Sugihara's damping E + 1e-3) with joint-limit clamping.

    The step is J^T (J J^T + lambda I)^-1 e, solved per pose by a 6x6 Cholesky vectorised across poses.
    Converged rows leave the active set; rows whose error stalls for STALL_WINDOW iterations are given up.
    Returns the joint vectors (M, n) and which converged (M,)."""
    targets = np.asarray(targets, dtype=np.float64)
    q = np.ascontiguousarray(np.clip(np.array(q0, dtype=np.float64), robot.lower, robot.upper).T)  # (n, M)
    n, m = q.shape
    lo, hi = robot.lower[:, None], robot.upper[:, None]
    t_rot = np.ascontiguousarray(targets[:, :3, :3].transpose(1, 2, 0))
    t_pos = np.ascontiguousarray(targets[:, :3, 3].T)
    ok = np.zeros(m, dtype=bool)
    active = np.arange(m)
    last = np.full(m, np.inf)
    eye6 = np.eye(6)[:, :, None]
    qa, tr, tp = q, t_rot, t_pos
    for it in range(iters + 1):
        _, pos, axes, tcp_r, tcp_t = _fk(robot, qa)
        ep = tp - tcp_t
        er = _rotvec_soa(np.einsum("ikb,jkb->ijb", tr, tcp_r))
        np_, nr = np.sqrt((ep * ep).sum(0)), np.sqrt((er * er).sum(0))
        conv = (np_ < tol_pos) & (nr < tol_rot)
        q[:, active] = qa
        ok[active[conv]] = True
        keep = ~conv
        err = np_ + 0.2 * nr
        if it > 0 and it % STALL_WINDOW == 0:
            keep &= err <= STALL_RATIO * last[active]
            last[active] = err
        elif it == 0:
            last[active] = err
        if it == iters or not keep.any():
            break
        if not keep.all():
            active, qa, tr, tp = active[keep], qa[:, keep], tr[..., keep], tp[:, keep]
            axes, pos, tcp_t, ep, er = axes[..., keep], pos[..., keep], tcp_t[:, keep], ep[:, keep], er[:, keep]
        e = np.concatenate([ep, er], axis=0)  # (6, B)
        jac = _jacobian_soa(robot, axes, pos, tcp_t)  # (6, n, B)
        energy = 0.5 * (e * e).sum(0)
        a = np.einsum("inb,jnb->ijb", jac, jac) + eye6 * (energy + 1e-3)
        dq = np.einsum("inb,ib->nb", jac, _spd_solve(a, e))
        step = np.abs(dq).max(axis=0)
        dq *= np.minimum(1.0, 0.6 / np.maximum(step, 1e-12))
        qa = np.clip(qa + dq, lo, hi)
    return np.ascontiguousarray(q.T), ok


class SeedLibrary:
    """Deterministic sampled configurations and their TCP poses; `nearest` picks the seeds whose TCP pose is
    closest to each target (k-d tree over position and `rho`-weighted rotation matrix entries)."""

    def __init__(self, robot: Robot, size: int, seed: int, rho: float = 0.1, collider: "Collider | None" = None):
        from scipy.spatial import cKDTree

        rng = np.random.default_rng(seed)
        q = rng.uniform(robot.lower, robot.upper, size=(size, robot.nq))
        q[0] = robot.neutral()
        if collider is not None:  # keep seeds whose arm is clear of the table
            free = ~collider.collides_q(q, None, table_only=True)
            if free.sum() >= min(size, 64):
                q = q[free]
        self.q = q
        size = len(q)
        _, _, r, t = forward(robot, self.q)
        self.rho = rho
        self.tree = cKDTree(np.concatenate([t, rho * r.reshape(size, 9)], axis=1))

    def nearest(self, targets: np.ndarray, k: int, pool: int = 1, spread: float = 1.0) -> np.ndarray:
        """(M, k) library indices, nearest first. With pool > k, the k are picked greedily among the `pool` nearest
        so that each differs from those already picked by more than `spread` rad (Euclidean in joint space),
        filling up with the nearest remaining ones: diverse seeds reach different IK branches."""
        k = max(1, min(k, len(self.q)))
        pool = max(k, min(pool, len(self.q)))
        emb = np.concatenate([targets[:, :3, 3], self.rho * targets[:, :3, :3].reshape(len(targets), 9)], axis=1)
        _, ix = self.tree.query(emb, k=pool)
        ix = np.asarray(ix, dtype=np.int64).reshape(len(targets), pool)
        if pool == k:
            return ix
        m = len(ix)
        cand = self.q[ix]  # (M, pool, n)
        chosen = np.zeros((m, pool), dtype=bool)
        chosen[:, 0] = True
        count = np.ones(m, dtype=np.int64)
        for c in range(1, pool):
            d = np.linalg.norm(cand[:, :c] - cand[:, c:c + 1], axis=2)
            d = np.where(chosen[:, :c], d, np.inf).min(axis=1)
            take = (d > spread) & (count < k)
            chosen[:, c] = take
            count += take
        # fill rows that found fewer than k diverse seeds with the nearest unchosen ones
        for c in range(1, pool):
            take = ~chosen[:, c] & (count < k)
            chosen[:, c] |= take
            count += take
        order = np.argsort(~chosen, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(ix, order, axis=1)


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


def _obb(mesh: trimesh.Trimesh, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounding box of `mesh` (axis-aligned in the mesh's frame) placed at `pose`: rotation (3, 3), centre (3,),
    half extents (3,) (plus 0.1 mm)."""
    lo, hi = np.asarray(mesh.bounds, dtype=np.float64)
    centre = pose[:3, :3] @ (0.5 * (lo + hi)) + pose[:3, 3]
    return pose[:3, :3].copy(), centre, 0.5 * (hi - lo) + 1e-4


class Collider:
    """Arm (without its own hand) and planning gripper against the table slab and the object.

    Broad phase: world axis-aligned boxes of each part's oriented bounding box (numpy, batched over
    configurations); narrow phase: python-fcl on the URDF's collision geometry for the overlapping
    (configuration, part) pairs only."""

    def __init__(self, robot: Robot, scene: Scene, obj_mesh: trimesh.Trimesh | None):
        import fcl

        self.fcl = fcl
        self.robot = robot
        joints, obbs, objs, vs_obj, names = [], [], [], [], []
        for k in robot.arm_geometry():
            go = robot.geom.geometryObjects[k]
            g, mesh = _geometry_mesh(go, fcl)
            pl = np.asarray(go.placement.homogeneous)
            joints.append(go.parentJoint - 1)
            obbs.append(_obb(mesh, pl))
            objs.append((pl, fcl.CollisionObject(g, fcl.Transform())))
            vs_obj.append(True)
            names.append(go.name)
        grip = robot.gripper.collision_mesh()
        joints.append(robot.nq - 1)
        obbs.append(_obb(grip, robot.tip_in_joint))
        objs.append((robot.tip_in_joint, fcl.CollisionObject(_bvh(grip, fcl), fcl.Transform())))
        vs_obj.append(False)
        names.append("gripper")
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
        self.table = fcl.CollisionObject(fcl.Box(*(tmax - tmin)), fcl.Transform(0.5 * (tmin + tmax)))
        self.obj = None
        if obj_mesh is not None:
            self.obj = fcl.CollisionObject(_bvh(obj_mesh, fcl), fcl.Transform())
            self.obj_obb = _obb(obj_mesh, np.eye(4))
        self.request = fcl.CollisionRequest()

    def fixed_parts_hit_table(self) -> list[str]:
        """Names of the robot's fixed collision objects (base, locked legs) that cut into the table below its top 5 mm."""
        fcl = self.fcl
        robot = self.robot
        tmin, tmax = self.table_box
        depth = max(tmax[2] - tmin[2] - 0.005, 1e-3)
        top = fcl.CollisionObject(fcl.Box(tmax[0] - tmin[0], tmax[1] - tmin[1], depth),
                                  fcl.Transform(np.array([0.5 * (tmin[0] + tmax[0]), 0.5 * (tmin[1] + tmax[1]), -0.005 - depth / 2])))
        out = []
        for k in robot.fixed_geometry():
            go = robot.geom.geometryObjects[k]
            g, _ = _geometry_mesh(go, fcl)
            pose = robot.base @ np.asarray(go.placement.homogeneous)
            obj = fcl.CollisionObject(g, fcl.Transform(pose[:3, :3], pose[:3, 3]))
            if fcl.collide(obj, top, self.request, fcl.CollisionResult()):
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
        fcl = self.fcl
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
        hit = np.zeros(b, dtype=bool)
        for bi, pi in zip(*np.nonzero(cand_table | cand_obj)):
            if hit[bi]:
                continue
            j = self.joint[pi]
            pl, cobj = self.parts[pi]
            cobj.setRotation(rot[bi, j] @ pl[:3, :3])
            cobj.setTranslation(rot[bi, j] @ pl[:3, 3] + pos[bi, j])
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

    def collides_q(self, q: np.ndarray, placements: np.ndarray | None, table_only: bool = False) -> np.ndarray:
        """`collides` for joint vectors (B, n)."""
        rot, pos, _, _ = forward(self.robot, np.atleast_2d(q))
        pl = None if placements is None else np.asarray(placements).reshape(-1, 4, 4)
        return self.collides(rot, pos, pl, table_only)


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


class ReachFilter:
    """Reachability pre-filter: necessary conditions on the TCP position only (never rejects a reachable pose).

    For a split joint s, the TCP is within L_s (the summed link lengths from joint s's origin to the TCP) of
    joint s's origin, which itself lies on the set swept by the joints before s. For the deepest joint whose
    origin no earlier joint moves (the shoulder) that set is a point; for up to `grid_joints` joints further
    (a humanoid's waist, a UR's shoulder offset) it is sampled on a grid of those joints within their limits,
    and the slack is the largest distance between neighbouring samples. A pose passes when every split's
    condition and the workspace box hold."""

    def __init__(self, robot: Robot, scene: Scene, grid_joints: int = 2, grid: int = 48):
        from scipy.spatial import cKDTree

        j0, _ = robot.shoulder()  # 1-based joint index
        n = robot.nq
        self.tests = []
        for s in range(j0, min(j0 + grid_joints, n) + 1):
            length = float(np.linalg.norm(robot.tip_in_joint[:3, 3]))
            for j in range(s + 1, n + 1):
                length += float(np.linalg.norm(robot.chain_placement[j - 1][:3, 3]))
            for j in range(s, n + 1):
                if robot.chain_prismatic[j - 1]:
                    length += float(max(abs(robot.lower[j - 1]), abs(robot.upper[j - 1])))
            gridded = [j for j in range(1, s) if j > 0] if s > j0 else []
            if len(gridded) > grid_joints:
                continue
            axes = [np.linspace(robot.lower[j - 1], robot.upper[j - 1], grid) for j in gridded]
            q = np.tile(robot.neutral(), (grid ** len(gridded), 1))
            if gridded:
                mesh = np.meshgrid(*axes, indexing="ij")
                for j, m in zip(gridded, mesh):
                    q[:, j - 1] = m.ravel()
            _, pos, _, _ = forward(robot, q)
            pts = pos[:, s - 1]
            slack = 0.0
            if gridded:
                g = pts.reshape(*([grid] * len(gridded)), 3)
                for ax in range(len(gridded)):
                    slack += float(np.linalg.norm(np.diff(g, axis=ax), axis=-1).max())
            self.tests.append((cKDTree(pts), length + slack))
        self.wmin = np.asarray(scene.workspace_min)
        self.wmax = np.asarray(scene.workspace_max)

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        """(...) bool for TCP poses (..., 4, 4): True where the pose may be reachable."""
        p = np.asarray(poses)[..., :3, 3]
        flat = p.reshape(-1, 3)
        ok = (flat >= self.wmin).all(-1) & (flat <= self.wmax).all(-1)
        for tree, bound in self.tests:
            if ok.any():
                d, _ = tree.query(flat[ok], k=1)
                sub = ok[ok]
                sub &= d <= bound
                ok[ok] = sub
        return ok.reshape(p.shape[:-1])


class _Solver:
    """Per-process state: robot, seed library, collider, pre-filter (built once per worker)."""

    def __init__(self, spec: RobotSpec, scene: Scene, opts: IKOptions, obj_mesh: trimesh.Trimesh | None):
        self.robot = robot_from_spec(spec)
        self.scene, self.opts = scene, opts
        self.collider = Collider(self.robot, scene, obj_mesh) if opts.collide else None
        self.library = SeedLibrary(self.robot, opts.library, opts.seed, collider=self.collider)
        self.prefilter = ReachFilter(self.robot, scene)

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
        the library seed nearest to the target; pass 2 retries the failures from up to `seeds` library seeds, one
        seed rank at a time for the poses still unsolved."""
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
        from_library = np.zeros(3 * c, dtype=bool)  # pass 1 already tried the nearest library seed
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
                from_library[rows[cold]] = True
            q, ok = solve_ik(robot, flat[rows], q0, o.iters_warm, o.tol_pos, o.tol_rot)
            ok = self._feasible(rows, q, ok, place)
            q_out[rows[ok]] = q[ok]
            good[rows[ok]] = True
            prev[lanes[ok]] = q[ok]
        pool = np.nonzero(pre & ~good)[0]
        if len(pool) and o.seeds > 0:
            near = self.library.nearest(flat[pool], o.seeds, pool=o.seed_pool, spread=o.seed_spread)
            left = np.ones(len(pool), dtype=bool)
            for k in range(near.shape[1]):  # seed by seed, only for the poses still unsolved
                if not left.any():
                    break
                sel = np.flatnonzero(left & ~from_library[pool]) if k == 0 else np.flatnonzero(left)
                if len(sel) == 0:
                    continue
                rows = pool[sel]
                q, ok = solve_ik(robot, flat[rows], self.library.q[near[sel, k]], o.iters_seed, o.tol_pos, o.tol_rot)
                ok = self._feasible(rows, q, ok, place)
                q_out[rows[ok]] = q[ok]
                good[rows[ok]] = True
                left[sel[ok]] = False
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


_JOB: dict = {}  # the current run's solver and arrays, inherited by forked workers


def _run_chunk(start: int, end: int) -> tuple[np.ndarray, np.ndarray]:
    ix = _JOB["order"][start:end]
    return _JOB["solver"].chunk(_JOB["targets"][ix], _JOB["placements"][ix])


def iter_ik(robot: Robot, grips: dict[str, np.ndarray], scene: Scene, handx: float, worldz: float,
            obj_mesh: trimesh.Trimesh | None = None, opts: IKOptions = IKOptions(), workers: int | None = None,
            skip: Callable[[np.ndarray], bool] | None = None, progress: bool = True
            ) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """IK feasibility chunk by chunk (Section IV): yields (grip indices, feasible (C, 3), joints (C, 3, n)).

    `grips` follows the placements contract (rotmat: TCP poses in the world, placement_rotmat: object poses,
    idfreeairgrip, tabletopposition, idtabletopgrips). Chunks for which `skip(indices)` is True are not computed
    (already stored). The solver (robot, seed library, collision models) is built once here; with workers > 1
    (default: all cores) forked processes inherit it and the arrays, so only chunk bounds and results travel."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

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
    obj_key = ""
    if obj_mesh is not None:
        obj_key = hashlib.sha256(np.asarray(obj_mesh.vertices, dtype=np.float64).tobytes()
                                 + np.asarray(obj_mesh.faces, dtype=np.int64).tobytes()).hexdigest()[:16]
    _JOB.update(solver=_solver(robot.spec, scene, opts, obj_key, obj_mesh), order=order,
                targets=retract(poses, handx, worldz), placements=placements)
    workers = workers or os.cpu_count() or 1
    workers = max(1, min(workers, len(todo)))
    if workers > 1 and "fork" not in mp.get_all_start_methods():
        workers = 1
    bar = tqdm(total=int(sum(e - s for s, e in todo)), desc=f"ik {robot.name}", unit="grip", disable=not progress, leave=False)
    pool = None
    try:
        if workers == 1:
            results = (_run_chunk(s, e) for s, e in todo)
        else:
            pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork"))
            futures = [pool.submit(_run_chunk, s, e) for s, e in todo]
            results = (f.result() for f in futures)
        for (s, e), (feas, joints) in zip(todo, results):
            bar.update(e - s)
            yield order[s:e], feas, joints
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)
        _JOB.clear()


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
