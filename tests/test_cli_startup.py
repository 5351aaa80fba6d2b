"""The command line starts fast (each command's module imported only when it runs), and no user-facing text cites
the project's issue tracker."""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

from workbench.cli.main import COMMANDS, build_parser

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("trimesh", "meshcat", "pinocchio", "duckdb", "IPython", "fcl", "dask", "scipy")
CITATION = re.compile(r"\b[Ii]ssues?\s+#?\d+")


def _imported_by(*argv: str) -> set[str]:
    code = ("import sys; from workbench.cli.main import build_parser; p = build_parser(sys.argv[1:]);\n"
            "try:\n p.parse_args(sys.argv[1:])\nexcept SystemExit:\n pass\n"
            "print('\\n'.join(sys.modules))")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, cwd=ROOT, check=True)
    return {line.split(".")[0] for line in out.stdout.splitlines()}


def test_top_level_help_imports_no_command():
    mods = _imported_by("--help")
    assert not mods & set(HEAVY), sorted(mods & set(HEAVY))
    assert "workbench" in mods


def test_a_command_imports_only_what_it_needs():
    mods = _imported_by("bench", "--help")
    assert not mods & set(HEAVY), sorted(mods & set(HEAVY))
    assert "trimesh" in _imported_by("grasps", "--help")


def _parsers(parser: argparse.ArgumentParser, path: str = "workbench"):
    yield path, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, child in action.choices.items():
                yield from _parsers(child, f"{path} {name}")


def test_each_command_registers_the_help_the_table_lists():
    full = build_parser(full=True)
    sub = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    assert helps == COMMANDS
    lazy = build_parser(["plan"])
    assert sorted(next(a for a in lazy._actions if isinstance(a, argparse._SubParsersAction)).choices) == sorted(COMMANDS)


def test_no_user_facing_text_cites_an_issue():
    found = []
    for path, parser in _parsers(build_parser(full=True)):
        text = parser.format_help()
        found += [f"{path} --help: {m.group(0)}" for m in CITATION.finditer(text)]
    texts = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    for p in texts:
        found += [f"{p.relative_to(ROOT)}: {m.group(0)}" for m in CITATION.finditer(p.read_text())]
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for cell in json.loads(nb.read_text())["cells"]:
            found += [f"{nb.name}: {m.group(0)}" for m in CITATION.finditer("".join(cell["source"]))]
    for py in sorted((ROOT / "workbench").rglob("*.py")):  # docstrings and messages reach users (the API docs)
        found += [f"{py.relative_to(ROOT)}: {m.group(0)}" for m in CITATION.finditer(py.read_text())]
    assert not found, found[:20]


def test_a_newcomers_slips_get_one_line_naming_what_to_type(capsys):
    """No option abbreviations (plan's --start given to gpplan is refused, not read as --start-held), an unknown
    option points to the command's help, a command without its subcommand names them, and --version answers."""
    from workbench.cli.main import main

    cases = [(["gpplan", "--db", "x.duckdb", "--start", "1,0.45,0.1,0"],
              "unrecognized arguments: --start 1,0.45,0.1,0 (`workbench gpplan --help` lists its options)"),
             (["grasps", "part.stl", "--db", "x.duckdb", "--unit", "mm"], "unrecognized arguments: --unit mm"),
             (["bench"], "name one of: grasps, placements, ik,"),
             (["catalog"], "name one of: build, report")]
    for argv, words in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err
    assert main(["--version"]) == 0
    assert re.fullmatch(r"workbench \d+\.\d+\.\d+", capsys.readouterr().out.strip())
