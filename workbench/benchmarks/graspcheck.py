"""An independent check of parallel-jaw grasps, written without the planner's code or collision library.

For each grasp (TCP pose in the object frame, opening, contacts and outward contact normals):
- both contacts lie on the object's surface within 0.5 mm (trimesh's exact closest point);
- each stored normal is the normal of a triangle within 0.5 mm of its contact (either side on an open mesh; the
  distance to every triangle by `point_triangle_distance`, exact on thin triangles too);
- both normals lie within the friction cone of the jaw axis (the TCP's y);
- the contacts are where the pads are: at +/- half the opening along y, inside the pad rectangles;
- the hand's collision geometry (the Franka hand loaded by pinocchio from example-robot-data's panda.urdf, the
  bundled parallel60 from its URDF, or a spec file's boxes built from its numbers and its palm mesh's convex hull)
  placed with its TCP frame at the
  grasp with the fingers at the grasp's opening and at its pre-grasp opening (the opening plus a margin, 10 mm by
  default, capped at the stroke; full opening without a margin), shrunk inward by 1 mm (each box by 1 mm on
  every side, the hand body's convex hull with every face moved 1 mm in), neither meets a triangle of the object
  (coal's boolean collision test, not python-fcl, which the planner uses) nor lies inside a closed object (a point
  inside it, by trimesh's ray test). No penetration depth enters: coal's box-against-mesh depth under-reports
  (3 mm reads as 0.5 mm), the boolean test of the shrunk solid does not.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh

from workbench.resources import ASSETS, erd_robots, erd_share


@dataclass
class Verdict:
    """Per grasp, whether it passes each criterion of the module docstring; `ok` when it passes all."""

    surface: np.ndarray
    normal: np.ndarray
    cone: np.ndarray
    pads: np.ndarray
    clear: np.ndarray  # no hand geometry, shrunk by INTRUSION_TOL, meets or lies in the object at either opening

    @property
    def ok(self) -> np.ndarray:
        return self.surface & self.normal & self.cone & self.pads & self.clear


INTRUSION_TOL = 1e-3  # m the hand may reach into the object's surface before a grasp is invalid
CHECKS = ("contacts on the surface (0.5 mm) with a nearby triangle's normal, inside the friction cone and on the pads; "
          "the hand's solids (from its URDF by pinocchio, or the spec file's boxes) shrunk 1 mm meet no triangle of "
          "the part and do not lie in it, at the grasp's and at the pre-grasp opening (coal's boolean test, no penetration "
          "depth)")


def failures(v: Verdict) -> str:
    """How many grasps fail each criterion, e.g. 'hand 3, cone 1' ('-' when none fails)."""
    parts = [(k, int((~getattr(v, a)).sum())) for k, a in (("surface", "surface"), ("normal", "normal"), ("cone", "cone"),
                                                           ("pads", "pads"), ("hand", "clear"))]
    return ", ".join(f"{k} {n}" for k, n in parts if n) or "-"


@lru_cache(maxsize=1)
def franka_geometry():
    """[(coal geometry, placement in the TCP frame as a function of the finger opening)] of the Franka hand."""
    urdf = str(erd_robots() / "panda_description" / "urdf" / "panda.urdf")
    return _urdf_geometry(urdf, ("panda_hand", "panda_leftfinger", "panda_rightfinger"))


@lru_cache(maxsize=4)
def _urdf_geometry(urdf: str, keep: tuple[str, ...]):
    model = pin.buildModelFromUrdf(urdf)
    geom = pin.buildGeomFromUrdf(model, urdf, pin.COLLISION, package_dirs=[str(erd_share())])
    parts = []
    for go in geom.geometryObjects:
        if model.frames[go.parentFrame].name in keep:
            g = go.geometry
            if isinstance(g, coal.BVHModelBase):  # the hand body mesh: its convex hull (the mesh is convex)
                g.buildConvexRepresentation(False)
                g = g.convex
            parts.append((go, g))
    return model, geom, parts


# Other hands, each from its own file and nothing of the planner's loaders:
# (URDF, hand and finger links, finger joints (opening / 2 each, pads touching at 0), TCP frame).
URDF_HANDS = {"franka": None,
              "parallel60": ("parallel60.urdf", ("p60_hand", "p60_left_finger", "p60_right_finger"),
                             ("p60_left_joint", "p60_right_joint"), "p60_tcp")}


def _box(size) -> coal.Box:
    return coal.Box(*map(float, size))


@lru_cache(maxsize=8)
def _spec(path: str) -> dict:
    import yaml

    return yaml.safe_load(open(path).read())


def _hand_model(hand: str):
    if hand == "franka":
        return (*franka_geometry(), ("panda_finger_joint1", "panda_finger_joint2"), "panda_hand_tcp")
    file, keep, joints, tcp_frame = URDF_HANDS[hand]
    return (*_urdf_geometry(str(ASSETS / "grippers" / file), keep), joints, tcp_frame)


def full_opening(hand: str = "franka") -> float:
    """A URDF hand's full opening: twice its finger joints' upper limit."""
    model, _, _, joints, _ = _hand_model(hand)
    return float(2 * model.upperPositionLimit[model.joints[model.getJointId(joints[0])].idx_q])


@lru_cache(maxsize=8)
def _palm_hull(path: str) -> coal.CollisionGeometry:
    return _convex(np.asarray(trimesh.load(path, force="mesh").convex_hull.vertices, dtype=np.float64))


def _convex(points: np.ndarray) -> coal.CollisionGeometry:
    vec = coal.StdVec_Vec3s()
    for p in points:
        vec.append(p)
    return coal.Convex.convexHull(vec, True, "Qt")


def hand_placements(opening: float, hand: str = "franka") -> list[tuple[coal.CollisionGeometry, np.ndarray]]:
    """Every hand collision geometry and its pose in the TCP frame with the pads `opening` apart: the Franka hand
    or parallel60 from its URDF (pinocchio), or a spec file's boxes built from its numbers (CONVENTIONS.md, Gripper
    spec: the pad's inner face at the opening, the finger box behind it with its tip flush, the palm box or the
    convex hull of its mesh)."""
    if hand.endswith((".yaml", ".yml", ".json")):
        spec = _spec(hand)
        from scipy.spatial.transform import Rotation

        tcp = np.eye(4)
        tcp[:3, :3] = Rotation.from_euler("xyz", spec.get("rpy", [0, 0, 0])).as_matrix()
        tcp[:3, 3] = spec["tcp"]
        inv = np.linalg.inv(tcp)
        (px, pz), t, f = spec["pad"]["size"], spec["pad"]["thickness"], spec["finger"]["size"]
        if "mesh" in spec["palm"]:  # a palm mesh, checked as its convex hull (trimesh reads it, coal holds it)
            out = [(_palm_hull(str(Path(hand).parent / spec["palm"]["mesh"])), inv)]
        else:
            palm = np.eye(4)
            palm[:3, 3] = spec["palm"].get("offset", [0, 0, spec["palm"]["size"][2] / 2])
            out = [(_box(spec["palm"]["size"]), inv @ palm)]
        for side in (1, -1):
            for size, y, z in (((px, t, pz), opening / 2 + t / 2, 0.0), (f, opening / 2 + f[1] / 2, pz / 2 - f[2] / 2)):
                m = np.eye(4)
                m[:3, 3] = (0.0, side * y, z)
                out.append((_box(size), m))
        return out
    model, geom, parts, joints, tcp_frame = _hand_model(hand)
    data = model.createData()
    q = pin.neutral(model)
    for name in joints:
        jid = model.getJointId(name)
        q[model.joints[jid].idx_q] = opening / 2
    pin.forwardKinematics(model, data, q)
    pin.updateFramePlacements(model, data)
    tcp_inv = data.oMf[model.getFrameId(tcp_frame)].inverse()
    out = []
    for go, g in parts:
        # geometry pose = joint placement * local placement
        M = tcp_inv * data.oMi[go.parentJoint] * go.placement
        out.append((g, M.homogeneous))
    return out


def _object_bvh(mesh: trimesh.Trimesh) -> coal.BVHModelOBBRSS:
    m = coal.BVHModelOBBRSS()
    m.beginModel(len(mesh.faces), len(mesh.vertices))
    m.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    m.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    m.endModel()
    return m


def shrunk(geometry: coal.CollisionGeometry, tol: float) -> coal.CollisionGeometry | None:
    """The solid `geometry` with its surface moved `tol` inward (None when nothing is left): a box's half sizes less
    `tol`, a convex body's every face plane moved in by `tol` (the halfspace intersection, exact for a polytope)."""
    if isinstance(geometry, coal.Box):
        half = np.asarray(geometry.halfSide, dtype=np.float64) - tol
        return coal.Box(*(2 * half)) if (half > 0).all() else None
    from scipy.spatial import ConvexHull, HalfspaceIntersection

    pts = np.array([geometry.point(i) for i in range(geometry.num_points)], dtype=np.float64)
    hull = ConvexHull(pts)
    eq = hull.equations.copy()  # n . x + d <= 0 inside, |n| = 1
    eq[:, 3] += tol
    centre = pts[hull.vertices].mean(axis=0)
    if (eq[:, :3] @ centre + eq[:, 3] >= 0).any():
        return None
    inner = HalfspaceIntersection(eq, centre).intersections
    return _convex(np.unique(np.round(inner, 10), axis=0))


@lru_cache(maxsize=64)
def _shrunk_parts(hand: str, opening: float, tol: float) -> tuple:
    """The hand's solids shrunk by `tol`, their poses in the TCP frame and a point inside each (its own frame)."""
    out = []
    for g, local in hand_placements(opening, hand):
        inner = shrunk(g, tol)
        if inner is not None:
            centre = (np.zeros(3) if isinstance(inner, coal.Box) else
                      np.mean([inner.point(i) for i in range(inner.num_points)], axis=0))
            out.append((inner, local, centre))
    return tuple(out)


def hand_intrudes(mesh: trimesh.Trimesh, poses: np.ndarray, openings: np.ndarray, hand: str = "franka",
                  tol: float = INTRUSION_TOL) -> np.ndarray:
    """Whether the hand at each TCP pose and opening reaches more than `tol` into the object: some collision
    geometry shrunk by `tol` meets a triangle of the object (coal's boolean test), or, for a closed object, has a
    point of its interior inside it (then it lies wholly inside, as it meets no triangle). No penetration depth is
    used."""
    obj = _object_bvh(mesh)
    ident = coal.Transform3s()
    poses, openings = np.asarray(poses, dtype=np.float64), np.asarray(openings, dtype=np.float64)
    out = np.zeros(len(poses), dtype=bool)
    centres = []
    for k, (pose, w) in enumerate(zip(poses, openings)):
        for g, local, inside in _shrunk_parts(hand, round(float(w), 9), tol):
            M = pose @ local
            if not out[k]:
                out[k] = coal.collide(obj, ident, g, coal.Transform3s(M[:3, :3], M[:3, 3]), coal.CollisionRequest(),
                                      coal.CollisionResult()) > 0
            centres.append((k, M[:3, :3] @ inside + M[:3, 3]))
    if centres and mesh.is_watertight:
        idx = np.array([k for k, _ in centres])
        inside = mesh.contains(np.array([c for _, c in centres]))
        out[np.unique(idx[inside])] = True
    return out


def pad_face(hand: str = "franka") -> tuple[float, float, float]:
    """(half size x, half size z, centre z) of the pad's contact face in the TCP frame: the finger box reaching
    farthest along the approach (the first such: a spec's pad before its finger)."""
    boxes = [(np.asarray(g.halfSide), M) for g, M in hand_placements(0.04, hand) if isinstance(g, coal.Box) and M[1, 3] > 0]
    half, M = max(boxes, key=lambda b: b[1][2, 3] + b[0][2])
    ext = np.abs(M[:3, :3]) @ half
    return float(ext[0]), float(ext[2]), float(M[2, 3])


def point_triangle_distance(p: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Distance (T,) from the point `p` to each triangle (T, 3, 3): to its plane where the point projects inside it,
    else to its nearest edge. Exact on sliver triangles too, where a closest point found through barycentric
    coordinates loses its precision (a sliver is its edges)."""
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    seg = np.full(len(tris), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        e = v - u
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", p - u, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        seg = np.minimum(seg, np.linalg.norm(u + t[:, None] * e - p, axis=1))
    n = np.cross(b - a, c - a)
    nn = np.linalg.norm(n, axis=1)
    wide = nn > 1e-12 * np.maximum(np.einsum("ij,ij->i", b - a, b - a) + np.einsum("ij,ij->i", c - a, c - a), 1e-300)
    n = n / np.where(nn > 0, nn, 1.0)[:, None]
    h = np.einsum("ij,ij->i", p - a, n)
    q = p - h[:, None] * n  # the projection on the plane: inside when on the inner side of every edge
    inside = wide.copy()
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= np.einsum("ij,ij->i", np.cross(v - u, q - u), n) >= 0
    return np.where(inside, np.abs(h), seg)


def check_grasps(mesh: trimesh.Trimesh, poses, widths, c0, c1, n0, n1, friction: float, jaw_max: float | None = None,
                 hand: str = "franka", pregrasp_margin: float | None = 0.010) -> Verdict:
    """The independent verdict on each grasp (see the module docstring) for `hand`: franka, parallel60 or the path
    of a spec file; `jaw_max` its full opening (default: the Franka hand's, from its URDF, or the spec's stroke);
    the hand is also checked at the pre-grasp opening, min(width + `pregrasp_margin`, jaw_max) (None: jaw_max)."""
    if jaw_max is None:
        jaw_max = _spec(hand)["stroke"][1] if hand.endswith((".yaml", ".yml", ".json")) else full_opening(hand)
    hx, hz, pad_z = pad_face(hand)
    pad_half = (hx, hz)
    poses, widths = np.asarray(poses), np.asarray(widths)
    G = len(poses)
    if G == 0:
        z = np.zeros(0, dtype=bool)
        return Verdict(surface=z, normal=z, cone=z, pads=z, clear=z)
    pts = np.vstack([c0, c1])
    nrm = np.vstack([n0, n1])
    _, dist, _ = trimesh.proximity.closest_point(mesh, pts)
    surface = (dist <= 5e-4).reshape(2, G).all(axis=0)
    # stored normal = the normal of some triangle within 0.5 mm (brute force over every triangle)
    tris = mesh.triangles
    fn = mesh.face_normals
    normal_ok = np.zeros(2 * G, dtype=bool)
    open_mesh = not mesh.is_watertight
    for i, (p, n) in enumerate(zip(pts, nrm)):
        near = point_triangle_distance(p, tris) <= 5e-4
        cos = fn[near] @ n
        if open_mesh:
            cos = np.abs(cos)
        normal_ok[i] = bool((cos >= np.cos(np.radians(1.0))).any())
    normal_ok = normal_ok.reshape(2, G).all(axis=0)
    y = poses[:, :3, 1]
    cosf = np.cos(np.arctan(friction))
    cone = (np.einsum("ij,ij->i", n0, y) >= cosf - 1e-9) & (np.einsum("ij,ij->i", n1, -y) >= cosf - 1e-9)
    inv = np.linalg.inv(poses)
    pads = np.ones(G, dtype=bool)
    for c, side in ((c0, 1), (c1, -1)):
        local = np.einsum("gij,gj->gi", inv[:, :3, :3], c) + inv[:, :3, 3]
        pads &= np.abs(local[:, 1] - side * widths / 2) <= 1e-5
        pads &= (np.abs(local[:, 0]) <= pad_half[0] + 1e-6) & (np.abs(local[:, 2] - pad_z) <= pad_half[1] + 1e-6)
    pads &= (widths >= 0) & (widths <= jaw_max + 1e-9)
    pre = np.full(G, jaw_max) if pregrasp_margin is None else np.minimum(widths + pregrasp_margin, jaw_max)
    clear = ~(hand_intrudes(mesh, poses, widths, hand) | hand_intrudes(mesh, poses, pre, hand))
    return Verdict(surface=surface, normal=normal_ok, cone=cone, pads=pads, clear=clear)
