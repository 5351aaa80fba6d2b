"""Notebooks saved through `make lab`'s save hook keep their outputs but no widget views or widget state."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest
from nbstripout import strip_output

from workbench.widgets.saving import WIDGET_VIEW, strip_widget_views

NOTEBOOKS = Path(__file__).resolve().parents[2] / "notebooks"


def notebook() -> dict:
    view = {"output_type": "display_data", "metadata": {},
            "data": {WIDGET_VIEW: {"model_id": "abc", "version_major": 2, "version_minor": 0}, "text/plain": "VBox()"}}
    text = {"output_type": "stream", "name": "stdout", "text": "331 grasps\n"}
    return {"nbformat": 4, "nbformat_minor": 5, "metadata": {"widgets": {"state": {}}},
            "cells": [{"cell_type": "code", "id": "0", "metadata": {}, "execution_count": 1, "source": "x",
                       "outputs": [view, text]},
                      {"cell_type": "markdown", "id": "1", "metadata": {}, "source": "# title"}]}


def test_hook_drops_widget_views_and_state_keeps_other_outputs():
    model = strip_widget_views({"type": "notebook", "content": notebook()}, path="a.ipynb")
    nb = model["content"]
    assert "widgets" not in nb["metadata"]
    assert nb["cells"][0]["outputs"] == [notebook()["cells"][0]["outputs"][1]]
    assert nb["cells"][1] == notebook()["cells"][1]


def test_hook_leaves_other_files_alone():
    model = {"type": "file", "content": "hello", "format": "text"}
    assert strip_widget_views(dict(model), path="a.txt") == model


def test_jupyter_server_loads_the_hook_by_name(tmp_path):
    """The import string `make lab` passes is accepted by the Jupyter server's contents manager and used on save."""
    code = ("from jupyter_server.services.contents.filemanager import FileContentsManager\n"
            f"cm = FileContentsManager(root_dir={str(tmp_path)!r}, "
            "pre_save_hook='workbench.widgets.saving.strip_widget_views')\n"
            f"import json; cm.save({{'type': 'notebook', 'content': json.loads({json.dumps(json.dumps(notebook()))})}}, 'n.ipynb')\n")
    subprocess.run([sys.executable, "-c", code], check=True)
    saved = json.loads((tmp_path / "n.ipynb").read_text())
    assert "widgets" not in saved["metadata"]
    assert all(WIDGET_VIEW not in o.get("data", {}) for o in saved["cells"][0]["outputs"])
    assert "".join(saved["cells"][0]["outputs"][0]["text"]) == "331 grasps\n"


def executed(nb: dict) -> dict:
    """The notebook as JupyterLab saves it after Run All: outputs, execution counts and timing metadata on every code
    cell, a widget view, the widget state and the kernel's language_info."""
    nb = json.loads(json.dumps(nb))
    nb["metadata"]["language_info"] = {"codemirror_mode": {"name": "ipython", "version": 3}, "file_extension": ".py",
                                       "mimetype": "text/x-python", "name": "python", "nbconvert_exporter": "python",
                                       "pygments_lexer": "ipython3", "version": sys.version.split()[0]}
    nb["metadata"]["widgets"] = {"application/vnd.jupyter.widget-state+json": {"state": {}}}
    for i, cell in enumerate(nb["cells"]):
        if cell["cell_type"] == "code":
            cell["execution_count"] = i + 1
            cell["metadata"] = {"execution": {"iopub.status.busy": "2026-01-01T00:00:00Z"}}
            cell["outputs"] = [notebook()["cells"][0]["outputs"][0], {"output_type": "stream", "name": "stdout",
                                                                      "text": "done\n"}]
    return nb


# the keys nbstripout's git filter strips besides outputs and counts (its defaults)
NBSTRIPOUT_KEYS = ["metadata.signature", "metadata.widgets", "cell.metadata.collapsed", "cell.metadata.ExecuteTime",
                   "cell.metadata.execution", "cell.metadata.heading_collapsed", "cell.metadata.hidden",
                   "cell.metadata.scrolled"]


@pytest.mark.parametrize("path", sorted(NOTEBOOKS.glob("*.ipynb")), ids=lambda p: p.name)
def test_running_a_notebook_leaves_it_unmodified_in_git(path):
    """What git stores of a notebook run and saved through `make lab` (its save hook, then the repository's
    nbstripout filter) is the committed file byte for byte: cell ids, metadata and all."""
    committed = path.read_text()
    model = strip_widget_views({"type": "notebook", "content": executed(json.loads(committed))}, path=path.name)
    saved = nbformat.reads(json.dumps(model["content"]), as_version=nbformat.NO_CONVERT)
    stored = nbformat.writes(strip_output(saved, keep_output=False, keep_count=False, keep_id=False,
                                          extra_keys=NBSTRIPOUT_KEYS)) + "\n"
    assert stored == committed, f"{path.name}: git would see a change after a run (renumbered cell ids?)"
