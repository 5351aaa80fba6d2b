"""`workbench bench WHAT`: benchmark tables (median of several runs) beside the papers' numbers."""

from __future__ import annotations

import argparse
import importlib

BENCHES = ("grasps", "placements", "ik", "regrasp", "motion", "fingers", "gptable", "catalog", "widgets")


def register(sub: argparse._SubParsersAction) -> None:
    parser = sub.add_parser("bench", help="print a benchmark table beside the papers' numbers")
    inner = parser.add_subparsers(dest="bench", required=True, parser_class=type(parser))
    for name in BENCHES:
        try:
            module = importlib.import_module(f"workbench.benchmarks.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"workbench.benchmarks.{name}":
                continue
            raise
        p = inner.add_parser(name, help=module.__doc__.splitlines()[0] if module.__doc__ else name)
        module.add_arguments(p)
        p.set_defaults(func=module.run)
