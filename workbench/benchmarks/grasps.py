"""Grasp planning (Section III) beside Table I's #-fg and t-fg, and on the organic set."""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from workbench.benchmarks import median_time, print_table
from workbench.benchmarks.graspcheck import CHECKS, check_grasps, failures
from workbench.benchmarks.pregrasp import run as mug_table
from workbench.benchmarks.organic import ORGANIC, blob, min_width
from workbench.benchmarks.paper import TABLE_I, bench_objects
from workbench.geometry.facets import FACETS_KEY
from workbench.geometry.objects import from_trimesh, load_object
from workbench.grasping.grasps import PREBUILD_TRIANGLES, GraspParams, plan_grasps
from workbench.grasping.pads import edge_share
from workbench.robots.gripper import BUNDLED, franka_hand, load_gripper


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=3, help="runs per object (the median is printed)")
    parser.add_argument("--set", dest="set", choices=["paper", "organic", "scale", "mug"], default="paper",
                        help="paper: the bundled and paper objects beside Table I; organic: procedural scans, blobs, "
                             "tori, cups and a studded brick; scale: one scanned-like part subdivided from 1k to 1M "
                             "triangles (the same surface), time and grasps per level and stage; mug: a mug with a "
                             "handle, its candidates by filter at the pre-grasp and at full opening")
    parser.add_argument("--max-triangles", type=int, default=1_200_000,
                        help="with --set scale: the largest level (default 1.2M)")
    parser.add_argument("--objects", choices=["all", "bundled", "paper"], default="all", help="with --set paper")
    parser.add_argument("--checked", type=int, default=100, help="grasps per object given to the independent check")
    parser.add_argument("--gripper", default=None, metavar="NAME,...",
                        help=f"compare grippers ({', '.join(BUNDLED)}, or spec files) on the paper objects and the "
                             f"organic set: grasps found, share valid by the independent check, time")


def run(args: argparse.Namespace) -> int:
    if args.gripper:
        return _grippers(args)
    if args.set == "scale":
        return _scale(args)
    if args.set == "mug":
        return mug_table(args)
    return _organic(args) if args.set == "organic" else _paper(args)


def _check_hand(name: str) -> str:
    """The independent check's name for a gripper: franka, parallel60, or the spec file's path."""
    path = BUNDLED.get(name)
    return name if path is None or path.suffix == ".urdf" else str(path)


def _plan_anew(obj, hand, params: GraspParams):
    """`plan_grasps` segmenting the part again, as the papers' grasp planning times count it (the hull and triangle
    hierarchy that `plan_grasps` keeps on the mesh are kept)."""
    obj.mesh._cache.delete(FACETS_KEY)
    return plan_grasps(obj, hand, params)


def _grippers(args: argparse.Namespace) -> int:
    names = [n.strip() for n in args.gripper.split(",") if n.strip()]
    objects = [(label, obj) for label, _, obj in bench_objects(args.objects)]
    objects += [(f"organic {name}", from_trimesh(make(), name)) for name, make in ORGANIC.items()]
    rows = []
    for name in names:
        hand, check = load_gripper(name), _check_hand(name)
        params = GraspParams()
        for label, obj in objects:
            t, plan = median_time(lambda: _plan_anew(obj, hand, params), args.repeats)
            g = plan.grasps
            pick = np.unique(np.linspace(0, len(g) - 1, min(len(g), args.checked)).astype(int)) if len(g) else np.zeros(0, int)
            v = check_grasps(obj.mesh, g.poses[pick], g.jawwidth[pick], g.contact0[pick], g.contact1[pick],
                             g.normal0[pick], g.normal1[pick], plan.params.friction_coefficient, hand=check,
                             pregrasp_margin=params.pregrasp_margin)
            inside = bool(((g.jawwidth >= hand.jaw_min - 1e-9) & (g.jawwidth <= hand.jaw_max + 1e-9)).all())
            rows.append([name, label, len(g), f"{int(v.ok.sum())}/{len(pick)}",
                         f"{100.0 * v.ok.mean():.0f}%" if len(pick) else "-", failures(v), "yes" if inside else "NO", t])
    print_table(["gripper", "object", "grasps", "checked ok", "valid", "failing", "jaw in stroke", "t-fg s"], rows,
                title=f"Grasps per gripper, pad contact model, default parameters (median of {args.repeats} runs; up to "
                      f"{args.checked} grasps per object checked independently, without the planner's code: {CHECKS})")
    return 0


def _paper(args: argparse.Namespace) -> int:
    hand = franka_hand()
    rows = []
    for label, row, obj in bench_objects(args.objects):
        conv = plan_grasps(obj, hand, GraspParams(segmentation="conventional"))
        t, plan = median_time(lambda: _plan_anew(obj, hand, GraspParams()), args.repeats)
        fixed = plan_grasps(obj, hand, GraspParams(lengths="fixed"))
        today = plan_grasps(obj, hand, GraspParams(contact_model="paper", lengths="fixed"))
        c = plan.counts
        paper = TABLE_I.get(row)
        kept = reproduced(today.grasps.poses, fixed.grasps.poses)
        rows.append([label, c["triangles"], conv.counts["facets"], c["facets"], c["samples"], c["samples_neighbour"],
                     c["facet_samples_distance"], c["hand_poses"], c["pads_com"], len(conv.grasps), c["grasps"],
                     len(fixed.grasps), len(today.grasps),
                     f"{kept.sum()}/{len(kept)}",
                     f"{100 * edge_share(plan.grasps.poses, plan.grasps.contact0, plan.grasps.contact1, hand):.0f}%",
                     t, paper[1] if paper else "-", paper[2] if paper else "-"])
    print_table(["object", "#-tri", "facets conv", "facets over", "samples", "after nbr", "after dist", "hand poses",
                 "pads ok", "#-fg conv", "#-fg", "#-fg fixed", "#-fg paper pairs", "paper pairs kept", "edge contacts",
                 "t-fg s", "paper #-fg", "paper t-fg s"],
                rows, title=f"Grasp planning, Franka hand, over-segmentation, pad contact model, lengths scaled with the part "
                            f"(median of {args.repeats} runs; '#-fg fixed': fixed lengths; '#-fg paper pairs': the paper's "
                            f"contact pairs and swept cylinders with fixed lengths, the paper's own model; 'paper pairs kept': those grasps "
                            f"the pad model with fixed lengths also finds, TCP within 1 mm and 3 degrees; it finds more "
                            f"where the paper's rotation-invariant level-1 cylinder rejects a pair at every rotation "
                            f"while the pad rectangle fits at some; 'edge contacts': contacts within 5% of their pad's "
                            f"half size from its edge; Table I beside)")
    return 0


def reproduced(poses: np.ndarray, found: np.ndarray, tol: float = 1e-3, tol_deg: float = 3.0) -> np.ndarray:
    """Which of the TCP `poses` (G, 4, 4) some pose of `found` matches: origins within `tol` metres and rotations
    within `tol_deg` degrees."""
    out = np.zeros(len(poses), dtype=bool)
    if len(poses) == 0 or len(found) == 0:
        return out
    near = cKDTree(found[:, :3, 3]).query_ball_point(poses[:, :3, 3], tol)
    cos_tol = np.cos(np.radians(tol_deg))
    for i, cand in enumerate(near):
        if cand:
            rel = np.einsum("ji,cjk->cik", poses[i, :3, :3], found[cand, :3, :3])
            out[i] = bool(((np.trace(rel, axis1=1, axis2=2) - 1) / 2 >= cos_tol).any())
    return out


def _organic(args: argparse.Namespace) -> int:
    hand = franka_hand()
    rows = []
    for name, make in ORGANIC.items():
        mesh = make()
        obj = from_trimesh(mesh, name)
        params = GraspParams()
        times = []
        for _ in range(max(1, args.repeats)):
            t0 = time.perf_counter()
            plan = _plan_anew(obj, hand, params)
            times.append(time.perf_counter() - t0)
        g = plan.grasps
        pick = np.unique(np.linspace(0, len(g) - 1, min(len(g), args.checked)).astype(int)) if len(g) else np.zeros(0, int)
        v = check_grasps(obj.mesh, g.poses[pick], g.jawwidth[pick], g.contact0[pick], g.contact1[pick],
                         g.normal0[pick], g.normal1[pick], plan.params.friction_coefficient,
                         pregrasp_margin=params.pregrasp_margin)
        graspable = min_width(mesh) < hand.jaw_max
        tm = plan.timings
        rows.append([name, len(mesh.faces), "yes" if mesh.is_watertight else "no", min_width(mesh) * 1e3,
                     "yes" if graspable else "no", len(g), tm.get("segmentation", 0.0), tm.get("sampling", 0.0),
                     tm.get("pads", 0.0), tm.get("level2", 0.0), tm.get("fingers", 0.0), sorted(times)[len(times) // 2],
                     f"{int(v.ok.sum())}/{len(pick)}", f"{100.0 * v.ok.mean():.0f}%" if len(pick) else "-", failures(v)])
    print_table(["object", "#-tri", "closed", "min width mm", "graspable", "grasps", "t seg s", "t sample s", "t pads s",
                 "t hand s", "t fingers s", "t total s", "checked ok", "valid", "failing"], rows,
                title=f"Organic set, Franka hand, pad contact model (median of {args.repeats} runs; up to {args.checked} "
                      f"grasps per object checked independently, without the planner's code: {CHECKS}). Targets: "
                      f">= 20 valid grasps on every graspable object, 100% valid, <= 1 s per 5,000 triangles")
    return 0


def _scale(args: argparse.Namespace) -> int:
    """One 60 mm blob scan at 960 triangles, subdivided four-fold per level (the surface unchanged) up to
    `--max-triangles` (983k by default): per level the CPU time to load it and to plan its grasps as a new part
    (nothing cached: its facets, hull, supports and triangle hierarchy built) and again (replanned with those kept,
    as a widget's slider replans), each beside the 960-triangle level's, the grasps (also of the level saved as STL
    and loaded) and each stage's time."""
    hand = franka_hand()
    mesh = blob(seed=1, rows=12, cols=24)
    rows, base = [], None
    while len(mesh.faces) <= args.max_triangles:
        load, first, again, wall, stages = [], [], [], [], []
        plan = None
        for _ in range(max(1, args.repeats)):
            c0 = time.process_time()
            obj = from_trimesh(mesh, "blob")
            load.append(time.process_time() - c0)
            c0, t0 = time.process_time(), time.perf_counter()
            plan = plan_grasps(obj, hand, GraspParams())
            first.append(time.process_time() - c0)
            wall.append(time.perf_counter() - t0)
            stages.append(plan.timings)
            c0 = time.process_time()
            plan_grasps(obj, hand, GraspParams())
            again.append(time.process_time() - c0)
        with tempfile.TemporaryDirectory() as folder:  # the level as a user's file: STL, in single precision
            path = Path(folder) / "blob.stl"
            mesh.export(path)
            stl = len(plan_grasps(load_object(path, name="blob"), hand, GraspParams()).grasps)
        c, r, w = float(np.median(first)), float(np.median(again)), float(np.median(wall))
        base = (c, r, w) if base is None else base
        tm = {k: float(np.median([t.get(k, 0.0) for t in stages])) for k in
              ("segmentation", "sampling", "supports", "pads", "level2", "fingers")}
        rows.append([len(mesh.faces), len(plan.grasps), stl, float(np.median(load)), c, w, f"{c / base[0]:.1f}x",
                     f"{w / base[2]:.1f}x", r, f"{r / base[1]:.1f}x", tm["segmentation"], tm["sampling"],
                     tm["supports"], tm["pads"], tm["level2"], tm["fingers"], plan.counts.get("hand_poses", 0)])
        mesh = mesh.subdivide()
    print_table(["#-tri", "grasps", "grasps from STL", "t load cpu s", "t plan cpu s", "t plan wall s", "cpu vs 960",
                 "wall vs 960", "t replan cpu s", "replan vs 960", "t seg s", "t sample s", "t supports s", "t pads s",
                 "t hand s", "t fingers s", "hand poses"], rows,
                title=f"Grasp planning against triangle count: one blob scan subdivided (the same surface), Franka hand, "
                      f"pad contact model (median of {args.repeats} runs per level; 'plan': the first plan of a newly "
                      f"loaded part, as `workbench grasps` on a new part, segmenting it and building its convex hull, "
                      f"supports and triangle hierarchy; 'replan': the same part planned again, those kept (a "
                      f"widget's slider other than the segmentation's); 'vs 960': CPU or wall "
                      f"time over the 960-triangle level's; from {PREBUILD_TRIANGLES:,} triangles the first plan "
                      f"builds the hull and triangle hierarchy in a second thread beside segmentation, which saves "
                      f"wall time on two free cores, not CPU time; stage times are wall, of the first plan, the wait "
                      f"for that thread in 'sample'; 'supports': the hull and the stable placements the levelled "
                      f"grasps use). Every stage runs on the full mesh: "
                      f"segmentation is not given a decimated copy, as it runs in compiled code linear in the "
                      f"triangles, and the facets of a copy would not hold the full mesh's triangles that the pads "
                      f"touch and the stored grasps name. 'grasps from STL': the level written to an STL file "
                      f"(single precision) and loaded as a user's part. Targets: <= 2 s at 1M triangles, 230k "
                      f"triangles within 3x the 960-triangle time, grasp counts stable across levels")
    return 0
