"""Replay a timed regrasp plan in MuJoCo and judge it (CONVENTIONS.md, Simulation).

The part starts resting at the plan's start pose and is never moved by hand: only the arm, following the plan's
timed joint trajectory with position actuators, and the fingers, closing with the grip force and opening where the
plan's jaw actions say, move it, under gravity, at a fixed timestep. After the trajectory the arm rests for
`hold_end` seconds and the part's final pose is compared with the goal.

The verdict, in time order (the first failure names the plan step and how it failed):
- collision: an arm link or the gripper goes into the table, an arm link into the part, or two links of the robot
  into each other (a self-collision pair), deeper than `collision_depth`;
- shove: while the fingers close, the part moves more than the slip tolerance (a curved surface pushed aside);
- slip / drop: during a transfer (from the close to the last straight line down) the part moves in the hand, as relative motion of
  part and TCP, beyond the slip tolerance; a drop when no pad touches it any more or it moved by more than
  `drop_distance`; at any time, a part that leaves the table and lands on the floor is a drop, and the replay
  stops there;
- roll: after a release the part does not settle (speeds below `settle_speed`, `settle_spin` within
  `settle_time`), or settles turned beyond the waypoint tolerance from its placement;
- pose: at a waypoint (the end of a motion) the part is beyond the waypoint tolerance from the plan's pose;
- goal: at the end the part is beyond the goal tolerance (defaults 5 mm and 5 degrees).

The part's poses are compared with the plan's up to the part's rotational symmetry (`geometry.symmetry`, found
from its mesh within 0.5 mm): a part at rest turned about its own axis of revolution, or by a turn that maps it onto
itself, is where the plan put it. Slip and shove measure motion, and count every turn.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
from dataclasses import dataclass, field

import numpy as np

from workbench.errors import SimulationError
from workbench.geometry.symmetry import Symmetry, part_symmetry
from workbench.params import Params, param
from workbench.simulation.decomposition import Decomposition
from workbench.simulation.scene import body_poses, build_scene, mass_properties, mujoco_module, part_qpos, part_scene

MODEL_VERSION = 5  # bump when the scene or the verdict changes what a stored simulation means
DEGREE = math.pi / 180
SQUEEZE = 0.02  # m: closing aims this far past the closed stop, so the finger force sits at its limit
DEFAULT_GRIP_FORCE = 70.0  # N: the Franka hand's continuous grasp force
PLAYBACK_HZ = 30.0  # samples per second of the simulated part's pose kept for the animation


@dataclass(frozen=True)
class SimParams(Params):
    """Every parameter of a simulation; their digest keys the stored result (with the plan)."""

    timestep: float = param(0.002, gt=0, le=0.01, unit="s", help="physics timestep")
    impratio: float = param(10.0, ge=1, le=100, help="ratio of frictional to normal contact impedance (MuJoCo's impratio)")
    density: float = param(1000.0, gt=0, le=30000, unit="kg/m^3", help="density of the part")
    grip_force: float | None = param(None, ge=0, le=2000, optional=True, unit="N",
                                     help="force of each finger when closed (default: the gripper's, 70 N for the Franka hand)")
    friction: float | None = param(None, ge=0, le=5, optional=True,
                                   help="pad-part friction coefficient (default: the plan's grasp friction)")
    table_friction: float | None = param(None, ge=0, le=5, optional=True,
                                         help="table-part friction coefficient (default: the pad friction)")
    goal_tol: float = param(0.005, gt=0, le=1, unit="m", help="goal position tolerance")
    goal_tol_angle: float = param(5 * DEGREE, gt=0, le=math.pi, unit="rad", cli_scale=180 / math.pi, cli_unit="deg",
                                  help="goal rotation tolerance")
    waypoint_tol: float = param(0.01, gt=0, le=1, unit="m", help="position tolerance at every waypoint")
    waypoint_tol_angle: float = param(10 * DEGREE, gt=0, le=math.pi, unit="rad", cli_scale=180 / math.pi, cli_unit="deg",
                                      help="rotation tolerance at every waypoint")
    slip_tol: float = param(0.005, gt=0, le=1, unit="m", help="largest motion of the part in the hand during a transfer")
    slip_tol_angle: float = param(5 * DEGREE, gt=0, le=math.pi, unit="rad", cli_scale=180 / math.pi, cli_unit="deg",
                                  help="largest rotation of the part in the hand during a transfer")
    drop_distance: float = param(0.02, gt=0, le=1, unit="m", help="motion in the hand counted as a drop")
    settle_speed: float = param(0.01, gt=0, le=1, unit="m/s", help="speed below which a released part has settled")
    settle_spin: float = param(0.2, gt=0, le=100, unit="rad/s", help="angular speed below which a released part has settled")
    settle_time: float = param(1.0, gt=0, le=30, unit="s", help="time a released part has to settle")
    hold_end: float = param(1.0, ge=0, le=30, unit="s", help="time simulated after the trajectory, the arm at rest")
    collision_depth: float = param(0.0005, gt=0, le=0.1, unit="m",
                                   help="penetration of the robot into the table, the part or itself counted as a collision")
    hull_concavity: float = param(0.1, ge=0.01, le=1,
                                  help="concavity each convex part of the part's collision shape may keep, relative to its size "
                                       "(CoACD's threshold)")
    max_hulls: int = param(16, ge=1, le=256, integer=True, help="most convex parts of the part's collision shape")
    hull_resolution: int = param(30, ge=2, le=200, integer=True,
                                 help="voxel resolution of CoACD's remeshing of the part before it cuts it")

    @property
    def decomposition(self) -> Decomposition:
        """The convex decomposition's settings these parameters ask for."""
        return Decomposition(threshold=self.hull_concavity, max_hulls=self.max_hulls, preprocess_resolution=self.hull_resolution)

    def digest(self, grip_force: float, friction: float, table_friction: float) -> str:
        """The digest of every simulation parameter, the defaults resolved (grip force, frictions), the convex
        decomposition's remaining settings and the model version."""
        d = {**self.as_dict(), "grip_force": grip_force, "friction": friction, "table_friction": table_friction,
             "decomposition": self.decomposition.__dict__, "model": MODEL_VERSION}
        return hashlib.sha256(json.dumps(d, sort_keys=True).encode()).hexdigest()[:24]


FAILURES = ("collision", "shove", "slip", "drop", "roll", "pose", "goal")


@dataclass
class Failure:
    """The first thing that went wrong: its kind (FAILURES), the plan step (0-based) and its kind, the time (s), a
    one-line description and, for a collision, the robot's links in its first contact."""

    kind: str
    step: int
    step_kind: str
    t: float
    message: str
    links: tuple[str, ...] = ()


@dataclass
class SimResult:
    """A simulated plan: the verdict, one row per waypoint (`steps`: arrays, see `waypoint_rows`), the final
    errors against the goal, the simulated part's poses for playback (t, (K, 4, 4)), timings (wall-clock and this
    process's CPU seconds of stepping, scene building), and the resolved
    parameters and their digest."""

    confirmed: bool
    failure: Failure | None
    steps: dict[str, np.ndarray]
    final_error: float
    final_angle: float
    playback_t: np.ndarray
    playback_pose: np.ndarray
    simulated: float
    seconds: float
    cpu_seconds: float
    build_seconds: float
    digest: str
    params: dict
    failures: list[Failure] = field(default_factory=list)

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second of stepping."""
        return self.simulated / self.seconds if self.seconds > 0 else math.inf

    def summary(self) -> str:
        head = (f"confirmed: the part ends {self.final_error * 1000:.1f} mm and {math.degrees(self.final_angle):.1f} deg from "
                f"its goal" if self.confirmed else f"not confirmed: {self.failure.message}")
        return (f"{head}; {self.simulated:.1f} s simulated in {self.seconds:.2f} s ({self.realtime_factor:.0f}x real time; "
                f"{self.cpu_seconds:.2f} CPU s; scene built in {self.build_seconds:.2f} s)")


def resolve(params: SimParams, gripper, friction: float) -> tuple[float, float, float]:
    """The grip force (N; the gripper's `max_force`, else the Franka hand's continuous 70 N), the pad friction (the
    plan's grasp friction) and the table friction (the pad's) where `params` leaves them to their defaults."""
    force = float(params.grip_force if params.grip_force is not None else gripper.spec_value("max_force") or DEFAULT_GRIP_FORCE)
    mu = float(params.friction if params.friction is not None else friction)
    return force, mu, float(params.table_friction if params.table_friction is not None else mu)


def _angle(ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """Rotation angle between rotation matrices (..., 3, 3)."""
    c = (np.einsum("...ij,...ij->...", ra, rb) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def pose_error(a: np.ndarray, b: np.ndarray, com: np.ndarray,
               symmetry: Symmetry | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Translation (m) of the part's centre of mass and rotation angle (rad) between part poses a and b (..., 4, 4);
    with the part's `symmetry`, the smallest angle between a and b turned by any of its symmetries (the centre of
    mass stays where it is under them)."""
    ca = np.einsum("...ij,j->...i", a[..., :3, :3], com) + a[..., :3, 3]
    cb = np.einsum("...ij,j->...i", b[..., :3, :3], com) + b[..., :3, 3]
    turn = _angle(a[..., :3, :3], b[..., :3, :3]) if symmetry is None else symmetry.angle(a[..., :3, :3], b[..., :3, :3])
    return np.linalg.norm(ca - cb, axis=-1), turn


def _finger_targets(segments) -> list[float]:
    """Per segment, the finger joint target (half the opening): past the closed stop while the hand holds the part,
    half the segment's jaw while it is open."""
    return [-SQUEEZE if s.holding else s.jaw / 2 for s in segments]


def simulate(plan, robot, mesh, scene, friction: float, hulls: list[tuple[np.ndarray, np.ndarray]],
             params: SimParams = SimParams(), self_pairs: list[tuple[str, str]] | None = None,
             symmetry: Symmetry | None = None) -> SimResult:
    """Replay `plan` (a timed Plan: steps and segments) with `robot` (its Robot, whose gripper is the planning
    gripper), the part's `mesh` and convex `hulls`, on `scene`'s table, with the plan's grasp `friction` unless
    `params.friction` overrides it; `self_pairs`: the robot's link pairs that may collide (the stored robot's
    `AllowedPairs.checked`); `symmetry`: the mesh's (`part_symmetry`, found here when not given); see the module
    docstring for the verdict."""
    mujoco = mujoco_module()
    if not plan.segments:
        raise SimulationError("the plan has no timed motions to simulate; plan it with its motions")
    gripper = robot.gripper
    grip_force, mu, mu_table = resolve(params, gripper, friction)
    t_build = time.perf_counter()
    ss = build_scene(robot, gripper, scene, mesh, hulls, params.density, grip_force, mu, mu_table, params.timestep,
                     gripper.spec_value("mass"), self_pairs, params.impratio)
    m = ss.model
    data = mujoco.MjData(m)
    build_seconds = time.perf_counter() - t_build

    segs = plan.segments
    dt = float(params.timestep)
    t_end = plan.duration + params.hold_end
    n = int(math.ceil(t_end / dt))
    times = np.arange(1, n + 1) * dt
    seg_end = np.array([s.t0 + s.duration for s in segs])
    seg_of = np.minimum(np.searchsorted(seg_end, times, side="left"), len(segs) - 1)
    q_des = np.empty((n, robot.nq))
    qd_des = np.zeros((n, robot.nq))
    for k, s in enumerate(segs):
        idx = np.flatnonzero(seg_of == k)
        if len(idx):
            q, qd, _ = s.traj.sample(times[idx] - s.t0)
            q_des[idx], qd_des[idx] = q, qd
    after = times > seg_end[-1]
    q_des[after], qd_des[after] = segs[-1].traj.q[-1], 0.0
    finger = np.asarray(_finger_targets(segs))[seg_of]

    data.qpos[ss.arm_qpos] = segs[0].traj.q[0]
    data.qpos[ss.finger_qpos] = gripper.jaw_max / 2
    start = np.asarray(plan.start_pose, dtype=np.float64)
    data.qpos[ss.part_qpos:ss.part_qpos + 7] = part_qpos(start, ss.part_com)
    mujoco.mj_forward(m, data)

    pads = {m.geom("left_pad").id, m.geom("right_pad").id}
    part_geoms = set(np.flatnonzero(m.geom_bodyid == ss.part_body).tolist())
    events = {int(round(e / dt)) - 1: i for i, e in enumerate(seg_end)}  # step index at each segment's end
    touching = np.zeros(len(segs), dtype=bool)
    part_pos, part_quat = np.empty((n, 3)), np.empty((n, 4))
    hand_pos, hand_quat = np.empty((n, 3)), np.empty((n, 4))
    ctrl = np.zeros((n, m.nu))
    ctrl[:, ss.arm_act], ctrl[:, ss.vel_act] = q_des, qd_des
    ctrl[:, ss.finger_act] = finger[:, None]
    pb, hb = ss.part_body, ss.hand_body
    bad = _forbidden(m, ss, part_geoms)
    on_floor = np.zeros((m.ngeom, m.ngeom), dtype=bool)
    on_floor[ss.floor_geom, sorted(part_geoms)] = on_floor[sorted(part_geoms), ss.floor_geom] = True
    fell = None  # the step at which the part reached the floor
    hit: list[tuple[int, int, int, float]] = []  # (step, geom, geom, depth) of every collision deeper than the tolerance
    depth = float(params.collision_depth)
    t0, c0 = time.perf_counter(), time.process_time()
    for k in range(n):
        data.ctrl[:] = ctrl[k]
        mujoco.mj_step(m, data)
        part_pos[k], part_quat[k] = data.xpos[pb], data.xquat[pb]
        hand_pos[k], hand_quat[k] = data.xpos[hb], data.xquat[hb]
        if k in events:
            touching[events[k]] = _touches(data, pads, part_geoms)
        if data.ncon:
            c = data.contact
            g, dist = c.geom[:data.ncon], c.dist[:data.ncon]
            deep = bad[g[:, 0], g[:, 1]] & (dist < -depth)
            if deep.any():
                i = int(np.argmin(np.where(deep, dist, np.inf)))
                hit.append((k, int(g[i, 0]), int(g[i, 1]), -float(dist[i])))
            if on_floor[g[:, 0], g[:, 1]].any():
                fell = k
                break
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if fell is not None:  # nothing moves after the drop: the rest of the replay keeps the scene as it was then
        for a in (part_pos, part_quat, hand_pos, hand_quat):
            a[fell + 1:] = a[fell]
    if not np.isfinite(part_pos).all():
        raise SimulationError(f"the physics diverged (timestep {dt:g} s); give a smaller --timestep")
    part = body_poses(part_pos, part_quat, ss.part_com)
    hand = body_poses(hand_pos, hand_quat)
    sym = symmetry if symmetry is not None else part_symmetry(mesh)
    rows, failures, final = _verdict(plan, robot, segs, times, seg_end, part, hand, touching, ss.part_com, params, start,
                                     sym)
    failures += _collisions(hit, m, ss, plan, segs, seg_of, times, params)
    if fell is not None:
        i = int(segs[seg_of[fell]].step)
        failures = [f for f in failures if f.t <= times[fell]]
        failures.append(Failure("drop", i, plan.steps[i].kind, float(times[fell]),
                                f"step {i + 1} ({plan.steps[i].kind}, {segs[seg_of[fell]].caption} {segs[seg_of[fell]].kind}) "
                                f"at {times[fell]:.2f} s: the part fell off the table onto the floor"))
        n = fell + 1
    failures.sort(key=lambda f: f.t)
    every = max(1, int(round(1.0 / (PLAYBACK_HZ * dt))))
    keep = np.r_[np.arange(0, n, every), n - 1] if (n - 1) % every else np.arange(0, n, every)
    resolved = {**params.as_dict(), "grip_force": grip_force, "friction": mu, "table_friction": mu_table,
                "decomposition": params.decomposition.__dict__, "model": MODEL_VERSION}
    return SimResult(confirmed=not failures, failure=failures[0] if failures else None, steps=rows, final_error=final[0],
                     final_angle=final[1], playback_t=np.r_[0.0, times[keep]], playback_pose=np.concatenate([start[None], part[keep]]),
                     simulated=float(n * dt), seconds=seconds, cpu_seconds=cpu, build_seconds=build_seconds,
                     digest=params.digest(grip_force, mu, mu_table), params=resolved, failures=failures)


def _forbidden(m, ss, part_geoms: set[int]) -> np.ndarray:
    """(ngeom, ngeom) True for the geom pairs whose contact is a collision: any robot geom with the table, an arm
    link's with the part, and the self-collision pairs (the gripper's own contact with the part is the grasp)."""
    bad = np.zeros((m.ngeom, m.ngeom), dtype=bool)
    robot = np.array(sorted(ss.robot_geoms), dtype=np.int64)
    arm = np.array(sorted(set(ss.robot_geoms) - ss.gripper_geoms), dtype=np.int64)
    bad[robot, ss.table_geom] = True
    for g in part_geoms:
        bad[arm, g] = True
    for a, b in ss.self_pairs:
        bad[a, b] = True
    return bad | bad.T


def _collisions(hit, m, ss, plan, segs, seg_of, times, p: SimParams) -> list[Failure]:
    """One failure per plan step with a collision: its first contact (time and the two geoms' links) and the
    deepest penetration in that step."""
    first: dict[int, tuple[int, int, int]] = {}
    deepest: dict[int, float] = {}
    for k, a, b, d in hit:
        i = int(segs[seg_of[k]].step)
        first.setdefault(i, (k, a, b))
        deepest[i] = max(deepest.get(i, 0.0), d)
    name = {**ss.robot_geoms, ss.table_geom: "the table"}
    out = []
    for i, (k, a, b) in first.items():
        s = segs[seg_of[k]]
        pair = tuple(name.get(g, "the part") for g in (a, b))
        out.append(Failure("collision", i, plan.steps[i].kind, float(times[k]),
                           f"step {i + 1} ({plan.steps[i].kind}, {s.caption} {s.kind}) at {times[k]:.2f} s: {pair[0]} and "
                           f"{pair[1]} collide, up to {deepest[i] * 1000:.1f} mm deep (tolerance {p.collision_depth * 1000:g} mm)",
                           tuple(x for x in pair if x not in ("the table", "the part"))))
    return out


def _touches(data, pads: set[int], part: set[int]) -> bool:
    for c in data.contact[:data.ncon]:
        a, b = int(c.geom1), int(c.geom2)
        if (a in pads and b in part) or (b in pads and a in part):
            return True
    return False


def _verdict(plan, robot, segs, times, seg_end, part, hand, touching, com, p: SimParams, start, sym: Symmetry | None = None):
    """Per-waypoint rows and every failure (see the module docstring), part poses compared up to the part's
    symmetry `sym`; also the final (translation, angle) error."""
    dt = times[1] - times[0] if len(times) > 1 else p.timestep
    idx_end = np.clip(np.round(seg_end / dt).astype(np.int64) - 1, 0, len(times) - 1)
    idx_start = np.r_[0, idx_end[:-1]]
    steps = plan.steps
    planned = np.empty((len(segs), 4, 4))
    for k, s in enumerate(segs):
        planned[k] = (robot.tcp_pose(s.traj.q[-1]) @ np.linalg.inv(steps[s.step].grasp) if s.holding
                      else steps[s.step].object_pose)  # grasp: the TCP in the part frame
    sim = part[idx_end]
    err_t, err_r = pose_error(sim, planned, com, sym)
    slip_t, slip_r = np.full(len(segs), np.nan), np.full(len(segs), np.nan)
    settle = np.full(len(segs), np.nan)
    failures: list[Failure] = []

    def fail(kind: str, k: int, t: float, what: str) -> None:
        i = segs[k].step
        failures.append(Failure(kind, i, steps[i].kind, float(t), f"step {i + 1} ({steps[i].kind}, {segs[k].caption} "
                                                                    f"{segs[k].kind}) at {t:.2f} s: {what}"))

    # relative pose of the part in the hand, from each close to the next open
    rel = np.einsum("nji,njk->nik", hand[:, :3, :3], part[:, :3, :3])
    rel_c = np.einsum("nji,nj->ni", hand[:, :3, :3], np.einsum("nij,j->ni", part[:, :3, :3], com) + part[:, :3, 3] - hand[:, :3, 3])
    k = 0
    while k < len(segs):
        s = segs[k]
        if s.kind == "gripper" and s.holding:  # the close
            a, b = idx_start[k], idx_end[k]
            dt_, dr_ = pose_error(part[b], part[a], com)
            if dt_ > p.slip_tol or dr_ > p.slip_tol_angle:
                fail("shove", k, times[b], f"closing the fingers shoved the part {dt_ * 1000:.1f} mm and {math.degrees(dr_):.1f} deg "
                                           f"(tolerance {p.slip_tol * 1000:g} mm, {math.degrees(p.slip_tol_angle):g} deg)")
            j = k + 1
            while j < len(segs) and segs[j].holding and segs[j].kind != "gripper":
                j += 1
            # up to the last straight line down: setting the part on the table may push it in the hand, which the
            # waypoint check and the settle check judge
            last = j - 1 if j - 1 > k + 1 and segs[j - 1].kind == "lower" else j
            lo, hi = b, idx_start[last] if last < len(segs) else len(times) - 1
            st = np.linalg.norm(rel_c[lo:hi + 1] - rel_c[lo], axis=1)
            sr = _angle(rel[lo:hi + 1], rel[lo])
            for h in range(k + 1, last):
                x, y = idx_start[h] - lo, idx_end[h] - lo
                slip_t[h], slip_r[h] = st[x:y + 1].max(), sr[x:y + 1].max()
            bad = np.flatnonzero((st > p.slip_tol) | (sr > p.slip_tol_angle))
            lost = [h for h in range(k + 1, j) if not touching[h]]
            if len(bad):
                first = lo + int(bad[0])
                h = min(int(np.searchsorted(idx_end, first, side="left")), last - 1)
                dropped = st.max() > p.drop_distance or bool(lost)
                what = (f"the part dropped from the hand (it moved {st.max() * 1000:.0f} mm in the hand"
                        f"{', no pad touches it' if lost else ''})" if dropped else
                        f"the part slipped {st[bad[0]:].max() * 1000:.1f} mm and {math.degrees(sr[bad[0]:].max()):.1f} deg in the "
                        f"hand (tolerance {p.slip_tol * 1000:g} mm, {math.degrees(p.slip_tol_angle):g} deg)")
                fail("drop" if dropped else "slip", h, times[first], what)
            elif lost:
                fail("drop", lost[0], times[idx_end[lost[0]]], "the part dropped from the hand (no pad touches it)")
            k = j
            continue
        if s.kind == "gripper":  # the open: the released part must come to rest at its placement
            a = idx_end[k]
            settle[k], at, what = settled(part, com, dt, a, steps[s.step].object_pose, p, sym)
            if what:
                fail("roll", k, times[at], what)
        k += 1
    flagged = {f.step for f in failures}
    for k in range(len(segs)):
        if (err_t[k] > p.waypoint_tol or err_r[k] > p.waypoint_tol_angle) and segs[k].step not in flagged:
            fail("pose", k, times[idx_end[k]], f"the part is {err_t[k] * 1000:.1f} mm and {math.degrees(err_r[k]):.1f} deg from "
                                               f"the plan (waypoint tolerance {p.waypoint_tol * 1000:g} mm, "
                                               f"{math.degrees(p.waypoint_tol_angle):g} deg)")
            flagged.add(segs[k].step)
    f_t, f_r = pose_error(part[-1], np.asarray(plan.goal_pose, dtype=np.float64), com, sym)
    if f_t > p.goal_tol or f_r > p.goal_tol_angle:
        fail("goal", len(segs) - 1, times[-1], f"the part ends {f_t * 1000:.1f} mm and {math.degrees(f_r):.1f} deg from its "
                                               f"goal (tolerance {p.goal_tol * 1000:g} mm, {math.degrees(p.goal_tol_angle):g} deg)")
    ok = (err_t <= p.waypoint_tol) & (err_r <= p.waypoint_tol_angle)
    rows = {"seq": np.arange(len(segs), dtype=np.int32), "step": np.array([s.step for s in segs], dtype=np.int32),
            "kind": np.array([s.kind for s in segs], dtype=object), "caption": np.array([s.caption for s in segs], dtype=object),
            "t": times[idx_end].astype(np.float64), "planned": planned.reshape(len(segs), 16),
            "simulated": sim.reshape(len(segs), 16), "error": err_t, "angle": err_r, "slip": slip_t, "slip_angle": slip_r,
            "settle": settle, "touching": touching, "ok": ok}
    return rows, failures, (float(f_t), float(f_r))


def settled(part: np.ndarray, com: np.ndarray, dt: float, a: int, placement: np.ndarray,
            p: SimParams, sym: Symmetry | None = None) -> tuple[float, int, str | None]:
    """Whether a part released at sample `a` of its poses `part` is at rest at `placement` `settle_time` later:
    (seconds until its speeds last fell below `settle_speed` and `settle_spin`, NaN if it still moves; the sample
    judged; None, or why it counts as a roll: it still moves, or it rests beyond the waypoint tolerance)."""
    w = min(len(part) - 1, a + int(round(p.settle_time / dt)))
    lin, ang = _speeds(part, com, dt, a, w)
    moving = np.flatnonzero((lin >= p.settle_speed) | (ang >= p.settle_spin))
    if len(moving) and moving[-1] >= len(lin) - 1:
        return math.nan, w, (f"the released part did not settle within {p.settle_time:g} s (still {lin[-1] * 1000:.0f} mm/s, "
                             f"{math.degrees(ang[-1]):.0f} deg/s)")
    calm = float((moving[-1] + 1) * dt) if len(moving) else 0.0
    e_t, e_r = pose_error(part[w], placement, com, sym)
    if e_r > p.waypoint_tol_angle or e_t > p.waypoint_tol:
        return calm, w, (f"the released part rolled: it rests {e_t * 1000:.1f} mm and {math.degrees(e_r):.1f} deg from its "
                         f"placement")
    return calm, w, None


def rest_on_table(mesh, hulls: list[tuple[np.ndarray, np.ndarray]], pose: np.ndarray, scene,
                  params: SimParams = SimParams(), friction: float = 0.5) -> tuple[str | None, np.ndarray]:
    """A part released at rest at `pose` on the table (no robot; a placement as a plan's release leaves it), judged
    as after a release (`settled`, over `settle_time` plus `hold_end`): (None or why it rolls, its final pose)."""
    mujoco = mujoco_module()
    m, body = part_scene(mesh, hulls, scene, params.density, friction, params.timestep, params.impratio)
    _, com, _ = mass_properties(mesh, params.density)
    data = mujoco.MjData(m)
    data.qpos[:7] = part_qpos(pose, com)
    n = int(math.ceil((params.settle_time + params.hold_end) / params.timestep))
    pos, q = np.empty((n + 1, 3)), np.empty((n + 1, 4))
    mujoco.mj_forward(m, data)
    pos[0], q[0] = data.xpos[body], data.xquat[body]
    for k in range(n):
        mujoco.mj_step(m, data)
        pos[k + 1], q[k + 1] = data.xpos[body], data.xquat[body]
    part = body_poses(pos, q, com)
    _, _, what = settled(part, com, params.timestep, 0, pose, params, part_symmetry(mesh))
    return what, part[-1]


def _speeds(part: np.ndarray, com: np.ndarray, dt: float, a: int, b: int, lag: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """Linear (m/s, of the centre of mass) and angular (rad/s) speeds of the part from step a to b, averaged over
    `lag` steps."""
    i = np.arange(a, b + 1)
    j = np.minimum(i + lag, len(part) - 1)
    span = np.maximum(j - i, 1) * dt
    e_t, e_r = pose_error(part[j], part[i], com)
    return e_t / span, e_r / span
