"""Paths to packaged data: example-robot-data's robots, the bundled objects, the paper's objects in ../shared."""

from __future__ import annotations

import importlib.metadata
import os
from pathlib import Path

from workbench.errors import WorkbenchError

ASSETS = Path(__file__).resolve().parent / "assets"  # package data: found in a wheel install too
OBJECTS_DIR = ASSETS / "objects"


def erd_share() -> Path:
    """The folder that resolves `package://example-robot-data/...` URIs (its parent holds `example-robot-data/`)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:  # pragma: no cover - install problem
        raise WorkbenchError("example-robot-data is not installed: run `make venv` or `pip install example-robot-data`") from exc
    for candidate in (Path(str(dist.locate_file("cmeel.prefix/share"))), Path("/opt/openrobots/share")):
        if (candidate / "example-robot-data" / "robots").is_dir():
            return candidate
    raise WorkbenchError("example-robot-data's robots folder was not found: reinstall the example-robot-data package")


def erd_robots() -> Path:
    """The `robots/` folder of example-robot-data (panda_description, ur_description, talos_data, ...)."""
    return erd_share() / "example-robot-data" / "robots"


def bundled_objects() -> dict[str, Path]:
    """The project's own objects (package data `workbench/assets/objects`), by name (file stem), in metres."""
    return {p.stem: p for p in sorted(OBJECTS_DIR.glob("*.stl"))}


def paper_objects() -> dict[str, Path]:
    """The Wan-Harada Table I objects in ../shared/objects/wan-harada (millimetres), when present, by Table I row."""
    roots = [Path(os.environ["WORKBENCH_SHARED"]) if "WORKBENCH_SHARED" in os.environ else None,
             Path(__file__).resolve().parents[2] / "shared", Path.cwd().parent / "shared"]
    for root in roots:
        if root is not None and (root / "objects" / "wan-harada").is_dir():
            return {p.stem.split("_")[0]: p for p in sorted((root / "objects" / "wan-harada").glob("*.stl"))}
    return {}
