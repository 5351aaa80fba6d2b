"""IK feasibility time per robot (t-tpgik) beside Table I's t-tpgikn / t-tpgikh (Wan & Harada Section VI).

First, per robot, the IK it gets (`robots.solvers`: a closed form read off its axes, or the numerical solver), its
poses per second in one process (the closed form with every branch; Levenberg-Marquardt from its seeds, no collision
checks) and the share of reachable poses each finds, over FK of random in-limit configurations.

`--protocol paper` (default) times what Table I times: the IK of every tabletop grip of each object's own roadmap
(all grasps, 168 tabletop placements per free placement), at the five poses of the `ik` table, in a fresh store
(cold: robot, seed library, collision models and worker processes built in the timing). `--protocol interactive`
is the synthetic box benchmark below (the same grips for every robot), labelled as such.

The tabletop grips are those of a box (0.04 x 0.06 x 0.12 m) resting on its three distinct faces at the
default 91 grid positions and 8 angles, grasped across its two narrow widths from 8 approach directions at
4 offsets (46,592 grips; the benchmark takes a seeded 40,000, like the paper's largest objects). `synthetic_grips` builds them in numpy in
the placements contract's format; `synthetic_store` writes them into a DuckDB store through the library
(object, gripper, parameter set, and bulk Arrow inserts), so the IK stage, the notebook and the tests run on
a real store before any grasp planning.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from workbench.benchmarks import print_table
from workbench.benchmarks.regrasp import paper_task_objects
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import (
    ensure_grasps,
    ensure_placements,
    run_ik,
)
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.chain import forward
from workbench.robots.collider import Scene, default_scene
from workbench.robots.gripper import franka_hand
from workbench.robots.ik import CLOSED_BLOCK, SOLVERS, WORKER_CPU_SECONDS, WORLDA, IKOptions, IKSolver, ik_feasibility, solver_kind
from workbench.robots.model import get_robot
from workbench.robots.solvers import closed_form
from workbench.store import Store
from workbench.store.objects import put_gripper, put_object
from workbench.store.placements import TABLETOP_STAGE, angle_ids, load_tabletop_grips

PAPER_ROWS = [  # obj, #-tpg, t-tpgikn (Nextage), t-tpgikh (HRP5P)
    ("TU", 18648, 1746.67, 1692.74), ("PB", 168, 4025.69, 4069.84), ("PW", 27048, 2200.94, 2346.49),
    ("PS", 29568, 16.46, 16.09), ("PT", 37296, 2680.36, 2679.52), ("ED", 39816, 3186.77, 2891.07)]

GRID_X = np.round(np.arange(0.35, 0.65 + 1e-9, 0.05), 4)
GRID_Y = np.round(np.arange(-0.30, 0.30 + 1e-9, 0.05), 4)
BOX = (0.04, 0.06, 0.12)


def _rot(axis: np.ndarray, angle: float) -> np.ndarray:

    out = np.eye(4)
    out[:3, :3] = Rotation.from_rotvec(np.asarray(axis, dtype=float) * angle).as_matrix()
    return out


def box_grasps(extents: tuple[float, float, float] = BOX, approaches: int = 8, offsets: int = 3,
               jaw_max: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """Antipodal grasps of a box centred at its origin: TCP poses (G, 4, 4) in the object frame and jaw widths (G,).

    The fingers close along an axis whose width fits the jaw; the approach turns about that axis in `approaches`
    steps; the TCP slides along the longest remaining axis at `offsets` positions."""
    ext = np.asarray(extents, dtype=float)
    poses, widths = [], []
    for a in range(3):
        if ext[a] > jaw_max:
            continue
        y = np.eye(3)[a]
        others = [i for i in range(3) if i != a]
        z0 = np.eye(3)[others[0]]
        x0 = np.cross(y, z0)
        base = np.eye(4)
        base[:3, :3] = np.stack([x0, y, z0], axis=1)
        for k in range(approaches):
            rot = _rot(y, 2 * np.pi * k / approaches) @ base
            x, z = rot[:3, 0], rot[:3, 2]
            hx, hz = 0.5 * np.abs(x) @ ext, 0.5 * np.abs(z) @ ext
            for s in np.linspace(-0.5, 0.5, offsets) if offsets > 1 else [0.0]:
                p = rot.copy()
                # pads 2 cm deep from the face the hand approaches, slid along the TCP's x
                p[:3, 3] = -z * max(hz - 0.02, 0.0) + x * s * hx
                poses.append(p)
                widths.append(ext[a])
    return np.array(poses), np.array(widths)


def box_placements(extents: tuple[float, float, float] = BOX) -> np.ndarray:
    """The box resting on its three distinct faces: object poses (3, 4, 4) in the table frame, lowest point on z = 0."""
    ext = np.asarray(extents, dtype=float)
    out = []
    for rot in (np.eye(4), _rot([1, 0, 0], np.pi / 2), _rot([0, 1, 0], np.pi / 2)):
        p = rot.copy()
        half = np.abs(rot[:3, :3]) @ (ext / 2)
        p[2, 3] = half[2]
        out.append(p)
    return np.array(out)


def synthetic_grips(extents: tuple[float, float, float] = BOX, xs: np.ndarray = GRID_X, ys: np.ndarray = GRID_Y,
                    angles: int = 8, approaches: int = 8, offsets: int = 3, clearance: float = 0.002
                    ) -> tuple[dict[str, np.ndarray], trimesh.Trimesh, dict[str, np.ndarray]]:
    """Tabletop grips of a box in the placements contract's format, the box mesh, and the free tables
    (grasps, placements, free tabletop grips) for `synthetic_store`."""

    mesh = trimesh.creation.box(extents=extents)
    grasps, widths = box_grasps(extents, approaches, offsets)
    places = box_placements(extents)
    hand = franka_hand().collision_mesh().vertices
    free = []  # (placement index, grasp index)
    for pi, pl in enumerate(places):
        tcp = pl @ grasps
        low = np.einsum("gij,vj->gvi", tcp[:, :3, :3], hand)[..., 2].min(1) + tcp[:, 2, 3]
        for gi in np.nonzero(low >= clearance)[0]:
            free.append((pi, gi))
    free = np.array(free)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    positions = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], axis=1)
    angle_values = 2 * np.pi * np.arange(angles) / angles
    # tabletop placements: (placement, angle, position)
    tp_place, tp_angle, tp_pos = np.meshgrid(np.arange(len(places)), np.arange(angles), np.arange(len(positions)), indexing="ij")
    tp_place, tp_angle, tp_pos = tp_place.ravel(), tp_angle.ravel(), tp_pos.ravel()
    yaw = np.array([_rot([0, 0, 1], a) for a in angle_values])
    tp_rot = yaw[tp_angle] @ places[tp_place]
    tp_rot[:, :3, 3] += positions[tp_pos]
    # tabletop grips: every free grip of the placement at each of its tabletop placements
    rows_tp, rows_fg = [], []
    for k in range(len(places)):
        tps = np.nonzero(tp_place == k)[0]
        fgs = np.nonzero(free[:, 0] == k)[0]
        a, b = np.meshgrid(tps, fgs, indexing="ij")
        rows_tp.append(a.ravel())
        rows_fg.append(b.ravel())
    rows_tp, rows_fg = np.concatenate(rows_tp), np.concatenate(rows_fg)
    gi = free[rows_fg, 1]
    grips = {
        "idtabletopgrips": np.arange(1, len(rows_tp) + 1, dtype=np.int64),
        "idtabletopplacements": rows_tp.astype(np.int64) + 1,
        "idfreeairgrip": gi.astype(np.int64) + 1,
        "rotmat": tp_rot[rows_tp] @ grasps[gi],
        "jawwidth": widths[gi],
        "placement_rotmat": tp_rot[rows_tp],
        "idangle": tp_angle[rows_tp].astype(np.int64) + 1,
        "tabletopposition": positions[tp_pos[rows_tp]],
    }
    tables = {"grasps": grasps, "widths": widths, "places": places, "free": free, "angles": angle_values,
              "tp_place": tp_place, "tp_angle": tp_angle, "tp_pos": positions[tp_pos], "tp_rot": tp_rot,
              "rows_fg": rows_fg}
    return grips, mesh, tables


def synthetic_store(db, name: str = "box", **kwargs) -> tuple[int, int]:
    """Write the synthetic box, its grasps, placements and tabletop grips into the store `db` (a path or Store);
    returns (idobject, idparamset of the tabletop placements). Reuses what is stored under `name`."""

    store = db if isinstance(db, Store) else Store(db)
    try:
        grips, mesh, t = synthetic_grips(**kwargs)
        obj = from_trimesh(mesh, name)
        oid = put_object(store, obj)
        with store.transaction():

            params = {"synthetic": "box", "kwargs": {k: np.asarray(v).tolist() for k, v in kwargs.items()}}
            pid, existed = store.paramset(TABLETOP_STAGE, params, oid)
            if existed:
                return oid, pid
            gid = put_gripper(store, franka_hand())
            fa0 = store.next_id("freeairgrip", "idfreeairgrip")
            g = t["grasps"]
            w = t["widths"]
            half = w / 2
            cp0 = g[:, :3, 3] + g[:, :3, 1] * half[:, None]
            cp1 = g[:, :3, 3] - g[:, :3, 1] * half[:, None]
            store.insert("freeairgrip", {
                "idfreeairgrip": fa0 + np.arange(len(g)), "idobject": np.full(len(g), oid), "idparamset": np.full(len(g), pid),
                "idgripper": np.full(len(g), gid), "contactpoint0": cp0, "contactpoint1": cp1,
                "contactnormal0": g[:, :3, 1], "contactnormal1": -g[:, :3, 1], "rotmat": g.reshape(len(g), 16), "jawwidth": w})
            ftp0 = store.next_id("freetabletopplacement", "idfreetabletopplacement")
            pl = t["places"]
            store.insert("freetabletopplacement", {
                "idfreetabletopplacement": ftp0 + np.arange(len(pl)), "idobject": np.full(len(pl), oid),
                "idparamset": np.full(len(pl), pid), "rotmat": pl.reshape(len(pl), 16), "stability": np.ones(len(pl))})
            ang_ids = angle_ids(store, t["angles"])
            tp0 = store.next_id("tabletopplacements", "idtabletopplacements")
            ntp = len(t["tp_rot"])
            store.insert("tabletopplacements", {
                "idtabletopplacements": tp0 + np.arange(ntp), "idfreetabletopplacement": ftp0 + t["tp_place"],
                "idangle": ang_ids[t["tp_angle"]], "idparamset": np.full(ntp, pid), "tabletopposition": t["tp_pos"],
                "rotmat": t["tp_rot"].reshape(ntp, 16)})
            tg0 = store.next_id("tabletopgrips", "idtabletopgrips")
            n = len(grips["rotmat"])
            rot = grips["rotmat"]
            hw = grips["jawwidth"][:, None] / 2
            store.insert("tabletopgrips", {
                "idtabletopgrips": tg0 + np.arange(n), "idtabletopplacements": tp0 + grips["idtabletopplacements"] - 1,
                "idfreeairgrip": fa0 + grips["idfreeairgrip"] - 1,
                "contactpoint0": rot[:, :3, 3] + rot[:, :3, 1] * hw, "contactpoint1": rot[:, :3, 3] - rot[:, :3, 1] * hw,
                "contactnormal0": rot[:, :3, 1], "contactnormal1": -rot[:, :3, 1], "rotmat": rot.reshape(n, 16),
                "jawwidth": grips["jawwidth"]})
        return oid, pid
    finally:
        if store is not db:
            store.close()


def benchmark_grips(n: int = 40000, seed: int = 0) -> tuple[dict[str, np.ndarray], trimesh.Trimesh]:
    """About `n` tabletop grips of the box (a seeded subset of its 46,592), and the box mesh."""
    grips, mesh, _ = synthetic_grips(offsets=4)
    total = len(grips["rotmat"])
    if n < total:
        keep = np.sort(np.random.default_rng(seed).choice(total, n, replace=False))
        grips = {k: v[keep] for k, v in grips.items()}
    return grips, mesh


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--protocol", choices=["paper", "interactive", "solvers"], default="paper",
                        help="paper: each object's own tabletop grips; interactive: a synthetic box's grips; solvers: "
                             "only the per-robot solver table")
    parser.add_argument("--objects", default="TU,PB,PW,PS,PT",
                        help="paper protocol: comma-separated paper rows (../shared) or bundled objects")
    parser.add_argument("--robots", default="panda,ur5,talos,puma560",
                        help="comma-separated robots (default: panda,ur5,talos,puma560); a robot with a closed form is "
                             "also run with the numerical solver, for comparison")
    parser.add_argument("--ik", choices=SOLVERS, default="auto", help="paper protocol: the IK solver (default auto)")
    parser.add_argument("--grasps", choices=["all", "paper"], default="all",
                        help="paper protocol: every grasp family (default), or only the paper's grasps (its parallel-facet contact model, no "
                             "support or gap grasps), the grasp set of the paper's Table I")
    parser.add_argument("--grips", type=int, default=40000, help="interactive protocol: tabletop grips (default 40,000)")
    parser.add_argument("--poses", type=int, default=20000,
                        help="solver table: random configurations per robot (default 20,000; the numerical solver takes "
                             "a tenth)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per timing (median)")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    parser.add_argument("--compare", type=int, default=2000,
                        help="paper protocol: a seeded sample of this many of each object's grips solved again by the "
                             "numerical solver, for the comparison columns (default 2,000; 0: none)")
    parser.add_argument("--handx", type=float, default=0.05)
    parser.add_argument("--worldz", type=float, default=0.10)
    parser.add_argument("--worlda", type=float, default=WORLDA)


def random_poses(robot, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n random in-limit configurations of `robot` and their TCP poses (N, 4, 4) (batched FK)."""
    q = np.random.default_rng(seed).uniform(robot.lower, robot.upper, (n, robot.nq))
    _, _, r, t = forward(robot, q)
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3], poses[:, :3, 3] = r, t
    return q, poses


def _median_time(f, repeats: int, clock=time.perf_counter) -> float:
    times = []
    for _ in range(max(1, repeats)):
        t0 = clock()
        f()
        times.append(clock() - t0)
    return statistics.median(times)


def run_solvers(args: argparse.Namespace) -> int:
    """Per robot: its solver, single-process poses/s and the share of reachable poses found (FK of random
    configurations: every pose is reachable), closed form beside the numerical solver."""
    rows = []
    for name in [n.strip() for n in args.robots.split(",") if n.strip()]:
        robot = get_robot(name)
        _, poses = random_poses(robot, args.poses)
        form = closed_form(robot)
        closed = ("-", "-", "-", "-", "-")
        if form is not None:
            found = form.solve(poses)[1].any(axis=1).mean()

            def blocks() -> None:  # each block's branches dropped before the next is solved, as the IK stage does
                for s in range(0, len(poses), CLOSED_BLOCK):
                    form.solve(poses[s:s + CLOSED_BLOCK])
            t = _median_time(blocks, args.repeats)
            cpu = _median_time(blocks, args.repeats, time.process_time)  # the process's own CPU time: less load-bound
            scene = Scene(workspace_min=(-10, -10, -10), workspace_max=(10, 10, 10))  # no reach box: every pose counts
            staged = IKSolver(robot, scene, IKOptions(collide=False))  # as the IK stage: LM where the sweep misses
            with_lm = staged.solve(poses, poses, None, 0)[1].mean()
            closed = (form.branches, f"{len(poses) / t:,.0f}", f"{len(poses) / cpu:,.0f}", f"{100 * found:.2f}",
                      f"{100 * with_lm:.2f}")
        few = poses[: max(1, args.poses // 10)]
        scene = Scene(workspace_min=(-10, -10, -10), workspace_max=(10, 10, 10))  # no reach box: every pose counts
        solver = IKSolver(robot, scene, IKOptions(collide=False, solver="numerical"))
        none = np.full((len(few), robot.nq), np.nan)
        ok = solver.solve_from_seeds(few, few, none)[1]
        t = _median_time(lambda: solver.solve_from_seeds(few, few, none), 1)
        rows.append((robot.name, robot.nq, solver_kind(robot, IKOptions()), *closed, f"{len(few) / t:,.0f}",
                     f"{100 * ok.mean():.2f}"))
    print_table(["robot", "dof", "solver (default)", "branches", "closed poses/s", "closed poses/CPU s", "closed found %",
                 "stage found %",
                 "numerical poses/s",
                 "numerical found %"], rows,
                title=f"IK solvers: TCP poses of {args.poses:,} random in-limit configurations per robot (the numerical "
                      f"solver: a tenth of them), one process, no collision checks; found = some solution within the "
                      f"limits reproduces the pose (closed form: every branch, solved {CLOSED_BLOCK:,} poses at a time as "
                      f"the IK stage solves them; stage: the IK stage's closed form, with Levenberg-Marquardt where a swept "
                      f"joint's samples miss; numerical: {IKOptions().seeds} library "
                      f"seeds and {IKOptions().restarts} restarts); median of {args.repeats} runs (numerical: one)")
    return 0


def run_paper(args: argparse.Namespace) -> int:
    """t-tpgik on each object's own tabletop grips (Table I's protocol)."""
    hand, rows = franka_hand(), []
    paper_rows = {r[0]: r for r in PAPER_ROWS}
    with tempfile.TemporaryDirectory() as tmp:
        for label, row, obj in paper_task_objects(args.objects):
            db = Path(tmp) / f"{obj.name}.duckdb"
            families = {} if args.grasps == "all" else {"contact_model": "paper", "support_grasps": False, "gap_grasps": False}
            g = ensure_grasps(db, obj, hand, GraspParams(**families))
            p = ensure_placements(db, g.idobject, obj, g.idparamset, hand, PlacementParams(), TabletopParams())
            for name in args.robots.split(","):
                with Store(db) as store:
                    cpu0 = _run_cpu_seconds()
                    t0 = time.perf_counter()
                    robot = get_robot(name.strip())
                    opts = IKOptions(solver=args.ik)
                    r = run_ik(store, obj.name, robot, None, args.handx, args.worldz, opts, args.workers,
                               progress=False, idtabletop=p.idtabletop, worlda=args.worlda)
                    t = time.perf_counter() - t0
                    cpu = _run_cpu_seconds() - cpu0
                ref = paper_rows.get(row)
                with Store(db) as store:
                    grips = load_tabletop_grips(store, g.idobject, p.idtabletop)
                rows.append((label, robot.name, solver_kind(robot, opts).split(" (")[0], robot.nq, r.grips, t, cpu, r.feasible,
                             r.feasible_all, f"{r.grips / t:,.0f}", *compare_numerical(robot, grips, obj.mesh, opts, args),
                             *(ref[1:] if ref else ("-", "-", "-"))))
    print_table(["object", "robot", "ik", "dof", "#-tpg", "t-tpgik (s)", "CPU (s)", "#feasible grasp", "#feasible all five",
                 "grips/s", "sample", "sample: feasible (this ik / numerical)", "numerical only", "paper #-tpg", "paper t-tpgikn (s)",
                 "paper t-tpgikh (s)"], rows,
                title=f"IK feasibility, protocol paper: every tabletop grip of each object ("
                      f"{'all grasps' if args.grasps == 'all' else 'only the paper grasps: parallel facet pairs, no support or gap grasps'}"
                      f", 168 placements per free "
                      f"placement) at the grasp, handx {args.handx} m, + worldz {args.worldz} m, worlda {args.worlda} m and "
                      f"+ worldz; one cold run in a fresh store; CPU: the seconds of processor time it took, its worker "
                      f"processes' included (what a loaded machine does not stretch). Sample: {args.compare:,} seeded grips solved again by this "
                      f"IK and by the numerical solver (Levenberg-Marquardt from seeds), grips feasible at all five poses, "
                      f"and the grips feasible at some pose for the numerical solver but not for this IK. Paper: "
                      f"Nextage / HRP5P, Xeon 2.8 GHz")
    return 0


def _run_cpu_seconds() -> float:
    """Processor time of this process, of its ended child processes and of the IK workers it closed, in seconds."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime + WORKER_CPU_SECONDS[0]


def compare_numerical(robot, grips: dict[str, np.ndarray], mesh: trimesh.Trimesh, opts: IKOptions,
                      args: argparse.Namespace) -> tuple:
    """(sample size, "feasible at all five: this IK / numerical", grips feasible at some pose for the numerical solver
    only) on a seeded sample of `args.compare` grips; dashes when the IK is the numerical one or no sample is asked."""
    if args.compare <= 0 or solver_kind(robot, opts).startswith("numerical"):
        return "-", "-", "-"
    n = len(grips["rotmat"])
    keep = np.sort(np.random.default_rng(0).choice(n, min(n, args.compare), replace=False))
    sample = {k: v[keep] for k, v in grips.items() if isinstance(v, np.ndarray) and v.shape[:1] == (n,)}
    scene = default_scene(robot.name)
    runs = [ik_feasibility(robot, sample, scene, args.handx, args.worldz, mesh, o, workers=args.workers, progress=False,
                           worlda=args.worlda).feasible for o in (opts, replace(opts, solver="numerical"))]
    ours, numerical = runs
    return (len(keep), f"{int(ours.all(1).sum()):,} / {int(numerical.all(1).sum()):,}",
            int((numerical & ~ours).any(1).sum()))


def run(args: argparse.Namespace) -> int:
    run_solvers(args)
    if args.protocol == "solvers":
        return 0
    print()
    if args.protocol == "paper":
        return run_paper(args)
    grips, mesh = benchmark_grips(args.grips)
    n = len(grips["rotmat"])
    rows = []
    runs = []
    for name in args.robots.split(","):
        runs.append((name.strip(), "auto"))
        if closed_form(get_robot(name.strip())) is not None:
            runs.append((name.strip(), "numerical"))
    for name, solver in runs:
        times, res = [], None
        opts = IKOptions(solver=solver)
        for _ in range(max(1, args.repeats)):
            t0 = time.perf_counter()
            robot = get_robot(name)
            res = ik_feasibility(robot, grips, default_scene(robot.name), args.handx, args.worldz, mesh,
                                 opts, workers=args.workers, progress=False, worlda=args.worlda)
            times.append(time.perf_counter() - t0)
        f = res.feasible
        t = statistics.median(times)
        rows.append((robot.name, solver_kind(robot, opts).split(" (")[0], robot.nq, n, t, int(f[:, 0].sum()),
                     int(f.all(1).sum()), f"{n / t:,.0f}", f"{min(times):.1f}-{max(times):.1f}"))
    print_table(["robot", "ik", "dof", "#-tpg", "t-tpgik (s)", "#feasible grasp", "#feasible all five", "grips/s", "range (s)"],
                rows, title=f"IK feasibility, protocol interactive (a synthetic box, not the paper's objects): {n:,} tabletop "
                            f"grips of a 4 x 6 x 12 cm box, 91 positions x 8 angles; each run cold: "
                            f"robot, seed library, collision models and worker processes built in the timing "
                            f"(median of {args.repeats} cold runs, handx {args.handx} m, worldz {args.worldz} m)")
    print()
    print_table(["obj", "#-tpg", "t-tpgikn (Nextage, s)", "t-tpgikh (HRP5P, s)"], PAPER_ROWS,
                title="Wan & Harada Table I (Xeon 2.8 GHz)")
    return 0
