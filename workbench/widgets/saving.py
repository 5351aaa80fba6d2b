"""A Jupyter server save hook: notebooks are saved without widget views, widget state and the kernel's language
details (so that, through the repository's nbstripout filter, a notebook run and saved is the committed file).

A saved widget view points at a model that lives only in the kernel that made it; reopened later, JupyterLab shows
"Error displaying widget: model not found". `make lab` starts JupyterLab with
`--ContentsManager.pre_save_hook=workbench.widgets.saving.strip_widget_views`, so autosave keeps every other output
(text, plots, the 3D views' HTML) and drops only those.
"""

from __future__ import annotations

WIDGET_VIEW = "application/vnd.jupyter.widget-view+json"


def strip_widget_views(model: dict, **kwargs) -> dict:
    """Remove widget-view outputs, saved widget state and `language_info` from a notebook model about to be saved
    (in place)."""
    if model.get("type") != "notebook" or not isinstance(model.get("content"), dict):
        return model
    nb = model["content"]
    nb.get("metadata", {}).pop("widgets", None)
    nb.get("metadata", {}).pop("language_info", None)  # the kernel's version: committed notebooks stay as they are
    for cell in nb.get("cells", []):
        if cell.get("cell_type") == "code":
            cell["outputs"] = [o for o in cell.get("outputs", []) if WIDGET_VIEW not in o.get("data", {})]
    return model
