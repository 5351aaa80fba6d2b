"""Parallel-jaw grasp planning on over-segmented facets (Wan & Harada, Section III) with the pad contact model.

Pipeline: segment the mesh into facets, sample the surface once and distribute the samples to facets (near-neighbour
and boundary-distance filters), then for every kept (facet, sample) the jaw axis through the sample along the
facet's normal at `rotations` hand rotations about it. Contacts follow CONVENTIONS.md (Gripper): each pad closes
along the axis until its rectangle first touches the object (`pads.first_touches`); a grasp is kept when both contact
normals lie within the friction cone, the opening fits the gripper, the contacts' centre is near the centre of mass
(resistance to gravity torque), the hand at its pre-grasp opening clears the object along the approach (level 2 of
the paper, which checks the hand at full opening at the grasp; `pregrasp_margin=None` approaches fully open) and the
hand and both fingers at the grasp's opening do not intersect it (within `finger_clearance`).

`contact_model="paper"` keeps the paper's own pairing, measured beside the default: project the sample along the
inverse facet normal to a parallel facet, then level 1 (the pads' swept cylinders, rotation invariant) and level 2.

Lengths scale with the part (the paper: sampling density, stability and torque strategies "are adaptive to varying
model geometry"). The part's size is the side of the cube of the same surface area, sqrt(area / 6); the neighbour
radius and the boundary distances are their fixed values times size / reference_size (60 mm, between the paper's tube
and tail, so those parts keep about the fixed values). The centre-of-mass distance, the paper's bound on the gravity
torque m g d, scales only up: a smaller part is lighter (m grows as size^3), so the fixed distance already bounds its
torque below the reference part's. Where the centre of mass lies outside the material (in a ring's or a frame's
hole), the distance is at least that to the part's surface plus half the jaw's stroke, so the grasps across
the material nearest the centre of mass, the least torque the part allows, are kept, however wide the hole
(`com_bound`). `lengths="fixed"` uses the fixed values as given.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Callable

import numpy as np
import trimesh
from scipy.spatial import QhullError

from workbench.errors import MeshError, ParameterError
from workbench.geometry.collision import cylinders_collide, object_collider
from workbench.geometry.facets import Facets, distance_to_boundary, segment
from workbench.geometry.hull import mesh_hull, part_hull
from workbench.geometry.objects import ObjectModel
from workbench.geometry.sampling import Samples, distribute, sample_count
from workbench.grasping._handkernel import convex_piece, hull_hits, pack
from workbench.grasping._padkernel import line_crossings, point_distance, triangle_bvh
from workbench.grasping.pads import (
    PREGRASP_TOL,
    Touches,
    axis_frames,
    fingertip_shifts,
    first_touches,
    gap_windows,
    line_surface_points,
    pad_offsets,
    pregrasp_touches,
    triangle_tree,
)
from workbench.grasping.memo import remembered
from workbench.grasping.placements import grips_above_table, stable_placements
from workbench.params import Params, bounds, check_memory, param, single_blas
from workbench.robots.gripper import Gripper

DEG = 180.0 / np.pi  # radians in the library, degrees on the command line
PREGRASP_MARGIN = 0.010
"""How much wider than the grasp the jaw opens to approach it (m), CONVENTIONS.md (Gripper)."""
DEFAULT_FRICTION = 0.3  # the pads' friction coefficient where neither the parameters nor the gripper give one
PREBUILD_TRIANGLES = 65_536
"""Triangles from which a part's first plan builds its triangle hierarchy and convex hull in a second thread while
segmentation and sampling run (the same arrays as built in turn; below this the thread costs more than it saves)."""


@dataclass(frozen=True)
class GraspParams(Params):
    """Parameters of grasp planning (SI units, angles in radians).

    tau: facet normal threshold (18 degrees, as the paper's code). segmentation: "over" or "conventional".
    merge_angle: over-segmentation seed skip angle (None: tau/2; 0 examines every triangle, the paper's literal
    reading). density: samples per m^2 (None: 8 per neighbour_radius^2). neighbour_radius: near-neighbour filter
    radius (10 mm). dist_min, dist_max: distance filter to the facet boundary (2 to 20 mm; a facet narrower than the
    margin gets half its own inradius, see `boundary_margin`). parallel_angle: the paper model's largest deviation
    from antiparallel facet normals (10 degrees). com_max: largest distance from the contacts' centre to the centre of
    mass (50 mm). rotations: hand rotations about the jaw axis (8). seed: sampling seed. contact_model: "pads"
    (CONVENTIONS.md) or "paper". friction: friction coefficient of the pads (None, the default: the one the
    gripper's spec states, else 0.3, a 16.7-degree cone, conservative for rubber pads; `for_gripper`).
    finger_clearance: how far the hand and fingers at the grasp's opening may reach into the
    object (0.5 mm). lengths: "adaptive" (scaled with the part) or "fixed". reference_size: the part size at which
    the fixed lengths apply unscaled (60 mm). axis_angle: the pad model tries one jaw axis per sample and group of
    facet normals within this angle (None: tau/2; 0: every facet sample, see `distinct_axes`). fingertip_margin:
    with the pad model, where the fingertips would poke past the part (thin parts), the same jaw axis is also tried
    with the hand moved back so they end this far short of its far side (3 mm, more than the placements' 2 mm table
    clearance; `pads.fingertip_shifts`; None turns it off). support_grasps: with the pad model, also try every jaw axis
    levelled for each support the part rests on, approaching straight down (`support_axes`). gap_grasps: with the pad
    model, also try every jaw axis with one pad starting inside a hole or cavity, gripping a wall (`pads.gap_windows`).
    """

    tau: float = param(float(np.radians(18.0)), gt=0, lt=np.pi / 2, unit="rad", help="facet normal threshold",
                       flag="--tau-deg", cli_scale=DEG, cli_unit="deg")
    segmentation: str = "over"
    merge_angle: float | None = param(None, ge=0, lt=np.pi / 2, optional=True, unit="rad",
                                      help="over-segmentation seed skip angle (0: every triangle seeds)", cli_scale=DEG,
                                      cli_unit="deg")
    density: float | None = param(None, gt=0, le=1e9, optional=True, unit="per m^2", help="surface samples per square metre")
    neighbour_radius: float = param(0.010, ge=0, le=0.1, unit="m", help="near-neighbour filter radius (0: no filter)")
    dist_min: float = param(0.002, ge=0, le=0.1, unit="m", help="min distance to the facet boundary")
    dist_max: float = param(0.020, ge=0, le=0.5, unit="m", help="max distance to the facet boundary")
    parallel_angle: float = param(float(np.radians(10.0)), ge=0, lt=np.pi / 2, unit="rad", help="antiparallel tolerance",
                                  flag="--parallel-deg", cli_scale=DEG, cli_unit="deg")
    com_max: float = param(0.050, gt=0, le=2.0, unit="m", help="max distance of the contact centre to the centre of mass")
    rotations: int = param(8, ge=1, le=360, integer=True, help="hand rotations about the contact axis")
    seed: int = param(0, ge=0, le=2**32 - 1, integer=True, help="sampling seed")
    contact_model: str = "pads"
    friction: float | None = param(None, ge=0, le=10.0, optional=True,
                                   help="pad friction coefficient (the cone of the pad model)")
    finger_clearance: float = param(5e-4, ge=0, le=0.01, unit="m",
                                    help="how far hand and fingers at the grasp's opening may reach into the object")
    lengths: str = "adaptive"
    reference_size: float = param(0.06, gt=0, le=2.0, unit="m", help="part size at which the fixed lengths apply unscaled")
    axis_angle: float | None = param(None, ge=0, lt=np.pi, optional=True, unit="rad",
                                     help="one jaw axis per sample and group of facet normals within this angle",
                                     cli_scale=DEG, cli_unit="deg")
    support_grasps: bool = True
    gap_grasps: bool = True
    fingertip_margin: float | None = param(0.003, ge=0, le=0.05, optional=True, unit="m",
                                           help="fingertip grasps of thin parts: the hand moved back so the fingertips "
                                                "end this far short of the part's far side")
    pregrasp_margin: float | None = param(PREGRASP_MARGIN, ge=0, le=0.5, optional=True, unit="m",
                                          help="the hand approaches with the jaw open to the grasp's opening plus this "
                                               "margin, capped at the stroke")
    approach_length: float = param(0.05, ge=0, le=1.0, unit="m",
                                   help="how far back along the approach the hand at its pre-grasp opening must clear "
                                        "the part")

    def check(self) -> None:
        self.require(self.dist_min <= self.dist_max, ("dist_min", "dist_max"), "the distance filter needs dist_min <= dist_max")
        self.require(self.neighbour_radius > 0 or self.density is not None, ("neighbour_radius", "density"),
                     "radius 0 turns the neighbour filter off and leaves the default density (8 per radius^2) undefined; "
                     "give a radius > 0 such as 0.01, or a --density")
        if self.segmentation not in ("over", "conventional"):
            raise ParameterError(f"segmentation {self.segmentation!r} must be 'over' or 'conventional'")
        if self.contact_model not in ("pads", "paper"):
            raise ParameterError(f"contact_model {self.contact_model!r} must be 'pads' or 'paper'")
        if self.lengths not in ("adaptive", "fixed"):
            raise ParameterError(f"lengths {self.lengths!r} must be 'adaptive' or 'fixed'")

    def pregrasp(self, widths: np.ndarray, gripper: Gripper) -> np.ndarray:
        """The pre-grasp opening of grasps of `widths` (CONVENTIONS.md, Gripper)."""
        return pregrasp_widths(widths, gripper.jaw_max, self.pregrasp_margin)

    @property
    def friction_coefficient(self) -> float:
        """The pads' friction coefficient: `friction`, or 0.3 where it is left to a gripper (`for_gripper`)."""
        return DEFAULT_FRICTION if self.friction is None else float(self.friction)

    def for_gripper(self, gripper: Gripper) -> "GraspParams":
        """These parameters with `friction` left to the gripper (None) set: the friction its spec states
        (CONVENTIONS.md, Gripper spec), else 0.3. Grasps are planned and stored with the value set."""
        if self.friction is not None:
            return self
        stated = gripper.spec_value("friction")
        return replace(self, friction=DEFAULT_FRICTION if stated is None else stated)

    def scaled(self, mesh: trimesh.Trimesh) -> dict[str, float]:
        """The lengths used on `mesh`: neighbour_radius, dist_min, dist_max, com_max, and the factor applied."""
        s = 1.0 if self.lengths == "fixed" else part_size(mesh) / self.reference_size
        # the gravity torque m g d grows with the mass, as size^3: a part smaller than the reference size held at
        # com_max is under less torque than the reference part, so the distance only ever scales up
        return {"scale": s, "neighbour_radius": self.neighbour_radius * s, "dist_min": self.dist_min * s,
                "dist_max": self.dist_max * s, "com_max": self.com_max * max(s, 1.0)}


def pregrasp_widths(widths: np.ndarray, jaw_max: float, margin: float | None) -> np.ndarray:
    """The jaw opening while approaching and leaving grasps of `widths`: min(width + margin, jaw_max), or `jaw_max`
    (full opening) when `margin` is None (CONVENTIONS.md, Gripper)."""
    widths = np.asarray(widths, dtype=np.float64)
    if margin is None:
        return np.full(widths.shape, float(jaw_max))
    return np.minimum(widths + float(margin), float(jaw_max))


def part_size(mesh: trimesh.Trimesh) -> float:
    """The side of the cube with the same surface area: a size that does not depend on the mesh's orientation."""
    return float(np.sqrt(mesh.area / 6.0))


@dataclass(frozen=True)
class ContactPairs:
    """Candidate contact pairs (one row each) and the filter each passed.

    point0/normal0 on the left finger's side (+y of the TCP), point1/normal1 on the right's; normals are outward.
    With the pad model a row is one hand pose (axis and rotation) and its first touches, and the facets of its
    contacts are named where `com_ok` holds or the row is a facet sample's (-1 elsewhere). Masks (cumulative):
    `width_ok`, `com_ok` (after the friction cone with the pad model), `level1_ok` (pads touch inside the cone with
    the pad model; the swept cylinders are free with the paper model).
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
    axis: np.ndarray | None = None  # the jaw axis (+y of the TCP) of each row, with the pad model

    def __len__(self) -> int:
        return len(self.sample)


@dataclass(frozen=True)
class GraspSet:
    """Collision-free grasps: contacts, outward normals, TCP poses in the object frame (G, 4, 4), jaw widths,
    facet ids, contact-pair ids and the rotation about the jaw axis; where each contact lies on its pad (`offset0`,
    `offset1` (G, 2): along the TCP's x and z from the pad's centre, in pad half sizes, `pads.pad_offsets`) and the
    grasp's `robustness` (`contact_robustness`: 1 with both contacts at their pads' centres, 0 at an edge)."""

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
    offset0: np.ndarray
    offset1: np.ndarray
    robustness: np.ndarray

    def __len__(self) -> int:
        return len(self.jawwidth)


def contact_robustness(offset0: np.ndarray, offset1: np.ndarray) -> np.ndarray:
    """(G,) how far both contacts of each grasp stay from their pads' edges: 1 - the largest offset of either contact
    from its pad's centre (in pad half sizes, either axis), clipped to [0, 1]. A contact at a pad's edge (0) is the
    least robust: a small slip or pose error moves it off the pad."""
    worst = np.maximum(np.abs(offset0).max(axis=1, initial=0.0), np.abs(offset1).max(axis=1, initial=0.0))
    return np.clip(1.0 - worst, 0.0, 1.0)


@dataclass
class GraspPlan:
    """Everything grasp planning computed, for the store, the notebook and the benchmark.

    `counts` holds the candidates left after every stage in order; `empty_reason` names the stage that removed the
    last candidate and what to try (None when there are grasps)."""

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
    lengths: dict = field(default_factory=dict)
    empty_reason: str | None = None


def boundary_margin(facets: Facets, dist_min: float) -> np.ndarray:
    """The boundary distance each facet asks of its samples: `dist_min`, or half the facet's inradius when smaller.

    The paper drops samples near a facet's boundary because a contact there may slip off the facet. On a scan the
    over-segmented facets are a few millimetres wide and a fixed margin removes nearly every sample, though the
    surface continues smoothly past the boundary. Half the facet's inradius (estimated as 2 area / perimeter) still
    keeps each sample well inside its facet, and with the pad model the contact is where the pad first touches, not
    the sample, so the margin only has to keep the jaw axis on the facet.
    """
    perimeter = facets.perimeters
    inradius = np.where(perimeter > 0, 2 * facets.areas / np.maximum(perimeter, 1e-300), np.inf)
    return np.minimum(dist_min, 0.5 * inradius)


@single_blas
def plan_grasps(obj: ObjectModel, gripper: Gripper, params: GraspParams = GraspParams()) -> GraspPlan:
    """Plan collision-free parallel-jaw grasps of `obj` (Section III; contacts per CONVENTIONS.md, Gripper)."""
    params = params.for_gripper(gripper)
    mesh = obj.mesh
    lengths = params.scaled(mesh)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    prebuilt = _prebuild(mesh, params)
    facets = segment(mesh, params.tau, params.segmentation, params.merge_angle)
    timings["segmentation"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    radius = lengths["neighbour_radius"]
    density = params.density if params.density is not None else 8.0 / max(radius, 1e-9) ** 2
    n = sample_count(mesh, density, radius)
    # the neighbour filter's pairs: n^2 pi r^2 / (2 area) for uniform samples, 16 bytes each, a few copies
    pairs_est = n * n * np.pi * radius**2 / (2.0 * max(mesh.area, 1e-12))
    check_memory(48.0 * pairs_est + 200.0 * n, f"sampling {n:,} points on {obj.name} ({mesh.area * 1e4:.3g} cm^2)",
                 "lower --density or --neighbour-radius")
    samples = distribute(mesh, facets, n, radius, 0.0, lengths["dist_max"], params.seed)
    margin = boundary_margin(facets, lengths["dist_min"])
    samples = Samples(**{**samples.__dict__, "pair_ok": samples.pair_ok & (samples.pair_dist >= margin[samples.pair_facet])})
    prebuilt()
    lengths = {**lengths, **com_bound(obj, gripper, params, lengths["com_max"])}
    timings["sampling"] = time.perf_counter() - t0
    counts = {
        "triangles": int(len(mesh.faces)),
        "facets": int(len(facets)),
        "samples": int(len(samples.points)),
        "samples_neighbour": int(samples.kept.sum()),
        "facet_samples": int(len(samples.pair_facet)),
        "facet_samples_distance": int(samples.pair_ok.sum()),
    }
    if params.contact_model == "pads":
        pairs, poses, cand_pair, cand_rot, free = _pads(obj, gripper, params, lengths, facets, samples, counts, timings)
    else:
        pairs, poses, cand_pair, cand_rot, free = _paper(obj, gripper, params, lengths, facets, samples, margin,
                                                         counts, timings)
    g = cand_pair[free]
    off0 = pad_offsets(poses[free], pairs.point0[g], gripper).reshape(-1, 2)
    off1 = pad_offsets(poses[free], pairs.point1[g], gripper).reshape(-1, 2)
    grasps = GraspSet(contact0=pairs.point0[g], contact1=pairs.point1[g], normal0=pairs.normal0[g],
                      normal1=pairs.normal1[g], poses=poses[free], jawwidth=pairs.width[g], facet0=pairs.facet0[g],
                      facet1=pairs.facet1[g], pair=g, rotation=cand_rot[free], offset0=off0, offset1=off1,
                      robustness=contact_robustness(off0, off1))
    counts["grasps"] = int(len(grasps))
    return GraspPlan(params=params, facets=facets, samples=samples, pairs=pairs, candidate_poses=poses,
                     candidate_pair=cand_pair, candidate_free=free, grasps=grasps, counts=counts, timings=timings,
                     lengths=lengths, empty_reason=empty_reason(counts, params, lengths, gripper, pairs))


_GENERIC = np.array([[0.5389, 0.6187, 0.5716], [-0.7071, 0.3149, 0.6332], [0.2673, -0.8017, 0.5345]])
_GENERIC /= np.linalg.norm(_GENERIC, axis=1, keepdims=True)
"""Three directions no part's symmetry aligns with an edge: rays from the centre of mass for `com_bound`'s parity."""


def com_bound(obj: ObjectModel, gripper: Gripper, params: GraspParams, com_max: float) -> dict[str, float]:
    """The centre-of-mass distance bound on `obj` (Section III's torque filter; `com_max`, already scaled): raised,
    with adaptive lengths on a closed part whose centre of mass lies outside the material, to its distance to the
    part's surface plus half the jaw's stroke (`_com_outside`), so that a grasp across the material nearest the
    centre of mass passes. Returns {"com_max": the bound, "com_hole": that distance, 0 where not raised}."""
    if params.lengths == "fixed" or not obj.mesh.is_watertight:
        return {"com_max": com_max, "com_hole": 0.0}
    hole = _com_outside(obj)
    bound = hole + 0.5 * float(gripper.jaw_max) if hole > 0 else 0.0
    return {"com_max": max(com_max, bound), "com_hole": hole if bound > com_max else 0.0}


def _com_outside(obj: ObjectModel) -> float:
    """The distance from a closed part's centre of mass to its surface where the centre lies outside the material
    (odd crossings of the surface by two of three rays from it), else 0; kept in the mesh's cache with the centre it
    was found for, so replanning the part finds it again."""
    mesh, com = obj.mesh, np.asarray(obj.com, dtype=np.float64)
    kept = mesh._cache["workbench_com_outside"]
    if kept is not None and np.array_equal(kept[0], com):
        return kept[1]
    shape, slots, leaf, tri, _ = triangle_tree(mesh)
    ray, _, along = line_crossings(shape, slots, leaf, tri, np.tile(com, (3, 1)), _GENERIC)
    inside = (np.bincount(ray[along > 0], minlength=3) % 2 == 1).sum() >= 2
    hole = 0.0 if inside else float(point_distance(tri, com))
    mesh._cache["workbench_com_outside"] = (com.copy(), hole)
    return hole


def _prebuild(mesh: trimesh.Trimesh, params: GraspParams) -> Callable[[], None]:
    """On a large part not planned before, start building what the pad model uses after sampling, the triangle
    hierarchy (`pads.triangle_tree`) and, for the levelled support grasps, the convex hull, in a thread: both are
    compiled or qhull work on arrays taken here, overlapping the segmentation's compiled kernels, which release the
    GIL. Returns the call that waits for them (timed with sampling) and keeps them in the mesh's cache, as building
    them in turn does."""
    todo = {}
    arrays = (mesh.vertices.view(np.ndarray), mesh.faces.view(np.ndarray), mesh.face_normals)
    if params.contact_model == "pads" and len(mesh.faces) >= PREBUILD_TRIANGLES:
        if mesh._cache["workbench_pad_bvh"] is None:
            todo["workbench_pad_bvh"] = lambda: triangle_bvh(*arrays)
        if params.support_grasps and mesh._cache["workbench_hull"] is None:
            watertight = mesh.is_watertight
            todo["workbench_hull"] = lambda: mesh_hull(*arrays, watertight)
    if not todo:
        return lambda: None
    built: dict = {}

    def build() -> None:
        for key, make in todo.items():
            try:
                built[key] = make()
            except Exception:  # left to the stage that needs it, which raises in the main thread as without this
                return

    thread = threading.Thread(target=build, name="workbench-prebuild", daemon=True)
    thread.start()

    def keep() -> None:
        thread.join()
        for key, value in built.items():
            if mesh._cache[key] is None:
                mesh._cache[key] = value
    return keep


def _level2(gripper: Gripper, poses: np.ndarray, widths: np.ndarray, mesh: trimesh.Trimesh, params: GraspParams,
            counts: dict, timings: dict, pads: bool = True) -> np.ndarray:
    """Level 2: the hand at its pre-grasp opening swept along the approach to each pose, then the fingers at the
    grasp's opening (CONVENTIONS.md, Gripper)."""
    t0 = time.perf_counter()
    free = ~approach_collides(gripper, poses, params.pregrasp(widths, gripper), mesh, params.approach_length,
                              params.finger_clearance)
    counts["hand_open"] = int(free.sum())
    timings["level2"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    idx = np.flatnonzero(free)
    free[idx] = ~fingers_collide(gripper, poses[idx], widths[idx], mesh, params.finger_clearance, pads)
    timings["fingers"] = time.perf_counter() - t0
    return free


def swept_body(gripper: Gripper, length: float) -> trimesh.Trimesh:
    """The volume the hand body sweeps moving `length` along the approach to its pose (TCP frame): the convex hull
    of the body and its copy `length` back along -z. Exact for a convex body (the Franka hand's hull is within
    0.01% of its volume), conservative otherwise."""
    v = np.ascontiguousarray(gripper.body.vertices, dtype=np.float64)
    return _swept_hull(v.tobytes(), v.shape, float(length)).copy()


@lru_cache(maxsize=64)
def _swept_hull(data: bytes, shape: tuple[int, ...], length: float) -> trimesh.Trimesh:
    """`swept_body` of the body's vertices (their bytes and shape), computed once per hand and length (every plan
    of a widget's slider sweeps the same hand)."""
    v = np.frombuffer(data, dtype=np.float64).reshape(shape)
    return trimesh.Trimesh(v if length <= 0 else np.vstack([v, v - [0.0, 0.0, length]])).convex_hull


def swept_fingers(boxes: list[tuple[np.ndarray, np.ndarray]], length: float,
                  clearance: float) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The volumes the left (+y) and right finger boxes (extents, pose; inner faces at y = 0) sweep moving `length`
    along the TCP's +z to their pose, each box shrunk by `clearance` on every side first: per finger, the corners
    (16, 3) of every box at both ends, whose convex hull is that box's sweep (exact); the finger's is their union."""
    left, right = [], []
    for ext, pose in boxes:
        c = box_corners(np.maximum(np.asarray(ext, dtype=np.float64) - 2 * clearance, 1e-6)) @ pose[:3, :3].T + pose[:3, 3]
        (left if pose[1, 3] > 0 else right).append(np.vstack([c, c - [0.0, 0.0, length]]))
    return left, right


def box_corners(extents: np.ndarray) -> np.ndarray:
    """The 8 corners (8, 3) of a box of full `extents` centred on its frame."""
    return np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5) for sz in (-0.5, 0.5)]) * extents


def hand_hits(mesh: trimesh.Trimesh, pieces: list[np.ndarray], poses: np.ndarray) -> np.ndarray:
    """(N,) whether any of the convex volumes (`pieces`: the points (V, 3) whose hull each is, in its own frame)
    placed at `poses` (N, P, 4, 4) meets the part: against the triangle hierarchy of the pad model
    (`_handkernel.hull_hits`), solid volumes."""
    poses = np.ascontiguousarray(np.asarray(poses, dtype=np.float64).reshape(-1, len(pieces), 4, 4))
    if len(poses) == 0:
        return np.zeros(0, dtype=bool)
    shape, slots, leaf, tri, _ = triangle_tree(mesh)
    packed = pack([convex_piece(p) for p in pieces])
    # a pose's answer follows from its placed pieces alone: poses checked before come from the part's memo
    constants = b"".join(np.ascontiguousarray(a).tobytes() for a in (*packed, [len(a) for a in packed]))
    return remembered(mesh, "hand_hits", constants, poses,
                      lambda k: (hull_hits(shape, slots, leaf, tri, *packed, poses[k], 0.0),))[0]


def approach_collides(gripper: Gripper, poses: np.ndarray, openings: np.ndarray, mesh: trimesh.Trimesh,
                      length: float, clearance: float) -> np.ndarray:
    """(N,) whether the hand, with the fingers at `openings`, hits the part `mesh` anywhere on its way along the
    approach axis from `length` back to each pose: the body's sweep (`swept_body`) and both fingers' (`swept_fingers`,
    pads included, shrunk by `clearance`), CONVENTIONS.md (Gripper: the gripper clears the object at its pre-grasp
    opening along the approach)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    openings = np.asarray(openings, dtype=np.float64)
    out = np.zeros(len(poses), dtype=bool)
    body = np.asarray(swept_body(gripper, length).vertices)
    for sel, shape in gripper.width_groups(openings):
        left, right = swept_fingers(shape, length, clearance)
        side = np.array([1.0] * len(left) + [-1.0] * len(right) + [0.0])
        placed = np.repeat(poses[sel][:, None], len(side), axis=1)
        placed[:, :, :3, 3] += (side[None, :, None] * (openings[sel] / 2)[:, None, None]
                                * poses[sel][:, None, :3, 1])
        # the fingers first: most poses that collide do so with a finger, and the body's sweep is the dearest test
        out[sel] = hand_hits(mesh, [*left, *right, body], placed)
    return out


def fingers_collide(gripper: Gripper, poses: np.ndarray, widths: np.ndarray, mesh: trimesh.Trimesh, clearance: float,
                    pads: bool = True) -> np.ndarray:
    """Do the finger boxes of both fingers at each grasp's opening, shrunk by `clearance` on every side, intersect
    the part `mesh`? (The body does not move with the fingers: `approach_collides` tests it.) `pads=False` skips the
    pad boxes, for grasps whose pads closed onto their first touches and so cannot overlap the object."""
    widths = np.asarray(widths)
    out = np.zeros(len(poses), dtype=bool)
    for sel, shape in gripper.width_groups(widths):  # one group unless a linkage's fingers change along the stroke
        boxes = [b for k, b in enumerate(shape) if pads or k // 2 != gripper.pad]
        if not boxes or not len(sel):  # fingers that are their pads only
            continue
        corners = [box_corners(np.maximum(ext - 2 * clearance, 1e-6)) for ext, _ in boxes]
        local = np.array([pose for _, pose in boxes])
        side = np.sign(local[:, 1, 3])
        placed = np.repeat(local[None], len(sel), axis=0)
        placed[:, :, 1, 3] += side[None, :] * widths[sel][:, None] / 2
        out[sel] = hand_hits(mesh, corners, np.einsum("gij,gbjk->gbik", poses[sel], placed))
    return out


def _pads(obj, gripper, params, lengths, facets, samples, counts, timings):
    mesh = obj.mesh
    t0 = time.perf_counter()
    sel = np.flatnonzero(samples.pair_ok)
    merge = params.tau / 2 if params.axis_angle is None else params.axis_angle
    sel = sel[distinct_axes(samples.pair_sample[sel], facets.normals[samples.pair_facet[sel]],
                            facets.areas[samples.pair_facet[sel]], merge)]
    counts["axes"] = int(len(sel))
    angles = 2 * np.pi * np.arange(params.rotations) / params.rotations
    origins = samples.points[samples.pair_sample[sel]]
    axes = facets.normals[samples.pair_facet[sel]]
    counts["gap"] = counts["support"] = 0
    # (sources, origins, jaw axes, rotations, approach references): the facet-normal axes, then the levelled ones
    axis_sets = [(sel, origins, axes, angles, None)]
    counts["slice"] = 0
    slice_gaps = None
    if params.support_grasps:
        t1 = time.perf_counter()
        downs = _support_normals(obj)
        timings["supports"] = time.perf_counter() - t1
        k, y, z = support_axes(axes, downs, params.rotations, params.friction_coefficient)
        axis_sets.append((sel[k], origins[k], y, np.zeros(1), z))
        counts["support"] = int(len(k))
        # after the sampling filters, as every other axis (zero samples: zero axes); twice the hand rotations in
        # direction, as the pads of a scan first touch bumps, whose normals vary
        if len(sel):
            o, y, z, held = slice_axes(mesh, obj.com, downs, 2 * params.rotations,
                                       max(lengths["neighbour_radius"] / 2, 1e-4))
            axis_sets.append((np.full(len(o), -1), o, y, np.zeros(1), z))  # no surface sample: source -1
            counts["slice"] = int(len(o))
            if params.gap_grasps:
                # a ring, a washer or a frame lying flat, its centre of mass in the hole (the vertical through it
                # misses the part): each slice line crosses the rim on either side of the hole, and the pads close
                # across the rim, one starting in the hole (the grip a person uses)
                hit, _, _ = line_surface_points(mesh, np.tile(obj.com, (len(downs), 1)), downs)
                ring = np.flatnonzero(~np.isin(held, hit))
                line, point, outward = line_surface_points(mesh, o[ring], y[ring])
                slice_gaps = (np.full(len(point), -1), point, outward, np.zeros(1), z[ring][line])
    # a pose whose left pad touches outside the friction cone is no grasp: its right pad is searched only where its
    # fingertip variant (`_fingertip_variants`, from this pose's TCP) may be one, and a gap pose's only where its
    # pre-grasp search (`pads.pregrasp_touches`) may start the left pad higher than the gap search did (at most half
    # the pre-grasp margin above its touch). The cone is loosened by rounding's width, so the filters below still
    # decide every pose at its edge.
    cos_f = np.cos(np.arctan(params.friction_coefficient))
    lift = (gripper.jaw_max if params.pregrasp_margin is None else params.pregrasp_margin) / 2 + PREGRASP_TOL + 1e-9
    tips = None if params.fingertip_margin is None else (_extreme_points(mesh), params.fingertip_margin)

    def needed(o, a, ang, ref) -> np.ndarray | None:
        if tips is None:
            return None
        return np.isfinite(fingertip_shifts(tips[0], axis_frames(o, a, ang, ref), gripper, tips[1], slack=1e-9))

    def filters(t: Touches) -> tuple[np.ndarray, ...]:
        """The left touch within the cone, the opening within the stroke, both touches within the cone and the
        contacts' centre near the centre of mass."""
        y = t.poses[:, :3, 1]
        left = (t.tri0 >= 0) & (np.einsum("ij,ij->i", t.normal0, y) >= cos_f)
        width = t.hit & (t.width <= gripper.jaw_max) & (t.width >= gripper.jaw_min)
        both = left & width & (np.einsum("ij,ij->i", t.normal1, -y) >= cos_f)
        return left, width, both, both & (np.linalg.norm(0.5 * (t.point0 + t.point1) - obj.com, axis=1)
                                          <= lengths["com_max"])

    def touches(cone: float | None) -> tuple[Touches, np.ndarray]:
        parts, source = [], []
        counts["gap"] = 0

        def add_gaps(src, o, a, ang, ref) -> None:  # pads starting inside a hole along the axes through surface points
            w, win, narrow = gap_windows(mesh, o, a, gripper.jaw_max, params.pregrasp_margin)
            ref = None if ref is None else ref[w]
            parts.append(gap_touches(mesh, o[w], a[w], ang, gripper, ref, win, narrow, params.finger_clearance,
                                     cone, lift, needed(o[w], a[w], ang, ref)))
            source.append(np.repeat(src[w], len(ang)))
            counts["gap"] += int(len(w))

        for src, o, a, ang, ref in axis_sets:
            parts.append(first_touches(mesh, o, a, ang, gripper, ref=ref, cone=cone, need=needed(o, a, ang, ref)))
            source.append(np.repeat(src, len(ang)))
            if params.gap_grasps and (src >= 0).all():  # gaps open from a surface sample along its normal
                add_gaps(src, o, a, ang, ref)
        if slice_gaps is not None:
            add_gaps(*slice_gaps)
        touch, source = _merge(parts), np.concatenate(source)
        if tips is not None:
            tip, tip_source = _fingertip_variants(mesh, gripper, tips, touch, source, cone)
            touch, source = _merge([touch, tip]), np.concatenate([source, tip_source])
            counts["fingertip"] = int(len(tip))
        # a pad that started inside a hole: its touches are those closing from the pre-grasp opening about its TCP
        inside = touch.hit & np.isfinite(touch.window).any(axis=1)
        again = pregrasp_touches(mesh, _subset(touch, inside), gripper, params.pregrasp_margin,
                                 params.finger_clearance, wanted=lambda t: filters(t)[3], cone=cone)
        return _put_rows(touch, inside, again), source

    touch, source = touches(float(cos_f) - 1e-12)
    left_ok, width_ok, cone_ok, com_ok = filters(touch)
    if not cone_ok.any():
        # no grasp passes the cone: searched again in full, so that the message's friction hint (`friction_hint`)
        # weighs every pair that fits the jaw; the counts are the same
        touch, source = touches(None)
        left_ok, width_ok, cone_ok, com_ok = filters(touch)
    timings["pads"] = time.perf_counter() - t0 - timings.get("supports", 0.0)
    y = touch.poses[:, :3, 1]
    counts.update(hand_poses=int(len(touch)), pads_left=int(left_ok.sum()), pads_width=int((left_ok & width_ok).sum()),
                  pads_cone=int(cone_ok.sum()), pads_com=int(com_ok.sum()))
    sampled = source >= 0
    live = np.flatnonzero(com_ok)
    facet0, facet1 = np.where(sampled, samples.pair_facet[source], -1), np.full(len(touch), -1)
    found = live[~sampled[live]]  # the facets of the contacts that may become grasps
    facet0[found] = _facet_of(facets, touch.tri0[found], y[found])
    facet1[live] = _facet_of(facets, touch.tri1[live], -y[live])
    pairs = ContactPairs(sample=np.where(sampled, samples.pair_sample[source], -1), facet0=facet0, facet1=facet1,
                         point0=touch.point0, point1=touch.point1, normal0=touch.normal0, normal1=touch.normal1,
                         width=touch.width, width_ok=width_ok, com_ok=com_ok, level1_ok=com_ok, axis=y)
    free = _level2(gripper, touch.poses[live], touch.width[live], mesh, params, counts, timings, pads=False)
    kept = touch.poses[live]
    return pairs, kept, live, rotation_about_axis(kept[:, :3, 1], kept[:, :3, 2]), free


def gap_touches(mesh: trimesh.Trimesh, origins: np.ndarray, axes: np.ndarray, angles: np.ndarray, gripper: Gripper,
                ref: np.ndarray | None, windows: np.ndarray, narrow: np.ndarray, clearance: float,
                cone: float | None = None, lift: float = 0.0, need: np.ndarray | None = None) -> Touches:
    """First touches of pads starting inside a hole (`pads.gap_windows`' windows and narrow windows, per axis).

    A pad whose start's plane cuts the part inside its footprint (but for `clearance`) starts inside it and touches
    nothing, so its search ends at that cut. Where the axis has a narrow window (the hole leaves room along it for
    the pre-grasp opening of its crossings), such a pose is searched again from there, and if that pad too starts
    inside the part, from the full opening through the part: its touches then only place the centre about which
    `pads.pregrasp_touches` searches every hit again from its own pre-grasp opening. A pose blocked at the full
    opening on an axis without a narrow window is a miss, which spares the costliest searches (a pad inside the
    part meets every triangle crossing its start) on parts whose holes do not take a finger.

    `cone`, `lift` and `need` (H,) as in `pads.first_touches`, for the first search; a pose it leaves without its
    right touch is searched again as every miss is where its axis has a narrow window, so those axes' poses are all
    needed."""
    axis = np.repeat(np.arange(len(origins)), len(angles))
    redone = np.isfinite(narrow[axis, 0])
    need = redone if need is None else np.asarray(need, dtype=bool).ravel() | redone
    touch = first_touches(mesh, origins, axes, angles, gripper, ref=ref, windows=windows, block=clearance, cone=cone,
                          need=need, lift=lift)
    for win, block in ((narrow, clearance), (np.where(np.isfinite(narrow), windows, np.nan), None)):
        redo = np.flatnonzero(~touch.hit & np.isfinite(win[axis, 0]))
        if len(redo) == 0:
            continue
        again = first_touches(mesh, origins[axis[redo]], axes[axis[redo]], np.zeros(1), gripper,
                              ref=touch.poses[redo, :3, 2], windows=win[axis[redo]], block=block)
        touch = _put_rows(touch, redo, again)
    return touch


def _support_normals(obj: ObjectModel) -> np.ndarray:
    """Outward normals (S, 3) of the supports the part rests on stably (the placement stage's defaults).

    Kept in the mesh's cache (dropped when the mesh changes), so replanning the same part with other grasp
    parameters does not recompute its placements."""
    key = "workbench_support_normals_" + np.asarray(obj.com, dtype=float).tobytes().hex()
    downs = obj.mesh._cache[key]
    if downs is None:
        try:
            downs = stable_placements(obj).normals
        except MeshError:  # a flat sheet rests on no face
            downs = np.zeros((0, 3))
        obj.mesh._cache[key] = downs
    return downs.copy()


def _merge(parts: list[Touches]) -> Touches:
    return Touches(**{f: np.concatenate([getattr(t, f) for t in parts]) for f in Touches.__dataclass_fields__})


def _subset(touch: Touches, mask: np.ndarray) -> Touches:
    return Touches(**{f: getattr(touch, f)[mask] for f in Touches.__dataclass_fields__})


def _put_rows(touch: Touches, rows: np.ndarray, new: Touches) -> Touches:
    """`touch` with its `rows` (a mask, or ascending indices) replaced by those of `new`, in order."""
    out = {}
    for f in Touches.__dataclass_fields__:
        out[f] = getattr(touch, f).copy()
        out[f][rows] = getattr(new, f)
    return Touches(**out)


def rotation_about_axis(axes: np.ndarray, approach: np.ndarray) -> np.ndarray:
    """The stored rotation (H,) of hand poses with jaw axes y and approaches z (H, 3): the angle in [0, 2 pi) about
    y from the reference approach z0 of `pads.axis_frames` to z."""
    ref = axis_frames(np.zeros((len(axes), 3)), axes, np.zeros(1))
    a = np.arctan2(np.einsum("ij,ij->i", approach, ref[:, :3, 0]), np.einsum("ij,ij->i", approach, ref[:, :3, 2]))
    return np.mod(a, 2 * np.pi)


def support_axes(normals: np.ndarray, downs: np.ndarray, rotations: int, friction: float,
                 same: float = np.radians(0.5)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jaw axes levelled for the supports the part rests on: (index into `normals`, axis y, approach z), one row per
    (axis, support) pair that the regular hand rotations miss.

    A part lying on the table is mostly gripped from above, with a level jaw axis and the approach straight down.
    The paper's axes follow the facet normals; on a curved or scanned part those are a few degrees off level, and
    the open fingers (half the stroke and a finger's thickness either side of the axis) then dip into the table. So every facet normal within the
    friction angle of level for a support's outward normal d (the direction into the table) is also tried levelled,
    y = n - (n . d) d normalised, with the approach z = d. A pair the regular rotations already give (y within
    `same` of n and a rotation within `same` of d, as on a CAD part's vertical faces) is skipped.
    `normals` (K, 3) unit facet normals; `downs` (S, 3) unit outward support normals in the part's frame.
    """
    if len(normals) == 0 or len(downs) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3))
    dots = normals @ downs.T  # (K, S)
    k, s = np.nonzero(np.abs(dots) <= np.sin(np.arctan(friction)))
    d = downs[s]
    y = normals[k] - dots[k, s][:, None] * d
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    a = rotation_about_axis(normals[k], d)
    step = 2 * np.pi / rotations
    off = np.abs(a / step - np.round(a / step)) * step
    dup = (np.einsum("ij,ij->i", y, normals[k]) >= np.cos(same)) & (off <= same)
    return k[~dup], y[~dup], d[~dup]


def slice_axes(mesh: trimesh.Trimesh, com: np.ndarray, downs: np.ndarray, directions: int, spacing: float,
               flat_share: float = 0.9, wall: float = float(np.arctan(0.3)), levels: int = 12
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Level jaw axes across the part as it rests on each support, approaching straight down: origins (K, 3) on the
    vertical line through the centre of mass at heights `spacing` apart (2 to `levels` levels), `directions` jaw
    directions about the vertical (each level's turned by its own fraction of their spacing), the approach z = the
    support's outward normal d, all in the part's frame, and the support (K,) each axis belongs to.

    On a rounded part (a pebble, a duck, a bottle lying down) the facet normals are level only on a thin band
    round its widest section, and the surface samples that fall in that band are few; top-down grasps of the part
    where it lies are what a regrasp needs most (Section IV keeps only grasps that clear the table). These axes
    close the pads across the part at fixed heights whatever the sampling; the friction cone, the width and the
    hand checks then decide as for every other axis. A support whose sides are flat (at least `flat_share` of the
    surface within 45 degrees of vertical is within `wall` of it, as a CAD part's walls) is skipped: its facet
    samples give those grasps already. The test is of the shape alone, not of the friction, so that a higher
    --friction never takes these axes away. `downs` (S, 3) unit outward support normals.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    # each level's directions turned by a different fraction of their spacing (golden-ratio steps), so that the
    # levels meet the facets of a ring or a round part at different phases
    phase = np.mod(np.arange(levels) * (np.sqrt(5.0) - 1) / 2, 1.0)
    theta = 2 * np.pi * (np.arange(directions)[None, :] + phase[:, None]) / directions  # (level, direction)
    origins, axes, approach, held = [], [], [], []
    tilt = np.abs(mesh.face_normals @ np.asarray(downs, dtype=np.float64).T)  # (F, S): |sin| of a face's tilt from vertical
    area = np.asarray(mesh.area_faces)
    for s, (d, t) in enumerate(zip(np.asarray(downs, dtype=np.float64), tilt.T)):
        side = area[t <= np.sin(np.pi / 4)].sum()
        if side <= 0 or area[t <= np.sin(wall)].sum() >= flat_share * side:
            continue
        up = -d
        heights = v @ up
        lo, hi = heights.min(), heights.max()
        n = int(np.clip(np.ceil((hi - lo) / spacing), 2, levels))
        h = lo + (np.arange(n) + 0.5) / n * (hi - lo)
        e1 = np.cross(up, [1.0, 0, 0] if abs(up[0]) < 0.9 else [0, 1.0, 0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(up, e1)
        base = com - (com @ up) * up
        o = base[None] + h[:, None] * up[None]
        turn = theta[:n].reshape(-1)
        y = np.cos(turn)[:, None] * e1[None] + np.sin(turn)[:, None] * e2[None]
        origins.append(np.repeat(o, directions, axis=0))
        axes.append(y)
        approach.append(np.tile(d, (n * directions, 1)))
        held.append(np.full(n * directions, s))
    if not origins:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, dtype=np.int64)
    return np.concatenate(origins), np.concatenate(axes), np.concatenate(approach), np.concatenate(held)


def _fingertip_variants(mesh, gripper, tips: tuple[np.ndarray, float], touch: Touches, source: np.ndarray,
                        cone: float | None = None) -> tuple[Touches, np.ndarray]:
    """The fingertip variants of `touch`'s hand poses that hit the part within the jaw range (the same jaw axis and
    approach, the TCP moved back by `pads.fingertip_shifts` of `tips`: the part's hull points and the margin), and
    their sources. `cone` as in `pads.first_touches`, for the variants searched from outside the part (those inside
    a hole are searched again by `pads.pregrasp_touches`)."""
    cand = np.flatnonzero(touch.hit & (touch.width <= gripper.jaw_max))
    d = fingertip_shifts(tips[0], touch.poses[cand], gripper, tips[1]) if len(cand) else np.zeros(0)
    cand, d = cand[np.isfinite(d)], d[np.isfinite(d)]
    poses = touch.poses[cand]
    origins = poses[:, :3, 3] - d[:, None] * poses[:, :3, 2]
    return (first_touches(mesh, origins, poses[:, :3, 1], np.zeros(1), gripper, ref=poses[:, :3, 2],
                          windows=touch.window[cand], block=None, cone=cone,
                          need=np.isfinite(touch.window[cand]).any(axis=1)), source[cand])


def _extreme_points(mesh: trimesh.Trimesh) -> np.ndarray:
    """Points whose extents along any direction are the part's: its convex hull's vertices."""
    try:
        return np.asarray(part_hull(mesh).vertices)
    except QhullError:  # a flat sheet has no hull; its own vertices bound it as well
        return np.unique(np.asarray(mesh.vertices), axis=0)


def distinct_axes(sample: np.ndarray, normals: np.ndarray, areas: np.ndarray, angle: float) -> np.ndarray:
    """Mask of the jaw axes to try: per sample, the facets holding it, largest first, each kept when its normal is more
    than `angle` from every axis already kept for that sample (0 keeps every facet sample).

    Overlapping facets of the over-segmentation give one sample several facet normals a few degrees apart; their
    pads close on the same first touches, so the paper's pairing keeps one pair per sample and opposite triangle.
    Here the same is done before closing the pads, which is what costs.
    """
    keep = np.ones(len(sample), dtype=bool)
    if angle <= 0 or len(sample) == 0:
        return keep
    order = np.lexsort((-areas, sample))
    cos_a = np.cos(angle)
    bounds = np.flatnonzero(np.r_[True, sample[order][1:] != sample[order][:-1], True])
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b - a == 1:
            continue
        idx = order[a:b]
        kept: list[int] = []
        for i in idx:
            if kept and (normals[kept] @ normals[i]).max() >= cos_a:
                keep[i] = False
            else:
                kept.append(i)
    return keep


def _facet_of(facets: Facets, tri: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """For each triangle, the facet holding it whose normal best follows `direction` (-1 for none)."""
    out = np.full(len(tri), -1, dtype=np.int64)
    cnt, cand = facets.holding(tri)
    row = np.repeat(np.arange(len(tri)), cnt)
    score = np.einsum("ij,ij->i", facets.normals[cand], direction[row])
    order = np.lexsort((-score, row))
    row, cand = row[order], cand[order]
    first = np.r_[True, row[1:] != row[:-1]] if len(row) else np.zeros(0, dtype=bool)
    out[row[first]] = cand[first]
    return out


def _paper(obj, gripper, params, lengths, facets, samples, margin, counts, timings):
    mesh = obj.mesh
    t0 = time.perf_counter()
    pairs = contact_pairs(mesh, facets, samples, obj.com, gripper, params, margin, lengths["com_max"])
    timings["contact_pairs"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    target = object_collider(mesh)
    ok = pairs.width_ok & pairs.com_ok
    level1 = np.zeros(len(pairs), dtype=bool)
    idx = np.flatnonzero(ok)
    level1[idx] = ~swept_pads_collide(gripper, pairs.point0[idx], pairs.point1[idx], target, pairs.normal0[idx],
                                      pairs.normal1[idx], params.pregrasp(pairs.width[idx], gripper))
    pairs = ContactPairs(**{**pairs.__dict__, "level1_ok": level1})
    timings["level1"] = time.perf_counter() - t0
    counts.update(contact_pairs=int(len(pairs)), pairs_width=int(pairs.width_ok.sum()),
                  pairs_com=int((pairs.width_ok & pairs.com_ok).sum()), pairs_level1=int(level1.sum()))
    live = np.flatnonzero(level1)
    check_memory(3 * 128.0 * len(live) * params.rotations,
                 f"{len(live):,} contact pairs times {params.rotations} hand rotations", "lower --rotations or --density")
    angles = 2 * np.pi * np.arange(params.rotations) / params.rotations
    poses = grasp_poses(pairs.point0[live], pairs.point1[live], angles)
    cand_pair = np.repeat(live, params.rotations)
    cand_rot = np.tile(angles, len(live))
    counts["hand_poses"] = int(len(poses))
    # the pads themselves are level 1's (their swept cylinders stop short of a tilted facet, where a flat pad
    # at the contact would dig in by its rim): the other finger boxes are tested at the grasp's opening
    free = _level2(gripper, poses, pairs.width[cand_pair], mesh, params, counts, timings, pads=False)
    return pairs, poses, cand_pair, cand_rot, free


def contact_pairs(mesh: trimesh.Trimesh, facets: Facets, samples: Samples, com: np.ndarray, gripper: Gripper,
                  params: GraspParams, margin: np.ndarray | None = None, com_max: float | None = None) -> ContactPairs:
    """The paper's pairing: project every filtered (facet, sample) along the facet's inverse normal; where the ray
    leaves the object inside a parallel facet (normals antiparallel within `parallel_angle`, at least that facet's
    boundary margin from its boundary), the sample and the exit point form a contact pair (Section III, "Parallel
    facets")."""
    margin = np.full(len(facets), params.dist_min) if margin is None else margin
    com_max = params.com_max if com_max is None else com_max
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
    corner = np.asarray(mesh.vertices)[np.asarray(mesh.faces)[tri, 0]]  # plain arrays: trimesh's would rehash
    t = np.einsum("ij,ij->i", corner - origin[ray], tn) / np.einsum("ij,ij->i", -na[ray], tn)
    locs = origin[ray] - t[:, None] * na[ray]
    depth = np.einsum("ij,ij->i", locs - p[ray], -na[ray])
    # exits only (the ray leaves material there), beyond the origin
    leaving = (np.einsum("ij,ij->i", tn, na[ray]) < 0) & (depth > 10 * eps)
    locs, ray, tri, depth = locs[leaving], ray[leaving], tri[leaving], depth[leaving]
    # every facet containing the hit triangle is a candidate opposite facet
    cnt, fb = facets.holding(tri)
    hit = np.repeat(np.arange(len(tri)), cnt)
    anti = -np.einsum("ij,ij->i", facets.normals[fb], na[ray[hit]])
    good = anti >= np.cos(params.parallel_angle)
    hit, fb, anti = hit[good], fb[good], anti[good]
    inner = distance_to_boundary(facets, fb, locs[hit]) >= margin[fb]
    hit, fb, anti = hit[inner], fb[inner], anti[inner]
    # best opposite facet per hit, then one pair per (sample, hit triangle): the most antiparallel
    order = np.lexsort((-anti, hit))
    hit, fb, anti = hit[order], fb[order], anti[order]
    first = np.r_[True, hit[1:] != hit[:-1]] if len(hit) else np.zeros(0, dtype=bool)
    hit, fb, anti = hit[first], fb[first], anti[first]
    r = ray[hit]
    key = sa[r].astype(np.int64) * len(mesh.faces) + tri[hit]
    order = np.lexsort((-anti, key))
    keep = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(key) else order
    keep.sort()
    hit, fb, r = hit[keep], fb[keep], r[keep]
    p0, p1 = p[r], locs[hit]
    width = np.linalg.norm(p0 - p1, axis=1)
    width_ok = (width >= gripper.jaw_min) & (width <= gripper.jaw_max)
    com_ok = np.linalg.norm(0.5 * (p0 + p1) - com, axis=1) <= com_max
    return ContactPairs(sample=sa[r], facet0=fa[r], facet1=fb, point0=p0, point1=p1, normal0=na[r],
                        normal1=facets.normals[fb], width=width, width_ok=width_ok, com_ok=com_ok,
                        level1_ok=np.zeros(len(r), dtype=bool))


def grasp_poses(point0: np.ndarray, point1: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """TCP poses (P * A, 4, 4): origin at the pair's midpoint, y toward point0, approach z = the reference z0
    rotated by +angle about y (right-handed; the stored `freeairgrip.rotation`), pair-major order."""
    poses = axis_frames(0.5 * (point0 + point1), point0 - point1, angles)
    return poses


def swept_pads_collide(gripper: Gripper, point0: np.ndarray, point1: np.ndarray, target,
                       normal0: np.ndarray | None = None, normal1: np.ndarray | None = None,
                       opening: np.ndarray | None = None) -> np.ndarray:
    """The paper's level 1: does either pad's swept cylinder (from `opening`, the pre-grasp opening, default full
    opening, down to its contact) hit the object?

    Each cylinder stops 0.5 mm short of its contact plus r * tan(tilt), where tilt is the angle between that
    side's facet normal and the jaw axis: a flat pad closing on a facet tilted within the antiparallel tolerance
    first touches it at the pad's rim, and that touch is the contact, not a collision.
    """
    out = np.zeros(len(point0), dtype=bool)
    if len(point0) == 0:
        return out
    frames = axis_frames(np.zeros_like(point0), point0 - point1, np.zeros(1))
    y, z0 = frames[:, :3, 1], frames[:, :3, 2]
    width = np.linalg.norm(point0 - point1, axis=1)
    radius, y_near, y_far = gripper.pad_sweep(width, opening)
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


def off_axis(normal0: np.ndarray, normal1: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(N,) the angle (rad) of the contact normal further from its side of the jaw axis: `normal0` from y, `normal1`
    from -y; a contact pair is inside the friction cone of friction mu when this is at most atan(mu)."""
    return np.maximum(np.arccos(np.clip(np.einsum("ij,ij->i", normal0, axes), -1.0, 1.0)),
                      np.arccos(np.clip(-np.einsum("ij,ij->i", normal1, axes), -1.0, 1.0)))


def friction_hint(mu: float, pairs: ContactPairs | None) -> str:
    """What --friction would change an empty friction cone, quoting its declared range: the friction the contacts
    tried need with their own jaw axes (the smallest over the pairs that fit the jaw: the cone half-angle of the
    normal further from its axis), and the bound no jaw axis can beat (half the angle between one normal and the
    other reversed, over the same pairs). Beyond the range, it says no friction in it would do."""
    bound = bounds(GraspParams)["friction"][0]
    if pairs is None or not pairs.width_ok.any():
        return f"raise --friction ({bound.describe(True)})"
    n0, n1 = pairs.normal0[pairs.width_ok], pairs.normal1[pairs.width_ok]
    half = 0.5 * np.arccos(np.clip(-np.einsum("ij,ij->i", n0, n1), -1.0, 1.0)).min()
    least = f"the most nearly opposed pair that fits needs at least {np.tan(half):.2g} ({np.degrees(half):.3g} degrees)"
    if pairs.axis is None:
        tried = np.tan(half)
    else:
        tried = float(np.tan(min(off_axis(n0, n1, pairs.axis[pairs.width_ok]).min(), np.pi / 2 - 1e-9)))
    if bound.problem(tried) is not None and bound.problem(np.tan(half)) is not None:
        return f"no --friction in its range ({bound.describe(True)}) would do: {least}"
    if bound.problem(tried) is not None:
        return (f"the jaw axes tried need a friction beyond --friction's range ({bound.describe(True)}); {least}, so only "
                f"other jaw axes could (a finer --density or --tau-deg)")
    return f"--friction {_ceil(tried)} passes the cone for the jaw axes tried ({bound.describe(True)}); {least}"


def table_friction_hint(obj: ObjectModel, gripper: Gripper, params: GraspParams, placement_poses: np.ndarray,
                        clearance: float, upto: float = 1.0) -> str:
    """What --friction would give grasps that clear the table at the stable placements (P, 4, 4), for the zero-grip
    message, or "" when no friction up to `upto` would, or the cone is not what removed them.

    A part lying flat with a bore or an inner wall (a flange, a bushing, a ring) is gripped from above with one pad
    inside: a flat pad meets a concave wall at its own edges, where the wall's normal lies further off the jaw axis
    than the friction cone of the default friction allows. The grasps are planned again at `upto`; the friction the
    best of those that clear the table needs is checked by planning at it, so the hint names only what it found."""
    mu = params.for_gripper(gripper).friction_coefficient
    if len(placement_poses) == 0 or mu >= upto:
        return ""

    def clear(friction: float) -> tuple[GraspSet, np.ndarray]:
        g = plan_grasps(obj, gripper, replace(params, friction=friction)).grasps
        return g, grips_above_table(placement_poses, g.poses, gripper, clearance).any(axis=0)

    g, above = clear(upto)
    if not above.any():
        return ""
    off = off_axis(g.normal0[above], g.normal1[above], g.poses[above][:, :3, 1])
    need = _ceil(float(np.tan(off.min())))
    if float(need) <= mu:
        return ""
    found = int(clear(float(need))[1].sum())
    if not found:
        return ""
    return (f"; --friction {need} (`workbench grasps` or `build`) keeps {found} grasps that clear the table: their "
            f"contact normals lie {np.degrees(off.min()):.3g} degrees or more off the jaw axis, outside the "
            f"{np.degrees(np.arctan(mu)):.3g}-degree cone of friction {mu:.2g}")


def _ceil(value: float) -> str:
    """`value` rounded up to two significant digits, as text: a friction that passes, not one just below."""
    digits = 1 - int(np.floor(np.log10(abs(value)))) if value > 0 else 2
    return f"{np.ceil(value * 10**digits) / 10**digits:.{max(digits, 0)}f}"


def outside_stroke(what: str, pairs: ContactPairs | None, gripper: Gripper) -> str:
    """Why no `what` fits the jaw: all narrower than its closed opening, all wider than its full one, or some of
    each (from the widths of `pairs`, when given)."""
    lo, hi = gripper.jaw_min * 1e3, gripper.jaw_max * 1e3
    w = np.zeros(0) if pairs is None else np.asarray(pairs.width)[np.isfinite(pairs.width)] * 1e3
    if len(w) and (w < lo).all():
        return (f"every {what} is narrower than the gripper's {lo:.3g} mm smallest opening (the widest is "
                f"{w.max():.3g} mm): a gripper that closes further grips this part")
    if len(w) and not (w > hi).all():
        return f"every {what} lies outside the gripper's {lo:.3g}-{hi:.3g} mm stroke"
    return f"every {what} is wider than the gripper's {hi:.0f} mm opening"


def empty_reason(counts: dict, params: GraspParams, lengths: dict, gripper: Gripper,
                 pairs: ContactPairs | None = None) -> str | None:
    """Which stage removed the last candidate, and what to try; None when grasps remain. An empty friction stage
    (`friction_hint`) names the friction its contacts need, within --friction's declared range or beyond it."""
    if counts.get("grasps", 0) > 0:
        return None
    mu = params.friction_coefficient
    stages = [
        ("facets", "the mesh has no facets"),
        ("samples_neighbour", "the surface got no samples; raise --density"),
        ("facet_samples_distance",
         f"no sample lies {lengths['dist_min'] * 1e3:.3g}-{lengths['dist_max'] * 1e3:.3g} mm from its facet's boundary "
         f"(a facet narrower than twice the minimum asks half its inradius); lower --dist-min, raise --dist-max or "
         f"raise --tau"),
        ("axes", "no jaw axis to try"),
        ("contact_pairs", f"no sample has a parallel facet opposite it (within {np.degrees(params.parallel_angle):.3g} "
                          f"degrees); raise --parallel-deg or use --contact-model pads"),
        ("pairs_width", outside_stroke("facet pair", pairs, gripper)),
        ("pads_left", f"no hand pose's first pad touches within the friction cone (friction {mu:.2g}, "
                      f"{np.degrees(np.arctan(mu)):.3g} degrees); {friction_hint(mu, pairs)}"),
        ("pads_width", outside_stroke("contact pair", pairs, gripper)),
        ("pads_cone", f"no pad contact has both normals within the friction cone (friction {mu:.2g}, "
                      f"{np.degrees(np.arctan(mu)):.3g} degrees); {friction_hint(mu, pairs)}"),
        ("pairs_com", f"every contact pair is more than {lengths['com_max'] * 1e3:.3g} mm from the centre of mass; "
                      f"raise --com-max"),
        ("pads_com", f"every grasp centre is more than {lengths['com_max'] * 1e3:.3g} mm from the centre of mass; "
                     f"raise --com-max"),
        ("pairs_level1", "the pads' swept volumes hit the object at every contact pair; use --contact-model pads"),
        ("hand_open", "the hand at its pre-grasp opening hits the object along the approach at every grasp pose; lower "
                      "--pregrasp-margin or --approach-length, or raise --rotations"),
        ("grasps", f"the fingers at the grasp's opening hit the object at every remaining pose; raise "
                   f"--finger-clearance (now {params.finger_clearance * 1e3:.3g} mm)"),
    ]
    for key, text in stages:
        if key in counts and counts[key] == 0:
            return f"{key}: {text}"
    return "no grasp"
