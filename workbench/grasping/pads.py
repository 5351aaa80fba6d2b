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
touches only what lies between its start and the TCP. `gap_windows` checks only the axis line; a pad whose starting
plane cuts the part anywhere inside its footprint starts inside the material and touches nothing (else it would
"touch" the material past its start, and a finger that is its pad would sit inside the part at the grasp).
`grasps.gap_touches` then tries such a pad from the narrower pre-grasp window `gap_windows` also gives, and
`pregrasp_touches` searches each grasp found again from its own pre-grasp opening about its TCP, so its touches
are what the pads meet as the hand closes from the opening it approached at. The hand at its pre-grasp opening is
checked against the object afterwards (level 2).

The work runs in a compiled kernel (`_padkernel`) over a bounding-volume hierarchy of the triangles: each pad
searches it by branch and bound for all the hand's rotations about an axis at once, skipping every subtree outside
a rotation's footprint or below its best touch found so far, so the cost follows the triangles near the first
touches, not the mesh, and the nodes near the axis that every rotation needs are opened once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import trimesh

from workbench.grasping._padkernel import first_touch_kernel, line_crossings, triangle_bvh
from workbench.geometry.vectors import cross
from workbench.grasping.memo import remembered
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


def pad_offsets(poses: np.ndarray, contacts: np.ndarray, gripper: Gripper) -> np.ndarray:
    """Where each contact lies on its pad: its offset (G, 2) from the pad's centre along the TCP's x and z, as a
    fraction of the pad's half size (0 at the centre, 1 on an edge). `contacts` (G, 3) in the frame of the TCP
    `poses` (G, 4, 4)."""
    cx, cz, hx, hz = pad_rectangle(gripper)
    rel = np.einsum("gji,gj->gi", poses[:, :3, :3], contacts - poses[:, :3, 3])
    return np.column_stack([(rel[:, 0] - cx) / hx, (rel[:, 2] - cz) / hz])


def edge_share(poses: np.ndarray, contact0: np.ndarray, contact1: np.ndarray, gripper: Gripper,
               within: float = 0.05) -> float:
    """The share of contacts (both pads of every grasp) within `within` of their pad's half size from its edge."""
    if len(poses) == 0:
        return 0.0
    off = np.vstack([pad_offsets(poses, contact0, gripper), pad_offsets(poses, contact1, gripper)])
    return float((np.abs(off).max(axis=1) >= 1 - within).mean())


def axis_frames(origins: np.ndarray, axes: np.ndarray, angles: np.ndarray, ref: np.ndarray | None = None) -> np.ndarray:
    """TCP frames (K * A, 4, 4): origin on the axis, y along it, approach z = the reference z0 (the world axis least
    aligned with y, made perpendicular) rotated by +angle about y (right-handed, the stored rotation), axis-major.
    `ref` (K, 3), when given, replaces the world axis as each axis's reference (it must not be parallel to y)."""
    y = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    if ref is None:
        ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    z0 = ref - np.einsum("ij,ij->i", ref, y)[:, None] * y
    z0 /= np.linalg.norm(z0, axis=1, keepdims=True)
    x0 = cross(y, z0)
    c, s = np.cos(angles)[None, :, None], np.sin(angles)[None, :, None]
    z = c * z0[:, None, :] + s * x0[:, None, :]  # R_y(angle) z0 = cos z0 + sin (y x z0)
    yy = np.broadcast_to(y[:, None, :], z.shape)
    poses = np.zeros((len(y), len(angles), 4, 4))
    poses[..., :3, 0], poses[..., :3, 1], poses[..., :3, 2] = cross(yy, z), yy, z
    poses[..., :3, 3] = origins[:, None, :]
    poses[..., 3, 3] = 1.0
    return poses.reshape(-1, 4, 4)


def fingertip_shifts(vertices: np.ndarray, poses: np.ndarray, gripper: Gripper, margin: float,
                     min_contact: float = 1e-3, slack: float = 0.0) -> np.ndarray:
    """How far to move each TCP back along its approach so the fingertips end `margin` short of the part's far side
    along it (H,), NaN where no shift is needed or possible.

    With the TCP at the pad's centre, a part thinner than half a pad beyond the contact (a washer or a bracket
    lying flat, gripped from above) leaves the fingertips poking past it, into the table in every placement with
    that side down. Moving the hand back by d = (pad tip) - (extent) + margin puts the pad's tip `margin` short of
    the far side; it is possible while the pad still covers at least `min_contact` of the part along the approach
    (the pads then close on what lies there: the jaw axis may leave the part, as across a 5 mm washer). `vertices`:
    the part's convex hull vertices (the extent along a direction is a hull vertex's); `poses` (H, 4, 4) TCP poses
    in the part's frame. `slack` (m) widens both conditions, for a conservative answer from poses whose TCPs lie
    elsewhere along their jaw axes (then from matrix products, whose rounding the slack covers).
    """
    _, cz, _, hz = pad_rectangle(gripper)
    tip = cz + hz
    z = poses[:, :3, 2]
    at = np.einsum("hj,hj->h", z, poses[:, :3, 3])
    far, near = _extents(z, vertices, _PAIRS if slack <= 0 else 0)
    extent, near = far - at, near - at  # the far and the near side, from the TCP along the approach
    d = tip - extent + margin
    covered = (extent - margin) - np.maximum(near, tip - 2 * hz - d)  # the part's span along the pad, once moved
    return np.where((d > -slack) & (covered >= min_contact - slack), d, np.nan)


_PAIRS = 10_000_000  # direction-vertex pairs in one product of `_extents`


def _extents(directions: np.ndarray, vertices: np.ndarray, dense: int = _PAIRS) -> tuple[np.ndarray, np.ndarray]:
    """The largest and smallest extents (H,), (H,) of `vertices` (V, 3) along each direction (H, 3), from one product
    of the two. Above `dense` direction-vertex pairs (a full-resolution scan's hull) as matrix products (BLAS: faster,
    rounded otherwise) in blocks of about `_PAIRS` pairs."""
    if len(directions) * len(vertices) <= dense:
        d = np.einsum("hj,vj->hv", directions, vertices)
        return d.max(axis=1), d.min(axis=1)
    step = max(1, _PAIRS // max(len(vertices), 1))
    hi, lo = np.empty(len(directions)), np.empty(len(directions))
    for i in range(0, len(directions), step):
        d = directions[i:i + step] @ vertices.T
        hi[i:i + step], lo[i:i + step] = d.max(axis=1), d.min(axis=1)
    return hi, lo


def first_touches(mesh: trimesh.Trimesh, origins: np.ndarray, axes: np.ndarray, angles: np.ndarray,
                  gripper: Gripper, tie: float = 1e-6, ref: np.ndarray | None = None,
                  windows: np.ndarray | None = None, block: float | None = 0.0, cone: float | None = None,
                  need: np.ndarray | None = None, lift: float = 0.0) -> Touches:
    """First touches of both pads closing along each axis at each hand rotation (CONVENTIONS.md, Gripper); `ref`
    as in `axis_frames` (rotation 0 approaching along it); `windows` (K, 2), heights along each axis from its origin:
    the right pad starts at the first and touches nothing below it, the left at the second (None: from outside).
    `block` (m): a pad whose start's plane, moved `block` beyond it (the intrusion tolerated), cuts the part inside
    its footprint starts inside it and touches nothing (None: it touches what lies past its start, a candidate for
    `pregrasp_touches`). `cone` (the cosine of the friction cone's half-angle; None: off): a pose whose left touch's
    normal lies outside the cone about +y cannot be a grasp, and its right pad is not searched (a miss, `tri0` kept)
    unless `need` (H,) names it or the touch lies less than `lift` (m) below the left pad's start (a search from a
    start up to `lift` higher may find another touch)."""
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    axes = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.asarray(angles, dtype=np.float64)
    if windows is None:
        windows = np.tile([-np.inf, np.inf], (len(origins), 1))
    windows = np.asarray(windows, dtype=np.float64).reshape(-1, 2)
    need = np.zeros((len(origins), len(angles)), dtype=bool) if need is None else \
        np.asarray(need, dtype=bool).reshape(len(origins), len(angles))
    frames = axis_frames(origins, axes, angles, ref)
    # the reference frames (rotation 0): the kernel turns every triangle into each rotation's pad coordinates from them
    fr0 = frames[::len(angles)] if len(angles) and angles[0] == 0 else axis_frames(origins, axes, np.zeros(1), ref)
    with np.errstate(divide="ignore", invalid="ignore"):
        return _touches(mesh, origins, frames, fr0, angles, gripper, tie, windows, block,
                        -2.0 if cone is None else float(cone), float(lift), need)


PREGRASP_TOL = 1e-6  # m: a pre-grasp search that moves a touch by more is not a hit (`pregrasp_touches`)


def pregrasp_touches(mesh: trimesh.Trimesh, touch: Touches, gripper: Gripper, margin: float | None,
                     clearance: float = 0.0, tol: float = PREGRASP_TOL,
                     wanted: Callable[[Touches], np.ndarray] | None = None, cone: float | None = None) -> Touches:
    """The touches of `touch`'s hand poses closing from their own pre-grasp opening (the width plus `margin`, at
    most the stroke; full opening when None) about their TCPs (CONVENTIONS.md, Gripper), with the starts clear of the
    part inside the pads' footprints but for `clearance` (the hand's tolerated intrusion). A pad that started inside
    a hole at full opening may have passed over material that the pad starting at the pre-grasp opening meets: its
    touch moves there. Searched twice; a pose whose second search moves by more than `tol` is not a hit. `wanted`
    (touches -> mask), when given, names the poses of the first search worth the second (those whose contacts pass
    the later filters); the others keep the first search's touches, which those filters remove. `cone` as in
    `first_touches`, for the first search: a pose outside it is no grasp whatever the second finds."""
    once = _from_pregrasp(mesh, touch, gripper, margin, clearance, tol, cone)
    # a pose the first search missed stays a miss: only the others are searched again
    live = np.flatnonzero(once.hit & (True if wanted is None else wanted(once)))
    once_live = Touches(**{f: getattr(once, f)[live] for f in Touches.__dataclass_fields__})
    twice = _from_pregrasp(mesh, once_live, gripper, margin, clearance, tol)
    same = np.ones(len(once), dtype=bool)
    with np.errstate(invalid="ignore"):  # misses carry infinite widths
        same[live] = (twice.hit & (np.abs(twice.width - once_live.width) <= tol)
                      & (np.linalg.norm(twice.poses[:, :3, 3] - once_live.poses[:, :3, 3], axis=1) <= tol))
    return Touches(**{**{f: getattr(once, f) for f in Touches.__dataclass_fields__}, "hit": once.hit & same})


def _from_pregrasp(mesh, touch: Touches, gripper: Gripper, margin: float | None, clearance: float,
                   tol: float, cone: float | None = None) -> Touches:
    poses = touch.poses
    width = np.where(touch.hit, touch.width, 0.0)
    half = (np.full(len(poses), gripper.jaw_max) if margin is None else np.minimum(width + margin, gripper.jaw_max)) / 2
    again = first_touches(mesh, poses[:, :3, 3], poses[:, :3, 1], np.zeros(1), gripper, ref=poses[:, :3, 2],
                          windows=np.column_stack([-half - tol, half + tol]), block=clearance, cone=cone)
    return Touches(**{**{f: getattr(again, f) for f in Touches.__dataclass_fields__},
                      "hit": again.hit & touch.hit & (again.width <= gripper.jaw_max)})


def gap_windows(mesh: trimesh.Trimesh, origins: np.ndarray, axes: np.ndarray, jaw_max: float,
                margin: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pad starts inside a hole or cavity for jaw axes through surface points `origins` (K, 3) along their outward
    normals `axes` (K, 3): (axis index (W,), window (W, 2), narrow window (W, 2)) for `first_touches`.

    Along the axis line, the left pad touches the origin's surface and the right pad a surface below it facing down
    (any surface on an open mesh) at most `jaw_max` away; with the TCP midway, the pads start `jaw_max` / 2 either
    side of it (full opening), or, where the line leaves no room for that and `margin` is given, at the pre-grasp
    opening: `margin` wider than the span between the two crossings, at most `jaw_max` (CONVENTIONS.md, Gripper:
    the hand approaches at the pre-grasp opening). Each start must leave the line clear up to its touch. The windows
    where both starts lie outside the part along the line are the ordinary grasp from outside and are not returned.
    The narrow window is that pre-grasp window where the full opening was returned and the pre-grasp one is narrower
    and leaves the line clear too (NaN elsewhere): where the open pads start inside the part off the line, the pads
    at the pre-grasp opening may not.
    """
    origins = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    axes = np.asarray(axes, dtype=np.float64).reshape(-1, 3)
    reach = 1.1 * float(np.linalg.norm(mesh.extents)) + 1e-3
    start = origins + reach * axes  # beyond the part: every crossing of the line is at a height below `reach`
    shape, slots, leaf, tri_s, _ = triangle_tree(mesh)
    ray, tri, along = line_crossings(shape, slots, leaf, tri_s, np.ascontiguousarray(start),
                                     np.ascontiguousarray(-axes))
    if len(ray) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2))
    # heights along the axis from the origin, on the crossed triangle's plane
    tn = mesh.face_normals[tri]
    a = axes[ray]
    corner = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[tri, 0]]  # plain arrays: trimesh's would rehash
    t = np.einsum("ij,ij->i", corner - start[ray], tn) / np.einsum("ij,ij->i", -a, tn)
    h = reach - np.where(np.isfinite(t), t, along)
    down = np.einsum("ij,ij->i", tn, a) < 0 if mesh.is_watertight else np.ones(len(h), dtype=bool)
    # every crossing, grouped by axis and in descending height along it; a line through an edge or a corner crosses
    # every triangle there: one crossing per height and side
    order = np.lexsort((tri, -h, ray))
    ray, h, down = ray[order], h[order], down[order]
    again = np.r_[False, (ray[1:] == ray[:-1]) & (h[:-1] - h[1:] <= 1e-9 * reach) & (down[1:] == down[:-1])]
    ray, h, down = ray[~again], h[~again], down[~again]
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
    base = (hit_origin[group] & (np.arange(n) > top[group]) & down & (span > eps) & (span <= jaw_max)
            & ~(np.isinf(ceiling) & np.isinf(floor)))  # not both outside the part: the ordinary grasp
    ok = base & (hi < ceiling - eps) & (lo > floor + eps)  # both starts in free space along the line
    narrow = np.full((n, 2), np.nan)
    if margin is not None:
        # where the line leaves no room for the open jaw, the pre-grasp opening; the opening from the crossings
        # on the line, not from the touches off it, so where the open jaw fits it stays (its touches may lie higher)
        half = np.minimum(span + margin, jaw_max) / 2
        fits = base & (mid + half < ceiling - eps) & (mid - half > floor + eps)
        pre = fits & ~ok
        both = ok & fits & (half < jaw_max / 2)
        narrow[both] = np.column_stack([mid - half, mid + half])[both]
        lo, hi = np.where(pre, mid - half, lo), np.where(pre, mid + half, hi)
        ok |= pre
    j = np.flatnonzero(ok)
    return ray[j].astype(np.int64), np.column_stack([lo[j], hi[j]]), narrow[j]


def line_surface_points(mesh: trimesh.Trimesh, points: np.ndarray, directions: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the lines through `points` (K, 3) along unit `directions` (K, 3) cross the surface: (line (C,), crossing
    (C, 3), the line's direction turned to the side the surface faces (C, 3)), line-major in order along each line;
    one crossing per line and height where the line passes through an edge or a corner. The crossings and these
    directions are surface points and outward axes for `gap_windows`."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    directions = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    off = float(np.abs(points - mesh.bounds.mean(axis=0)).max(initial=0.0))  # how far the points lie from the part
    reach = 1.1 * float(np.linalg.norm(mesh.extents)) + 1e-3 + off
    start = np.ascontiguousarray(points - reach * directions)
    shape, slots, leaf, tri_s, _ = triangle_tree(mesh)
    ray, tri, along = line_crossings(shape, slots, leaf, tri_s, start, np.ascontiguousarray(directions))
    facing = np.einsum("ij,ij->i", mesh.face_normals[tri], directions[ray])
    order = np.lexsort((tri, along, ray))
    ray, tri, along, facing = ray[order], tri[order], along[order], facing[order]
    again = np.r_[False, (ray[1:] == ray[:-1]) & (along[1:] - along[:-1] <= 1e-9 * reach)
                  & (np.sign(facing[1:]) == np.sign(facing[:-1]))]
    keep = ~again & (facing != 0)
    ray, along, facing = ray[keep], along[keep], facing[keep]
    return ray, start[ray] + along[:, None] * directions[ray], np.sign(facing)[:, None] * directions[ray]


def _touches(mesh, origins, frames, fr0, angles, gripper, tie, windows, block: float | None, cone: float,
             lift: float, need: np.ndarray) -> Touches:
    fn = np.ascontiguousarray(mesh.face_normals, dtype=np.float64)
    flip = not mesh.is_watertight
    rect = np.array(pad_rectangle(gripper))
    tree = triangle_tree(mesh)
    basis = np.ascontiguousarray(np.transpose(fr0[:, :3, :3], (0, 2, 1)))  # rows: x0, y, z0
    origins, angles, windows = (np.ascontiguousarray(a) for a in (origins, angles, windows))
    tie, jaw, block = float(tie), float(gripper.jaw_max), -1.0 if block is None else float(block)
    K, A = len(origins), len(angles)

    def rows(k: np.ndarray) -> tuple[np.ndarray, ...]:
        out = first_touch_kernel(*tree, flip, origins[k], basis[k], angles, rect, tie, windows[k], jaw, block, cone,
                                 lift, need[k])
        return tuple(a.reshape(len(k), A, *a.shape[1:]) for a in out)

    # a jaw axis's rows follow from its origin, basis, window and needed rotations alone: those seen before come
    # from the part's memo
    constants = np.concatenate([[float(flip), tie, jaw, block, cone, lift], rect, angles]).tobytes()
    found, height, local, tri_id = (a.reshape(K * A, *a.shape[2:]) for a in remembered(
        mesh, "first_touches", constants, np.hstack([origins, basis.reshape(K, 9), windows, need]), rows))
    hit = found.all(axis=1)
    res = {}
    for si, side in enumerate((1, -1)):
        pts = frames[:, :3, 3] + np.einsum("hij,hj->hi", frames[:, :3, :3], local[:, si])
        n = fn[np.maximum(tri_id[:, si], 0)]
        if flip:
            n = n * np.where(side * np.einsum("hj,hj->h", n, frames[:, :3, 1]) < 0, -1.0, 1.0)[:, None]
        res[side] = (height[:, si], pts, n, tri_id[:, si])
    poses = frames.copy()
    mid = np.where(hit, 0.5 * (res[1][0] + res[-1][0]), 0.0)
    poses[:, :3, 3] += poses[:, :3, 1] * mid[:, None]
    width = np.where(hit, res[1][0] - res[-1][0], np.inf)
    window = np.repeat(windows, len(angles), axis=0) - mid[:, None]
    return Touches(poses=poses, width=width, hit=hit, point0=res[1][1], normal0=res[1][2], tri0=res[1][3],
                   point1=res[-1][1], normal1=res[-1][2], tri1=res[-1][3], window=window)


def triangle_tree(mesh: trimesh.Trimesh) -> tuple:
    """The triangle hierarchy of `mesh` (`_padkernel.triangle_bvh`), built once per mesh: the pads' first touches and
    the hand's collision checks (`grasps.hand_hits`) share it."""
    tree = mesh._cache["workbench_pad_bvh"]  # trimesh's cache: dropped when the mesh changes
    if tree is None:
        tree = mesh._cache["workbench_pad_bvh"] = triangle_bvh(mesh.vertices.view(np.ndarray),
                                                               mesh.faces.view(np.ndarray), mesh.face_normals)
    return tree
