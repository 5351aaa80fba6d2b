"""Which inverse kinematics a robot gets: the fastest valid closed form its model admits, else the numerical solver.

`closed_form(robot)` reads the joint axes and offsets off the robot model (never a table of names) and returns, in
order of preference:

- **spherical wrist** (Tournassoud et al. 1987 Section 5.2; PUMA 560, KUKA, ABB, Staubli): axes 4-6 meet and axes 1-2
  meet, 8 branches (`robots.analytic`);
- **spherical shoulder**: the same arm run backwards, axes 1-3 meet and axes 5-6 meet, 8 branches;
- **three parallel axes** (the UR family): axes 2-4 parallel and axes 5-6 meet, 8 branches (`robots.parallel`);
- **7 joints, one swept** (He & Liu 2021 for the Franka Panda): a joint (the last one first) held at `samples` angles
  evenly spread over its limits, each leaving a 6R arm with one of the forms above (the Panda: a spherical shoulder),
  8 branches per sample, of which the Panda's elbow limits (q4 < 0) mostly keep at most 4; where a pose's branches at
  the samples all miss or collide, `refine` solves it at REFINE sub-steps between the samples next to those with a
  branch (a window of the swept joint narrower than the samples' spacing);
- **subproblem decomposition** (EAIK, Ostermeier et al. 2024) for any other 6R arm whose axes decompose
  (intersecting or parallel), through the `eaik` package, one pose at a time in C++.

Each returns every branch of many poses at once: joints (N, B, n), NaN where a branch has no real solution or leaves
the joint limits, and valid (N, B). An arm with more joints (a humanoid's waist and arm) has no closed form, but
`nearby_form` gives its numerical solver seeds from the nearest decomposable model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from workbench.robots import analytic, parallel
from workbench.robots.analytic import Chain, _limit, _rotation, chain_of, reverse_poses, reversed_chain, sub_chain

SWEEP = 16  # samples of a 7-joint arm's swept joint
REFINE = 8  # sub-steps per interval between those samples, where a pose's branches at the samples all miss or collide


@dataclass(frozen=True)
class ClosedForm:
    """A robot's closed-form IK: its `kind` (said when the robot loads), the number of branches per pose, and
    `solve(poses) -> (joints (N, branches, nq), valid (N, branches))`. A swept joint's form also has
    `refine(poses, valid) -> (joints, valid)`: the branches at the joint's angles between its samples (REFINE sub-steps
    per interval), in the intervals next to a sample where `valid` (its `solve`'s) has a branch, or in all of them
    where none has."""

    kind: str
    branches: int
    nq: int
    solve: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
    refine: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None


def _six(chain: Chain, limits: bool) -> tuple[str, bool, Callable, object] | None:
    """The fastest closed form of a 6R chain as (kind, reversed, solve, constants), or None. With `reversed`, `solve`
    takes `reverse_poses(chain, poses)` and returns the joints in reversed order."""
    if not analytic.spherical_wrist_reason(chain):
        ik = analytic.analytic_ik(chain, limits=limits)
        return "spherical wrist", False, lambda poses: analytic.solve(ik, poses), ik
    rev = reversed_chain(chain)
    if not analytic.spherical_wrist_reason(rev):
        ik = analytic.analytic_ik(rev, limits=limits)
        return "spherical shoulder", True, lambda poses: analytic.solve(ik, poses), ik
    if not parallel.parallel_axes_reason(chain):
        ik = parallel.parallel_ik(chain, limits=limits)
        return "three parallel axes", False, lambda poses: parallel.solve(ik, poses), ik
    return None


EAIK_BRANCHES = 16  # a general 6R arm has at most 16 solutions


def _eaik(chain: Chain, limits: bool) -> ClosedForm | None:
    """EAIK's subproblem decomposition of a 6R chain (its H and P vectors at q = 0, in the root frame), or None when
    EAIK knows no decomposition of its axes. Solutions EAIK marks as least-squares are dropped, the others moved
    into the joint limits by whole turns and checked against the chain's FK."""
    try:
        from eaik.IK_HP import HPRobot
    except ImportError:  # pragma: no cover - eaik is a dependency
        return None
    frames, m = [], np.eye(4)
    for k in range(6):
        m = m @ chain.chain_placement[k]
        frames.append(m.copy())
    tcp0 = m @ chain.tip_in_joint
    h = np.stack([f[:3, :3] @ a for f, a in zip(frames, chain.chain_axis)])
    o = np.stack([f[:3, 3] for f in frames])
    p = np.vstack([o[:1], np.diff(o, axis=0), tcp0[None, :3, 3] - o[-1:]])
    robot = HPRobot(h, p)
    if not robot.hasKnownDecomposition():
        return None
    base_inv, r0t = np.linalg.inv(chain.base), tcp0[:3, :3].T
    lower, upper = (chain.lower, chain.upper) if limits else (np.full(6, -np.inf), np.full(6, np.inf))

    def solve(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        rel = base_inv @ poses
        rel[:, :3, :3] = rel[:, :3, :3] @ r0t               # EAIK's end effector has the root's axes at q = 0
        q = np.full((len(poses), EAIK_BRANCHES, 6), np.nan)
        for i, sol in enumerate(robot.IK_batched(np.ascontiguousarray(rel), 1)):
            qs = np.asarray(sol.Q, dtype=np.float64).reshape(-1, 6)[~np.asarray(sol.is_LS, dtype=bool)][:EAIK_BRANCHES]
            q[i, :len(qs)] = np.angle(np.exp(1j * qs))       # into (-pi, pi]
        for j in range(6):
            q[..., j] = _limit(q[..., j], lower[j], upper[j])
        valid = ~np.isnan(q).any(axis=2)
        if valid.any():  # EAIK's exact solutions, checked: 1e-6 m and rad
            r, b = np.nonzero(valid)
            back = _fk(chain, q[r, b])
            err = np.abs(back - poses[r]).max(axis=(1, 2))
            valid[r[err > 1e-6], b[err > 1e-6]] = False
            q[~valid] = np.nan
        return q, valid
    return ClosedForm(f"subproblem decomposition, EAIK {robot.getKinematicFamily()}", EAIK_BRANCHES, 6, solve)


def _fk(chain: Chain, q: np.ndarray) -> np.ndarray:
    """TCP poses (M, 4, 4) of joint vectors (M, 6) of a chain (the check of EAIK's solutions)."""
    out = np.repeat(chain.base[None], len(q), axis=0)
    for k in range(len(chain.chain_axis)):
        rot = np.repeat(np.eye(4)[None], len(q), axis=0)
        a = chain.chain_axis[k]
        kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
        s, c = np.sin(q[:, k])[:, None, None], np.cos(q[:, k])[:, None, None]
        rot[:, :3, :3] = np.eye(3) + s * kx + (1 - c) * (kx @ kx)
        out = out @ chain.chain_placement[k] @ rot
    return out @ chain.tip_in_joint


def _swept(chain: Chain, free: int, angles: np.ndarray, limits: bool) -> ClosedForm | None:
    """A 7-joint chain's IK with joint `free` held at each of `angles`: the 6R form of every sample (the same kind
    for all), branches stacked sample by sample."""
    subs = [sub_chain(chain, {free: float(a)}) for a in angles]
    forms = [_six(c, limits) for c in subs]
    if any(f is None for f in forms) or len({f[:2] for f in forms}) > 1:
        return None
    kind, rev = forms[0][:2]
    others = [k for k in range(chain.nq) if k != free]
    wrists = None
    if isinstance(forms[0][3], analytic.AnalyticIK) and not (rev and free == 0):
        wrists = analytic.kernel_constants([f[3] for f in forms])
    cols = tuple(others[::-1] if rev else others)

    def solve(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        q = np.empty((len(poses), 8 * len(angles), chain.nq))
        valid = np.empty((len(poses), 8 * len(angles)), dtype=bool)
        x = reverse_poses(subs[0], poses) if rev else poses
        if wrists is not None:  # every sample in one compiled pass, written in place
            analytic.solve_into(wrists, x, q, valid, cols=cols, fixed_col=free, fixed=angles)
            return q, valid
        for k, (a, sub, f) in enumerate(zip(angles, subs, forms)):
            if rev and free == 0 and k:  # the held first joint moves the reversed chain's target
                x = reverse_poses(sub, poses)
            qk, valid[:, 8 * k:8 * k + 8] = f[2](x)
            q[:, 8 * k:8 * k + 8, others] = qk[..., ::-1] if rev else qk
            q[:, 8 * k:8 * k + 8, free] = a
        return q, valid

    between = (angles[:-1, None] + np.arange(1, REFINE) / REFINE * np.diff(angles)[:, None]).ravel()
    fine: list = []  # the in-between samples' constants, built on the first refinement

    def refine(poses: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        if not fine:
            fine.append(analytic.kernel_constants([_six(sub_chain(chain, {free: float(a)}), limits)[3] for a in between]))
        coarse = np.asarray(valid).reshape(len(poses), len(angles), 8).any(axis=2)
        near = coarse[:, :-1] | coarse[:, 1:] | ~coarse.any(axis=1, keepdims=True)
        q = np.empty((len(poses), 8 * len(between), chain.nq))
        ok = np.empty((len(poses), 8 * len(between)), dtype=bool)
        analytic.solve_into(fine[0], reverse_poses(subs[0], poses) if rev else poses, q, ok, cols=cols, fixed_col=free,
                            fixed=between, use=np.repeat(near, REFINE - 1, axis=1))
        return q, ok
    return ClosedForm(f"{kind}, {chain.joint_names[free]} swept over {len(angles)} samples", 8 * len(angles), chain.nq,
                      solve, refine if wrists is not None and len(angles) > 1 else None)


def _sweep7(chain: Chain, limits: bool, samples: int) -> ClosedForm | None:
    """The first joint (the last one first) whose sweep leaves a 6R closed form at every sample."""
    for free in (6, 0, 1, 2, 3, 4, 5):
        lo, hi = chain.lower[free], chain.upper[free]
        angles = np.linspace(lo, hi, samples) if samples > 1 else np.array([(lo + hi) / 2])
        form = _swept(chain, free, angles, limits)
        if form is not None:
            return form
    return None


def closed_form(robot, limits: bool = True, samples: int = SWEEP) -> ClosedForm | None:
    """The robot's fastest closed-form IK (module docstring), or None when its axes admit none."""
    if robot.chain_prismatic.any() or robot.nq not in (6, 7):
        return None
    chain = chain_of(robot)
    if robot.nq == 7:
        return _sweep7(chain, limits, samples)
    six = _six(chain, limits)
    if six is None:
        return _eaik(chain, limits)
    kind, rev, f, _ = six

    def solve(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        if not rev:
            return f(poses)
        q, valid = f(reverse_poses(chain, poses))
        return q[..., ::-1], valid
    return ClosedForm(kind, 8, 6, solve)


def nearby_form(robot, samples: int = 4) -> ClosedForm | None:
    """Seeds for the numerical solver of an arm with more than 7 joints (a humanoid's waist and arm): the closed form
    of the nearest decomposable model, its first joints held at the home configuration and one of the 7 others swept
    over `samples`; joint vectors of the whole arm (the held joints at home)."""
    if robot.chain_prismatic.any() or robot.nq <= 7:
        return None
    chain, home = chain_of(robot), robot.home()
    held = {k: float(home[k]) for k in range(robot.nq - 7)}
    inner = _sweep7(sub_chain(chain, held), True, samples)
    if inner is None:
        return None
    keep = [k for k in range(robot.nq) if k not in held]

    def solve(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        qi, valid = inner.solve(poses)
        q = np.empty(qi.shape[:2] + (robot.nq,))
        q[..., keep] = qi
        for k, v in held.items():
            q[..., k] = v
        return q, valid
    names = ", ".join(robot.joint_names[k] for k in held)
    return ClosedForm(f"{inner.kind}, {names} held at home", inner.branches, robot.nq, solve)


# Revision of each solver's rows: bump one when a change to that solver (or to the collision checks every solver's
# rows go through) can change a stored `ik` row. The IK stage's digest holds the revisions of the solvers a robot
# uses, so a store built by an older solver computes its rows again instead of reusing them.
REVISIONS = {"collision checks": 1, "spherical wrist": 1, "spherical shoulder": 1, "three parallel axes": 1,
             "subproblem decomposition": 1, "swept joint": 2, "numerical": 1, "whole turns": 1}


def revision(robot, numerical: bool = False) -> dict[str, int]:
    """The revisions (`REVISIONS`) of the solvers whose answers make the robot's `ik` rows: its closed form's kind
    (with the swept joint and the Levenberg-Marquardt fall-back of a 7-joint arm), or the numerical solver."""
    form = None if numerical else closed_form(robot)
    keys = ["collision checks"]
    if form is None:
        keys.append("numerical")
        if (robot.upper - robot.lower > 2 * np.pi).any():  # its solutions moved by whole turns toward home
            keys.append("whole turns")
        nearby = None if numerical else nearby_form(robot)
        if nearby is not None:  # its seeds come from a swept closed form
            keys += [k for k in REVISIONS if nearby.kind.startswith(k)] + ["swept joint"]
    else:
        keys += [k for k in REVISIONS if form.kind.startswith(k)]
        if robot.nq == 7:
            keys += ["swept joint", "numerical"]
    return {k: REVISIONS[k] for k in keys}


def describe(robot, numerical: bool = False) -> str:
    """The IK the robot gets, in words: 'closed form (KIND, B branches)' or 'numerical (...)'."""
    form = None if numerical else closed_form(robot)
    if form is None:
        why = "forced" if numerical else "no closed form for its axes"
        return f"numerical (Levenberg-Marquardt from seeds; {why})"
    return f"closed form ({form.kind}, {form.branches} branches)"


def _meet(p: np.ndarray, u: np.ndarray, q: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    """The point where the lines p + s u and q + t v meet (unit directions), or None when they miss by 1e-9 m or
    are parallel."""
    w, c = p - q, float(u @ v)
    if 1.0 - abs(c) < 1e-12:
        return None
    s = (c * (v @ w) - (u @ w)) / (1.0 - c * c)
    t = (v @ w) + c * s
    a, b = p + s * u, q + t * v
    return (a + b) / 2 if np.linalg.norm(a - b) < 1e-9 else None


def _off_line(x: np.ndarray, p: np.ndarray, u: np.ndarray) -> float:
    """Distance of the point x from the line p + s u (unit u)."""
    d = x - p
    return float(np.linalg.norm(d - (d @ u) * u))


@dataclass(frozen=True)
class WristShell:
    """A necessary condition for a 7-joint arm to reach a TCP pose (the Panda's): axes 1-3 meet at the shoulder S
    (fixed in the base), axes 5-6 meet at the wrist W, and |S - W| depends on joint 4 alone, within [r_min, r_max]
    over its limits. W is fixed in link 6, so in the TCP frame it lies on a circle about axis 7 (`center`, `axis`,
    `radius`) whatever joint 7 is. A pose whose circle stays farther than `margin` outside [r_min, r_max] is out of
    reach; `margin` covers the solver's tolerances, so no pose the numerical solver can accept is rejected."""

    shoulder: np.ndarray
    center: np.ndarray
    axis: np.ndarray
    radius: float
    r_min: float
    r_max: float
    margin: float

    def __call__(self, poses: np.ndarray) -> np.ndarray:
        """(N,) bool for TCP poses (N, 4, 4): False where the pose is out of reach."""
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        rot = poses[:, :3, :3]
        c = rot @ self.center + poses[:, :3, 3]
        n = rot @ self.axis
        v = self.shoulder - c
        along = np.einsum("ij,ij->i", v, n)
        across = np.linalg.norm(v - along[:, None] * n, axis=1)
        near = np.hypot(along, across - self.radius)
        far = np.hypot(along, across + self.radius)
        return (near <= self.r_max + self.margin) & (far >= self.r_min - self.margin)


def wrist_shell(robot, tol_pos: float, tol_rot: float, margin: float = 1e-3) -> WristShell | None:
    """The `WristShell` of a 7-revolute-joint arm read off its model, or None when its axes do not meet as there.

    The margin is `margin` plus what a pose within `tol_pos` (m) and `tol_rot` (rad) of the target moves the circle:
    tol_pos + tol_rot * (|center| + radius)."""
    if robot.nq != 7 or robot.chain_prismatic.any():
        return None
    chain = chain_of(robot)
    frames, m = [], chain.base.copy()
    for k in range(7):
        m = m @ chain.chain_placement[k]
        frames.append(m.copy())
    tcp = m @ chain.tip_in_joint
    o = [f[:3, 3] for f in frames]
    d = [f[:3, :3] @ (a / np.linalg.norm(a)) for f, a in zip(frames, chain.chain_axis)]
    s = _meet(o[0], d[0], o[1], d[1])
    w = _meet(o[4], d[4], o[5], d[5])
    if s is None or w is None or _off_line(s, o[2], d[2]) > 1e-9:
        return None
    # |S - W|^2 over joint 4 is A + B cos q4 + C sin q4 (W turns about axis 4, S is fixed in link 3)
    def dist2(q4: float) -> float:
        rot = _rotation(chain.chain_axis[3], q4)
        w4 = np.linalg.inv(frames[3]) @ np.append(w, 1.0)
        x = frames[3][:3, :3] @ (rot @ w4[:3]) + o[3]
        return float(np.sum((x - s) ** 2))
    a0, api, ahalf = dist2(0.0), dist2(np.pi), dist2(np.pi / 2)
    big, b, c = (a0 + api) / 2, (a0 - api) / 2, ahalf - (a0 + api) / 2
    amp, phase = float(np.hypot(b, c)), float(np.arctan2(c, b))
    lo, hi = float(chain.lower[3]), float(chain.upper[3])
    cands = [lo, hi] + [x for k in range(-3, 4) for x in (phase + k * np.pi,) if lo < x < hi]
    values = [big + amp * np.cos(x - phase) for x in cands]
    r_min, r_max = np.sqrt(max(min(values), 0.0)), np.sqrt(max(values))
    inv = np.linalg.inv(tcp)
    wl = inv[:3, :3] @ w + inv[:3, 3]
    pl, ul = inv[:3, :3] @ o[6] + inv[:3, 3], inv[:3, :3] @ d[6]
    center = pl + ((wl - pl) @ ul) * ul
    radius = float(np.linalg.norm(wl - center))
    slack = margin + tol_pos + tol_rot * (float(np.linalg.norm(center)) + radius)
    return WristShell(s, center, ul, radius, float(r_min), float(r_max), slack)
