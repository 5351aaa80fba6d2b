"""The pad contact model of CONVENTIONS.md (Gripper): pads close along the jaw axis until each first touches.

A candidate grasp is a jaw axis (a point on it and its unit direction y) and a rotation of the hand about it.
Each pad is the rectangle of the pad box's inner face (in the TCP's x-z plane); closing along -y (left pad) or +y
(right pad) from full opening, it first touches the object at the highest (lowest) point of the object inside its
rectangle's footprint. Those first touches are the grasp's contacts; the TCP sits midway between them on the axis.

The highest point of a triangle over a convex rectangle is a vertex of their intersection polygon, so it is one of:
a triangle vertex inside the rectangle, a crossing of a triangle edge with a rectangle side, or a rectangle corner
inside the triangle (heights interpolated). The axis point itself is added so that on a flat facet the contact is
the paper's sampled point (Wan & Harada, Section III: the contact pair lies on the jaw axis). Where several points
touch first (within `tie` metres, e.g. a face parallel to the pad), the one nearest the axis is the contact and,
at an edge or vertex touch, the triangle whose normal faces the pad best gives the normal.

On a mesh that is not watertight the side of a triangle is unknown; its normal is flipped to face the pad.

The pads start at full opening, half the jaw range either side of the TCP. Where the part is narrower than the jaw
along the axis, they start outside it and only the first touches matter. Where it is not, one pad may start inside
a hole or a cavity and close outwards onto a wall (a washer's rim, a mug's wall, the tube of a ring wider than the
jaw): `gap_windows` finds those starts along the axis line and `first_touches` takes a window per axis, so each pad
touches only what lies between its start and the TCP. The hand at full opening is checked against the object
afterwards (level 2), which rejects a start inside material.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from workbench.robots.gripper import Gripper


@dataclass(frozen=True)
class Touches:
    """First touches of the two pads for H hand poses (axis-major, rotation-minor).

    `poses` TCP poses (H, 4, 4) centred between the touches; `width` the opening; `hit` whether the pad footprint
    meets the object at all; `point0/normal0` the left pad's contact (+y side), `point1/normal1` the right pad's;
    `tri0/tri1` their triangles; `window` (H, 2) the lowest and highest heights along y, from the TCP, that the
    right and left pads can touch (their starts; -inf, inf: from outside the part).
    """

    poses: np.ndarray
    width: np.ndarray
    hit: np.ndarray
    point0: np.ndarray
    normal0: np.ndarray
    tri0: np.ndarray
    point1: np.ndarray
    normal1: np.ndarray
    tri1: np.ndarray
    window: np.ndarray

    def __len__(self) -> int:
        return len(self.width)


def pad_rectangle(gripper: Gripper) -> tuple[float, float, float, float]:
    """(centre x, centre z, half size x, half size z) of the pad's contact face in the TCP frame."""
    ext, c = gripper.pad_extents, gripper.pad_center
    return float(c[0]), float(c[2]), float(ext[0] / 2), float(ext[2] / 2)


def axis_frames(origins: np.ndarray, axes: np.ndarray, angles: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
    """TCP frames (K * A, 4, 4): origin on the axis, y along it, approach z = the reference z0 (the world axis least
    aligned with y, made perpendicular) rotated by +angle about y (right-handed, the stored rotation), axis-major.
    `ref` (K, 3), when given, replaces the world axis as each axis's reference (it must not be parallel to y)."""
    y = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    if ref is None:
        ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    z0 = ref - np.einsum("ij,ij->i", ref, y)[:, None] * y
    z0 /= np.linalg.norm(z0, axis=1, keepdims=True)
    x0 = np.cross(y, z0)
    c, s = np.cos(angles)[None, :, None], np.sin(angles)[None, :, None]
    z = c * z0[:, None, :] + s * x0[:, None, :]  # R_y(angle) z0 = cos z0 + sin (y x z0)
    yy = np.broadcast_to(y[:, None, :], z.shape)
    poses = np.zeros((len(y), len(angles), 4, 4))
    poses[..., :3, 0], poses[..., :3, 1], poses[..., :3, 2] = np.cross(yy, z), yy, z
    poses[..., :3, 3] = origins[:, None, :]
    poses[..., 3, 3] = 1.0
    return poses.reshape(-1, 4, 4)


def fingertip_shifts(vertices: np.ndarray, poses: np.ndarray, gripper: Gripper, margin: float,
                     min_contact: float = 1e-3) -> np.ndarray:
    """How far to move each TCP back along its approach so the fingertips end `margin` short of the part's far side
    along it (H,), NaN where no shift is needed or possible.

    With the TCP at the pad's centre, a part thinner than half a pad beyond the contact (a washer or a bracket
    lying flat, gripped from above) leaves the fingertips poking past it, into the table in every placement with
    that side down. Moving the hand back by d = (pad tip) - (extent) + margin puts the contact on the pad's tip
    end; it is possible while the contact stays `min_contact` inside the pad. `vertices`: the part's convex hull
    vertices (the extent along a direction is a hull vertex's); `poses` (H, 4, 4) TCP poses in the part's frame.
    """
    _, cz, _, hz = pad_rectangle(gripper)
    tip = cz + hz
    extent = np.einsum("hj,vj->hv", poses[:, :3, 2], vertices).max(axis=1) - np.einsum("hj,hj->h", poses[:, :3, 2],
                                                                                       poses[:, :3, 3])
    d = tip - extent + margin
    return np.where((d > 0) & (d <= tip - min_contact), d, np.nan)


def _near_axis_tri(tri: np.ndarray, origins: np.ndarray, axes: np.ndarray, radius: float,
                   budget: int = 2_000_000) -> tuple[np.ndarray, np.ndarray]:
    """(axis, triangle) pairs whose triangle may reach within `radius` of the axis line (broad phase)."""
    centre = tri.mean(axis=1)
    reach = np.linalg.norm(tri - centre[:, None, :], axis=2).max(axis=1) + radius
    ks, ts = [], []
    step = max(1, budget // max(len(centre), 1))
    for a in range(0, len(origins), step):
        d = centre[None, :, :] - origins[a:a + step, None, :]
        along = np.einsum("ktj,kj->kt", d, axes[a:a + step])
        perp2 = np.einsum("ktj,ktj->kt", d, d) - along**2
        k, t = np.nonzero(perp2 <= reach[None, :] ** 2)
        ks.append(k + a)
        ts.append(t)
    return np.concatenate(ks), np.concatenate(ts)


def first_touches(mesh: trimesh.Trimesh, origins: np.ndarray, axes: np.ndarray, angles: np.ndarray,
                  gripper: Gripper, tie: float = 1e-6, ref: np.ndarray | None = None,
                  windows: np.ndarray | None = None) -> Touches:
    """First touches of both pads closing along each axis at each hand rotation (CONVENTIONS.md, Gripper); `ref`
    as in `axis_frames` (rotation 0 approaching along it); `windows` (K, 2), heights along each axis from its origin:
    the right pad starts at the first and touches nothing below it, the left at the second (None: from outside)."""
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    axes = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.asarray(angles, dtype=np.float64)
    if windows is None:
        windows = np.tile([-np.inf, np.inf], (len(origins), 1))
    windows = np.asarray(windows, dtype=np.float64).reshape(-1, 2)
    frames = axis_frames(origins, axes, angles, ref)
    # the reference frames (rotation 0): `_rows` turns every triangle into each rotation's pad coordinates from them
    fr0 = axis_frames(origins, axes, np.zeros(1), ref)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _touches(mesh, origins, frames, fr0, angles, gripper, tie, windows)


def gap_windows(mesh: trimesh.Trimesh, origins: np.ndarray, axes: np.ndarray,
                jaw_max: float) -> tuple[np.ndarray, np.ndarray]:
    """Pad starts inside a hole or cavity for jaw axes through surface points `origins` (K, 3) along their outward
    normals `axes` (K, 3): (axis index (W,), window (W, 2)) for `first_touches`.

    Along the axis line, the left pad touches the origin's surface and the right pad a surface below it facing down
    (any surface on an open mesh) at most `jaw_max` away; with the TCP midway, the pads start `jaw_max` / 2 either
    side of it, and each start must leave the line clear up to its touch. The windows where both starts lie outside
    the part along the line are the ordinary grasp from outside and are not returned.
    """
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    axes = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    reach = 1.1 * float(np.linalg.norm(mesh.extents)) + 1e-3
    start = origins + reach * axes  # beyond the part: every crossing of the line is at a height below `reach`
    locs, ray, tri = mesh.ray.intersects_location(start, -axes, multiple_hits=True)
    if len(ray) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2))
    # heights along the axis from the origin, in float64 on the hit triangle's plane (the caster may be float32)
    tn = mesh.face_normals[tri]
    a = axes[ray]
    t = np.einsum("ij,ij->i", mesh.triangles[tri, 0] - start[ray], tn) / np.einsum("ij,ij->i", -a, tn)
    h = np.where(np.isfinite(t), reach - t, np.einsum("ij,ij->i", locs - origins[ray], a))
    down = np.einsum("ij,ij->i", tn, a) < 0 if mesh.is_watertight else np.ones(len(h), dtype=bool)
    # every crossing, grouped by axis and in descending height along it
    order = np.lexsort((-h, ray))
    ray, h, down = ray[order], h[order], down[order]
    n = len(h)
    first = np.flatnonzero(np.r_[True, ray[1:] != ray[:-1]])
    group = np.repeat(np.arange(len(first)), np.diff(np.r_[first, n]))
    last = np.r_[first[1:], n][group] - 1
    # the origin's own surface: the crossing nearest height 0 (the line may miss it on a sliver)
    nearest = np.abs(h) == np.minimum.reduceat(np.abs(h), first)[group]
    top = np.full(len(first), n)
    np.minimum.at(top, group[nearest], np.flatnonzero(nearest))
    hit_origin = np.abs(h[top]) <= 1e-5 * reach
    ceiling = np.where(top > first, h[np.maximum(top - 1, 0)], np.inf)[group]  # lowest crossing above it
    floor = np.where(np.arange(n) < last, np.r_[h[1:], -np.inf], -np.inf)  # highest crossing below each
    eps = max(1e-7, 1e-9 * reach)
    span = h[top][group] - h
    mid = 0.5 * (h[top][group] + h)
    lo, hi = mid - jaw_max / 2, mid + jaw_max / 2
    ok = (hit_origin[group] & (np.arange(n) > top[group]) & down & (span > eps) & (span <= jaw_max)
          & (hi < ceiling - eps) & (lo > floor + eps)  # both starts in free space along the line
          & ~(np.isinf(ceiling) & np.isinf(floor)))  # not both outside the part: the ordinary grasp
    j = np.flatnonzero(ok)
    return ray[j].astype(np.int64), np.column_stack([lo[j], hi[j]])


def _touches(mesh, origins, frames, fr0, angles, gripper, tie, windows, budget=1_500_000) -> Touches:
    H = len(frames)
    tri = mesh.triangles
    fn = np.asarray(mesh.face_normals)
    flip = not mesh.is_watertight
    rows: dict[int, list] = {1: [], -1: []}
    # axes in chunks: at most about `budget` (axis, triangle) pairs at a time, so memory stays bounded
    step = max(1, budget // max(len(tri), 1))
    for a0 in range(0, len(origins), step):
        _rows(tri, fn, flip, origins[a0:a0 + step], fr0[a0:a0 + step], a0, angles, gripper, tie, rows,
              windows[a0:a0 + step])
    hit = np.ones(H, dtype=bool)
    res = {}
    for side in (1, -1):
        m = np.vstack(rows[side]) if rows[side] else np.zeros((0, 8))
        m = m[np.argsort(m[:, 0], kind="stable")]
        hh = m[:, 0].astype(np.int64)
        gmax = _segment_max(hh, m[:, 2])
        m = m[m[:, 2] >= gmax[hh] - tie]
        hh = m[:, 0].astype(np.int64)
        order = np.lexsort((-m[:, 7], np.round(m[:, 6] / tie**2), hh))
        m, hh = m[order], hh[order]
        first = np.r_[True, hh[1:] != hh[:-1]] if len(hh) else np.zeros(0, dtype=bool)
        m, hh = m[first], hh[first]
        found = np.zeros(H, dtype=bool)
        found[hh] = True
        hit &= found
        local = np.zeros((H, 3))
        local[hh] = m[:, 3:6]
        tri_id = np.full(H, -1, dtype=np.int64)
        tri_id[hh] = m[:, 1].astype(np.int64)
        sv = np.zeros(H)
        sv[hh] = side * m[:, 2]
        pts = frames[:, :3, 3] + np.einsum("hij,hj->hi", frames[:, :3, :3], local)
        n = fn[np.maximum(tri_id, 0)]
        if flip:
            n = n * np.where(side * np.einsum("hj,hj->h", n, frames[:, :3, 1]) < 0, -1.0, 1.0)[:, None]
        res[side] = (sv, pts, n, tri_id)
    poses = frames.copy()
    mid = np.where(hit, 0.5 * (res[1][0] + res[-1][0]), 0.0)
    poses[:, :3, 3] += poses[:, :3, 1] * mid[:, None]
    width = np.where(hit, res[1][0] - res[-1][0], np.inf)
    window = np.repeat(windows, len(angles), axis=0) - mid[:, None]
    return Touches(poses=poses, width=width, hit=hit, point0=res[1][1], normal0=res[1][2], tri0=res[1][3],
                   point1=res[-1][1], normal1=res[-1][2], tri1=res[-1][3], window=window)


def _rows(tri, fn, flip, origins, fr0, offset, angles, gripper, tie, rows, windows) -> None:
    """Candidate first-touch rows (pose, triangle, height, local point, distance to the axis, alignment) of a chunk of
    axes, appended to `rows[side]`; only rows within `tie` of their pose's best in this chunk are kept. A pad
    touches only heights inside its axis's window."""
    na = len(angles)
    cx, cz, hx, hz = pad_rectangle(gripper)
    radius = float(np.hypot(abs(cx) + hx, abs(cz) + hz))
    k, t = _near_axis_tri(tri, origins, fr0[:, :3, 1], radius)
    # per (axis, triangle): heights along the axis and coordinates on the rotation-0 frame's z (a) and x (b)
    rel = tri[t] - origins[k][:, None, :]
    ly = np.einsum("pvj,pj->pv", rel, fr0[k, :3, 1])
    ca = np.einsum("pvj,pj->pv", rel, fr0[k, :3, 2])
    cb = np.einsum("pvj,pj->pv", rel, fr0[k, :3, 0])
    ny = np.einsum("pj,pj->p", fn[t], fr0[k, :3, 1])
    w_lo, w_hi = windows[:, 0], windows[:, 1]
    # a triangle wholly outside its axis's window is touched by neither pad (the right pad's touch is below the left's)
    near = (_max3(ly) >= w_lo[k]) & (_min3(ly) <= w_hi[k])
    if not near.all():
        k, t, ly, ca, cb, ny = k[near], t[near], ly[near], ca[near], cb[near], ny[near]
    # heights where the axis itself crosses each triangle: true surface points inside every rotation's footprint
    hx_axis = _axis_heights(cb, ly, ca, 0.0, 0.0)
    a_max = np.full(len(origins), -np.inf)
    a_min = np.full(len(origins), np.inf)
    np.maximum.at(a_max, k, np.where(np.isfinite(hx_axis) & (hx_axis <= w_hi[k]), hx_axis, -np.inf))
    np.minimum.at(a_min, k, np.where(np.isfinite(hx_axis) & (hx_axis >= w_lo[k]), hx_axis, np.inf))
    # an axis whose own crossings are farther apart than the jaw opens cannot be grasped at any rotation
    live = (a_max - a_min <= gripper.jaw_max + tie) | ~np.isfinite(a_max - a_min)
    sel = live[k]
    k, t, ly, ca, cb, ny = k[sel], t[sel], ly[sel], ca[sel], cb[sel], ny[sel]
    for j, ang in enumerate(angles):
        c, s = np.cos(ang), np.sin(ang)
        # frame j: z = c z0 + s x0 and x = y x z = c x0 - s z0, where rotation 0 has x = x0 and z = z0
        lz = c * ca + s * cb - cz
        lx = c * cb - s * ca - cx
        ok = (_min3(lx) <= hx) & (_max3(lx) >= -hx) & (_min3(lz) <= hz) & (_max3(lz) >= -hz)
        p = np.flatnonzero(ok)
        if len(p) == 0:
            continue
        h = (k[p] + offset) * na + j
        x3, y3, z3 = lx[p], ly[p], lz[p]
        # bounds from vertices inside the rectangle: rows that cannot reach them are skipped
        inside = (np.abs(x3) <= hx) & (np.abs(z3) <= hz)
        top_lim, bottom_lim = w_hi[k[p]][:, None], w_lo[k[p]][:, None]
        vmax = _max3(np.where(inside & (y3 <= top_lim), y3, -np.inf))
        vmin = _min3(np.where(inside & (y3 >= bottom_lim), y3, np.inf))
        lo = np.maximum(_segment_max(h, vmax)[h], a_max[k[p]])
        hi = np.minimum(-_segment_max(h, -vmin)[h], a_min[k[p]])
        need = (_max3(y3) >= lo - tie) | (_min3(y3) <= hi + tie)
        q = p[need]
        h, x3, y3, z3 = h[need], x3[need], y3[need], z3[need]
        px, pz, py, valid = _candidates(x3, y3, z3, hx, hz, -cx, -cz)
        r = np.arange(len(q))
        for side in (1, -1):
            reach = py <= w_hi[k[q]][:, None] if side == 1 else py >= w_lo[k[q]][:, None]
            score = np.where(valid & reach, side * py, -np.inf)
            top = score.max(axis=1)
            near = valid & reach & (score >= top[:, None] - tie)
            d2 = np.where(near, (px + cx) ** 2 + (pz + cz) ** 2, np.inf)
            m = d2.argmin(axis=1)
            align = np.abs(ny[q]) if flip else side * ny[q]
            keep = np.isfinite(top) & (top >= _segment_max(h, top)[h] - tie)
            rows[side].append(np.column_stack([h, t[q], top, px[r, m] + cx, py[r, m], pz[r, m] + cz, d2[r, m], align])[keep])


def _axis_heights(lx, ly, lz, ax, az) -> np.ndarray:
    """Height of each triangle (rows of 3 local vertices) where the line x = ax, z = az crosses it, NaN elsewhere."""
    e1x, e1z = lx[:, 1] - lx[:, 0], lz[:, 1] - lz[:, 0]
    e2x, e2z = lx[:, 2] - lx[:, 0], lz[:, 2] - lz[:, 0]
    det = e1x * e2z - e2x * e1z
    good = np.abs(det) > 1e-18
    inv = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
    qx, qz = ax - lx[:, 0], az - lz[:, 0]
    u = (qx * e2z - e2x * qz) * inv
    v = (e1x * qz - qx * e1z) * inv
    y = ly[:, 0] + u * (ly[:, 1] - ly[:, 0]) + v * (ly[:, 2] - ly[:, 0])
    inside = good & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12)
    return np.where(inside, y, np.nan)


def _min3(a: np.ndarray) -> np.ndarray:
    return np.minimum(np.minimum(a[:, 0], a[:, 1]), a[:, 2])


def _max3(a: np.ndarray) -> np.ndarray:
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def _segment_max(keys: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Per-key maximum of `values` for sorted integer `keys`, as a dense array indexed by key (-inf elsewhere)."""
    out = np.full(int(keys.max()) + 1 if len(keys) else 0, -np.inf)
    if len(keys):
        start = np.flatnonzero(np.r_[True, keys[1:] != keys[:-1]])
        out[keys[start]] = np.maximum.reduceat(values, start)
    return out


def _candidates(lx, ly, lz, hx, hz, ax, az):
    """Candidate extreme points (R, 20) of each triangle over the rectangle |x| <= hx, |z| <= hz (local, centred on the
    pad): 3 vertices, 12 edge-side crossings, 4 corners and the axis point (ax, az) inside the triangle."""
    eps = 1e-12
    R = len(lx)
    px = np.empty((R, 20))
    pz = np.empty((R, 20))
    py = np.empty((R, 20))
    valid = np.zeros((R, 20), dtype=bool)
    px[:, :3], pz[:, :3], py[:, :3] = lx, lz, ly
    valid[:, :3] = (np.abs(lx) <= hx + eps) & (np.abs(lz) <= hz + eps)
    col = 3
    for i, j in ((0, 1), (1, 2), (2, 0)):
        xa, xb, za, zb, ya, yb = lx[:, i], lx[:, j], lz[:, i], lz[:, j], ly[:, i], ly[:, j]
        dx, dz = xb - xa, zb - za
        for X in (-hx, hx):
            s = (X - xa) / dx
            zz = za + s * dz
            px[:, col], pz[:, col], py[:, col] = X, zz, ya + s * (yb - ya)
            valid[:, col] = (np.abs(dx) > eps) & (s >= 0) & (s <= 1) & (np.abs(zz) <= hz + eps)
            col += 1
        for Z in (-hz, hz):
            s = (Z - za) / dz
            xx = xa + s * dx
            px[:, col], pz[:, col], py[:, col] = xx, Z, ya + s * (yb - ya)
            valid[:, col] = (np.abs(dz) > eps) & (s >= 0) & (s <= 1) & (np.abs(xx) <= hx + eps)
            col += 1
    # corners and the axis point, inside the triangle's x-z projection
    e1x, e1z = lx[:, 1] - lx[:, 0], lz[:, 1] - lz[:, 0]
    e2x, e2z = lx[:, 2] - lx[:, 0], lz[:, 2] - lz[:, 0]
    det = e1x * e2z - e2x * e1z
    good = np.abs(det) > 1e-18
    inv = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
    for X, Z in ((-hx, -hz), (hx, -hz), (hx, hz), (-hx, hz), (ax, az)):
        qx, qz = X - lx[:, 0], Z - lz[:, 0]
        u = (qx * e2z - e2x * qz) * inv
        v = (e1x * qz - qx * e1z) * inv
        px[:, col], pz[:, col] = X, Z
        py[:, col] = ly[:, 0] + u * (ly[:, 1] - ly[:, 0]) + v * (ly[:, 2] - ly[:, 0])
        valid[:, col] = good & (u >= -1e-12) & (v >= -1e-12) & (u + v <= 1 + 1e-12)
        col += 1
    py = np.where(valid, py, 0.0)
    return px, pz, py, valid
