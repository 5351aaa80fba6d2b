"""Stable placements on a table and the grasps that survive them (Wan & Harada, Sections IV and VI).

Candidate supports are the faces of the object's convex hull, hull triangles merged when coplanar within a
tolerance (0.5 mm and 1 degree: a scanned base is flat only to a tolerance; geometry/supports.py). The object
rests on a face; it is stable when the centre of mass projects inside the support polygon, and its stability
is the distance from that projection to the polygon's boundary divided by the height of the centre of mass
(Section VI, "Experiences"), i.e. the tangent of the tilt it can take before tipping. Each placement also gets the
quasi-static probability that a part dropped at random comes to rest on it (geometry/supports.py,
`rest_probabilities`): it says where parts arriving from a feeder lie, and a face the part rolls off (a faceted round
side, whose neighbouring facet is within `rock_angle`) gets little or none and is flagged `rocking`. Placements are
ordered by probability.
Free-air grasps are
transformed into each placement (not re-planned) and kept when the hand and both fingers at full opening stay
above the table.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from scipy.spatial import ConvexHull

from workbench.errors import MeshError
from workbench.geometry.hull import part_hull
from workbench.geometry.objects import ObjectModel
from workbench.geometry.supports import (coplanar_groups, rest_probabilities, stabilities, support_stability,
                                        support_image, symmetric_average)
from workbench.geometry.symmetry import part_symmetry
from workbench.params import Params, param, single_blas
from workbench.robots.gripper import Gripper


@dataclass(frozen=True)
class PlacementParams(Params):
    """min_stability: smallest accepted stability (distance to the support boundary over centre-of-mass height;
    0.1 is a tilt of 5.7 degrees). clearance: how far above the table (m) the hand must stay. coplanar_distance,
    coplanar_angle: hull faces within 0.5 mm of a support's plane and 1 degree of its normal merge into one candidate
    support. support_tolerance: once settled, the hull vertices within 0.1 mm of the table form the support polygon
    (the plan validator's flatness tolerance). min_probability: smallest quasi-static rest probability kept.
    rock_angle: a support that tips within half this angle onto a hull neighbour within this angle rocks (35 degrees:
    a round side of 11 facets or more). reject_rocking: a rocking support is not stable (the part tips when a tilt
    of half `rock_angle` disturbs it and rolls on); by default it is kept, flagged, with the probability the drop
    statistics give it."""

    min_stability: float = param(0.1, ge=0, help="smallest stability (support margin over centre-of-mass height)")
    clearance: float = param(0.002, ge=0, le=0.5, unit="m", help="hand clearance above the table")
    coplanar_distance: float = param(5e-4, ge=0, le=0.05, unit="m",
                                     help="convex-hull faces within this distance of a support plane merge into it")
    coplanar_angle: float = param(float(np.radians(1.0)), ge=0, lt=np.pi / 2, unit="rad",
                                  help="convex-hull faces within this angle of a support plane merge into it",
                                  cli_scale=180.0 / np.pi, cli_unit="deg")
    support_tolerance: float = param(1e-4, ge=0, le=0.01, unit="m",
                                     help="hull vertices within this height of the table support the part")
    min_probability: float = param(0.0, ge=0, le=1, help="smallest quasi-static probability of coming to rest on a placement")
    rock_angle: float = param(float(np.radians(35.0)), ge=0, lt=np.pi / 2, unit="rad",
                              help="a support that tips within half this angle, onto a neighbouring hull face within this "
                                   "angle, rocks (the part rolls on)", cli_scale=180.0 / np.pi, cli_unit="deg")
    reject_rocking: bool = False


@dataclass(frozen=True)
class Placements:
    """Stable placements: object poses in the table frame (P, 4, 4) with the centre of mass above the origin and
    the lowest point on z = 0; stability values; support polygons (in the table frame, z = 0); the outward normal
    of the supporting hull face in the object frame; `probability` the quasi-static chance of resting there;
    `rocking` whether the support rocks (a small tilt rolls the part onto the next hull face, as on a faceted round
    side: `supports.rest_probabilities`). `rejected_stability` keeps every unstable candidate's value (0 for those that
    cannot reach 0.9 of the threshold, scored without a polygon) and `rejected_poses` the first 64 poses."""

    poses: np.ndarray
    stability: np.ndarray
    supports: list[np.ndarray]
    normals: np.ndarray
    rejected_poses: np.ndarray
    rejected_stability: np.ndarray
    probability: np.ndarray
    rocking: np.ndarray

    def __len__(self) -> int:
        return len(self.stability)


def rest_pose(normal: np.ndarray, com: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """The pose putting the face with outward `normal` down (rotation about a horizontal axis only), the centre of
    mass above the origin and the lowest vertex on z = 0."""
    n = normal / np.linalg.norm(normal)
    down = np.array([0.0, 0.0, -1.0])
    axis = np.cross(n, down)
    s, c = np.linalg.norm(axis), float(n @ down)
    if s < 1e-12:
        rot = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = axis / s
        kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        rot = np.eye(3) + s * kx + (1 - c) * kx @ kx
    pose = np.eye(4)
    pose[:3, :3] = rot
    rc = rot @ com
    pose[:3, 3] = (-rc[0], -rc[1], -float((vertices @ rot.T)[:, 2].min()))
    return pose


@single_blas
def stable_placements(obj: ObjectModel, params: PlacementParams = PlacementParams()) -> Placements:
    """Stable placements of `obj` on its convex-hull faces (Section IV, freetabletopplacement).

    Hull faces coplanar within the tolerance are merged (`supports.coplanar_groups`); each group is a candidate
    resting with its area-weighted normal down, scored first on the group's own vertices. A candidate that can reach
    `min_stability` is then settled: the object rests with that normal down, its support polygon is the hull of the
    hull vertices within `support_tolerance` (0.1 mm, the plan validator's flatness tolerance) of the table, and its
    stability is margin / height on that polygon (Section VI).
    """
    pts = np.asarray(obj.mesh.vertices)
    centred = pts - pts.mean(axis=0)
    thickness = float(np.linalg.svd(centred, compute_uv=False)[-1]) / np.sqrt(max(len(pts), 1)) if len(pts) >= 4 else 0.0
    if thickness <= 1e-9 * max(float(obj.mesh.scale), 1e-12):
        raise MeshError(f"{obj.source or obj.name} is flat (every vertex lies in one plane): it has no volume to rest on the "
                        f"table; give a mesh of a solid part (a closed surface, or a sheet with thickness)")
    hull = part_hull(obj.mesh)
    verts = np.asarray(hull.vertices)
    groups, normals = coplanar_groups(hull, params.coplanar_distance, params.coplanar_angle)
    threshold = max(params.min_stability, 1e-9)
    # candidates that cannot reach the threshold are scored 0 without building their support polygon
    stability = stabilities(hull, obj.com, groups, normals, floor=0.9 * threshold)
    poses, supports = {}, {}
    for i in np.flatnonzero(stability >= 0.9 * threshold):
        pose = rest_pose(normals[i], obj.com, verts)
        placed = verts @ pose[:3, :3].T + pose[:3, 3]
        contact = placed[placed[:, 2] <= params.support_tolerance][:, :2]
        height = float((pose[:3, :3] @ obj.com + pose[:3, 3])[2])
        stability[i] = support_stability(np.column_stack([contact, np.zeros(len(contact))]),
                                         np.array([0.0, 0.0, height]), np.array([0.0, 0.0, -1.0]))
        poses[i], supports[i] = pose, _polygon(contact)
    # every support holding the centre of mass's projection, for the drop statistics
    holds = stabilities(hull, obj.com, groups, normals) > 0
    holds[list(poses)] = stability[list(poses)] > 0
    prob, rocking = rest_probabilities(hull, obj.com, groups, normals, holds, params.rock_angle)
    held = np.flatnonzero(holds)  # the supports a drop can end on: a symmetry permutes them
    if len(held) > 1:  # supports swapped by a turn of the hull about the centre of mass are equally likely
        heights = np.array([float((verts[hull.faces[groups[g][0], 0]] - obj.com) @ normals[g]) for g in held])
        sym = part_symmetry(hull, centre=obj.com,
                            admits=lambda turn: support_image(turn, normals[held], heights) is not None)
        prob[held] = symmetric_average(prob[held], normals[held], heights, sym.turns)
    ok = (stability >= threshold) & np.isin(np.arange(len(groups)), list(poses)) & (prob >= params.min_probability)
    if params.reject_rocking:
        ok &= ~rocking
    idx = np.flatnonzero(ok)[np.lexsort((-stability[ok], -np.round(prob[ok], 12)))]
    rejected = np.flatnonzero(~ok)
    rejected_poses = np.array([rest_pose(normals[i], obj.com, verts) for i in rejected[:64]]).reshape(-1, 4, 4)
    return Placements(poses=np.array([poses[i] for i in idx]).reshape(-1, 4, 4), stability=stability[idx],
                      supports=[supports[i] for i in idx], normals=normals[idx].reshape(-1, 3),
                      rejected_poses=rejected_poses, rejected_stability=stability[rejected], probability=prob[idx],
                      rocking=rocking[idx])


def stability_hint(obj: ObjectModel, params: PlacementParams = PlacementParams()) -> str:
    """Why no placement was kept, for the zero-placement message: the best support's stability and the threshold
    that keeps at least one placement (a rounded base rocks on a small support; a ball has none), or the probability
    or rocking filter that removed the steady ones. The stability is that of the part settled on each support, as
    `stable_placements` scores it."""
    every = stable_placements(obj, replace(params, min_stability=1e-9, min_probability=0.0, reject_rocking=False))
    best = float(every.stability.max(initial=0.0))
    if best <= 0:
        return "no convex-hull face holds the centre of mass above its support (the part rolls or tips)"
    if best >= params.min_stability:
        steady = every.stability >= params.min_stability
        by = ([f"--min-probability {params.min_probability:g} (the likeliest has "
               f"{float(every.probability[steady].max()):.2g})"] if params.min_probability > 0 else []) + \
            (["--reject-rocking (they rock: a small tilt rolls the part on)"] if params.reject_rocking else [])
        return (f"{int(steady.sum())} supports reach --min-stability {params.min_stability:g}, and every one is removed by "
                f"{' or '.join(by)}; lower or drop {'that filter' if len(by) == 1 else 'those filters'}")
    step = 10.0 ** np.floor(np.log10(best))
    lower = float(np.floor(best / step) * step)  # rounded down to one significant digit
    kept = len(stable_placements(obj, replace(params, min_stability=lower)))
    what = f"--min-stability {lower:g} keeps {kept} (each rocks on a small support: check them in the viewer)" if kept else \
        "even a lower --min-stability keeps none"
    return (f"the steadiest support of {obj.name} scores {best:.3g} (support margin over centre-of-mass height), below "
            f"--min-stability {params.min_stability:g}: a rounded base rests on a small support; {what}")


THIN_PART = 0.004  # m: a part lower than this on the table (a card, a foil) is named as too thin to grip


def no_grip_hint(obj: ObjectModel, placement_poses: np.ndarray, clearance: float,
                 highest: float | None = None) -> str:
    """Why no grasp clears the table at any of the placements (P, 4, 4), for the zero-grip message: a part lower than
    THIN_PART is named too thin to grip, with its height. `highest`: the greatest height of the hand's lowest point
    over every grasp and placement (`table_heights`), when the grasps are known: then the hint says whether a lower
    --clearance would keep one, or how far into the table the best grasp reaches."""
    rows = np.asarray(placement_poses)[:, 2]  # the height of a vertex v in placement p: rows[p, :3] . v + rows[p, 3]
    top = float((np.asarray(obj.mesh.vertices) @ rows[:, :3].T + rows[:, 3]).max()) if len(rows) else 0.0
    thin = (f" ({obj.name} stands at most {top * 1e3:.3g} mm above the table: too thin for the fingers to close "
            f"on its sides from above)") if len(rows) and top < THIN_PART else ""
    if highest is None or not np.isfinite(highest):  # no grasp known
        what = "lower --clearance or plan more grasps"
    elif highest >= 0:
        keep = np.floor(highest * 1e5) / 1e5  # m, rounded down to 0.01 mm
        what = (f"the best grasp keeps the hand {highest * 1e3:.3g} mm above the table, within --clearance "
                f"{clearance * 1e3:g} mm: --clearance {keep:g} keeps it")
    else:
        what = (f"the best grasp puts the hand {-highest * 1e3:.3g} mm into the table, so no --clearance keeps one; "
                f"plan more grasps")
    return "every grasp puts the hand into the table at every stable placement" + thin + "; " + what


def empty_placement_stage(obj: ObjectModel, params: PlacementParams, placement_poses: np.ndarray,
                          n_free_grips: int, grips_hint: Callable[[], str] | None = None,
                          grasp_poses: np.ndarray | None = None, gripper: Gripper | None = None) -> str | None:
    """"placements: why" when no placement is stable, "free tabletop grips: why" when no grasp clears the table at
    any, else None (the stage that kept nothing, for `workbench build` and the catalogue alike). `grips_hint`, when
    given, adds what a grasp parameter would change to the second (`grasps.table_friction_hint`); with the grasps'
    poses (G, 4, 4) and their `gripper`, it says how near the table the best of them comes (`no_grip_hint`)."""
    if len(placement_poses) == 0:
        return f"placements: {stability_hint(obj, params)}"
    if n_free_grips == 0:
        best = None if grasp_poses is None or gripper is None else \
            float(table_heights(placement_poses, grasp_poses, gripper).max(initial=-np.inf))
        return (f"free tabletop grips: {no_grip_hint(obj, placement_poses, params.clearance, best)}"
                f"{grips_hint() if grips_hint else ''}")
    return None


def _polygon(points2d: np.ndarray) -> np.ndarray:
    """Convex support polygon (counter-clockwise, z = 0) of the contact points."""
    if len(points2d) >= 3:
        try:
            h = ConvexHull(points2d)
            ring = points2d[h.vertices]
            return np.column_stack([ring, np.zeros(len(ring))])
        except Exception:  # collinear contacts: a segment, no area
            pass
    return np.column_stack([points2d, np.zeros(len(points2d))])


def table_heights(placement_poses: np.ndarray, grasp_poses: np.ndarray, gripper: Gripper) -> np.ndarray:
    """(P, G) the height above the table (z = 0) of the lowest point of the hand and both fingers at full opening,
    for grasp g in placement p (negative: into the table)."""
    pts = np.asarray(gripper.collision_mesh().convex_hull.vertices)  # lowest point of a mesh is a hull vertex
    # z of every hull point for every (placement, grasp): row 2 of P @ G applied to the points
    row = np.einsum("pj,gjk->pgk", np.asarray(placement_poses)[:, 2, :], np.asarray(grasp_poses))  # (P, G, 4)
    p_n, g_n = row.shape[:2]
    z = row[..., :3].reshape(-1, 3) @ pts.T                                # (P G, V) through BLAS
    return (z.min(axis=1, initial=np.inf) + row[..., 3].reshape(-1)).reshape(p_n, g_n)


def grips_above_table(placement_poses: np.ndarray, grasp_poses: np.ndarray, gripper: Gripper,
                      clearance: float) -> np.ndarray:
    """(P, G) mask: the hand and both fingers at full opening stay `clearance` above the table (z = 0) for grasp g in
    placement p (Section IV, freetabletopgrip)."""
    return table_heights(placement_poses, grasp_poses, gripper) >= clearance


def free_tabletop_grips(placements: Placements, grasp_poses: np.ndarray, gripper: Gripper,
                        params: PlacementParams = PlacementParams()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grasps kept at each placement: (placement index, grasp index, TCP pose in the table frame)."""
    ok = grips_above_table(placements.poses, grasp_poses, gripper, params.clearance)
    p, g = np.nonzero(ok)
    return p, g, placements.poses[p] @ grasp_poses[g]
