"""The `workbench` command line. Each subcommand lives in `workbench.cli.<name>` with `register(subparsers)`;
the command line only parses arguments and prints: the work is done by `workbench.planners.*.stages`.

Bad input prints one line and exits with status 2 (CONVENTIONS.md, Errors).
"""

from __future__ import annotations

import argparse
import importlib
import sys

from workbench.errors import WorkbenchError

COMMANDS = ("grasps", "placements", "ik", "build", "catalog", "plan", "fingers", "gptable", "gpplan", "demo", "bench")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, status 2, like WorkbenchError
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="workbench", description="Regrasp planning workbench.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name in COMMANDS:
        importlib.import_module(f"workbench.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except WorkbenchError as exc:
        print(f"workbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"workbench {args.command}: interrupted; the store keeps only completed stages", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
