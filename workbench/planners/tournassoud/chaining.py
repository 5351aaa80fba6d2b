"""Regrasping by backward chaining in the grasp-placement table (Tournassoud, Lozano-Perez & Mazer 1987, Sections
4.2 and 6, Fig. 7).

States are grasps (G_i, theta sample); a regrasp goes through a placement (P_j, phi sample) compatible with both
grasps (Proposition 1). One chaining step (Fig. 7): for each placement P_j, the phi range is the union of the phi
cross-sections of Q_goal,j over the current theta range; then for every class G_k the new theta range is the union
of the theta cross-sections of Q_kj over that phi range. Both unions are computed at once over all placements with Q
laid out as a boolean (classes x theta, placements x phi) matrix: the rows of the current grasps (or placements,
in the transpose) are OR-ed together. The chaining expands level by level (breadth first) from
the goal set until it meets the start set, so the returned sequence has the minimum number of placements.

Two queries:
- grasp to grasp (the paper's): an initial grasp (G_ini, theta_ini) and a goal class with a theta range;
- placement to placement (Proposition 2's dual reading): the object from (P_s, phi_s) to (P_g, phi_g), so the same
  task can be given to the roadmap planner. The start set is every grasp compatible with (P_s, phi_s), the goal
  set every grasp compatible with (P_g, phi_g).

Concrete angles are the middles of the longest runs of the legal samples, so they sit away from the boundaries.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from workbench.errors import PlanningError
from workbench.planners.tournassoud.table import GraspPlacementTable, runs


ANGLE_TOL = 1e-6
"""Radians: an angle range [lo, hi] keeps the samples within this of either end (a range typed in degrees meets
the grid's samples only up to float rounding: 85 degrees in radians is not exactly sample 17 of 72)."""


class NoSequence(PlanningError):
    """A valid query without an answer: the table does not connect its start and goal (zero results). When realising
    a sequence removed conjunctions first, `removals` lists them and `table_sequence` is the table's own answer."""

    removals: tuple = ()
    table_sequence: "Sequence | None" = None


@dataclass
class Sequence:
    """A regrasp sequence: grasps [(class, theta sample)] and placements [(placement, phi sample)] interleaved as
    grasp_0, placement_1, grasp_1, ..., placement_n, grasp_n (grasp query), or for a placement query
    placement_0, grasp_1, placement_1, ..., grasp_n, placement_n. `levels` is the number of chaining steps."""

    kind: str
    grasps: list[tuple[int, int]]
    placements: list[tuple[int, int]]
    levels: int
    seconds: float = 0.0
    theta_ini: float | None = None
    extra: dict = field(default_factory=dict)

    def conjunctions(self) -> list[tuple[tuple[int, int], tuple[int, int]]]:
        """The (grasp, placement) conjunctions in execution order: each grasp with the placement it picks the object
        from and the one it puts it down on."""
        g, p = self.grasps, self.placements
        if self.kind == "grasp":
            out = []
            for k, pl in enumerate(p):
                out += [(g[k], pl), (g[k + 1], pl)]
            return out
        out = [(g[0], p[0])]
        for k in range(1, len(p) - 1):
            out += [(g[k - 1], p[k]), (g[k], p[k])]
        return out + [(g[-1], p[-1])]

    @property
    def regrasps(self) -> int:
        """Number of regrasps: intermediate placements (grasp query) or grasp changes (placement query)."""
        return len(self.placements) if self.kind == "grasp" else max(len(self.grasps) - 1, 0)

    def as_dict(self, table: GraspPlacementTable | None = None) -> dict:
        out = {"kind": self.kind, "levels": self.levels, "regrasps": self.regrasps, "seconds": self.seconds,
               "grasps": [[int(c), int(t)] for c, t in self.grasps], "placements": [[int(p), int(f)] for p, f in self.placements]}
        if table is not None:
            out["theta"] = [float(table.theta[t]) for _, t in self.grasps]
            out["phi"] = [float(table.phi[f]) for _, f in self.placements]
        return out


def _middle(mask: np.ndarray) -> int:
    """Index at the middle of the longest circular run of True (mask must have a True)."""
    n = len(mask)
    if mask.all():
        return n // 2
    start = int(np.argmin(mask))
    m = np.roll(mask, -start)
    best, best_len, k = 0, -1, 0
    while k < n:
        if m[k]:
            j = k
            while j + 1 < n and m[j + 1]:
                j += 1
            if j - k > best_len:
                best, best_len = (k + j) // 2, j - k
            k = j + 1
        else:
            k += 1
    return (best + start) % n


def _pick2(mask: np.ndarray) -> tuple[int, int]:
    """(row, column) of a robust True in a 2D mask: the row with the longest run, its run's middle."""
    rows = np.flatnonzero(mask.any(axis=1))
    lengths = [mask[r].sum() for r in rows]
    r = int(rows[int(np.argmax(lengths))])
    return r, _middle(mask[r])


def chain(table: GraspPlacementTable, start: np.ndarray, goal: np.ndarray, max_levels: int = 32) -> list[np.ndarray] | None:
    """Backward chaining (Fig. 7) from `goal` (C, T) bool until `start` (C, T) is met. Returns the level sets
    [goal, level 1, ..., level L] (each (C, T), L = number of placements crossed) or None when unreachable."""
    c_n, t_n = table.q.shape[0], table.q.shape[2]
    goal = np.asarray(goal, dtype=bool).reshape(c_n, t_n)
    start = np.asarray(start, dtype=bool).reshape(c_n, t_n)
    levels = [goal]
    if (goal & start).any():
        return levels
    seen = goal.copy()
    frontier = goal
    for _ in range(max_levels):
        phi = table.placements_of(frontier)                              # (P F): placements reachable
        if not phi.any():
            return None
        grasp = table.grasps_of(phi).reshape(c_n, t_n)                   # every grasp sharing one of them
        new = grasp & ~seen
        if not new.any():
            return None
        levels.append(new)
        if (new & start).any():
            return levels
        seen |= new
        frontier = new
    return None


def _through(table: GraspPlacementTable, grasp: tuple[int, int], prev: np.ndarray) -> tuple[tuple[int, int], tuple[int, int]]:
    """A placement (j, f) compatible with `grasp` and a grasp of the level set `prev` compatible with it."""
    c, t = grasp
    q = table.q
    p_n, f_n = q.shape[1], q.shape[3]
    reach = table.placements_of(prev).reshape(p_n, f_n)
    cand = q[c, :, t, :] & reach
    j, f = _pick2(cand)
    nxt = q[:, j, :, f] & prev
    k, tk = _pick2(nxt)
    return (j, f), (k, tk)


def grasp_query(table: GraspPlacementTable, initial: tuple[int, float], goal_class: int, goal_range: tuple[float, float],
                start_mask: np.ndarray | None = None, goal_mask: np.ndarray | None = None) -> Sequence:
    """Section 6: from (G_ini, theta_ini) to (G_goal, [theta_min, theta_max]) (radians, both ends kept within
    `ANGLE_TOL`); theta_ini is taken at its nearest sample. `start_mask` / `goal_mask` ((C, T) bool, from the task's
    obstacles at the pick-up and the destination, Section 5.1) further restrict the initial and final grasps.
    Raises PlanningError when no sequence exists."""
    c_n, t_n = table.q.shape[0], table.q.shape[2]
    ci, theta_ini = initial
    for name, c in (("initial", ci), ("goal", goal_class)):
        if not 0 <= c < c_n:
            raise PlanningError(f"{name} grasp class {c} does not exist: the table has classes 0..{c_n - 1}")
    ti = nearest_sample(table.theta, theta_ini)
    if not table.hand_object[ci, ti]:
        legal = ", ".join(f"{np.degrees(a):.0f}..{np.degrees(b):.0f}" for a, b in runs(table.hand_object[ci], table.theta)) or "none"
        raise PlanningError(f"initial grasp (class {ci}, theta {np.degrees(theta_ini):.1f} deg) collides with the object; "
                            f"choose theta in the class's legal range (deg: {legal})")
    if start_mask is not None and not start_mask[ci, ti]:
        legal = ", ".join(f"{np.degrees(a):.0f}..{np.degrees(b):.0f}" for a, b in runs(start_mask[ci], table.theta)) or "none"
        raise PlanningError(f"initial grasp (class {ci}, theta {np.degrees(theta_ini):.1f} deg) is not free at the pick-up "
                            f"(the hand hits an obstacle there or the arm cannot reach it); class {ci}'s free angles there "
                            f"(deg): {legal}")
    start = np.zeros((c_n, t_n), dtype=bool)
    start[ci, ti] = True
    goal = np.zeros((c_n, t_n), dtype=bool)
    goal[goal_class] = in_range(table.theta, goal_range) & table.hand_object[goal_class]
    if goal_mask is not None:
        goal &= goal_mask
    if not goal.any():
        raise PlanningError(f"goal class {goal_class} has no legal theta in [{np.degrees(goal_range[0]):.1f}, "
                            f"{np.degrees(goal_range[1]):.1f}] deg{' free at the destination' if goal_mask is not None else ''}; "
                            f"widen the range")
    return grasp_set_query(table, start, goal, theta_ini=float(theta_ini))


def grasp_set_query(table: GraspPlacementTable, start: np.ndarray, goal: np.ndarray, theta_ini: float | None = None) -> Sequence:
    """Section 6 with sets of grasps at both ends: from any grasp of `start` to any of `goal` ((C, T) bool, e.g. the
    grasps that clear the pick-up's and the destination's obstacles, Section 5.1), fewest placements. With
    `theta_ini` the start is one grasp, realised at that exact angle."""
    t0 = time.perf_counter()
    c_n, t_n = table.q.shape[0], table.q.shape[2]
    start = np.asarray(start, dtype=bool).reshape(c_n, t_n) & table.hand_object
    goal = np.asarray(goal, dtype=bool).reshape(c_n, t_n) & table.hand_object
    if not start.any():
        raise NoSequence("no initial grasp: no legal (class, theta) is free at the pick-up")
    if not goal.any():
        raise NoSequence("no final grasp: no legal (class, theta) is free at the destination")
    levels = chain(table, start, goal)
    if levels is None:
        what = (f"class {int(np.argwhere(start)[0][0])} at {np.degrees(theta_ini):.1f} deg" if theta_ini is not None
                else f"the {int(start.sum())} initial grasp sample(s)")
        raise NoSequence(f"no regrasp sequence from {what} to the {int(goal.sum())} goal grasp sample(s): the grasp-placement "
                         f"table does not connect them (try another table point or finer steps)")
    cur = _pick2(levels[-1] & start)
    grasps, placements = [cur], []
    for prev in reversed(levels[:-1]):
        pl, cur = _through(table, cur, prev)
        placements.append(pl)
        grasps.append(cur)
    return Sequence("grasp", grasps, placements, len(levels) - 1, time.perf_counter() - t0, theta_ini=theta_ini)


def _other_angle(table: GraspPlacementTable, p: int) -> str:
    """What to try when no grasp holds placement `p` at the asked angle: another angle phi (degrees, as runs of
    samples, wrapping around) at which some grasp of the table holds it, or, with none, another table."""
    spans = runs(table.q[:, p].any(axis=(0, 1)), np.degrees(table.phi))
    if not spans:
        return (f"no angle of placement {p} has a grasp at this table point: more grasp points per class "
                f"(`workbench gptable --points N`) or another --table-point may give some")
    text = [f"{a:.0f}" if a == b else f"{a:.0f} to {b:.0f}{' through 0' if a > b else ''}" for a, b in spans]
    more = " ..." if len(text) > 6 else ""
    return f"choose another angle (placement {p} has grasps at {', '.join(text[:6])}{more} deg)"


def placement_query(table: GraspPlacementTable, start: tuple[int, float], goal: tuple[int, float]) -> Sequence:
    """The object from placement (P_s, phi_s) to (P_g, phi_g) (radians; the table is read at the nearest samples, the
    plan realises the exact angles), fewest grasps."""
    t0 = time.perf_counter()
    p_n = table.q.shape[1]
    (ps, phs), (pg, phg) = start, goal
    for name, p in (("start", ps), ("goal", pg)):
        if not 0 <= p < p_n:
            raise PlanningError(f"{name} placement {p} does not exist: the table has placements 0..{p_n - 1}")
    fs, fg = nearest_sample(table.phi, phs), nearest_sample(table.phi, phg)
    a = table.q[:, ps, :, fs]
    b = table.q[:, pg, :, fg]
    if not a.any():
        raise NoSequence(f"no grasp can pick the object at placement {ps}, {np.degrees(phs):.1f} deg; "
                         f"{_other_angle(table, ps)}")
    if not b.any():
        raise NoSequence(f"no grasp can put the object at placement {pg}, {np.degrees(phg):.1f} deg; "
                         f"{_other_angle(table, pg)}")
    levels = chain(table, a, b)
    if levels is None:
        raise NoSequence(f"no regrasp sequence from placement {ps} to placement {pg}: the table does not connect them: "
                         f"{why_apart(table, ps, pg)}")
    cur = _pick2(levels[-1] & a)
    grasps, placements = [cur], [(ps, fs)]
    for prev in reversed(levels[:-1]):
        pl, cur = _through(table, cur, prev)
        placements.append(pl)
        grasps.append(cur)
    # the last grasp belongs to the goal set; it puts the object down at the goal
    placements.append((pg, fg))
    return Sequence("placement", grasps, placements, len(levels) - 1, time.perf_counter() - t0,
                    extra={"phi_start": float(phs), "phi_goal": float(phg)})


def placement_groups(table: GraspPlacementTable) -> list[set[int]]:
    """The placement classes linked by a grasp class usable in both (any theta, any phi), as connected groups: a
    placement query between two groups has no answer at any angle (Proposition 1 needs a shared grasp)."""
    cells = table.q.any(axis=(2, 3))                          # (C, P)
    p_n = cells.shape[1]
    link = (cells.T.astype(np.int32) @ cells.astype(np.int32)) > 0   # (P, P) sharing a class
    seen, out = set(), []
    for j in range(p_n):
        if j in seen:
            continue
        group, todo = set(), [j]
        while todo:
            k = todo.pop()
            if k in group:
                continue
            group.add(k)
            todo += [int(m) for m in np.flatnonzero(link[k]) if m not in group]
        seen |= group
        out.append(group)
    return out


def why_apart(table: GraspPlacementTable, ps: int, pg: int) -> str:
    """Why the table does not connect placement `ps` to `pg` (for the NoSequence message and the benchmark)."""
    cells = table.q.any(axis=(2, 3))
    for j in (ps, pg):
        only = np.flatnonzero(cells[:, j])
        others = [k for k in range(cells.shape[1]) if k != j]
        if len(only) and not cells[np.ix_(only, others)].any():
            return (f"placement {j} is held only by grasp class(es) {only.tolist()}, usable at no other placement at the table "
                    f"point H (the paper's one grasp point per class and single H; try more grasp points per class "
                    f"(--points) or another table point)")
    group = next(g for g in placement_groups(table) if ps in g)
    if pg not in group:
        return (f"no chain of shared grasp classes links placement {ps} (group {sorted(group)}) to placement {pg} at the "
                f"table point H (the paper's one grasp point per class and single H; try --points or another table point)")
    return "the shared grasps' theta and phi ranges do not meet at these angles (try finer steps or other angles)"


def nearest_sample(grid: np.ndarray, angle: float) -> int:
    """Index of the sample of the uniform circular `grid` nearest to `angle` (radians)."""
    n = len(grid)
    return int(np.round(np.mod(angle, 2 * np.pi) / (2 * np.pi / n))) % n


def in_range(grid: np.ndarray, rng: tuple[float, float], tol: float = ANGLE_TOL) -> np.ndarray:
    """Samples inside [lo - tol, hi + tol] (radians, hi >= lo; wraps around 2 pi): both ends are kept, so a range
    typed in degrees keeps the samples at its ends and [a, a] is the sample at a."""
    lo, hi = rng
    if hi - lo >= 2 * np.pi - 2 * tol:
        return np.ones(len(grid), dtype=bool)
    d = np.mod(np.asarray(grid, dtype=np.float64) - lo + tol, 2 * np.pi)
    return d <= (hi - lo) + 2 * tol
