"""Parallel-jaw grasp planning on over-segmented facets (Wan & Harada, Section III).

Pipeline: segment the mesh into facets, sample the surface once and distribute the samples to facets
(distance and near-neighbour filters), project each sample along its facet's inverse normal to the far
side of the object to find contact pairs on parallel facets, keep jaw widths the gripper reaches and pairs
near the centre of mass (resistance to gravity torque), then two levels of collision detection with
python-fcl: level 1, the finger pads' swept volumes as cylinders (rotation invariant, once per pair);
level 2, the whole hand with both fingers fully open at every sampled rotation about the contact axis.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import trimesh

from workbench.errors import ParameterError
from workbench.geometry.collision import (
    bvh,
    collide_at_poses,
    cylinders_collide,
    object_collider,
)
from workbench.geometry.facets import Facets, distance_to_boundary, segment
from workbench.geometry.objects import ObjectModel
from workbench.geometry.sampling import Samples, distribute, sample_count
from workbench.params import Params, check_memory, param
from workbench.robots.gripper import Gripper

DEG = 180.0 / np.pi  # radians in the library, degrees on the command line


@dataclass(frozen=True)
class GraspParams(Params):
    """Parameters of grasp planning (SI units, angles in radians).

    tau: facet normal threshold (18 degrees, as the paper's code). segmentation: "over" or "conventional".
    merge_angle: over-segmentation seed skip angle (None: tau/2). density: samples per m^2 (None: 8 per
    neighbour_radius^2). neighbour_radius: near-neighbour filter radius (10 mm). dist_min, dist_max: distance
    filter to the facet boundary (2 to 20 mm). parallel_angle: largest deviation from antiparallel facet normals
    (10 degrees). com_max: largest distance from the contact pair's centre to the centre of mass (50 mm).
    rotations: hand rotations about the contact axis (8). seed: sampling seed.
    """

    tau: float = param(float(np.radians(18.0)), gt=0, lt=np.pi / 2, unit="rad", help="facet normal threshold",
                       flag="--tau-deg", cli_scale=DEG, cli_unit="deg")
    segmentation: str = "over"
    merge_angle: float | None = param(None, gt=0, lt=np.pi / 2, optional=True, unit="rad",
                                      help="over-segmentation seed skip angle", cli_scale=DEG, cli_unit="deg")
    density: float | None = param(None, gt=0, le=1e9, optional=True, unit="per m^2", help="surface samples per square metre")
    neighbour_radius: float = param(0.010, ge=0, le=0.1, unit="m", help="near-neighbour filter radius (0: no filter)")
    dist_min: float = param(0.002, ge=0, le=0.1, unit="m", help="min distance to the facet boundary")
    dist_max: float = param(0.020, ge=0, le=0.5, unit="m", help="max distance to the facet boundary")
    parallel_angle: float = param(float(np.radians(10.0)), ge=0, lt=np.pi / 2, unit="rad", help="antiparallel tolerance",
                                  flag="--parallel-deg", cli_scale=DEG, cli_unit="deg")
    com_max: float = param(0.050, gt=0, le=2.0, unit="m", help="max distance of the contact centre to the centre of mass")
    rotations: int = param(8, ge=1, le=360, integer=True, help="hand rotations about the contact axis")
    seed: int = param(0, ge=0, le=2**32 - 1, integer=True, help="sampling seed")

    def check(self) -> None:
        self.require(self.dist_min <= self.dist_max, ("dist_min", "dist_max"), "the distance filter needs dist_min <= dist_max")
        self.require(self.neighbour_radius > 0 or self.density is not None, ("neighbour_radius", "density"),
                     "radius 0 turns the neighbour filter off and leaves the default density (8 per radius^2) undefined; "
                     "give a radius > 0 such as 0.01, or a --density")
        if self.segmentation not in ("over", "conventional"):
            raise ParameterError(f"segmentation {self.segmentation!r} must be 'over' or 'conventional'")


@dataclass(frozen=True)
class ContactPairs:
    """Candidate contact pairs (one row each) and the filter each passed.

    point0/normal0 on the sampled facet (left finger, +y of the TCP), point1/normal1 its projection on the
    parallel facet; normals are outward. Masks: `width_ok`, `com_ok`, `level1_ok` (cumulative).
    """

    sample: np.ndarray
    facet0: np.ndarray
    facet1: np.ndarray
    point0: np.ndarray
    point1: np.ndarray
    normal0: np.ndarray
    normal1: np.ndarray
    width: np.ndarray
    width_ok: np.ndarray
    com_ok: np.ndarray
    level1_ok: np.ndarray

    def __len__(self) -> int:
        return len(self.sample)


@dataclass(frozen=True)
class GraspSet:
    """Collision-free grasps: contacts, outward normals, TCP poses in the object frame (G, 4, 4), jaw widths,
    facet ids, contact-pair ids and the rotation about the contact axis."""

    contact0: np.ndarray
    contact1: np.ndarray
    normal0: np.ndarray
    normal1: np.ndarray
    poses: np.ndarray
    jawwidth: np.ndarray
    facet0: np.ndarray
    facet1: np.ndarray
    pair: np.ndarray
    rotation: np.ndarray

    def __len__(self) -> int:
        return len(self.jawwidth)


@dataclass
class GraspPlan:
    """Everything grasp planning computed, for the store, the notebook and the benchmark."""

    params: GraspParams
    facets: Facets
    samples: Samples
    pairs: ContactPairs
    candidate_poses: np.ndarray
    candidate_pair: np.ndarray
    candidate_free: np.ndarray
    grasps: GraspSet
    counts: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)


def plan_grasps(obj: ObjectModel, gripper: Gripper, params: GraspParams = GraspParams()) -> GraspPlan:
    """Plan collision-free parallel-jaw grasps of `obj` (Section III)."""
    mesh = obj.mesh
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    facets = segment(mesh, params.tau, params.segmentation, params.merge_angle)
    timings["segmentation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    n = sample_count(mesh, params.density, params.neighbour_radius)
    # the neighbour filter's pairs: n^2 pi r^2 / (2 area) for uniform samples, 16 bytes each, a few copies
    pairs_est = n * n * np.pi * params.neighbour_radius**2 / (2.0 * max(mesh.area, 1e-12))
    check_memory(48.0 * pairs_est + 200.0 * n, f"sampling {n:,} points on {obj.name} ({mesh.area * 1e4:.3g} cm^2)",
                 "lower --density or --neighbour-radius")
    samples = distribute(mesh, facets, n, params.neighbour_radius, params.dist_min, params.dist_max, params.seed)
    timings["sampling"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    pairs = contact_pairs(mesh, facets, samples, obj.com, gripper, params)
    timings["contact_pairs"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    target = object_collider(mesh)
    ok = pairs.width_ok & pairs.com_ok
    level1 = np.zeros(len(pairs), dtype=bool)
    idx = np.flatnonzero(ok)
    level1[idx] = ~swept_pads_collide(gripper, pairs.point0[idx], pairs.point1[idx], target, pairs.normal0[idx],
                                      pairs.normal1[idx])
    pairs = ContactPairs(**{**pairs.__dict__, "level1_ok": level1})
    timings["level1"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    live = np.flatnonzero(level1)
    check_memory(3 * 128.0 * len(live) * params.rotations,
                 f"{len(live):,} contact pairs times {params.rotations} hand rotations", "lower --rotations or --density")
    angles = 2 * np.pi * np.arange(params.rotations) / params.rotations
    poses = grasp_poses(pairs.point0[live], pairs.point1[live], angles)
    cand_pair = np.repeat(live, params.rotations)
    cand_rot = np.tile(angles, len(live))
    free = ~collide_at_poses(bvh(gripper.collision_mesh()), poses, target)
    timings["level2"] = time.perf_counter() - t0
    g = cand_pair[free]
    grasps = GraspSet(contact0=pairs.point0[g], contact1=pairs.point1[g], normal0=pairs.normal0[g], normal1=pairs.normal1[g],
                      poses=poses[free], jawwidth=pairs.width[g], facet0=pairs.facet0[g], facet1=pairs.facet1[g],
                      pair=g, rotation=cand_rot[free])
    counts = {
        "triangles": int(len(mesh.faces)),
        "facets": int(len(facets)),
        "samples": int(len(samples.points)),
        "samples_neighbour": int(samples.kept.sum()),
        "facet_samples": int(len(samples.pair_facet)),
        "facet_samples_distance": int(samples.pair_ok.sum()),
        "contact_pairs": int(len(pairs)),
        "pairs_width": int(pairs.width_ok.sum()),
        "pairs_com": int((pairs.width_ok & pairs.com_ok).sum()),
        "pairs_level1": int(level1.sum()),
        "hand_poses": int(len(poses)),
        "grasps": int(len(grasps)),
    }
    return GraspPlan(params=params, facets=facets, samples=samples, pairs=pairs, candidate_poses=poses,
                     candidate_pair=cand_pair, candidate_free=free, grasps=grasps, counts=counts, timings=timings)


def contact_pairs(mesh: trimesh.Trimesh, facets: Facets, samples: Samples, com: np.ndarray, gripper: Gripper,
                  params: GraspParams) -> ContactPairs:
    """Project every filtered (facet, sample) along the facet's inverse normal; where the ray leaves the object
    inside a parallel facet (normals antiparallel within `parallel_angle`, at least dist_min from its boundary),
    the sample and the exit point form a contact pair (Section III, "Parallel facets")."""
    sel = np.flatnonzero(samples.pair_ok)
    fa = samples.pair_facet[sel]
    sa = samples.pair_sample[sel]
    na = facets.normals[fa]
    p = samples.points[sa]
    empty = np.zeros(0, dtype=np.int64)
    if len(sel) == 0:
        z3 = np.zeros((0, 3))
        zb = np.zeros(0, dtype=bool)
        return ContactPairs(empty, empty, empty, z3, z3, z3, z3, np.zeros(0), zb, zb, zb)
    eps = 1e-6 * max(1.0, float(mesh.scale))
    origin = p - eps * na
    # Embree (embreex) when installed, else trimesh's rtree caster; hits are recomputed in float64 on their triangle
    _, ray, tri = mesh.ray.intersects_location(origin, -na, multiple_hits=True)
    tn = mesh.face_normals[tri]
    t = np.einsum("ij,ij->i", mesh.triangles[tri, 0] - origin[ray], tn) / np.einsum("ij,ij->i", -na[ray], tn)
    locs = origin[ray] - t[:, None] * na[ray]
    depth = np.einsum("ij,ij->i", locs - p[ray], -na[ray])
    # exits only (the ray leaves material there), beyond the origin
    leaving = (np.einsum("ij,ij->i", tn, na[ray]) < 0) & (depth > 10 * eps)
    locs, ray, tri, depth = locs[leaving], ray[leaving], tri[leaving], depth[leaving]
    # every facet containing the hit triangle is a candidate opposite facet
    fid, tid = facets.membership()
    lo = np.searchsorted(tid, tri, side="left")
    hi = np.searchsorted(tid, tri, side="right")
    cnt = hi - lo
    hit = np.repeat(np.arange(len(tri)), cnt)
    fb = fid[np.repeat(lo - np.cumsum(cnt) + cnt, cnt) + np.arange(cnt.sum())]
    anti = -np.einsum("ij,ij->i", facets.normals[fb], na[ray[hit]])
    good = anti >= np.cos(params.parallel_angle)
    hit, fb, anti = hit[good], fb[good], anti[good]
    inner = distance_to_boundary(facets, fb, locs[hit]) >= params.dist_min
    hit, fb, anti = hit[inner], fb[inner], anti[inner]
    # best opposite facet per hit, then one pair per (sample, hit triangle): the most antiparallel
    order = np.lexsort((-anti, hit))
    hit, fb, anti = hit[order], fb[order], anti[order]
    first = np.r_[True, hit[1:] != hit[:-1]]
    hit, fb, anti = hit[first], fb[first], anti[first]
    r = ray[hit]
    key = sa[r].astype(np.int64) * len(mesh.faces) + tri[hit]
    order = np.lexsort((-anti, key))
    keep = order[np.r_[True, key[order][1:] != key[order][:-1]]]
    keep.sort()
    hit, fb, r = hit[keep], fb[keep], r[keep]
    p0, p1 = p[r], locs[hit]
    width = np.linalg.norm(p0 - p1, axis=1)
    width_ok = (width >= gripper.jaw_min) & (width <= gripper.jaw_max)
    com_ok = np.linalg.norm(0.5 * (p0 + p1) - com, axis=1) <= params.com_max
    return ContactPairs(sample=sa[r], facet0=fa[r], facet1=fb, point0=p0, point1=p1, normal0=na[r],
                        normal1=facets.normals[fb], width=width, width_ok=width_ok, com_ok=com_ok,
                        level1_ok=np.zeros(len(r), dtype=bool))


def contact_frames(point0: np.ndarray, point1: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit contact axis y (from point1 to point0), a reference approach z0 perpendicular to it, and x0 = y x z0."""
    y = point0 - point1
    y = y / np.linalg.norm(y, axis=1, keepdims=True)
    # reference: the world axis least aligned with y, made perpendicular (deterministic)
    ref = np.eye(3)[np.argmin(np.abs(y), axis=1)]
    z0 = ref - np.einsum("ij,ij->i", ref, y)[:, None] * y
    z0 /= np.linalg.norm(z0, axis=1, keepdims=True)
    return y, z0, np.cross(y, z0)


def grasp_poses(point0: np.ndarray, point1: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """TCP poses (P * A, 4, 4): origin at the pair's midpoint, y toward point0, approach z = the reference z0
    rotated by +angle about y (right-handed; the stored `freeairgrip.rotation`), pair-major order."""
    y, z0, x0 = contact_frames(point0, point1)
    c, s = np.cos(angles)[None, :, None], np.sin(angles)[None, :, None]
    z = c * z0[:, None, :] + s * x0[:, None, :]  # R_y(angle) z0 = cos z0 + sin (y x z0)
    yy = np.broadcast_to(y[:, None, :], z.shape)
    x = np.cross(yy, z)
    poses = np.zeros((len(y), len(angles), 4, 4))
    poses[..., :3, 0], poses[..., :3, 1], poses[..., :3, 2] = x, yy, z
    poses[..., :3, 3] = (0.5 * (point0 + point1))[:, None, :]
    poses[..., 3, 3] = 1.0
    return poses.reshape(-1, 4, 4)


def swept_pads_collide(gripper: Gripper, point0: np.ndarray, point1: np.ndarray, target,
                       normal0: np.ndarray | None = None, normal1: np.ndarray | None = None) -> np.ndarray:
    """Level 1: does either pad's swept cylinder (from full opening down to its contact) hit the object?

    Each cylinder stops 0.5 mm short of its contact plus r * tan(tilt), where tilt is the angle between that
    side's facet normal and the jaw axis: a flat pad closing on a facet tilted within the antiparallel tolerance
    first touches it at the pad's rim, and that touch is the contact, not a collision.
    """
    out = np.zeros(len(point0), dtype=bool)
    if len(point0) == 0:
        return out
    y, z0, _ = contact_frames(point0, point1)
    width = np.linalg.norm(point0 - point1, axis=1)
    radius, y_near, y_far = gripper.pad_sweep(width)
    mid = 0.5 * (point0 + point1)
    for side, normal in ((1.0, normal0), (-1.0, normal1)):
        axis = side * y
        near = y_near.copy()
        if normal is not None:
            cos = np.clip(np.einsum("ij,ij->i", normal, axis), 1e-3, 1.0)
            near += radius * np.sqrt(1 - cos**2) / cos
        near = np.minimum(near, y_far - 1e-4)
        rot = np.stack([z0, np.cross(axis, z0), axis], axis=2)  # right-handed: fcl needs a proper rotation
        centre = mid + axis * (0.5 * (near + y_far))[:, None]
        out |= cylinders_collide(radius, y_far - near, rot, centre, target, skip=out)
    return out
