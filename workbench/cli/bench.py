"""`workbench bench WHAT`: benchmark tables (median of several runs) beside the papers' numbers."""

from __future__ import annotations

import argparse
import importlib

# Each benchmark and its one-line help; its module (workbench.benchmarks.NAME) is imported only when it runs.
BENCHES = {
    "grasps": "grasp planning beside Table I's #-fg and t-fg, and on the organic set",
    "placements": "placements and the tabletop roadmap data beside Table I",
    "ik": "IK feasibility time per robot (t-tpgik) beside Table I",
    "regrasp": "regrasp search time and regrasp count beside Table I",
    "motion": "motion planning and timing of searched regrasp plans",
    "simulate": "searched regrasp plans replayed in MuJoCo: share confirmed, failures by kind, speed",
    "fingers": "five-finger regrasp by contact-point clustering beside Tables I-III",
    "gptable": "the grasp-placement table: classes, build times, chaining, closed-form IK",
    "catalog": "catalogue build on a local Dask cluster: speed-up, the driver's load, simulated workers, cost model",
    "widgets": "notebook widgets driven headless: latency from a change to the scene's update",
    "grippers": "a real gripper model (MJCF, driven in MuJoCo) beside the bundled spec that stands for it",
}


def register(sub: argparse._SubParsersAction, argv: list[str] | None = None) -> None:
    """`bench` and its benchmarks; with `argv`, only the benchmark it names is imported (the others are listed)."""
    parser = sub.add_parser("bench", help="print a benchmark table beside the papers' numbers")
    inner = parser.add_subparsers(dest="bench", required=True, parser_class=type(parser))
    words = [t for t in (argv or []) if not t.startswith("-")]
    chosen = words[1] if argv is not None and len(words) > 1 and words[0] == "bench" else None
    for name in BENCHES:
        if argv is not None and name != chosen:
            inner.add_parser(name, help=BENCHES[name], add_help=False)
            continue
        try:
            module = importlib.import_module(f"workbench.benchmarks.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"workbench.benchmarks.{name}":
                continue
            raise
        p = inner.add_parser(name, help=BENCHES[name], description=module.__doc__)
        module.add_arguments(p)
        p.set_defaults(func=module.run)
