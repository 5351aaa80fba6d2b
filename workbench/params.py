"""Valid ranges of every numeric parameter, declared once on the parameters dataclasses (CONVENTIONS.md, Errors).

A parameter is declared with `param(default, ge=..., le=..., ...)`: the range lives in the dataclass field's
metadata, `Params.__post_init__` checks every field before any work is done, and the command line builds its
options from the same declaration (`add_param`), so the library and the CLI give the same one-line message
naming the parameter, the value, the valid range and a value to try. Relations between fields (min <= max) go in
`Params.check`. Work whose memory can be estimated before it starts is checked against a budget with
`check_memory` (default: half the machine's memory; `--memory-budget` or `WORKBENCH_MEMORY_BUDGET`).
"""

from __future__ import annotations

import argparse
import functools
import math
import os
from dataclasses import MISSING, Field, asdict, dataclass, field, fields, replace
from typing import Any, Callable, TypeVar

__all__ = ["BUDGET_ENV", "DEG", "HAND_SIZED", "PART_SIZE", "SCALE", "check_workers", "WAIT_ENV", "Bound", "MemoryBudgetError", "ParameterError", "Params", "add_param", "bounds", "check_memory", "single_blas", "cli_bound",
           "from_cli", "memory_budget", "param", "parse_number", "parse_size", "validate"]

import numpy as np

from workbench.errors import MemoryBudgetError, ParameterError

F = TypeVar("F", bound=Callable)

BOUND = "workbench.bound"
BUDGET_ENV = "WORKBENCH_MEMORY_BUDGET"
DEG = 180.0 / math.pi  # radians in the library, degrees on the command line (cli_scale)
WAIT_ENV = "WORKBENCH_WAIT"  # seconds to wait for a store another process holds (the command line's --wait)


@dataclass(frozen=True)
class Bound:
    """The valid range of one parameter: bounds (inclusive unless `*_open`), integer or real, optional (None
    allowed), unit and meaning for messages; `flag` and `cli_scale`/`cli_unit` say how the command line spells it
    (e.g. radians in the library, degrees on the command line: cli_scale = 180/pi)."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False
    optional: bool = False
    unit: str = ""
    help: str = ""
    flag: str | None = None
    cli_scale: float = 1.0
    cli_unit: str | None = None

    def describe(self, cli: bool = False) -> str:
        """The range in words, e.g. 'an integer in [1, 360]', '> 0 m', 'a number >= 0 deg'."""
        s = self.cli_scale if cli else 1.0
        unit = (self.cli_unit if cli and self.cli_unit is not None else self.unit)
        unit = f" {unit}" if unit else ""
        kind = "an integer" if self.integer else "a number"
        lo = None if self.lo is None else _fmt(self.lo * s)
        hi = None if self.hi is None else _fmt(self.hi * s)
        if lo is not None and hi is not None:
            text = f"{kind} in {'(' if self.lo_open else '['}{lo}, {hi}{')' if self.hi_open else ']'}{unit}"
        elif lo is not None:
            text = f"{kind} {'>' if self.lo_open else '>='} {lo}{unit}"
        elif hi is not None:
            text = f"{kind} {'<' if self.hi_open else '<='} {hi}{unit}"
        else:
            text = f"a finite {kind[2:] if kind.startswith('a ') else kind[3:]}{unit}"
        return text + (" or none" if self.optional and not cli else "")

    def label(self, name: str) -> str:
        """The library name with the command-line option, e.g. 'neighbour_radius (--neighbour-radius)'."""
        flag = self.flag or "--" + name.replace("_", "-")
        return f"{name} ({flag})"

    def problem(self, value: Any, scale: float = 1.0) -> str | None:
        """Why `value` (in units where the bounds are multiplied by `scale`) is not valid, or None."""
        if value is None:
            return None if self.optional else "is missing"
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            return f"is not a number ({type(value).__name__})"
        v = float(value)
        if not math.isfinite(v):
            return "is not finite"
        if self.integer and v != int(v):
            return "is not an integer"
        if self.lo is not None and (v < self.lo * scale or (self.lo_open and v <= self.lo * scale)):
            return "is out of range"
        if self.hi is not None and (v > self.hi * scale or (self.hi_open and v >= self.hi * scale)):
            return "is out of range"
        return None

    def message(self, name: str, value: Any, problem: str, default: Any = MISSING, cli: bool = False) -> str:
        """'--rotations 0 is out of range: hand rotations about the contact axis must be an integer in [1, 360];
        try 8 (the default)'."""
        label = self.flag if cli and self.flag else self.label(name)
        what = f"{self.help} must be" if self.help else "must be"
        text = f"{label} {_fmt(value)} {problem}: {what} {self.describe(cli)}"
        if default is not MISSING and default is not None:
            shown = default * self.cli_scale if cli and isinstance(default, (int, float)) else default
            text += f"; try {_fmt(shown)} (the default)"
        return text


# Sizes a part may have, in metres after scaling (CONVENTIONS.md, Units): outside PART_SIZE a mesh is refused as
# implausible for a gripper; read in metres without units, one above HAND_SIZED is refused as a likely unit mistake
# unless --accept-size. SCALE: the factor from a file's units to metres (--scale).
PART_SIZE = Bound(lo=0.005, hi=2.0, unit="m", help="a part's largest extent")
HAND_SIZED = Bound(lo=0.01, hi=0.5, unit="m", help="a hand-sized part's largest extent")
SCALE = Bound(lo=0.0, hi=1e3, lo_open=True, help="the scale", flag="--scale")


def param(default: Any = MISSING, *, ge: float | None = None, gt: float | None = None, le: float | None = None,
          lt: float | None = None, integer: bool = False, optional: bool = False, unit: str = "", help: str = "",
          flag: str | None = None, cli_scale: float = 1.0, cli_unit: str | None = None, **kwargs: Any) -> Any:
    """A dataclass field with a declared range (checked by `Params.__post_init__`, reused by `add_param`)."""
    if ge is not None and gt is not None or le is not None and lt is not None:
        raise ValueError("give ge or gt, le or lt, not both")
    bound = Bound(lo=ge if gt is None else gt, hi=le if lt is None else lt, lo_open=gt is not None,
                  hi_open=lt is not None, integer=integer, optional=optional, unit=unit, help=help, flag=flag,
                  cli_scale=cli_scale, cli_unit=cli_unit)
    return field(default=default, metadata={BOUND: bound}, **kwargs)


def bounds(cls_or_obj: Any) -> dict[str, tuple[Bound, Any]]:
    """Every declared range of a parameters dataclass: name -> (Bound, default)."""
    out = {}
    for f in fields(cls_or_obj):
        if BOUND in f.metadata:
            out[f.name] = (f.metadata[BOUND], _default(f))
    return out


def validate(obj: Any) -> None:
    """Check every declared range of `obj` (elementwise for tuples), then its `check()` relations."""
    for name, (bound, default) in bounds(obj).items():
        value = getattr(obj, name)
        values = value if isinstance(value, (tuple, list)) else (value,)
        for v in values:
            problem = bound.problem(v)
            if problem is not None:
                raise ParameterError(f"{type(obj).__name__}: " + bound.message(name, v, problem, default))
    check = getattr(obj, "check", None)
    if check is not None:
        check()


@dataclass(frozen=True)
class Params:
    """Base of the parameters dataclasses: declared ranges checked at construction; `check` for relations."""

    def __post_init__(self) -> None:
        validate(self)

    def check(self) -> None:
        """Relations between fields; raise ParameterError naming both (override, use `require`)."""

    def require(self, ok: bool, names: tuple[str, ...], rule: str) -> None:
        """Raise a ParameterError naming the fields (and their options) when a relation `rule` does not hold."""
        if not ok:
            b = bounds(self)
            shown = ", ".join(f"{b[n][0].label(n) if n in b else n} = {_fmt(getattr(self, n))}" for n in names)
            raise ParameterError(f"{type(self).__name__}: {shown}: {rule}")

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "Params":
        """The inverse of `as_dict` (a stored parameter set); keys that are not fields (the ids of the parameter sets
        a stage consumed) are ignored."""
        names = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in names})


# ---------------------------------------------------------------------------------------------------------------
# Command line: options built from the same declarations.


def parse_number(bound: Bound, label: str, default: Any = MISSING) -> Callable[[str], float | int]:
    """An argparse `type`: text -> number in command-line units, refused with the range's one-line message
    (`default` in library units, suggested in the message)."""
    if bound.flag != label:
        bound = replace(bound, flag=label)

    def parse(text: str) -> float | int:
        try:
            value: float | int = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"{text!r} is not a number: {bound.help + ' ' if bound.help else ''}must be {bound.describe(True)}") from None
        if bound.integer and math.isfinite(value) and value == int(value):
            value = int(value)
        problem = bound.problem(value, bound.cli_scale)
        if problem is not None:
            # argparse prefixes "argument --flag:", so the message starts at the value
            msg = bound.message(label, value, problem, default, cli=True)
            raise argparse.ArgumentTypeError(msg.split(" ", 1)[1] if msg.startswith(label + " ") else msg)
        return value

    parse.__name__ = "number"
    return parse


def add_param(parser: argparse.ArgumentParser, cls: type, name: str, flag: str | None = None, default: Any = MISSING,
              help: str | None = None, cli_default: Any = MISSING, **kwargs: Any) -> argparse.Action:
    """Add the option of `cls.name` to `parser`: its range checked while parsing and shown in --help.

    The value is in command-line units (`cli_scale`); convert with `from_cli` when building the dataclass.
    `cli_default` gives the default in command-line units directly (else `default`, or the field's, scaled)."""
    bound, lib_default = bounds(cls)[name]
    flag = flag or bound.flag or "--" + name.replace("_", "-")
    shown = lib_default if default is MISSING else default
    scaled = bound.cli_scale != 1.0 and isinstance(shown, (int, float)) and not isinstance(shown, bool)
    if cli_default is MISSING:
        cli_default = shown * bound.cli_scale if scaled else shown
    text = (help if help is not None else bound.help) or name
    extra = f"; default {_fmt(cli_default)}" if cli_default is not None else ""
    if bound.lo is not None and bound.lo < 0 or bound.hi is not None and bound.hi < 0:
        extra += f"; negative values parse ({flag} -1 or {flag}=-1)"
    return parser.add_argument(flag, type=parse_number(bound, flag, shown), default=cli_default, metavar="N" if bound.integer else "X",
                               help=f"{text} ({bound.describe(True)}{extra})", **kwargs)


def cli_bound(lo: float | None = None, hi: float | None = None, *, integer: bool = False, unit: str = "", help: str = "",
              lo_open: bool = False, optional: bool = False) -> Bound:
    """A range for an option that is not a dataclass field (e.g. `--queries`), for `parse_number`."""
    return Bound(lo=lo, hi=hi, lo_open=lo_open, integer=integer, unit=unit, help=help, optional=optional)


def from_cli(cls: type, name: str, value: Any) -> Any:
    """A command-line value of `cls.name` in library units (undoes `cli_scale`, e.g. degrees to radians)."""
    bound = bounds(cls)[name][0]
    if value is None or bound.cli_scale == 1.0:
        return value
    return float(value) / bound.cli_scale


# ---------------------------------------------------------------------------------------------------------------
# Memory budget.


def machine_memory() -> int:
    """Physical memory in bytes (the cgroup limit when lower)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    try:
        with open("/sys/fs/cgroup/memory.max") as fh:
            text = fh.read().strip()
        if text.isdigit():
            total = min(total, int(text))
    except OSError:
        pass
    return int(total)


def parse_size(text: str | float | int) -> int:
    """'2GiB', '512M', '1.5g' or a number of bytes -> bytes."""
    if isinstance(text, (int, float)):
        return int(text)
    t = text.strip().lower().removesuffix("b").removesuffix("i")
    factor = {"k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}.get(t[-1:], 1)
    try:
        value = float(t[:-1] if factor > 1 else t)
    except ValueError:
        raise ParameterError(f"memory budget {text!r} is not a size; give bytes or a size such as 4GiB") from None
    if not math.isfinite(value) or value <= 0:
        raise ParameterError(f"memory budget {text!r} must be positive, such as 4GiB")
    return int(value * factor)


def memory_budget(budget: int | str | None = None) -> int:
    """The memory budget in bytes: `budget` if given, else WORKBENCH_MEMORY_BUDGET, else half the machine's memory."""
    if budget is not None:
        return parse_size(budget)
    env = os.environ.get(BUDGET_ENV)
    if env:
        return parse_size(env)
    return machine_memory() // 2


def check_memory(nbytes: float, what: str, hint: str, budget: int | str | None = None) -> None:
    """Refuse work estimated at `nbytes` above the budget, in one line naming the work and what to lower."""
    limit = memory_budget(budget)
    if nbytes > limit:
        raise MemoryBudgetError(f"{what} needs about {format_bytes(nbytes)}, above the memory budget of {format_bytes(limit)} "
                                f"(default half this machine's memory; --memory-budget or {BUDGET_ENV}); {hint}")


WORKER_BYTES = 200 * 2**20  # one worker process with the library imported (numpy, pinocchio, coal, DuckDB): ~150-200 MiB RSS


def check_workers(n: int, budget: int | str | None = None) -> None:
    """Refuse more worker processes than the memory budget holds (each about WORKER_BYTES), before any starts."""
    limit = memory_budget(budget)
    check_memory(n * WORKER_BYTES, f"--workers {n} ({format_bytes(WORKER_BYTES)} per worker process)",
                 f"give --workers {max(1, int(limit // WORKER_BYTES))} or fewer", budget)


_POOLS: list = []  # threadpoolctl's view of the loaded BLAS and OpenMP libraries, taken at the first call


def single_blas(fn: F) -> F:
    """Run `fn` with the BLAS and OpenMP thread pools limited to one thread (threadpoolctl).

    The workbench's arrays are many small ones or long (N, 3) ones, where a pool gains nothing; its threads spin
    after every call, taking the core that the workbench's own second thread or another worker needs (a
    245,760-triangle part's grasps took 20% more CPU with OpenBLAS's pool; a 500 x 500 eigensolve took seconds
    instead of milliseconds). The libraries are looked up once per process, so the limit costs microseconds."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        if not _POOLS:
            from threadpoolctl import ThreadpoolController

            _POOLS.append(ThreadpoolController())
        with _POOLS[0].limit(limits=1):
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def format_bytes(n: float) -> str:
    """A byte count in binary units (KiB, MiB, GiB, TiB)."""
    for unit, f in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= f:
            return f"{n / f:.1f} {unit}"
    return f"{int(n)} B"


def _fmt(value: Any) -> str:
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if math.isfinite(value) and value == int(value) and abs(value) < 1e15:
            return str(int(value))
        return f"{value:.6g}"
    return str(value)


def _default(f: Field) -> Any:
    if f.default is not MISSING:
        return f.default
    if f.default_factory is not MISSING:  # type: ignore[misc]
        return f.default_factory()  # type: ignore[misc]
    return MISSING
