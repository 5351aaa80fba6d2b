"""Committed notebooks carry no outputs, execution counts or widget state.

Saved widget views point at models that exist only while the kernel that made them runs, so a notebook committed
with them shows "Error displaying widget: model not found" when reopened. The repository strips them with
nbstripout's git filter (see the README's set-up section); this test reads what git would commit (the index), so
a developer's working copy may hold outputs while the filter keeps them out of the repository.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
WIDGET_MIME = ("application/vnd.jupyter.widget-view+json", "application/vnd.jupyter.widget-state+json")


def committed_text(path: Path) -> str:
    """The notebook as staged in git (after the nbstripout filter), or the file when git does not track it."""
    rel = path.relative_to(ROOT).as_posix()
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "show", f":{rel}"], capture_output=True, text=True, check=False)
    except FileNotFoundError:
        return path.read_text()
    return out.stdout if out.returncode == 0 else path.read_text()


def test_notebooks_exist():
    assert NOTEBOOKS, f"no notebooks found in {ROOT / 'notebooks'}"


def problems(nb: dict, name: str) -> list[str]:
    """What in a notebook would be committed but should not be: outputs, execution counts, widget state."""
    out = ["notebook metadata holds saved widget state"] if "widgets" in nb.get("metadata", {}) else []
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] != "code":
            continue
        if cell.get("outputs"):
            out.append(f"cell {i} has outputs")
        if cell.get("execution_count") is not None:
            out.append(f"cell {i} has an execution count")
        if any(k in json.dumps(cell.get("metadata", {})) for k in WIDGET_MIME):
            out.append(f"cell {i} metadata holds widget state")
    return [f"{name}: {p}" for p in out]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_committed_without_outputs_or_widget_state(path: Path):
    found = problems(json.loads(committed_text(path)), path.name)
    assert not found, "; ".join(found) + " (strip with nbstripout, see the README)"


def test_gitattributes_strip_notebooks():
    attrs = (ROOT / ".gitattributes").read_text().split("\n")
    assert "*.ipynb filter=nbstripout" in attrs


def test_saved_widget_state_is_detected_and_stripped(tmp_path):
    """A notebook saved with a widget view and widget state fails the check; nbstripout makes it pass."""
    nb = json.loads(NOTEBOOKS[0].read_text())
    cell = next(c for c in nb["cells"] if c["cell_type"] == "code")
    cell["execution_count"] = 3
    cell["outputs"] = [{"output_type": "display_data", "metadata": {},
                        "data": {WIDGET_MIME[0]: {"model_id": "abc", "version_major": 2, "version_minor": 0}}}]
    nb["metadata"]["widgets"] = {WIDGET_MIME[1]: {"state": {}, "version_major": 2, "version_minor": 0}}
    assert len(problems(nb, "saved")) == 3
    bad = tmp_path / "saved.ipynb"
    bad.write_text(json.dumps(nb))
    strip = Path(sys.executable).parent / "nbstripout"
    if not strip.exists():
        pytest.skip("nbstripout is not installed (pip install -e '.[test]')")
    subprocess.run([str(strip), str(bad)], check=True)
    assert problems(json.loads(bad.read_text()), "stripped") == []
