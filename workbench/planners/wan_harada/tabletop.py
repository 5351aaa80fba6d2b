"""Tabletop placements and grips over a grid of table positions and rotations (Wan & Harada, Section IV, Fig. 7).

Each free placement is displaced to every grid position and rotated about world z by every value of the
`angle` table; every free tabletop grip of that placement follows it into the world. The world frame is the
table frame here (table top z = 0). Table I uses 21 positions and 8 rotations (168 tabletop placements per free
placement); Fig. 7 shows 91 positions. Every free tabletop grip enters the roadmap by default, as in Table I
(#-tpg = 168 x the sum of #-fpg). `max_grasps` is an explicit option for a quick look: it caps the free-air grasps
carried into the roadmap, picked spread out over the object (farthest-point order, preferring grasps usable in
more placements, and keeping a few for every placement); every command and benchmark names it in its output
(`TabletopParams.grasps_label`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.params import Params, check_memory, param


@dataclass(frozen=True)
class TabletopParams(Params):
    """Table grid (metres, world frame): x from x_min to x_max in nx steps, y likewise; `angles` rotations about
    z in [0, 2 pi); `max_grasps` free-air grasps carried into the roadmap (None, the default: all, as the paper)."""

    x_min: float = param(0.35, ge=-10, le=10, unit="m", help="grid start along x", flag="--x")
    x_max: float = param(0.65, ge=-10, le=10, unit="m", help="grid end along x", flag="--x")
    nx: int = param(7, ge=1, le=1000, integer=True, help="grid positions along x", flag="--x")
    y_min: float = param(-0.20, ge=-10, le=10, unit="m", help="grid start along y", flag="--y")
    y_max: float = param(0.20, ge=-10, le=10, unit="m", help="grid end along y", flag="--y")
    ny: int = param(3, ge=1, le=1000, integer=True, help="grid positions along y", flag="--y")
    angles: int = param(8, ge=1, le=360, integer=True, help="rotations about z")
    max_grasps: int | None = param(None, ge=1, le=1_000_000, integer=True, optional=True,
                                   help="free-air grasps carried into the roadmap")

    def check(self) -> None:
        self.require(self.x_min <= self.x_max, ("x_min", "x_max"), "the grid along x needs MIN <= MAX")
        self.require(self.y_min <= self.y_max, ("y_min", "y_max"), "the grid along y needs MIN <= MAX")

    def positions(self) -> np.ndarray:
        """Grid positions (nx * ny, 3) on the table top, x-major."""
        xs = np.linspace(self.x_min, self.x_max, self.nx) if self.nx > 1 else np.array([(self.x_min + self.x_max) / 2])
        ys = np.linspace(self.y_min, self.y_max, self.ny) if self.ny > 1 else np.array([(self.y_min + self.y_max) / 2])
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        return np.column_stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)])

    def angle_values(self) -> np.ndarray:
        return 2 * np.pi * np.arange(self.angles) / self.angles

    def grasps_label(self, chosen: int | None = None) -> str:
        """How many free-air grasps enter the roadmap, for every printed output; `chosen`, the grasps
        `select_grasps` took, when known (above the cap: those that keep every placement some)."""
        if self.max_grasps is None:
            return "all grasps"
        above = chosen is not None and chosen > self.max_grasps
        extra = ", plus a few so that every placement keeps 4" if above else ""
        return f"grasps capped at {self.max_grasps} (--max-grasps){extra}"


def paper_grid() -> TabletopParams:
    """The grid of Fig. 7: 91 positions (13 x 7) and 8 rotations, all grasps."""
    return TabletopParams(x_min=0.35, x_max=0.65, nx=7, y_min=-0.30, y_max=0.30, ny=13, angles=8, max_grasps=None)


def select_grasps(grasp_poses: np.ndarray, usable: np.ndarray, count: int | None, per_placement: int = 4) -> np.ndarray:
    """Indices of about `count` grasps spread over contact centres and approach directions (farthest-point order),
    starting from and favouring grasps usable in more placements. Every placement keeps at least `per_placement`
    of its usable grasps (or all it has), so no placement drops out of the roadmap. `usable` is the (P, G) mask."""
    uses = usable.sum(axis=0)
    cand = np.flatnonzero(uses > 0)
    if count is None or len(cand) <= count:
        return cand
    pos = grasp_poses[cand, :3, 3]
    scale = max(float(np.ptp(pos, axis=0).max()), 1e-9)
    feat = np.column_stack([pos / scale, 0.5 * grasp_poses[cand, :3, 2]])
    weight = 0.5 + uses[cand] / uses[cand].max()
    chosen = np.zeros(len(cand), dtype=bool)
    dist = np.full(len(cand), np.inf)

    def take(k: int) -> None:
        chosen[k] = True
        np.minimum(dist, np.linalg.norm(feat - feat[k], axis=1), out=dist)

    take(int(np.argmax(uses[cand])))
    for _ in range(count - 1):
        take(int(np.argmax(np.where(chosen, -1.0, dist * weight))))
    for row in usable[:, cand]:
        need = min(per_placement, int(row.sum())) - int((row & chosen).sum())
        for _ in range(max(need, 0)):
            take(int(np.argmax(np.where(row & ~chosen, dist, -1.0))))
    return cand[chosen]


def yaw(theta: float | np.ndarray) -> np.ndarray:
    """Rotation(s) about world z as 4x4 transforms."""
    t = np.atleast_1d(np.asarray(theta, dtype=np.float64))
    out = np.zeros((len(t), 4, 4))
    out[:, 0, 0] = out[:, 1, 1] = np.cos(t)
    out[:, 0, 1], out[:, 1, 0] = -np.sin(t), np.sin(t)
    out[:, 2, 2] = out[:, 3, 3] = 1.0
    return out if np.ndim(theta) else out[0]


@dataclass(frozen=True)
class Tabletop:
    """Tabletop placements (T rows: free placement index, angle index, position, object pose in the world, and the
    move (translation and yaw) from the free placement) and tabletop grips (R rows: tabletop placement row, free
    tabletop grip row, TCP pose in the world)."""

    placement: np.ndarray
    angle: np.ndarray
    position: np.ndarray
    poses: np.ndarray
    moves: np.ndarray
    grip_tp: np.ndarray
    grip_ftg: np.ndarray
    grip_poses: np.ndarray


def tabletop(free_poses: np.ndarray, ftg_placement: np.ndarray, ftg_poses: np.ndarray, ftg_keep: np.ndarray,
             params: TabletopParams) -> Tabletop:
    """Displace and rotate every free placement over the grid; carry the kept free tabletop grips along.

    free_poses: (P, 4, 4) free placements; ftg_placement: (F,) placement index of each free tabletop grip;
    ftg_poses: (F, 4, 4) their TCP poses in the table frame; ftg_keep: (F,) which grips enter the roadmap.
    """
    n_p, n_a, n_x = len(free_poses), params.angles, params.nx * params.ny
    n_grips = int(np.count_nonzero(ftg_keep)) * n_x * n_a
    check_memory(600.0 * n_p * n_x * n_a + 900.0 * n_grips,
                 f"{n_p} placements x {n_x:,} grid positions x {n_a} angles ({n_grips:,} tabletop grips)",
                 "lower --x/--y N, --angles or --max-grasps")
    pos = params.positions()
    ang = params.angle_values()
    move = yaw(ang)[None, :, :, :].repeat(n_x, axis=0)  # (X, A, 4, 4)
    move[..., :3, 3] = pos[:, None, :]
    move = move.reshape(-1, 4, 4)  # position-major, then angle
    tp_place = np.repeat(np.arange(n_p), n_x * n_a)
    tp_angle = np.tile(np.tile(np.arange(n_a), n_x), n_p)
    tp_pos = np.tile(np.repeat(pos, n_a, axis=0), (n_p, 1))
    tp_move = np.tile(move, (n_p, 1, 1))
    tp_poses = tp_move @ free_poses[tp_place]
    # grips: for each free placement, its kept grips times its X*A tabletop placements
    kept = np.flatnonzero(ftg_keep)
    per = np.bincount(ftg_placement[kept], minlength=n_p)
    order = kept[np.argsort(ftg_placement[kept], kind="stable")]
    grip_tp, grip_ftg = [], []
    start = 0
    for p in range(n_p):
        g = order[start:start + per[p]]
        start += per[p]
        tps = np.arange(p * n_x * n_a, (p + 1) * n_x * n_a)
        grip_tp.append(np.repeat(tps, len(g)))
        grip_ftg.append(np.tile(g, len(tps)))
    grip_tp = np.concatenate(grip_tp) if grip_tp else np.zeros(0, dtype=np.int64)
    grip_ftg = np.concatenate(grip_ftg) if grip_ftg else np.zeros(0, dtype=np.int64)
    grip_poses = tp_move[grip_tp] @ ftg_poses[grip_ftg]
    return Tabletop(placement=tp_place, angle=tp_angle, position=tp_pos, poses=tp_poses, moves=tp_move, grip_tp=grip_tp,
                    grip_ftg=grip_ftg, grip_poses=grip_poses)


def plan_tabletop(free_poses: np.ndarray, ftg_placement: np.ndarray, ftg_grasp: np.ndarray, ftg_poses: np.ndarray,
                  grasp_poses: np.ndarray, params: TabletopParams) -> Tabletop:
    """The tabletop roadmap's placements and grips of Section IV from the free placements and free tabletop grips:
    the grasps carried along (`select_grasps`, capped by `params.max_grasps`), then `tabletop`.

    ftg_placement, ftg_grasp: (F,) placement index and grasp index (into `grasp_poses`, (G, 4, 4) TCP in the
    object frame) of each free tabletop grip; ftg_poses: (F, 4, 4) their TCP poses in the table frame."""
    ids = np.unique(ftg_grasp)
    usable = np.zeros((len(free_poses), len(ids)), dtype=bool)
    usable[ftg_placement, np.searchsorted(ids, ftg_grasp)] = True
    chosen = ids[select_grasps(grasp_poses[ids], usable, params.max_grasps)] if len(ids) else ids
    return tabletop(free_poses, ftg_placement, ftg_poses, np.isin(ftg_grasp, chosen), params)
