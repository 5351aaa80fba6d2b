"""`workbench fingers MESH --db DB`: five-finger regrasp roadmap by contact-point clustering (Phoka & Sudsang).

Builds and stores T_O, the clusters, T_R, E and the representative-level roadmap R, samples force-closure
grasps, runs Algorithms 1-3 and N random queries, and prints the numbers of Tables I-III.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import TYPE_CHECKING

from workbench.benchmarks import print_table
from workbench.cli.grasps import add_object_arguments
from workbench.cli.outputs import add_output, write_text
from workbench.geometry.objects import load_object
from workbench.params import add_param, cli_bound, parse_number
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.phoka_sudsang.contacts import ContactParams
from workbench.planners.phoka_sudsang.stages import run_pipeline, tables

if TYPE_CHECKING:
    from workbench.store.phoka_sudsang import ContactIds


def add_finger_arguments(parser: argparse.ArgumentParser) -> None:
    """Contact, clustering and experiment parameters (Section IV's defaults)."""
    add_param(parser, ContactParams, "faces", help="decimate the mesh to about this many triangles (0: keep it)")
    for name in ("k", "mu", "sides"):
        add_param(parser, ClusterParams, name)
    parser.add_argument("--torque-scale", choices=["none", "radius"], default=ClusterParams().torque_scale,
                        help="torque arms of d(i, j): none (the paper's formula, metres) or divided by the object's radius")
    add_param(parser, ClusterParams, "seed", help="seed of k-means and of the sampled grasps and queries")
    for flag, default, bound in (("--samples", 10000, SAMPLES), ("--picks", 30, PICKS), ("--queries", 30, QUERIES)):
        parser.add_argument(flag, type=parse_number(bound, flag, default), default=default, metavar="N",
                            help=f"{bound.help} ({bound.describe(True)}; default {default})")


SAMPLES = cli_bound(0, 1_000_000, integer=True, help="sampled force-closure grasps (Table II)")
PICKS = cli_bound(0, 100_000, integer=True, help="grasps picked per algorithm (Table II)")
QUERIES = cli_bound(0, 100_000, integer=True, help="random start/goal queries (Table III)")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("fingers", help="five-finger regrasp roadmap by contact-point clustering (Tables I-III)")
    add_object_arguments(parser)
    parser.add_argument("--db", required=True, help="DuckDB store file")
    add_finger_arguments(parser)
    parser.add_argument("--algorithm3", choices=["update", "one-off"], default="update",
                        help="update: Algorithm 3 adds to R for good, stored and reused by later queries (the paper); "
                             "one-off: each query's extension is forgotten")
    add_output(parser, "--json", "write the tables and every query's sequence to this JSON file")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sklearn.cluster  # noqa: F401  (loaded before the clock starts on clustering)


    obj = load_object(args.mesh, scale=args.scale, units=args.units, name=args.name, accept_size=args.accept_size)
    params = ClusterParams(k=args.clusters, mu=args.friction, sides=args.pyramid, seed=args.seed, torque_scale=args.torque_scale)
    t0 = time.perf_counter()
    r = run_pipeline(args.db, obj, ContactParams(faces=args.faces or None), params, args.samples, args.picks, args.queries,
                     progress=sys.stderr.isatty(), persistent=args.algorithm3 == "update")
    dt = time.perf_counter() - t0
    tab = tables(r)
    n = len(r.planner.contacts)
    print(f"{obj.name}: {obj.n_triangles} triangles -> {n} contact points; k={params.k}, mu={params.mu}, m={params.sides}, "
          f"seed={params.seed}, torque arms {'/ radius' if params.torque_scale == 'radius' else 'in metres (the paper)'}")
    t1 = tab["table1"]
    print_table(["#vertex", "#edge", "#CC", "clustering s", "roadmap s"],
                [[t1["vertex"], t1["edges"], t1["cc"], t1["seconds_clustering"], t1["seconds_roadmap"]]],
                title="Table I: representative-level roadmap" + (" (reused from the store)" if r.reused[0] else ""))
    if "table2" in tab:
        t2, t3 = tab["table2"], tab["table3"]
        print()
        print_table(["samples", "alg1 %run", "alg1 #connect", "alg2 %run", "alg2 #connect", "alg3 #connect"],
                    [[t2["samples"], t2["alg1_run"], f"{t2['alg1_connect']}/{t2['alg1_picked']}", t2["alg2_run"],
                      f"{t2['alg2_connect']}/{t2['alg2_picked']}", f"{t2['alg3_connect']}/{t2['alg3_picked']}"]],
                    title="Table II: local planning" + (" (reused from the store)" if r.reused[1] else ""))
        print()
        print_table(["#connect", "min s", "max s", "average s"],
                    [[f"{t3['connect']}/{t3['queries']}", t3["min"] if t3["min"] is not None else "-",
                      t3["max"] if t3["max"] is not None else "-", t3["average"] if t3["average"] is not None else "-"]],
                    title=f"Table III: regrasp queries (Algorithm 3: {args.algorithm3}; R has {t1['vertex_updated']:,} vertices "
                          f"after {t1['updates']} stored update(s))")
    print(f"\nstore {args.db}: contacts paramset {r.idcontacts}, roadmap paramset {r.idroadmap}"
          + (f", queries paramset {r.idqueries}" if r.idqueries else "") + f" ({dt:.2f} s)")
    if args.json:
        doc = {"object": obj.name, "contacts": n, "params": {"faces": args.faces, "k": params.k, "mu": params.mu,
                                                             "sides": params.sides, "seed": params.seed,
                                                             "torque_scale": params.torque_scale, "algorithm3": args.algorithm3},
               "paramsets": {"contacts": r.idcontacts, "roadmap": r.idroadmap, "queries": r.idqueries}, **tab,
               "queries": [_query_json(q, r.ids) for q in (r.stats.queries if r.stats else [])]}
        write_text(args.json, json.dumps(doc, indent=1))
        print(f"json: {args.json}")
    return 0


def _query_json(q, ids: "ContactIds") -> dict:
    """A query with contacts as stored idfingercontact ids; `sequence` is a list of grasps of four ids."""
    return {"start": ids.to_ids(q.start).tolist(), "goal": ids.to_ids(q.goal).tolist(), "connected": q.connected,
            "start_method": q.start_method, "goal_method": q.goal_method, "seconds": q.seconds,
            "sequence": None if q.sequence is None else ids.to_ids(q.sequence).tolist()}
