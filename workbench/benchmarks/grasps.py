"""Grasp planning (Section III) beside Table I's #-fg and t-fg."""

from __future__ import annotations

import argparse

from workbench.benchmarks import median_time, print_table
from workbench.benchmarks.paper import TABLE_I, bench_objects
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.robots.gripper import franka_hand


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--repeats", type=int, default=3, help="runs per object (the median is printed)")
    parser.add_argument("--objects", choices=["all", "bundled", "paper"], default="all")


def run(args: argparse.Namespace) -> int:
    hand = franka_hand()
    rows = []
    for label, row, obj in bench_objects(args.objects):
        conv = plan_grasps(obj, hand, GraspParams(segmentation="conventional"))
        t, plan = median_time(lambda: plan_grasps(obj, hand, GraspParams()), args.repeats)
        c = plan.counts
        paper = TABLE_I.get(row)
        rows.append([label, c["triangles"], conv.counts["facets"], c["facets"], c["samples"], c["samples_neighbour"],
                     c["facet_samples_distance"], c["contact_pairs"], c["pairs_level1"], len(conv.grasps), c["grasps"],
                     t, paper[1] if paper else "-", paper[2] if paper else "-"])
    print_table(["object", "#-tri", "facets conv", "facets over", "samples", "after nbr", "after dist", "pairs",
                 "pairs L1", "#-fg conv", "#-fg", "t-fg s", "paper #-fg", "paper t-fg s"], rows,
                title=f"Grasp planning, Franka hand, over-segmentation (median of {args.repeats} runs; Table I beside)")
    return 0
