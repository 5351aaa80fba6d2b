"""Five-finger regrasp by contact-point clustering beside Phoka & Sudsang's Tables I-III.

Six bundled objects decimated to about 500 triangles, 50 clusters, 10,000 sampled force-closure grasps and 30
picks per algorithm as in Section IV. Construction times are the median of `--repeats` builds. The paper's
objects (Fig. 2 (a)-(f)) are not published, so its rows are printed in order beside ours, not matched by shape.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from workbench.benchmarks import print_table
from workbench.benchmarks.paper import bench_objects
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.phoka_sudsang.contacts import ContactParams, contact_points
from workbench.planners.phoka_sudsang.experiments import (
    local_planning_stats,
    random_queries,
    sample_grasps,
)
from workbench.planners.phoka_sudsang.switching import build_planner

# Phoka & Sudsang, Tables I-III, rows (a)-(f) (2.4 GHz PC)
PAPER_I = [(25160, 1, 38.98), (6602, 5, 9.95), (2148, 13, 4.02), (2571, 15, 4.80), (2372, 21, 4.38), (19317, 1, 28.85)]
PAPER_II = [(35.18, 30, 91.21, 30, 30), (34.29, 30, 87.92, 30, 30), (10.02, 29, 81.15, 29, 30),
            (10.77, 30, 81.55, 29, 30), (8.94, 30, 77.87, 28, 30), (45.67, 30, 91.20, 30, 30)]
PAPER_III = [(30, 7.80, 109.49, 80.31), (30, 11.55, 43.74, 25.77), (29, 2.14, 11.07, 5.42),
             (30, 2.17, 14.51, 6.99), (29, 1.84, 9.22, 4.91), (30, 31.37, 145.32, 80.07)]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    d = ClusterParams()
    parser.add_argument("--objects", choices=["bundled", "paper"], default="bundled",
                        help="the six bundled objects, or the Wan-Harada objects in ../shared")
    parser.add_argument("--repeats", type=int, default=3, help="roadmap builds per object (the median is printed)")
    parser.add_argument("--faces", type=int, default=500, help="triangles after decimation")
    parser.add_argument("--clusters", type=int, default=d.k)
    parser.add_argument("--friction", type=float, default=d.mu)
    parser.add_argument("--pyramid", type=int, default=d.sides)
    parser.add_argument("--seed", type=int, default=d.seed)
    parser.add_argument("--samples", type=int, default=10000)
    parser.add_argument("--picks", type=int, default=30)
    parser.add_argument("--queries", type=int, default=30)


def run(args: argparse.Namespace) -> int:

    objects = [(label, obj) for label, _, obj in bench_objects(args.objects)][:6]
    params = ClusterParams(k=args.clusters, mu=args.friction, sides=args.pyramid, seed=args.seed)
    rows1, rows2, rows3 = [], [], []
    for i, (label, obj) in enumerate(objects):
        contacts = contact_points(obj, ContactParams(faces=args.faces))
        build_planner(contacts, params)                     # warm-up: imports and caches off the clock
        runs = []
        for _ in range(max(1, args.repeats)):
            t0 = time.perf_counter()
            planner = build_planner(contacts, params)
            runs.append((time.perf_counter() - t0, planner.times["clustering"], planner.times["roadmap"]))
        total, clus, road = (float(np.median([r[j] for r in runs])) for j in range(3))
        rm = planner.roadmap
        p1 = PAPER_I[i] if i < len(PAPER_I) else ("-",) * 3
        rows1.append([label, len(contacts), len(rm), rm.ncomponents, road, clus, total, *p1])
        samples = sample_grasps(planner.tester, args.samples, seed=args.seed)
        st = local_planning_stats(planner, samples, picks=args.picks, seed=args.seed)
        p2 = PAPER_II[i] if i < len(PAPER_II) else ("-",) * 5
        rows2.append([label, st.alg1_run, f"{st.alg1_connect}/{st.alg1_picked}", st.alg2_run,
                      f"{st.alg2_connect}/{st.alg2_picked}", f"{st.alg3_connect}/{st.alg3_picked}", *p2])
        qs = random_queries(planner, samples, args.queries, seed=args.seed)
        t = [q.seconds for q in qs]
        p3 = PAPER_III[i] if i < len(PAPER_III) else ("-",) * 4
        rows3.append([label, f"{sum(q.connected for q in qs)}/{len(qs)}", min(t), max(t), float(np.mean(t)), *p3])
    head = (f"k={params.k}, mu={params.mu}, m={params.sides}, ~{args.faces} triangles, {args.samples:,} sampled grasps, "
            f"{args.picks} picks, {args.queries} queries")
    print_table(["object", "#contacts", "#vertex", "#CC", "roadmap s", "clustering s", "total s",
                 "paper #vertex", "paper #CC", "paper s"], rows1,
                title=f"Table I: representative-level roadmap ({head}; median of {args.repeats} builds)")
    print()
    print_table(["object", "alg1 %run", "alg1 #connect", "alg2 %run", "alg2 #connect", "alg3 #connect",
                 "paper 1 %run", "paper 1 #c", "paper 2 %run", "paper 2 #c", "paper 3 #c"], rows2,
                title="Table II: local planning (#connect out of the grasps picked)")
    print()
    print_table(["object", "#connect", "min s", "max s", "average s", "paper #c", "paper min", "paper max", "paper avg"],
                rows3, title="Table III: regrasp queries")
    return 0
