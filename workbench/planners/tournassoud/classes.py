"""Grasp classes G_i and placement classes P_j (Tournassoud, Lozano-Perez & Mazer 1987, Sections 2 and 3).

A grasp class is a pair of features the two pads can hold (Section 2.1): (i) face/face, two parallel faces with
opposite outward normals whose projections overlap; (ii) face/edge, a face and a parallel feature edge whose
projection crosses it; (iii) face/vertex, a face and a convex vertex projecting inside it. Each class keeps its
grasp-plane normal n_i (the jaw axis, the outward normal of its face), the plane basis (u_i, v_i), the opening,
the grasp point C_i on the mid-plane between the contacts and its eccentricity e_i = n_i . (C_i - centre of mass).

The angle theta (Section 2.3) fixes the hand relative to the object: the TCP (CONVENTIONS.md) sits at C_i with its
y axis (jaw) along n_i and its approach axis z = cos(theta) u_i + sin(theta) v_i.

The paper leaves the grasp point open (Section 2.3, "as wide as possible"). Here it is chosen among a few
candidates inside the overlap of the contacts' projections (rasterised at about 1/200 of its size, >= 0.2 mm): for
face/face the overlap's centroid, its deepest point (farthest from its boundary) and the centroids of its largest
connected pieces; for face/edge the middles of the edge's pieces over the face and the quarter points of the
longest; for face/vertex the vertex's projection. The candidate with the widest legal theta range against
hand-object collision (Section 5.1) at a coarse step (1/24 turn) wins; ties go to the earlier candidate. When no
candidate is free at any coarse sample, the candidates are scanned again at `theta_step` (a narrow legal range is
still a legal range: the paper keeps every class whose range is non-empty). A class is dropped only when it is free
at no `theta_step` sample (any legal range it has is then narrower than the resolution) or, with the documented
parameter `min_range` > 0 (default 0: keep all), when its legal range is narrower than `min_range`. Legal theta
ranges are intervals found at `theta_step` and refined at their ends by bisection down to `bisection`.

One grasp point per feature pair is the paper's "reasonable approximation" (Section 2.3), which it says fails for
elongated parts; its remedy, "a discrete set of positions of the grasp point to represent them all, as is done in
Handey", is the parameter `points` (default 1, the paper's method): with `points` > 1 the overlap's candidates also
spread over it (farthest-point sampling among its cells at least half as deep as the deepest; the ends of an edge's
longest piece), and up to `points` of them become classes of the same feature pair (`features["point"]` = 0, 1,
...): first the one free at the most theta samples, then each adding the most theta samples not yet free at a kept
point (a point adding none is not kept). With `min_contact_area` > 0 the pad's
rectangle must also cover that much of the face overlap at each theta (Section 5.1's minimum contact area).

Placement classes are the stable faces of the convex hull (Section 3) with the roadmap planner's stability margin:
`workbench.placements.stable_placements`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from tqdm import tqdm

from workbench.params import DEG, Params, bounds, param
from workbench.geometry.collision import bvh, collide_at_poses, object_collider
from workbench.geometry.objects import ObjectModel
from workbench.planners.tournassoud.features import (
    Features,
    Raster,
    face_overlap,
    faces_of,
    features,
    grid_for,
    plane_basis,
    rasterise,
    segment_spans,
)
from workbench.robots.gripper import Gripper

KINDS = ("face/face", "face/edge", "face/vertex")


@dataclass(frozen=True)
class ClassParams(Params):
    """Parameters of the grasp classes (Sections 2 and 5.1); angles in radians, lengths in metres (ranges declared
    once here, shown by `workbench gptable --help`)."""

    min_face_area: float = param(2e-5, ge=0, le=1.0, unit="m^2", help="smallest planar face used by a class")
    edge_angle: float = param(np.radians(30.0), ge=0, le=np.pi, unit="rad", cli_scale=DEG, cli_unit="deg",
                              help="dihedral angle above which a mesh edge is a feature edge")
    parallel_tol: float = param(np.radians(2.0), ge=0, le=np.radians(45.0), unit="rad", cli_scale=DEG, cli_unit="deg",
                                help="angle within which two features count as parallel")
    theta_step: float = param(np.radians(5.0), gt=0, le=np.pi / 2, unit="rad", cli_scale=DEG, cli_unit="deg",
                              help="theta step (grasp angle resolution)")
    bisection: float = param(np.radians(0.1), gt=0, le=np.pi / 2, unit="rad", cli_scale=DEG, cli_unit="deg",
                             help="bisection resolution of a legal theta range's ends")
    tolerance: float = param(5e-4, ge=0, le=0.01, unit="m", help="hand-object collision tolerance")
    min_contact_area: float = param(0.0, ge=0, le=0.01, unit="m^2",
                                    help="pad area that must cover the face overlap at every legal theta (Section 5.1; 0: off)")
    candidates: int = param(5, ge=1, le=100, integer=True, help="grasp point candidates tried per class")
    min_overlap: float = param(1e-6, ge=0, le=1.0, unit="m^2", help="smallest face overlap of a face/face class")
    min_range: float = param(0.0, ge=0, le=2 * np.pi, unit="rad", cli_scale=DEG, cli_unit="deg",
                             help="narrowest legal theta range a class keeps (0, the paper's rule: any non-empty range)")
    points: int = param(1, ge=1, le=100, integer=True,
                        help="grasp points per feature pair (1: the paper's one point per class; more: its remedy for "
                             "elongated parts, a discrete set of points as in Handey, Section 2.3)")

    def check(self) -> None:
        self.require(self.bisection <= self.theta_step, ("bisection", "theta_step"),
                     "the bisection resolution must be at most the theta step")

    def as_dict(self) -> dict:
        return {k: float(v) if not isinstance(v, int) else v for k, v in asdict(self).items()}


@dataclass
class GraspClass:
    """One grasp class G_i (Section 2): kind, feature description, n_i, (u_i, v_i), C_i, e_i, opening and the legal
    theta intervals against hand-object collision (radians, [lo, hi] with lo in [0, 2 pi), hi may exceed 2 pi)."""

    kind: str
    features: dict
    normal: np.ndarray
    u: np.ndarray
    v: np.ndarray
    point: np.ndarray
    eccentricity: float
    opening: float
    intervals: list[tuple[float, float]] = field(default_factory=list)
    candidates: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def pose(self, theta: np.ndarray | float) -> np.ndarray:
        """TCP poses in the object frame at angles theta: (4, 4) for a scalar, else (N, 4, 4) (Section 2.3)."""
        return grasp_poses(self.normal, self.u, self.v, self.point, theta)

    @property
    def legal_range(self) -> float:
        return float(sum(b - a for a, b in self.intervals))

    def legal(self, theta: np.ndarray) -> np.ndarray:
        """Whether angles (any real values) lie in a legal interval."""
        t = np.mod(np.asarray(theta, dtype=np.float64), 2 * np.pi)
        out = np.zeros(t.shape, dtype=bool)
        for a, b in self.intervals:
            out |= ((t >= a) & (t <= b)) | ((t + 2 * np.pi >= a) & (t + 2 * np.pi <= b))
        return out


def grasp_poses(n: np.ndarray, u: np.ndarray, v: np.ndarray, c: np.ndarray, theta) -> np.ndarray:
    """TCP poses: y = n, z = cos(theta) u + sin(theta) v, x = y x z, origin c (Section 2.3)."""
    th = np.asarray(theta, dtype=np.float64)
    scalar = th.ndim == 0
    th = th.reshape(-1)
    z = np.cos(th)[:, None] * u + np.sin(th)[:, None] * v
    y = np.broadcast_to(n, z.shape)
    x = np.cross(y, z)
    out = np.zeros((len(th), 4, 4))
    out[:, :3, 0], out[:, :3, 1], out[:, :3, 2], out[:, :3, 3], out[:, 3, 3] = x, y, z, c, 1.0
    return out[0] if scalar else out


# -- candidate pairs of features -----------------------------------------------------------------------------------


def _project(points: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.stack((points @ u, points @ v), axis=-1)


def _pairs(feats: Features, opening: tuple[float, float], p: ClassParams) -> list[dict]:
    """Every feature pair of Section 2.1 with its normal, opening and candidate grasp points. The geometric filters
    (parallelism, opening, which side the contact faces) run on arrays over all edges and vertices per face."""
    cos_par = np.cos(p.parallel_tol)
    sin_par = np.sin(p.parallel_tol)
    jaw_min, jaw_max = opening
    out = []
    faces = feats.faces
    normals = np.array([f.normal for f in faces]).reshape(-1, 3)
    offsets = np.array([f.offset for f in faces])
    edges = feats.edges
    e0 = np.array([e.p0 for e in edges]).reshape(-1, 3)
    e1 = np.array([e.p1 for e in edges]).reshape(-1, 3)
    ed = e1 - e0
    elen = np.linalg.norm(ed, axis=1)
    en = np.array([e.normals for e in edges]).reshape(-1, 2, 3)
    verts = feats.vertices
    vp = np.array([v.point for v in verts]).reshape(-1, 3)
    vn = np.concatenate([v.normals for v in verts]) if verts else np.zeros((0, 3))
    vstart = np.concatenate([[0], np.cumsum([len(v.normals) for v in verts])[:-1]]).astype(np.int64) if verts else np.zeros(0, np.int64)
    for a, fa in enumerate(faces):
        n = fa.normal
        u, v = plane_basis(n)
        tri_a = _project(fa.triangles, u, v)
        # (i) face/face: opposite normals, the other face behind this one by an opening the gripper spans
        w_all = fa.offset + offsets
        ok = (normals @ n <= -cos_par) & (w_all >= max(jaw_min, 1e-9)) & (w_all <= jaw_max) & (np.arange(len(faces)) > a)
        for b in np.flatnonzero(ok):
            fb = faces[b]
            w = float(w_all[b])
            region = face_overlap(tri_a, _project(fb.triangles, u, v))
            if region is None or region.area < p.min_overlap:
                continue
            area = region.area
            cands = _face_candidates(region, max(p.candidates, 2 * p.points) if p.points > 1 else p.candidates, spread=p.points > 1)
            mid = fa.offset - w / 2
            pts = cands[:, :1] * u + cands[:, 1:] * v + mid * n
            out.append(dict(kind="face/face", features={"faces": [a, int(b)], "overlap": float(area)}, normal=n, u=u, v=v,
                            opening=w, candidates=pts, region=region, mid=mid))
        face_region: Raster | None = None

        def region_of_face(tri_a=tri_a) -> Raster:
            flat = tri_a.reshape(-1, 2)
            return rasterise(tri_a, *grid_for(flat.min(0), flat.max(0)))

        # (ii) face/edge: an edge parallel to the face, convex toward -n, at an opening the gripper spans
        if len(edges):
            dots = en @ n                                                       # (E, 2)
            w_e = fa.offset - ((e0 + e1) @ n) / 2
            ok = ((np.abs(ed @ n) <= sin_par * elen) & (dots < 1e-9).all(axis=1) & (dots < -1e-9).any(axis=1)
                  & (dots > -cos_par).all(axis=1) & (w_e >= max(jaw_min, 1e-9)) & (w_e <= jaw_max))
            for k in np.flatnonzero(ok):
                w = float(w_e[k])
                if face_region is None:
                    face_region = region_of_face()
                spans = segment_spans(_project(e0[k], u, v), _project(e1[k], u, v), face_region)
                length = sum(b_ - a_ for a_, b_ in spans) * float(elen[k])
                if length < 1e-4:
                    continue
                ss = [(a_ + b_) / 2 for a_, b_ in spans]
                lo, hi = max(spans, key=lambda sp: sp[1] - sp[0])
                ss += [lo + (hi - lo) / 4, lo + 3 * (hi - lo) / 4]
                if p.points > 1:  # spread along the longest piece too: its ends' neighbourhoods and its middle
                    ss += [lo + (hi - lo) * f for f in (0.1, 0.9)]
                pts = np.array([e0[k] + t * ed[k] + (w / 2) * n for t in ss[: max(p.candidates, 2 * p.points if p.points > 1 else 1)]])
                out.append(dict(kind="face/edge", features={"faces": [a], "edge": [e0[k].tolist(), e1[k].tolist()],
                                                            "length": length}, normal=n, u=u, v=v, opening=w,
                                candidates=pts, region=None, mid=fa.offset - w / 2))
        # (iii) face/vertex: a convex vertex pointing toward -n whose projection lies in the face
        if len(verts):
            d = vn @ n
            hi_d = np.maximum.reduceat(d, vstart)
            lo_d = np.minimum.reduceat(d, vstart)
            w_v = fa.offset - vp @ n
            ok = (hi_d < -1e-9) & (lo_d > -cos_par) & (w_v >= max(jaw_min, 1e-9)) & (w_v <= jaw_max)
            idx = np.flatnonzero(ok)
            if len(idx):
                if face_region is None:
                    face_region = region_of_face()
                inside = face_region.lookup(_project(vp[idx], u, v))
                for k in idx[inside]:
                    w = float(w_v[k])
                    out.append(dict(kind="face/vertex", features={"faces": [a], "vertex": vp[k].tolist()}, normal=n, u=u, v=v,
                                    opening=w, candidates=(vp[k] + (w / 2) * n)[None], region=None, mid=fa.offset - w / 2))
    return out


def _face_candidates(region: Raster, k: int, spread: bool = False) -> np.ndarray:
    """Grasp point candidates in an overlap region (2D): its centroid when inside, its deepest point (farthest from
    the boundary) and the centroids of its largest connected pieces; with `spread`, then points spread over the
    region (farthest-point sampling among the cells at least half as deep as the deepest), up to `k` in all."""
    from scipy import ndimage

    pts = region.points()
    out = []
    centroid = pts.mean(axis=0)
    if region.lookup(centroid[None])[0]:
        out.append(centroid)
    depth = ndimage.distance_transform_edt(np.pad(region.mask, 1))[1:-1, 1:-1]
    i, j = np.unravel_index(int(np.argmax(depth)), depth.shape)
    out.append(region.origin + (np.array([j, i]) + 0.5) * region.cell)
    labels, n = ndimage.label(region.mask)
    if n > 1:
        sizes = np.bincount(labels.ravel())[1:]
        for lab in np.argsort(-sizes, kind="stable")[: max(k - len(out), 0)] + 1:
            ii, jj = np.nonzero(labels == lab)
            out.append(region.origin + (np.array([jj.mean(), ii.mean()]) + 0.5) * region.cell)
    if spread and len(out) < k:
        ii, jj = np.nonzero(depth >= 0.5 * depth.max())
        deep = region.origin + (np.stack([jj, ii], axis=1) + 0.5) * region.cell
        dist = np.min(np.linalg.norm(deep[:, None] - np.array(out)[None], axis=2), axis=1)
        while len(out) < k and dist.max() > 2 * region.cell:
            far = deep[int(np.argmax(dist))]
            out.append(far)
            dist = np.minimum(dist, np.linalg.norm(deep - far, axis=1))
    uniq = []
    for c in out:
        if all(np.linalg.norm(c - d) > 1e-6 for d in uniq):
            uniq.append(c)
    return np.array(uniq[:k])


# -- legal theta ranges (Section 5.1) -------------------------------------------------------------------------------


class HandObject:
    """Hand-object collision of the gripper at a class's opening (+ tolerance) against the object mesh
    (`geometry.collision`: python-fcl BVHs, one per opening rounded up to 0.1 mm)."""

    def __init__(self, obj: ObjectModel, gripper: Gripper, tolerance: float):
        from scipy.spatial import cKDTree

        self.target = object_collider(obj.mesh)
        self.gripper, self.tol = gripper, tolerance
        self._geom: dict[float, object] = {}
        self.vertices = np.asarray(obj.mesh.vertices, dtype=np.float64)
        self.tree = cKDTree(self.vertices)
        ext, centre = gripper.pad_extents, gripper.pad_center
        # the disc about the TCP's y axis that a pad covers at every theta, and the pad's thickness along y
        self.disc = float(min(ext[0], ext[2]) / 2 - np.hypot(centre[0], centre[2]))
        self.thick = float(ext[1])

    def blocked_everywhere(self, cls: dict, points: np.ndarray) -> np.ndarray:
        """(K,) bool: an object vertex lies strictly inside a pad at grasp point points[k] for every theta (inside the
        disc both pads cover whatever theta, between their inner and outer faces), so the point is blocked at every
        angle without asking fcl (a cheap pre-test; the object surface through that vertex crosses the pad)."""
        out = np.zeros(len(points), dtype=bool)
        if self.disc <= 0:
            return out
        n = cls["normal"]
        inner = cls["opening"] / 2 + self.tol
        outer = inner + self.thick
        for k, c in enumerate(points):
            near = self.tree.query_ball_point(c, float(np.hypot(self.disc, outer)))
            if not near:
                continue
            d = self.vertices[near] - c
            y = d @ n
            rho2 = (d * d).sum(axis=1) - y * y
            out[k] = bool(((rho2 < (self.disc - 1e-7) ** 2) & (np.abs(y) > inner + 1e-7) & (np.abs(y) < outer - 1e-7)).any())
        return out

    def geometry(self, opening: float) -> object:
        """The hand with its pads `tolerance` clear of both contacts, widths rounded up to 0.1 mm (shared BVHs)."""
        key = float(np.ceil((opening + 2 * self.tol) * 1e4) / 1e4)
        if key not in self._geom:
            self._geom[key] = bvh(self.gripper.collision_mesh(min(key, self.gripper.jaw_max)))
        return self._geom[key]

    def free(self, cls: dict, point: np.ndarray, theta: np.ndarray) -> np.ndarray:
        poses = grasp_poses(cls["normal"], cls["u"], cls["v"], point, theta)
        return ~collide_at_poses(self.geometry(cls["opening"]), poses, self.target)


def _intervals(free: np.ndarray, theta: np.ndarray, step: float, test, resolution: float) -> list[tuple[float, float]]:
    """Circular runs of free samples as intervals whose ends are refined by bisection toward the blocked neighbours."""
    n = len(free)
    if free.all():
        return [(0.0, 2 * np.pi)]
    if not free.any():
        return []
    start = int(np.argmin(free))  # a blocked sample: runs do not wrap past it
    out = []
    k = 0
    while k < n:
        i = (start + k) % n
        if free[i]:
            j = k
            while j + 1 < n and free[(start + j + 1) % n]:
                j += 1
            lo_free, hi_free = theta[i], theta[i] + (j - k) * step
            out.append((_bisect(lo_free, lo_free - step, test, resolution), _bisect(hi_free, hi_free + step, test, resolution)))
            k = j + 1
        else:
            k += 1
    norm = []
    for a, b in out:
        shift = np.floor(a / (2 * np.pi)) * 2 * np.pi
        norm.append((float(a - shift), float(b - shift)))
    return sorted(norm)


def _bisect(good: float, bad: float, test, resolution: float) -> float:
    while abs(bad - good) > resolution:
        mid = (good + bad) / 2
        if test(np.array([mid]))[0]:
            good = mid
        else:
            bad = mid
    return good


def select_point(cands: np.ndarray, test, theta: np.ndarray, coarse: np.ndarray,
                 resolution: float) -> tuple[np.ndarray, list[tuple[float, float]]] | None:
    """The grasp point among `cands` with the widest legal theta range and its legal intervals (Sections 2.3, 5.1):
    `test(theta, point=c)` says which angles are free. Candidates are compared at the `coarse` samples (stopping at
    one free at all of them); when none is free at any coarse sample they are compared again at every sample of
    `theta`, so a range narrower than the coarse step is kept. None when no candidate is free at any `theta` sample."""
    best_k, best_free = 0, 0
    for grid_ in (coarse, theta[~np.isin(theta, coarse)]):
        for k, c in enumerate(cands):
            n_free = int(test(grid_, point=c).sum())
            if n_free > best_free:
                best_k, best_free = k, n_free
            if n_free == len(grid_):
                break
        if best_free:
            break
    if best_free == 0:
        return None
    point = cands[best_k]
    free = test(theta, point=point)
    if not free.any():
        return None
    step = float(theta[1] - theta[0]) if len(theta) > 1 else 2 * np.pi
    return point, _intervals(free, theta, step, lambda t: test(t, point=point), resolution)


def select_points(cands: np.ndarray, test, theta: np.ndarray, resolution: float,
                  points: int) -> list[tuple[np.ndarray, list[tuple[float, float]]]]:
    """Up to `points` grasp points among `cands` for one feature pair (Section 2.3: "a discrete set of positions of
    the grasp point to represent them all, as is done in Handey"): the candidate free at the most `theta` samples,
    then greedily the candidate adding the most samples not yet free at a kept point (at least one), each with its
    legal intervals."""
    free = np.array([test(theta, point=c) for c in cands]).reshape(len(cands), len(theta))
    covered = np.zeros(len(theta), dtype=bool)
    step = float(theta[1] - theta[0]) if len(theta) > 1 else 2 * np.pi
    out = []
    while len(out) < points:
        gain = (free & ~covered).sum(axis=1)
        k = int(np.argmax(gain))
        if gain[k] == 0:
            break
        covered |= free[k]
        c = cands[k]
        out.append((c, _intervals(free[k], theta, step, lambda t, c=c: test(t, point=c), resolution)))
    return out


def no_class_reason(obj: ObjectModel, gripper: Gripper, params: ClassParams = ClassParams()) -> str:
    """Why `obj` has no grasp class, and what to try (Section 2.1: classes pair planar faces with parallel features)."""
    faces = faces_of(obj.mesh, params.min_face_area)
    area = f"{params.min_face_area * 1e6:.3g} mm^2"
    if len(faces) < 2:
        planar = sorted((float(obj.mesh.area_faces[f].sum()) for f in obj.mesh.facets), reverse=True)
        if len(planar) >= 2 and planar[1] < params.min_face_area:  # planar faces there are, only smaller
            bound = bounds(ClassParams)["min_face_area"][0]
            digits = 1 - int(np.floor(np.log10(planar[1])))
            keep = np.floor(planar[1] * 0.999 * 10**digits) / 10**digits  # two digits, safely below the face's area
            return (f"{obj.name} has {len(faces)} planar face(s) of at least {area}, and a grasp class needs a planar face "
                    f"opposite a parallel feature; its two largest are {planar[0] * 1e6:.4g} and {planar[1] * 1e6:.4g} "
                    f"mm^2: --min-face-area {keep:g} keeps them ({bound.describe(True)})")
        return (f"{obj.name} has {len(faces)} planar face(s) of at least {area} (a curved or scanned surface), and a "
                f"grasp class needs a planar face opposite a parallel feature; plan its regrasps with `workbench build` "
                f"and `workbench plan` (Wan & Harada), or lower --min-face-area")
    return (f"the gripper (jaw {gripper.jaw_max * 1000:.0f} mm) spans no pair of parallel features of {obj.name} "
            f"({len(faces)} planar faces of at least {area}); check the scale or lower --min-face-area")


def grasp_classes(obj: ObjectModel, gripper: Gripper, params: ClassParams = ClassParams(),
                  progress: bool = False, dropped: list[GraspClass] | None = None) -> list[GraspClass]:
    """The grasp classes of `obj` for `gripper` with their grasp points and legal theta intervals (Sections 2, 5.1).

    Classes whose legal theta range is empty are dropped. With `params.min_range` > 0, classes narrower than it are
    dropped too and appended to `dropped` (for the caller's warning and count); with 0 (the default, the paper's
    rule) every class of any width is kept."""
    feats = features(obj.mesh, params.min_face_area, params.edge_angle)
    pairs = _pairs(feats, (gripper.jaw_min, gripper.jaw_max - 2 * params.tolerance), params)
    hand = HandObject(obj, gripper, params.tolerance)
    step = params.theta_step
    theta = np.arange(int(round(2 * np.pi / step))) * (2 * np.pi / round(2 * np.pi / step))
    step = float(theta[1] - theta[0]) if len(theta) > 1 else 2 * np.pi
    out = []
    coarse = theta[:: max(len(theta) // 24, 1)]
    for cls in tqdm(pairs, desc="grasp classes", unit="pair", disable=not progress, leave=False):

        def test(t, cls=cls, point=None):
            ok = hand.free(cls, point, t)
            if params.min_contact_area > 0 and cls["region"] is not None:
                ok &= _contact_area(cls, point, t, gripper) >= params.min_contact_area
            return ok

        cands = cls["candidates"][~hand.blocked_everywhere(cls, cls["candidates"])]
        if not len(cands):
            continue
        if params.points > 1:
            picked = select_points(cands, test, theta, params.bisection, params.points)
        else:
            one = select_point(cands, test, theta, coarse, params.bisection)
            picked = [] if one is None else [one]
        n, u, v = cls["normal"], cls["u"], cls["v"]
        for k, (point, intervals) in enumerate(picked):
            feats = cls["features"] if params.points == 1 else {**cls["features"], "point": k}
            g = GraspClass(kind=cls["kind"], features=feats, normal=n.copy(), u=u, v=v, point=point.copy(),
                           eccentricity=float(n @ (point - obj.com)), opening=float(cls["opening"]),
                           intervals=intervals, candidates=cls["candidates"])
            if params.min_range > 0 and g.legal_range < params.min_range:
                if dropped is not None:
                    dropped.append(g)
                continue
            out.append(g)
    order = sorted(range(len(out)), key=lambda i: (KINDS.index(out[i].kind), -out[i].legal_range))
    return [out[i] for i in order]


def _contact_area(cls: dict, point: np.ndarray, theta: np.ndarray, gripper: Gripper) -> np.ndarray:
    """Area of the face overlap covered by the pad rectangle rotated by theta in the grasp plane (Section 5.1)."""
    ext, centre = gripper.pad_extents, gripper.pad_center
    region: Raster = cls["region"]
    rel = region.points() - np.array([point @ cls["u"], point @ cls["v"]])
    th = np.asarray(theta, dtype=np.float64).reshape(-1, 1)
    along = rel[:, 0] * np.cos(th) + rel[:, 1] * np.sin(th)     # approach z in the plane
    across = -rel[:, 0] * np.sin(th) + rel[:, 1] * np.cos(th)   # TCP x = n x z (u x v = n)
    inside = (np.abs(along - centre[2]) <= ext[2] / 2) & (np.abs(across - centre[0]) <= ext[0] / 2)
    return inside.sum(axis=1) * region.cell ** 2
