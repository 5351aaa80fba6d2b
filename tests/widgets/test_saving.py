"""Notebooks saved through `make lab`'s save hook keep their outputs but no widget views or widget state."""

from __future__ import annotations

import json
import subprocess
import sys

from workbench.widgets.saving import WIDGET_VIEW, strip_widget_views


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
