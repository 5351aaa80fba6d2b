"""The package's architecture (issue 9): layers, import rules and no import cycles, read from the source itself."""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parents[1] / "workbench"


def _modules() -> dict[str, Path]:
    out = {}
    for p in PACKAGE.rglob("*.py"):
        parts = list(p.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = _modules()


def _imports(path: Path) -> list[tuple[str, list[str], bool]]:
    """(module imported, names, at module top) for every workbench import in a file."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    type_checking = {id(s) for n in tree.body if isinstance(n, ast.If) and "TYPE_CHECKING" in ast.unparse(n.test)
                     for s in ast.walk(n)}
    out = []
    for node in ast.walk(tree):
        if id(node) in type_checking:
            continue
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("workbench"):
            assert node.level == 0, f"{path}: relative import"
            names = [a.name for a in node.names]
            for n in names:  # `from workbench.x import submodule`
                sub = f"{node.module}.{n}"
                out.append((sub if sub in MODULES else node.module, [n], id(node) in top))
        elif isinstance(node, ast.Import):
            out += [(a.name, [], id(node) in top) for a in node.names if a.name.startswith("workbench")]
    return out


def _graph() -> nx.DiGraph:
    g = nx.DiGraph()
    for mod, path in MODULES.items():
        g.add_node(mod)
        for target, _, _ in _imports(path):
            if target != mod:
                g.add_edge(mod, target)
    return g


def test_the_tree_shows_the_architecture():
    for folder in ("geometry", "robots", "grasping", "planners/wan_harada", "planners/phoka_sudsang", "store", "viewer",
                   "widgets", "cli", "benchmarks"):
        assert (PACKAGE / folder / "__init__.py").exists(), folder
    flat = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert flat == ["__init__.py", "__main__.py", "errors.py", "params.py", "resources.py", "validation.py"], flat


def test_no_import_cycles():
    cycles = list(nx.simple_cycles(_graph()))
    assert not cycles, cycles[:5]


def _layer(mod: str) -> str:
    parts = mod.split(".")
    return parts[1] if len(parts) > 1 else ""


def test_only_stages_store_cli_and_benchmarks_import_the_store():
    allowed = {"store", "cli", "benchmarks"}
    for mod, path in MODULES.items():
        if _layer(mod) in allowed or mod.endswith(".stages"):
            continue
        bad = [t for t, _, _ in _imports(path) if t == "workbench.store" or t.startswith("workbench.store.")]
        assert not bad, f"{mod} imports {bad}: only the planners' stages.py talk to the store"


def test_store_imports_result_types_not_computations():
    for mod in MODULES:
        if _layer(mod) != "store":
            continue
        m = importlib.import_module(mod)
        for target, names, _ in _imports(MODULES[mod]):
            if target.startswith(("workbench.store", "workbench.errors")) or target in MODULES and not names:
                continue
            for n in names:
                obj = getattr(m, n)
                assert not inspect.isfunction(obj), f"{mod} imports the function {target}.{n}: the store computes nothing"


def test_viewer_never_imports_widgets_and_nothing_but_cli_imports_cli():
    for mod, path in MODULES.items():
        targets = [t for t, _, _ in _imports(path)]
        if _layer(mod) == "viewer":
            assert not [t for t in targets if t.startswith("workbench.widgets")], mod
        if _layer(mod) != "cli" and mod != "workbench.__main__":  # the `python -m workbench` entry point
            assert not [t for t in targets if t.startswith("workbench.cli")], mod


def test_notebooks_use_stages_viewer_and_widgets_not_cli():
    import json

    for nb in (PACKAGE.parent / "notebooks").glob("*.ipynb"):
        src = "\n".join("".join(c["source"]) for c in json.loads(nb.read_text())["cells"] if c["cell_type"] == "code")
        assert "workbench.cli" not in src, nb.name


def test_workbench_imports_sit_at_module_top():
    late = [(mod, t) for mod, path in MODULES.items() for t, _, top in _imports(path) if not top]
    assert not late, late


def test_no_module_level_caches():
    """Caches are explicit objects (a planner, a solver), never module-level dicts that outlive their inputs."""
    caches = []
    for mod, path in MODULES.items():
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.Assign, ast.AnnAssign)) and isinstance(node.value, ast.Dict) and not node.value.keys:
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                caches.append(f"{mod}.{ast.unparse(targets[0])}")
    assert caches == [], f"module-level mutable caches: {caches}"
    # the check itself sees one: an empty dict bound at module level
    probe = ast.parse("_CACHE: dict = {}\nLIMIT = 3\n").body
    assert [n for n in probe if isinstance(n, ast.AnnAssign) and isinstance(n.value, ast.Dict)]


def test_a_wheel_ships_the_bundled_objects(tmp_path):
    """A wheel install finds the bundled parts: they are package data, not files beside the repository."""
    import subprocess
    import sys
    import zipfile

    root = PACKAGE.parent
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "-w", str(tmp_path),
                    str(root)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    stls = [n for n in names if n.startswith("workbench/assets/objects/") and n.endswith(".stl")]
    assert {Path(n).stem for n in stls} >= {"tube", "wheel", "bracket", "planebody", "tail", "drill"}


def test_the_validator_shares_no_code_with_the_planners():
    """It rebuilds the robot, the gripper, the table and the object from stored rows, with its own FK and collisions."""
    targets = {t for t, _, _ in _imports(MODULES["workbench.validation"])}
    assert targets <= {"workbench.errors", "workbench.resources"}, targets


def test_one_ik_solver_and_one_home_for_python_fcl():
    for mod, path in MODULES.items():
        text = path.read_text()
        if mod not in ("workbench.robots.ik", "workbench.robots.chain"):
            assert "solve_ik(" not in text, f"{mod} runs its own IK tiers; use robots.ik.IKSolver"
        if mod not in ("workbench.geometry.collision", "workbench.validation"):
            assert "import fcl" not in text and "fcl." not in text, f"{mod} calls python-fcl outside geometry.collision"


def test_every_third_party_import_is_a_declared_dependency():
    import sys
    import tomllib

    project = tomllib.loads((PACKAGE.parent / "pyproject.toml").read_text())["project"]
    # the physics extra (MuJoCo, CoACD) is imported inside the functions that need it, with an install hint
    deps = project["dependencies"] + project["optional-dependencies"]["physics"]
    declared = {d.split(">")[0].split("=")[0].split("[")[0].strip().lower().replace("-", "_") for d in deps}
    alias = {"fcl": "python_fcl", "pinocchio": "pin", "sklearn": "scikit_learn", "yaml": "pyyaml", "IPython": "ipython",
             "example_robot_data": "example_robot_data", "embreex": "embreex", "manifold3d": "manifold3d",
             "fast_simplification": "fast_simplification", "coal": "pin"}
    missing = set()
    for mod, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else [])
            for n in names:
                top = n.split(".")[0]
                if top == "workbench" or top in sys.stdlib_module_names or top == "__future__":
                    continue
                if alias.get(top, top).lower().replace("-", "_") not in declared:
                    missing.add((mod, top))
    assert not missing, sorted(missing)
