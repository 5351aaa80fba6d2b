"""MkDocs hooks: pages generated from the code at build time, so they cannot drift from it.

- `cli.md`: every command's and subcommand's options, from the argparse parser itself;
- `store.md`: every table and column of a new store, from DuckDB;
- `api/*.md`: one page per package, rendered by mkdocstrings from the docstrings;
- `notebooks/*.ipynb`: the notebooks, rendered by mkdocs-jupyter (not executed).
A public module-level function or class without a docstring is logged as a warning, which `mkdocs build --strict`
turns into a failure.
"""

from __future__ import annotations

import argparse
import ast
import logging
from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]
log = logging.getLogger("mkdocs.plugins.workbench")

API = {
    "geometry": "Meshes: loading, repair, over-segmentation, sampling, supports, collision",
    "grasping": "Parallel-jaw grasps and stable placements",
    "robots": "Grippers, robot models, IK, collision, motion planning and timing",
    "planners.wan_harada": "Wan & Harada: the regrasp roadmap and its search",
    "planners.phoka_sudsang": "Phoka & Sudsang: five-finger contact-point clustering",
    "planners.tournassoud": "Tournassoud, Lozano-Perez & Mazer: the grasp-placement table",
    "store": "The DuckDB store",
    "catalog": "Catalogues of parts x robots on Dask",
    "simulation": "Plans replayed in MuJoCo",
    "viewer": "meshcat scenes",
    "widgets": "Notebook widgets",
    "validation": "The independent plan validator",
    "params": "Declared parameters",
    "errors": "Errors",
}


def _modules(package: str) -> list[str]:
    base = ROOT / "workbench" / Path(*package.split("."))
    if base.with_suffix(".py").is_file():
        return [f"workbench.{package}"]
    if not base.is_dir():
        return []
    out = []
    for p in sorted(base.glob("*.py")):
        if not p.name.startswith("_"):  # the package's own and its private (compiled kernel) modules are not API
            out.append(f"workbench.{package}.{p.stem}")
    return out


def _check_docstrings(module: str) -> None:
    path = ROOT / Path(*module.split(".")).with_suffix(".py")
    tree = ast.parse(path.read_text())
    if not ast.get_docstring(tree):
        log.warning(f"{module}: the module has no docstring")
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            if not ast.get_docstring(node):
                log.warning(f"{module}.{node.name} (line {node.lineno}) is public and has no docstring")


def _api_page(package: str, title: str) -> str:
    lines = [f"# `workbench.{package}`", "", title + ".", ""]
    for module in _modules(package):
        _check_docstrings(module)
        lines += [f"## `{module}`", "", f"::: {module}", "    options:", "      show_root_heading: false",
                  "      heading_level: 3", ""]
    return "\n".join(lines)


def _cli_page() -> str:
    from workbench.cli.main import build_parser

    lines = ["# Command line reference", "",
             "Generated from the `workbench` command's own parser. Every command also prints this with `--help`.",
             "Lengths are in metres and angles in degrees unless an option says otherwise; each option's valid",
             "range is part of its help.", ""]

    def walk(parser: argparse.ArgumentParser, path: str, depth: int) -> None:
        lines.extend([f"{'#' * min(depth, 4)} `{path}`", "", "```text", parser.format_help().rstrip(), "```", ""])
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, child in action.choices.items():
                    walk(child, f"{path} {name}", depth + 1)

    parser = build_parser(full=True)
    parser.formatter_class = argparse.HelpFormatter
    walk(parser, "workbench", 2)
    return "\n".join(lines)


def _store_page() -> str:
    from workbench.store import schema
    from workbench.store.reference import table_columns

    paper = ("object", "robot", "freeairgrip", "freetabletopplacement", "freetabletopgrip", "angle",
             "tabletopplacements", "tabletopgrips", "ikret", "ik")
    tables = table_columns()
    lines = ["# The store's schema", "",
             "One DuckDB file holds every stage's rows. The ten tables of Wan & Harada keep their names and",
             "columns; the others hold parameter sets, the gripper, scenes, plans and the other planners' results.",
             "Poses are `DOUBLE[16]` row-major 4x4 transforms, points and normals `DOUBLE[3]`, lengths in metres,",
             "angles in radians. The tables below are read from a new, empty store, so they are always current.", "",
             "## What the tables mean", "", "```text", (schema.__doc__ or "").strip(), "```", ""]
    for group, names in (("The paper's tables", [t for t in paper if t in tables]),
                         ("Further tables", [t for t in sorted(tables) if t not in paper])):
        lines += [f"## {group}", ""]
        for t in names:
            lines += [f"### `{t}`", "", "| column | type | null |", "|---|---|---|"]
            lines += [f"| `{c}` | `{d}` | {'yes' if n else 'no'} |" for c, d, n in tables[t]]
            lines.append("")
    return "\n".join(lines)


@event_priority(50)  # before mkdocs-jupyter's, which renders the notebooks it finds among the files
def on_files(files, config):
    """Add the generated pages and the notebooks to the site."""
    def add(uri: str, content: str | bytes) -> None:
        files.append(File.generated(config, uri, content=content))

    add("cli.md", _cli_page())
    add("store.md", _store_page())
    for package, title in API.items():
        if _modules(package):
            add(f"api/{package}.md", _api_page(package, title))
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):  # the files themselves: mkdocs-jupyter reads their path
        files.append(File(f"notebooks/{nb.name}", src_dir=str(ROOT), dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    return files


def on_config(config):
    """The navigation's generated sections: the API pages of the packages that exist, and the notebooks."""
    api = [{f"workbench.{p}": f"api/{p}.md"} for p in API if _modules(p)]
    notebooks = [{nb.stem.replace("_", " ", 1).replace("_", " "): f"notebooks/{nb.name}"}
                 for nb in sorted((ROOT / "notebooks").glob("*.ipynb"))]
    config["nav"] = [item for item in config["nav"]] + [{"Notebooks": notebooks}, {"API reference": api}]
    return config
