"""Time parametrisation of joint paths under velocity and acceleration limits (CONVENTIONS.md, Plans and motions).

A path with two vertices (a straight joint line) gets the time-optimal trapezoidal velocity profile along the
line, synchronised over the joints, from rest to rest: it stays exactly on the checked line. A path with more
vertices (a solved TCP line, a shortcut RRT-Connect path) is timed with TOPP-RA (`toppra`) along a cubic spline
through its vertices, pieces longer than `densify` first subdivided so the spline keeps to the checked path;
callers check the timed samples and fall back to `stops` (rest-to-rest along every piece) when the spline strays.

A timed trajectory is knots: times (s), joint positions and velocities, consecutive knots at most `max_step`
(1 degree) apart in every joint (callers that know the arm lower it until the TCP also travels at most 5 mm
between knots), so checking the knots checks the motion at the stated resolution; between knots
a controller interpolates (cubic Hermite from positions and velocities). `sample` and `resample` serve
validation and animation; `to_csv` and `to_json` export a whole timed plan for replay.
"""

from __future__ import annotations

import csv
import functools
import io
import json
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.errors import PlanningError

ONE_DEGREE = math.radians(1.0)
LIMIT_MARGIN = 0.97  # TOPP-RA enforces limits at grid points only; aim slightly below them


@dataclass
class Trajectory:
    """Knots of a timed joint trajectory: t (K,) seconds from its start, q (K, n) rad, qd (K, n) rad/s."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) else 0.0

    def sample(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions, velocities and accelerations at `times` by cubic Hermite interpolation of the knots."""
        t, q, qd = self.t, self.q, self.qd
        times = np.clip(np.asarray(times, dtype=np.float64), t[0], t[-1])
        i = np.clip(np.searchsorted(t, times, side="right") - 1, 0, len(t) - 2)
        h = (t[i + 1] - t[i])[:, None]
        s = ((times - t[i])[:, None] / np.where(h > 0, h, 1.0))
        p0, p1, m0, m1 = q[i], q[i + 1], qd[i] * h, qd[i + 1] * h
        h00, h10, h01, h11 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s, -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
        pos = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
        hs = np.where(h > 0, h, 1.0)
        vel = ((6 * s ** 2 - 6 * s) * p0 + (3 * s ** 2 - 4 * s + 1) * m0 + (-6 * s ** 2 + 6 * s) * p1 + (3 * s ** 2 - 2 * s) * m1) / hs
        acc = ((12 * s - 6) * p0 + (6 * s - 4) * m0 + (-12 * s + 6) * p1 + (6 * s - 2) * m1) / hs ** 2
        return pos, vel, acc

    def shifted(self, dt: float) -> "Trajectory":
        return Trajectory(self.t + dt, self.q, self.qd)

    def accelerations(self) -> np.ndarray:
        """Accelerations at the knots (finite differences of the knot velocities, one-sided at the ends)."""
        if len(self.t) < 2:
            return np.zeros_like(self.qd)
        return np.gradient(self.qd, self.t, axis=0)

    def as_dict(self) -> dict:
        return {"t": self.t.tolist(), "q": self.q.tolist(), "qd": self.qd.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> "Trajectory":
        return cls(np.asarray(d["t"], dtype=np.float64), np.asarray(d["q"], dtype=np.float64).reshape(len(d["t"]), -1),
                   np.asarray(d["qd"], dtype=np.float64).reshape(len(d["t"]), -1))


def check_limits(vlim: np.ndarray, alim: np.ndarray | float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration limits as (n,) positive finite arrays, or a PlanningError naming the bad one."""
    v = np.broadcast_to(np.asarray(vlim, dtype=np.float64), (n,)).copy()
    a = np.broadcast_to(np.asarray(alim, dtype=np.float64), (n,)).copy()
    for label, x in (("velocity", v), ("acceleration", a)):
        if not np.isfinite(x).all() or (x <= 0).any():
            raise PlanningError(f"joint {label} limits must be finite and > 0, got {x.tolist()}; check the URDF or --acc")
    return v, a


def _knot_times(duration: float, vpeak: float, max_step: float) -> np.ndarray:
    n = max(1, int(math.ceil(duration * vpeak / max_step)))
    return np.linspace(0.0, duration, n + 1)


Spacing = Callable[[np.ndarray], float]
"""A second measure of knot spacing: joint positions (K, n) -> the largest gap between consecutive knots over its
limit (e.g. TCP travel over 5 mm); knots are added until it is at most 1."""


def _knots(duration: float, vpeak: float, max_step: float, positions: Callable[[np.ndarray], np.ndarray],
           spacing: Spacing | None) -> np.ndarray:
    """Evenly spaced knot times at most `max_step` apart in every joint (at peak speed) and, with `spacing`, dense
    enough for it too (`positions(t)` gives the joint positions at times t)."""
    t = _knot_times(duration, vpeak, max_step)
    for _ in range(8):
        ratio = spacing(positions(t)) if spacing is not None and len(t) > 1 else 0.0
        if ratio <= 1.0:
            break
        t = np.linspace(0.0, duration, int(math.ceil((len(t) - 1) * 1.1 * ratio)) + 1)
    return t


def time_line(qa: np.ndarray, qb: np.ndarray, vlim: np.ndarray, alim: np.ndarray, max_step: float = ONE_DEGREE,
              spacing: Spacing | None = None) -> Trajectory:
    """The time-optimal rest-to-rest trapezoidal profile along the straight joint line qa -> qb (all joints
    synchronised, so the motion stays on the line); knots at most `max_step` apart in every joint and, with
    `spacing`, within it too."""
    qa, qb = np.asarray(qa, dtype=np.float64), np.asarray(qb, dtype=np.float64)
    vlim, alim = check_limits(vlim, alim, len(qa))
    d = qb - qa
    ad = np.abs(d)
    if ad.max() < 1e-12:
        return Trajectory(np.zeros(1), qa[None].copy(), np.zeros((1, len(qa))))
    mask = ad > 1e-12
    vs = float((vlim[mask] / ad[mask]).min())  # path-parameter limits
    as_ = float((alim[mask] / ad[mask]).min())
    if vs * vs / as_ >= 1.0:  # triangular
        ta = math.sqrt(1.0 / as_)
        vs, tc = as_ * ta, 0.0
    else:
        ta = vs / as_
        tc = (1.0 - vs * ta) / vs
    dur = 2 * ta + tc

    def path_s(t: np.ndarray) -> np.ndarray:
        return np.where(t < ta, 0.5 * as_ * t ** 2, np.where(t < ta + tc, 0.5 * as_ * ta ** 2 + vs * (t - ta),
                                                             1.0 - 0.5 * as_ * np.maximum(dur - t, 0.0) ** 2))

    t = _knots(dur, vs * ad.max(), max_step, lambda t: qa + path_s(t)[:, None] * d, spacing)
    s = path_s(t)
    sd = np.where(t < ta, as_ * t, np.where(t < ta + tc, vs, as_ * np.maximum(dur - t, 0.0)))
    s[-1], sd[-1], sd[0] = 1.0, 0.0, 0.0
    return Trajectory(t, qa + s[:, None] * d, sd[:, None] * d)


def time_stops(path: np.ndarray, vlim: np.ndarray, alim: np.ndarray, max_step: float = ONE_DEGREE,
               spacing: Spacing | None = None) -> Trajectory:
    """Rest to rest along every straight piece of a path (exactly on the checked pieces)."""
    path = np.asarray(path, dtype=np.float64)
    out = time_line(path[0], path[min(1, len(path) - 1)], vlim, alim, max_step, spacing)
    for a, b in zip(path[1:-1], path[2:]):
        nxt = time_line(a, b, vlim, alim, max_step, spacing).shifted(out.t[-1])
        out = Trajectory(np.r_[out.t, nxt.t[1:]], np.vstack([out.q, nxt.q[1:]]), np.vstack([out.qd, nxt.qd[1:]]))
    return out


def densify(path: np.ndarray, spacing: float) -> np.ndarray:
    """Subdivide pieces longer than `spacing` (max joint difference) into equal parts."""
    path = np.asarray(path, dtype=np.float64)
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        k = max(1, int(math.ceil(np.abs(b - a).max() / spacing - 1e-9)))
        s = np.linspace(0.0, 1.0, k + 1)[1:, None]
        out.append(a + s * (b - a))
    return np.vstack(out)


def time_spline(path: np.ndarray, vlim: np.ndarray, alim: np.ndarray, density: float = 0.05,
                max_step: float = ONE_DEGREE, gridpoints: int = 60, spacing: Spacing | None = None) -> Trajectory:
    """TOPP-RA along a natural cubic spline through the path vertices (pieces longer than `density` in any joint
    subdivided first), rest to rest; on `gridpoints` grid points first, on five times as many when the knots break a
    limit between grid points. Knots at most `max_step` apart in every joint and, with `spacing`, within it too."""
    import toppra as ta
    import toppra.algorithm as algo

    logging.getLogger("toppra").setLevel(logging.ERROR)
    path = np.asarray(path, dtype=np.float64)
    vlim, alim = check_limits(vlim, alim, path.shape[1])
    pts = densify(path, density)
    chord = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))]
    keep = np.r_[True, np.diff(chord) > 1e-12]
    pts, chord = pts[keep], chord[keep]
    if len(pts) < 2:
        return Trajectory(np.zeros(1), pts[:1].copy(), np.zeros((1, pts.shape[1])))
    if len(pts) == 2:
        return time_line(pts[0], pts[1], vlim, alim, max_step, spacing)
    s = chord / chord[-1]
    geo = ta.SplineInterpolator(s, pts, bc_type="natural")
    v, a = LIMIT_MARGIN * vlim, LIMIT_MARGIN * alim
    cons = _constraints(v.tobytes(), a.tobytes())
    out = None
    for grid in (gridpoints, 5 * gridpoints):
        inst = algo.TOPPRA(cons, geo, parametrizer="ParametrizeConstAccel", gridpoints=propose_gridpoints(geo, grid))
        traj = inst.compute_trajectory(0.0, 0.0)
        if traj is None:
            raise PlanningError("TOPP-RA found no time parametrisation of a path; check the velocity and acceleration limits")
        dur = float(traj.duration)
        coarse = np.linspace(0.0, dur, 100)
        vpeak = float(np.abs(traj(coarse, 1)).max()) * 1.2 + 1e-9
        t = _knots(dur, vpeak, max_step, lambda t: np.asarray(traj(t)), spacing)
        q, qd = np.asarray(traj(t)), np.asarray(traj(t, 1))
        q[0], q[-1] = path[0], path[-1]
        qd[0], qd[-1] = 0.0, 0.0
        out = Trajectory(t, q, qd)
        if not within_limits(out, -np.inf, np.inf, vlim, alim) and np.abs(np.diff(q, axis=0)).max() <= max_step + 1e-12:
            break
    return out


@functools.lru_cache(maxsize=32)
def _constraints(v: bytes, a: bytes) -> list:
    """TOPP-RA's joint velocity and acceleration constraints for limits +-v, +-a (float64 bytes); they hold only
    the limits, so one pair serves every path."""
    import toppra.constraint as constraint

    v, a = np.frombuffer(v), np.frombuffer(a)
    return [constraint.JointVelocityConstraint(np.stack([-v, v], axis=1)),
            constraint.JointAccelerationConstraint(np.stack([-a, a], axis=1),
                                                   discretization_scheme=constraint.DiscretizationType.Interpolation)]


def propose_gridpoints(path, min_nb_points: int, max_err_threshold: float = 1e-3, max_seg_length: float = 0.05,
                       max_iteration: int = 100) -> np.ndarray:
    """The grid TOPP-RA proposes for `path` (`toppra.interpolator.propose_gridpoints` with TOPPRA's defaults), the
    same points computed a pass at a time: each pass halves every segment longer than `max_seg_length` or whose
    estimated interpolation error 0.5 |p''(mid)| d^2 exceeds the threshold, then segments are halved until there
    are `min_nb_points` points."""
    grid = np.array([path.path_interval[0], path.path_interval[1]], dtype=np.float64)
    for iteration in range(max_iteration):
        a, b = grid[:-1], grid[1:]
        mid, dist = 0.5 * (a + b), b - a
        split = dist > max_seg_length
        check = np.flatnonzero(~split)
        if len(check):
            err = np.abs(0.5 * np.asarray(path(mid[check], 2)).reshape(len(check), -1) * dist[check, None] ** 2)
            split[check] = err.max(axis=1) > max_err_threshold
        if not split.any():
            break
        grid = np.sort(np.r_[grid, mid[split]])
    if iteration == max_iteration - 1:
        raise PlanningError("TOPP-RA found no grid fine enough for a path")
    while len(grid) < min_nb_points:
        grid = np.sort(np.r_[grid, 0.5 * (grid[:-1] + grid[1:])])
    return grid


def reversed_trajectory(traj: Trajectory) -> Trajectory:
    """The same motion played backwards (rest to rest, so within the same limits)."""
    return Trajectory(traj.t[-1] - traj.t[::-1], traj.q[::-1].copy(), -traj.qd[::-1])


def within_limits(traj: Trajectory, lower: np.ndarray, upper: np.ndarray, vlim: np.ndarray, alim: np.ndarray,
                  tol: float = 1e-6, slack: float = 0.0) -> list[str]:
    """Which limits the knots break (position, velocity, acceleration from knot velocities, each allowed `slack`
    relative excess), empty when none."""
    out = []
    if ((traj.q < lower - tol) | (traj.q > upper + tol)).any():
        out.append("position")
    if (np.abs(traj.qd) > vlim * (1 + slack) + tol).any():
        out.append("velocity")
    if len(traj.t) > 1:
        dt = np.diff(traj.t)[:, None]
        acc = np.diff(traj.qd, axis=0) / np.where(dt > 0, dt, 1.0)
        if (np.abs(acc) > alim * (1 + slack) + tol).any():
            out.append("acceleration")
    return out


# ----------------------------------------------------------------------------------------------------------------
# A whole timed plan: segments one after the other.


@dataclass
class TimedSegment:
    """One motion of a plan: `kind` (approach, retract, transit, transfer, gripper), `caption` (the plan step it
    serves: pick, transfer, release, regrasp, place), plan step index, whether the object is held, its start time
    in the plan and its trajectory (times relative to the segment's start); `method` says how the path was found."""

    kind: str
    caption: str
    step: int
    holding: bool
    t0: float
    traj: Trajectory
    method: str = ""
    jaw: float = 0.0

    @property
    def duration(self) -> float:
        return self.traj.duration

    def as_dict(self) -> dict:
        """The segment with its knot times `t` in plan time (s from the plan's start, CONVENTIONS.md); t0 = t[0]."""
        return {"kind": self.kind, "caption": self.caption, "step": self.step, "holding": self.holding, "t0": self.t0,
                "duration": self.duration, "method": self.method, "jaw": self.jaw,
                **self.traj.shifted(self.t0).as_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "TimedSegment":
        """The inverse of `as_dict`; knot times that start at 0 rather than at t0 (files of versions before plan
        time) are read as from the segment's start."""
        t0 = float(d["t0"])
        traj = Trajectory.from_dict(d)
        if len(traj.t) and abs(float(traj.t[0]) - t0) < 1e-9:
            traj = traj.shifted(-t0)
        return cls(d["kind"], d["caption"], int(d["step"]), bool(d["holding"]), t0, traj, d.get("method", ""),
                   float(d.get("jaw", 0.0)))


def plan_knots(segments: list[TimedSegment]) -> dict[str, np.ndarray]:
    """All knots of a timed plan in plan time: t (K,), q (K, n), qd (K, n), segment index (K,)."""
    ts, qs, qds, idx = [], [], [], []
    for k, s in enumerate(segments):
        ts.append(s.t0 + s.traj.t)
        qs.append(s.traj.q)
        qds.append(s.traj.qd)
        idx.append(np.full(len(s.traj.t), k))
    if not ts:
        return {"t": np.zeros(0), "q": np.zeros((0, 0)), "qd": np.zeros((0, 0)), "segment": np.zeros(0, dtype=np.int64)}
    return {"t": np.concatenate(ts), "q": np.vstack(qs), "qd": np.vstack(qds), "segment": np.concatenate(idx)}


def resample(segments: list[TimedSegment], fps: float) -> dict[str, np.ndarray]:
    """The timed plan at `fps` frames per second (animation): t, q, segment index."""
    total = segments[-1].t0 + segments[-1].duration if segments else 0.0
    times = np.arange(0.0, total + 1e-9, 1.0 / fps)
    q = np.zeros((len(times), segments[0].traj.q.shape[1])) if segments else np.zeros((0, 0))
    seg = np.zeros(len(times), dtype=np.int64)
    for k, s in enumerate(segments):
        m = (times >= s.t0 - 1e-12) & (times <= s.t0 + s.duration + 1e-12)
        if m.any():
            q[m] = s.traj.sample(times[m] - s.t0)[0]
            seg[m] = k
    return {"t": times, "q": q, "segment": seg}


def to_json(segments: list[TimedSegment], joint_names: list[str]) -> str:
    """A replayable timed plan: joint names, and per segment its kind, caption, start time and knots."""
    return json.dumps({"joint_names": list(joint_names), "units": {"t": "s", "q": "rad or m", "qd": "rad/s or m/s"},
                       "duration": (segments[-1].t0 + segments[-1].duration) if segments else 0.0,
                       "segments": [s.as_dict() for s in segments]})


def to_csv(segments: list[TimedSegment], joint_names: list[str]) -> str:
    """One row per knot: t (plan time, s), segment, kind, caption, holding, jaw (m), positions, velocities."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["t", "segment", "kind", "caption", "holding", "jaw"] + [f"q_{n}" for n in joint_names] + [f"qd_{n}" for n in joint_names])
    for k, s in enumerate(segments):
        for t, q, qd in zip(s.traj.t, s.traj.q, s.traj.qd):
            w.writerow([f"{s.t0 + t:.6f}", k, s.kind, s.caption, int(s.holding), f"{s.jaw:.6f}"]
                       + [f"{x:.9f}" for x in q] + [f"{x:.9f}" for x in qd])
    return buf.getvalue()


def _ros2_knots(segments: list[TimedSegment]):
    """(segment index, knot index, plan time) of every knot written to a ROS 2 trajectory: consecutive segments
    share their boundary knot, which is written once (with the earlier segment), so times strictly increase."""
    last = -math.inf
    for k, s in enumerate(segments):
        for i, t in enumerate(s.traj.t + s.t0):
            if t <= last + 1e-9:
                continue
            last = float(t)
            yield k, i, last


def _ros2_time(t: float) -> dict:
    sec = int(math.floor(t))
    return {"sec": sec, "nanosec": min(int(round((t - sec) * 1e9)), 999_999_999)}


def _ros2_message(joint_names: list[str], points: list[dict]) -> str:
    import yaml

    msg = {"header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": ""}, "joint_names": list(joint_names),
           "points": points}
    return yaml.safe_dump(msg, sort_keys=False, default_flow_style=None, width=120)


def to_ros2_yaml(segments: list[TimedSegment], joint_names: list[str]) -> str:
    """The whole plan as one ROS 2 `trajectory_msgs/JointTrajectory` in YAML: `joint_names` in the URDF's names, and
    per knot `positions`, `velocities`, `accelerations` and `time_from_start` (sec, nanosec) from the plan's start.

    Consecutive segments share their boundary knot; it is written once, so `time_from_start` strictly increases, as
    a controller requires. A knot where the arm is at rest gets zero acceleration: the segments meet at rest, and a
    controller interpolating with accelerations must not carry the stopping segment's deceleration into the next.
    The gripper is not a joint of this message: `to_ros2_gripper_yaml` gives its jaw width at the same times.
    """
    acc = [np.where(np.all(np.abs(s.traj.qd) < 1e-12, axis=1)[:, None], 0.0, s.traj.accelerations()) for s in segments]
    points = [{"positions": [float(x) for x in segments[k].traj.q[i]], "velocities": [float(x) for x in segments[k].traj.qd[i]],
               "accelerations": [float(x) for x in acc[k][i]], "effort": [], "time_from_start": _ros2_time(t)}
              for k, i, t in _ros2_knots(segments)]
    return _ros2_message(joint_names, points)


GRIPPER_JOINT = "jaw_width"


def jaw_widths(segments: list[TimedSegment], k: int, t: np.ndarray) -> np.ndarray:
    """The jaw width (m) at times `t` (s, from segment k's start): the segment's jaw, except in a `gripper` segment,
    where the jaw moves at a constant rate from the previous segment's width to its own while the arm rests."""
    s = segments[k]
    if s.kind != "gripper" or k == 0 or s.duration <= 0:
        return np.full(len(t), s.jaw)
    before = segments[k - 1].jaw
    return before + (s.jaw - before) * np.clip(np.asarray(t, dtype=np.float64) / s.duration, 0.0, 1.0)


def to_ros2_gripper_yaml(segments: list[TimedSegment], joint: str = GRIPPER_JOINT) -> str:
    """The gripper's part of the plan as a second ROS 2 `trajectory_msgs/JointTrajectory` in YAML: one joint,
    `joint` (default `jaw_width`: the opening between the pads, m), its `positions` at every `time_from_start` of
    `to_ros2_yaml`'s message, so the two play together (positions only: a controller interpolates them linearly)."""
    points = [{"positions": [float(jaw_widths(segments, k, segments[k].traj.t[i:i + 1])[0])], "velocities": [],
               "accelerations": [], "effort": [], "time_from_start": _ros2_time(t)}
              for k, i, t in _ros2_knots(segments)]
    return _ros2_message([joint], points)
