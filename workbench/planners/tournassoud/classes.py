"""Grasp classes G_i and placement classes P_j (Tournassoud, Lozano-Perez & Mazer 1987, Sections 2 and 3).

A grasp class is a pair of features the two pads can hold (Section 2.1): (i) face/face, two parallel faces with
opposite outward normals whose projections overlap; (ii) face/edge, a face and a parallel feature edge whose
projection crosses it; (iii) face/vertex, a face and a convex vertex projecting inside it. Each class keeps its
grasp-plane normal n_i (the jaw axis, the outward normal of its face), the plane basis (u_i, v_i), the opening,
the grasp point C_i on the mid-plane between the contacts and its eccentricity e_i = n_i . (C_i - centre of mass).

The angle theta (Section 2.3) fixes the hand relative to the object: the TCP (CONVENTIONS.md) sits at C_i with its
y axis (jaw) along n_i and its approach axis z = cos(theta) u_i + sin(theta) v_i.

The paper leaves the grasp point open (Section 2.3, "as wide as possible"). Here it is chosen among a few
candidates inside the overlap of the contacts' projections: for face/face the overlap's centroid and the centroids
of its largest convex pieces, for face/edge the middles of the edge's pieces over the face and the quarter points
of the longest, for face/vertex the vertex's projection. The candidate with the widest legal theta range against
hand-object collision (Section 5.1) wins; ties go to the earlier candidate. Legal theta ranges are intervals found
at `theta_step` and refined at their ends by bisection down to `bisection`. With `min_contact_area` > 0 the pad's
rectangle must also cover that much of the face overlap at each theta (Section 5.1's minimum contact area).

Placement classes are the stable faces of the convex hull (Section 3) with the roadmap planner's stability margin:
`workbench.placements.stable_placements`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import fcl
import numpy as np

from ...collision import bvh, collide_at_poses, object_collider
from ...errors import WorkbenchError
from ...gripper import Gripper
from ...objects import ObjectModel
from .features import (Features, area2d, ccw, centroid2d, clip_convex, clip_segment, features, in_triangles,
                       plane_basis)

KINDS = ("face/face", "face/edge", "face/vertex")


@dataclass(frozen=True)
class ClassParams:
    """Parameters of the grasp classes (Sections 2 and 5.1); angles in radians, lengths in metres."""

    min_face_area: float = 2e-5
    edge_angle: float = np.radians(30.0)
    parallel_tol: float = np.radians(2.0)
    theta_step: float = np.radians(5.0)
    bisection: float = np.radians(0.1)
    tolerance: float = 5e-4
    min_contact_area: float = 0.0
    candidates: int = 5
    min_overlap: float = 1e-6

    def __post_init__(self) -> None:
        if not (0 < self.theta_step <= np.pi / 2):
            raise WorkbenchError(f"theta step must be in (0, 90] degrees, got {np.degrees(self.theta_step):g}")
        if not (0 < self.bisection <= self.theta_step):
            raise WorkbenchError("bisection resolution must be positive and at most the theta step")
        if min(self.min_face_area, self.tolerance, self.min_contact_area, self.min_overlap) < 0 or self.candidates < 1:
            raise WorkbenchError(f"grasp class parameters must be non-negative (and candidates >= 1), got {self}")

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
    """Every feature pair of Section 2.1 with its normal, opening and candidate grasp points."""
    cos_par = np.cos(p.parallel_tol)
    sin_par = np.sin(p.parallel_tol)
    jaw_min, jaw_max = opening
    out = []
    faces = feats.faces
    normals = np.array([f.normal for f in faces]).reshape(-1, 3)
    for a, fa in enumerate(faces):
        n = fa.normal
        u, v = plane_basis(n)
        tri_a = _project(fa.triangles, u, v)
        # (i) face/face
        for b in range(a + 1, len(faces)):
            fb = faces[b]
            if normals[b] @ n > -cos_par:
                continue
            w = fa.offset + fb.offset
            if not (jaw_min <= w <= jaw_max) or w <= 0:
                continue
            tri_b = _project(fb.triangles, u, v)
            pieces = _overlap(tri_a, tri_b)
            area = sum(area2d(q) for q in pieces)
            if area < p.min_overlap:
                continue
            cands = _face_candidates(pieces, p.candidates)
            mid = fa.offset - w / 2
            pts = cands[:, :1] * u + cands[:, 1:] * v + mid * n
            out.append(dict(kind="face/face", features={"faces": [a, b], "overlap": float(area)}, normal=n, u=u, v=v,
                            opening=w, candidates=pts, pieces=pieces, mid=mid))
        # (ii) face/edge
        for k, e in enumerate(feats.edges):
            d = e.p1 - e.p0
            if abs(d @ n) > sin_par * np.linalg.norm(d):
                continue
            en = e.normals @ n
            if not ((en < 1e-9).all() and (en < -1e-9).any() and (en > -cos_par).all()):
                continue
            w = fa.offset - float((e.p0 + e.p1) @ n) / 2
            if not (jaw_min <= w <= jaw_max) or w <= 0:
                continue
            q0, q1 = _project(e.p0, u, v), _project(e.p1, u, v)
            spans = clip_segment(q0, q1, tri_a)
            length = sum(b - a_ for a_, b in spans) * float(np.linalg.norm(d))
            if length < 1e-4:
                continue
            ss = [(a_ + b) / 2 for a_, b in spans]
            lo, hi = max(spans, key=lambda s: s[1] - s[0])
            ss += [lo + (hi - lo) / 4, lo + 3 * (hi - lo) / 4]
            pts = np.array([e.p0 + s * d + (w / 2) * n for s in ss[: max(p.candidates, 1)]])
            out.append(dict(kind="face/edge", features={"faces": [a], "edge": [e.p0.tolist(), e.p1.tolist()],
                                                        "length": length}, normal=n, u=u, v=v, opening=w,
                            candidates=pts, pieces=None, mid=fa.offset - w / 2))
        # (iii) face/vertex
        for k, vx in enumerate(feats.vertices):
            vn = vx.normals @ n
            if not ((vn < -1e-9).all() and (vn > -cos_par).all()):
                continue
            w = fa.offset - float(vx.point @ n)
            if not (jaw_min <= w <= jaw_max) or w <= 0:
                continue
            if not in_triangles(_project(vx.point, u, v)[None], tri_a, eps=-1e-15)[0]:
                continue
            out.append(dict(kind="face/vertex", features={"faces": [a], "vertex": vx.point.tolist()}, normal=n, u=u, v=v,
                            opening=w, candidates=(vx.point + (w / 2) * n)[None], pieces=None, mid=fa.offset - w / 2))
    return out


def _overlap(tri_a: np.ndarray, tri_b: np.ndarray) -> list[np.ndarray]:
    """Convex pieces of the overlap of two triangle sets in 2D (pairs pre-filtered by bounding boxes)."""
    la, ha = tri_a.min(axis=1), tri_a.max(axis=1)
    lb, hb = tri_b.min(axis=1), tri_b.max(axis=1)
    hit = ((la[:, None] < hb[None]) & (lb[None] < ha[:, None])).all(axis=2)
    pieces = []
    for i, j in zip(*np.nonzero(hit)):
        q = clip_convex(ccw(tri_a[i]), ccw(tri_b[j]))
        if len(q) >= 3 and area2d(q) > 1e-12:
            pieces.append(q)
    return pieces


def _face_candidates(pieces: list[np.ndarray], k: int) -> np.ndarray:
    """The overlap's centroid (when it lies in a piece) and the centroids of the largest pieces."""
    areas = np.array([area2d(q) for q in pieces])
    cents = np.array([centroid2d(q) for q in pieces])
    overall = (cents * areas[:, None]).sum(axis=0) / areas.sum()
    out = []
    tris = np.array([[q[0], q[m], q[m + 1]] for q in pieces for m in range(1, len(q) - 1)])
    if in_triangles(overall[None], tris, eps=-1e-15)[0]:
        out.append(overall)
    for i in np.argsort(-areas, kind="stable"):
        if len(out) >= k:
            break
        if all(np.linalg.norm(cents[i] - c) > 1e-6 for c in out):
            out.append(cents[i])
    return np.array(out)


# -- legal theta ranges (Section 5.1) -------------------------------------------------------------------------------


class HandObject:
    """Hand-object collision of the gripper at a class's opening (+ tolerance) against the object mesh (python-fcl)."""

    def __init__(self, obj: ObjectModel, gripper: Gripper, tolerance: float):
        self.target = object_collider(obj.mesh)
        self.gripper, self.tol = gripper, tolerance
        self._geom: dict[float, fcl.BVHModel] = {}

    def geometry(self, opening: float) -> fcl.BVHModel:
        key = round(float(opening), 9)
        if key not in self._geom:
            width = min(opening + 2 * self.tol, self.gripper.jaw_max)
            self._geom[key] = bvh(self.gripper.collision_mesh(width))
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


def grasp_classes(obj: ObjectModel, gripper: Gripper, params: ClassParams = ClassParams()) -> list[GraspClass]:
    """The grasp classes of `obj` for `gripper` with their grasp points and legal theta intervals (Sections 2, 5.1).

    Classes whose legal theta range is empty are dropped."""
    feats = features(obj.mesh, params.min_face_area, params.edge_angle)
    pairs = _pairs(feats, (gripper.jaw_min, gripper.jaw_max - 2 * params.tolerance), params)
    hand = HandObject(obj, gripper, params.tolerance)
    step = params.theta_step
    theta = np.arange(int(round(2 * np.pi / step))) * (2 * np.pi / round(2 * np.pi / step))
    step = float(theta[1] - theta[0]) if len(theta) > 1 else 2 * np.pi
    out = []
    for cls in pairs:
        best, best_free, best_k = None, -1, 0
        for k, c in enumerate(cls["candidates"]):
            free = hand.free(cls, c, theta)
            if params.min_contact_area > 0 and cls["pieces"] is not None:
                free &= _contact_area(cls, c, theta, gripper) >= params.min_contact_area
            if free.sum() > best_free:
                best, best_free, best_k = free, int(free.sum()), k
        if best_free <= 0:
            continue
        point = cls["candidates"][best_k]

        def test(t, cls=cls, point=point):
            ok = hand.free(cls, point, t)
            if params.min_contact_area > 0 and cls["pieces"] is not None:
                ok &= _contact_area(cls, point, t, gripper) >= params.min_contact_area
            return ok

        intervals = _intervals(best, theta, step, test, params.bisection)
        n, u, v = cls["normal"], cls["u"], cls["v"]
        out.append(GraspClass(kind=cls["kind"], features=cls["features"], normal=n.copy(), u=u, v=v, point=point.copy(),
                              eccentricity=float(n @ (point - obj.com)), opening=float(cls["opening"]),
                              intervals=intervals, candidates=cls["candidates"]))
    order = sorted(range(len(out)), key=lambda i: (KINDS.index(out[i].kind), -out[i].legal_range))
    return [out[i] for i in order]


def _contact_area(cls: dict, point: np.ndarray, theta: np.ndarray, gripper: Gripper) -> np.ndarray:
    """Area of the pad rectangle (rotated by theta in the grasp plane) over the face overlap (Section 5.1)."""
    ext, centre = gripper.pad_extents, gripper.pad_center
    u, v = cls["u"], cls["v"]
    c2 = np.array([point @ u, point @ v])
    out = np.zeros(len(theta))
    for k, t in enumerate(theta):
        z2 = np.array([np.cos(t), np.sin(t)])          # approach in the plane
        x2 = np.array([-np.sin(t), np.cos(t)])         # TCP x = n x z (u x v = n)
        corners = [c2 + x2 * (centre[0] + sx * ext[0] / 2) + z2 * (centre[2] + sz * ext[2] / 2)
                   for sx, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        rect = ccw(np.array(corners))
        out[k] = sum(abs(area2d(clip_convex(ccw(q), rect))) for q in cls["pieces"])
    return out
