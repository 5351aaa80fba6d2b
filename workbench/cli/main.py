"""The `workbench` command line. Each subcommand lives in `workbench.cli.<name>` with `register(subparsers)`;
the command line only parses arguments and prints: the work is done by `workbench.planners.*.stages`.

Bad input prints one line and exits with status 2 (CONVENTIONS.md, Errors).
"""

from __future__ import annotations

import os
import signal
import sys

import workbench  # noqa: E402
from workbench import _stopped_while_loading  # noqa: E402

# Loading the command line is the slow part of a start (under load a second or more). A Ctrl-C in it has started
# nothing, so it ends the process at once: raised as KeyboardInterrupt inside an extension's import, numpy's among
# them, it would surface as an ImportError with a traceback instead. The package installs the handler first when it
# is run as the command line; imported by a test or a script, this module does.
_SIGINT = signal.getsignal(signal.SIGINT)
if _SIGINT is _stopped_while_loading:
    _SIGINT = workbench.SIGINT_BEFORE_LOADING
elif _SIGINT is signal.default_int_handler:
    try:
        signal.signal(signal.SIGINT, _stopped_while_loading)
    except ValueError:  # imported outside the main thread: Python's default stays
        _SIGINT = None

import argparse  # noqa: E402
import importlib  # noqa: E402
import inspect  # noqa: E402
import re  # noqa: E402
import threading  # noqa: E402
import warnings  # noqa: E402

import numpy  # noqa: E402, F401

from workbench.errors import WorkbenchError
from workbench.params import BUDGET_ENV, WAIT_ENV, check_workers, cli_bound, parse_number, parse_size

if _SIGINT is signal.default_int_handler:
    signal.signal(signal.SIGINT, _SIGINT)

WAIT = cli_bound(0, 86400, unit="s", help="seconds to wait for a store another process holds")

# Every command and its one-line help. A command's module is imported only when that command runs, so
# `workbench --help` and each command's start-up stay fast; `tests/test_cli_startup.py` checks that each module's own
# help matches this table.
COMMANDS = {
    "grasps": "plan free-air grasps of a mesh and store them",
    "placements": "compute and store placements and the tabletop roadmap data",
    "ik": "IK feasibility of every tabletop grip for a robot (paper Section IV: ik, ikret)",
    "build": "run every stage for a mesh and a robot (grasps, placements, IK, regrasp graph)",
    "catalog": "build a parts x robots catalogue on a Dask cluster, or print one",
    "plan": "plan regrasps from a start to a goal pose on the table",
    "simulate": "replay a stored plan in MuJoCo physics: does the part stay in the hand and end at its goal?",
    "fingers": "five-finger regrasp roadmap by contact-point clustering (Tables I-III)",
    "gptable": "grasp classes and the grasp-placement table (Tournassoud et al. 1987)",
    "gpplan": "regrasp sequence by backward chaining in the grasp-placement table (Tournassoud et al.)",
    "demo": "build a bundled object, plan a regrasp task and write the animation",
    "bench": "print a benchmark table beside the papers' numbers",
}


# A token such as -0.3,0.3,3 or -1e-3 is a value, not an option (no option of ours starts with a digit), so
# `--y -0.3,0.3,3` parses as well as `--y=-0.3,0.3,3`.
NEGATIVE = re.compile(r"^-\.?\d")


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs) -> None:
        # no abbreviations: `plan`'s --start given to `gpplan` must be refused, not taken for its --start-held
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE

    def error(self, message: str) -> None:  # one line, status 2, like WorkbenchError
        command = getattr(self, "command", None)
        if command and message.startswith("unrecognized arguments"):
            message += f" (`workbench {command} --help` lists its options)"
        missing = re.fullmatch(r"the following arguments are required: (\w+)", message)
        subs = [a for a in self._actions
                if isinstance(a, argparse._SubParsersAction) and a.dest == (missing and missing[1])]
        if subs:  # a command without its subcommand: name them
            message = f"name one of: {', '.join(subs[0].choices)} (`{self.prog} --help` says what each does)"
        self.exit(2, f"{self.prog}: error: {message}\n")


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("regrasp-workbench")
    except PackageNotFoundError:  # run from a source tree that is not installed
        return "(not installed)"


def _budget(text: str) -> int:
    try:
        return parse_size(text)
    except WorkbenchError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _selected(argv: list[str]) -> str | None:
    """The command named on the command line: the first token that is not an option."""
    for token in argv:
        if not token.startswith("-"):
            return token if token in COMMANDS else None
    return None


def build_parser(argv: list[str] | None = None, full: bool = False) -> argparse.ArgumentParser:
    """The command line's parser. Only the command named in `argv` is registered with its options (its module
    imported); the others are listed with their help. `full` registers every command (the CLI reference)."""
    parser = _Parser(prog="workbench", description="Regrasp planning workbench. Negative values parse as they are "
                                                   "(--y -0.3,0.3,3) or joined with = (--y=-0.3,0.3,3).")
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    chosen = None if full else _selected(sys.argv[1:] if argv is None else argv)
    parser.command = chosen
    for name, text in COMMANDS.items():
        if full or name == chosen:
            register = importlib.import_module(f"workbench.cli.{name}").register
            if "argv" in inspect.signature(register).parameters:  # a command with lazily imported subcommands
                register(sub, argv=None if full else (sys.argv[1:] if argv is None else argv))
            else:
                register(sub)
        else:
            sub.add_parser(name, help=text, add_help=False)
    for name, parent in sub.choices.items():
        if not (full or name == chosen):
            continue
        # a command with subcommands (catalog build, ...) takes the options after its subcommand, as the others do
        nested = [a for a in parent._actions if isinstance(a, argparse._SubParsersAction)]
        for child in [p for a in nested for p in a.choices.values()] or [parent]:
            child.add_argument("--memory-budget", type=_budget, default=None, metavar="SIZE",
                               help=f"largest memory a step may plan to use, e.g. 4GiB (default: half this machine's "
                                    f"memory, or {BUDGET_ENV}); larger work is refused before it starts")
            child.add_argument("--wait", type=parse_number(WAIT, "--wait"), default=None, metavar="SECONDS",
                               help=f"when another process holds the store, wait up to SECONDS for it "
                                    f"({WAIT.describe(True)}; default 0: say it is busy and stop; or {WAIT_ENV})")
    return parser


class _CtrlC:
    """While the command's modules load, SIGINT is only noted, so no KeyboardInterrupt lands inside an extension's
    import or in a library that catches everything there (trimesh does); `loaded()` then stops a noted Ctrl-C. After
    that SIGINT raises KeyboardInterrupt, as Python's default does, and is still noted: a library that swallows it
    cannot make a Ctrl-C'd command end as if it had finished. A KeyboardInterrupt raised where Python cannot pass
    it on (a finaliser, such as llvmlite's when numba loads a kernel) is not reported as an ignored exception: it is
    noted, and the command stops with its one line."""

    def __init__(self) -> None:
        self.seen = False
        self.loading = True
        self.old = None
        self.old_hook = None

    def __enter__(self) -> "_CtrlC":
        if threading.current_thread() is threading.main_thread():
            self.old = signal.signal(signal.SIGINT, self._handle)
            self.old_hook = sys.unraisablehook
            sys.unraisablehook = self._unraisable
        return self

    def _unraisable(self, unraisable) -> None:
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            self.seen = True
            return
        self.old_hook(unraisable)

    def _handle(self, signum, frame) -> None:
        self.seen = True
        if not self.loading:
            raise KeyboardInterrupt

    def loaded(self) -> None:
        """The modules are loaded: a Ctrl-C noted meanwhile raises KeyboardInterrupt now, and later ones at once."""
        self.loading = False
        if self.seen:
            raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        if self.old is not None:
            signal.signal(signal.SIGINT, self.old)
            sys.unraisablehook = self.old_hook


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns its exit status (2 for bad input, argparse's refusals included)."""
    with _CtrlC() as ctrl_c:
        status = _main(argv, ctrl_c)
    if ctrl_c.seen and status == 0:  # the command went on to the end, but the user asked it to stop
        name = _selected(sys.argv[1:] if argv is None else argv) or ""
        print(f"workbench {name}: interrupted; the store keeps only completed stages".replace("  ", " "), file=sys.stderr)
        return 130
    return status


def _main(argv: list[str] | None, ctrl_c: _CtrlC) -> int:
    try:
        parser = build_parser(argv)
        ctrl_c.loaded()
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help (0) or a refused option (2, one line already printed)
        return exc.code if isinstance(exc.code, int) else 0
    except KeyboardInterrupt:  # Ctrl-C while the command's modules load: nothing started yet
        name = _selected(sys.argv[1:] if argv is None else argv) or ""
        print(f"workbench {name}: interrupted; the store keeps only completed stages".replace("  ", " "), file=sys.stderr)
        return 130

    def one_line(message, category, *_args, **_kwargs) -> None:  # warnings: one line each, no source excerpt
        print(f"workbench {args.command}: warning: {message}", file=sys.stderr)

    warnings.showwarning = one_line
    if getattr(args, "memory_budget", None):
        os.environ[BUDGET_ENV] = str(args.memory_budget)  # inherited by worker processes
    if getattr(args, "wait", None) is not None:
        os.environ[WAIT_ENV] = str(args.wait)  # read where the store is opened (workbench.store.Store)
    try:
        if getattr(args, "workers", None):
            check_workers(args.workers)  # every command's worker pool, before any process starts
        return int(args.func(args) or 0)
    except WorkbenchError as exc:
        print(f"workbench {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"workbench {args.command}: error: out of memory; lower the sizes of this run (grid, angles, rotations, "
              f"density) or give --memory-budget below the free memory", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"workbench {args.command}: interrupted; the store keeps only completed stages", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
