"""Shared fixtures: meshes built in code, the Franka hand, and the paper's objects when ../shared is present."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

from workbench.geometry.objects import MeshWarning, from_trimesh, load_object
from workbench.resources import bundled_objects, paper_objects
from workbench.robots.gripper import franka_hand


@pytest.fixture(scope="session")
def hand():
    return franka_hand()


@pytest.fixture(scope="session")
def box():
    """A 50 x 40 x 30 mm box: every size within the Franka hand's 80 mm jaw."""
    return from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")


@pytest.fixture(scope="session")
def cylinder():
    return from_trimesh(trimesh.creation.cylinder(radius=0.025, height=0.08, sections=48), "cylinder")


@pytest.fixture(scope="session")
def tube_paper():
    """The paper's TU tube (millimetres), or skip when ../shared is absent."""
    objs = paper_objects()
    if "TU" not in objs:
        pytest.skip("the paper's objects (../shared/objects/wan-harada) are not present")
    return load_object(objs["TU"], units="mm", name="TU")


@pytest.fixture(scope="session")
def bundled():
    """The project's own objects, loaded (metres)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshWarning)
        return {name: load_object(path) for name, path in bundled_objects().items()}


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) of the rotation between two 3x3 rotation matrices."""
    c = (np.trace(a.T @ b) - 1) / 2
    return float(np.arccos(np.clip(c, -1, 1)))
