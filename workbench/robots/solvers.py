"""Which inverse kinematics a robot gets: the fastest valid closed form its model admits, else the numerical solver.

`closed_form(robot)` reads the joint axes and offsets off the robot model (never a table of names) and returns, in
order of preference:

- **spherical wrist** (Tournassoud et al. 1987 Section 5.2; PUMA 560, KUKA, ABB, Staubli): axes 4-6 meet and axes 1-2
  meet, 8 branches (`robots.analytic`);
- **spherical shoulder**: the same arm run backwards, axes 1-3 meet and axes 5-6 meet, 8 branches;
- **three parallel axes** (the UR family): axes 2-4 parallel and axes 5-6 meet, 8 branches (`robots.parallel`);
- **7 joints, the last one swept** (He & Liu 2021 for the Franka Panda): the last joint held at `samples` angles
  evenly spread over its limits, each leaving a 6R arm with one of the forms above (the Panda: a spherical shoulder),
  8 branches per sample, of which the Panda's elbow limits (q4 < 0) mostly keep at most 4;
- **subproblem decomposition** (EAIK, Ostermeier et al. 2024) for any other 6R arm whose axes decompose
  (intersecting or parallel), through the `eaik` package, one pose at a time in C++.

Each returns every branch of many poses at once: joints (N, B, n), NaN where a branch has no real solution or leaves
the joint limits, and valid (N, B).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from workbench.robots import analytic, parallel
from workbench.robots.analytic import Chain, chain_of, reverse_poses, reversed_chain, sub_chain

SWEEP = 16  # samples of a 7-joint arm's last joint


@dataclass(frozen=True)
class ClosedForm:
    """A robot's closed-form IK: its `kind` (said when the robot loads), the number of branches per pose, and
    `solve(poses) -> (joints (N, branches, nq), valid (N, branches))`."""

    kind: str
    branches: int
    nq: int
    solve: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]

    def reachable(self, poses: np.ndarray) -> np.ndarray:
        """(N,) bool: whether some branch of each pose is within the joint limits."""
        return self.solve(poses)[1].any(axis=1)


def _six(chain: Chain, limits: bool) -> tuple[str, bool, Callable] | None:
    """The fastest closed form of a 6R chain as (kind, reversed, solve), or None. With `reversed`, `solve` takes
    `reverse_poses(chain, poses)` and returns the joints in reversed order."""
    if not analytic.spherical_wrist_reason(chain):
        ik = analytic.analytic_ik(chain, limits=limits)
        return "spherical wrist", False, lambda poses: analytic.solve(ik, poses)
    rev = reversed_chain(chain)
    if not analytic.spherical_wrist_reason(rev):
        ik = analytic.analytic_ik(rev, limits=limits)
        return "spherical shoulder", True, lambda poses: analytic.solve(ik, poses)
    if not parallel.parallel_axes_reason(chain):
        ik = parallel.parallel_ik(chain, limits=limits)
        return "three parallel axes", False, lambda poses: parallel.solve(ik, poses)
    return None


def closed_form(robot, limits: bool = True, samples: int = SWEEP) -> ClosedForm | None:
    """The robot's fastest closed-form IK (module docstring), or None when its axes admit none."""
    if robot.chain_prismatic.any() or robot.nq not in (6, 7):
        return None
    chain = chain_of(robot)
    if robot.nq == 6:
        angles, forms = np.zeros(0), [_six(chain, limits)]
    else:
        lo, hi = chain.lower[6], chain.upper[6]
        angles = np.linspace(lo, hi, samples) if samples > 1 else np.array([(lo + hi) / 2])
        forms = [_six(sub_chain(chain, {6: float(a)}), limits) for a in angles]
    if any(f is None for f in forms) or len({f[:2] for f in forms}) > 1:
        return None
    kind, rev = forms[0][:2]
    solvers = [f[2] for f in forms]

    def solve(poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
        x = reverse_poses(chain, poses) if rev else poses  # the same for every sample: the base does not move
        if not len(angles):
            q, valid = solvers[0](x)
            return (q[..., ::-1] if rev else q), valid
        q = np.empty((len(poses), 8 * len(angles), 7))
        valid = np.empty((len(poses), 8 * len(angles)), dtype=bool)
        for k, (a, f) in enumerate(zip(angles, solvers)):
            qk, valid[:, 8 * k:8 * k + 8] = f(x)
            q[:, 8 * k:8 * k + 8, :6] = qk[..., ::-1] if rev else qk
            q[:, 8 * k:8 * k + 8, 6] = a
        return q, valid
    if len(angles):
        kind = f"{kind}, last joint swept over {len(angles)} samples"
    return ClosedForm(kind, 8 * max(1, len(angles)), robot.nq, solve)


def describe(robot, numerical: bool = False) -> str:
    """The IK the robot gets, in words: 'closed form (KIND, B branches)' or 'numerical (...)'."""
    form = None if numerical else closed_form(robot)
    if form is None:
        why = "forced" if numerical else "no closed form for its axes"
        return f"numerical (Levenberg-Marquardt from seeds; {why})"
    return f"closed form ({form.kind}, {form.branches} branches)"
