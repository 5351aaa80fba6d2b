"""Objects and the PUMA 560 for the grasp-placement table tests."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.gripper import franka_hand
from workbench.objects import from_trimesh
from workbench.planners.tournassoud.shapes import l_part, prism
from workbench.resources import ASSETS
from workbench.robots import robot_from_urdf

HAND = ("panda_hand", "panda_leftfinger", "panda_rightfinger")


def puma(base_z: float = 0.0):
    base = np.eye(4)
    base[2, 3] = base_z
    return robot_from_urdf(ASSETS / "robots" / "puma560.urdf", "panda_hand_tcp", name="puma560", drop_geometry=HAND, base=base)


def extrude(outline, caps, depth):
    mesh = prism(outline, caps, depth)
    assert mesh.is_watertight and mesh.volume > 0
    return mesh


@pytest.fixture(scope="session")
def hand():
    return franka_hand()


@pytest.fixture(scope="session")
def box():
    return from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")


@pytest.fixture(scope="session")
def lpart():
    return l_part()


@pytest.fixture(scope="session")
def puma560():
    return puma()
