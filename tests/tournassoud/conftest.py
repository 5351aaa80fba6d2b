"""Objects and the PUMA 560 for the grasp-placement table tests."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from workbench.gripper import franka_hand
from workbench.objects import from_trimesh
from workbench.resources import ASSETS
from workbench.robots import robot_from_urdf

HAND = ("panda_hand", "panda_leftfinger", "panda_rightfinger")
L_OUTLINE = [(0, 0), (0.06, 0), (0.06, 0.02), (0.02, 0.02), (0.02, 0.06), (0, 0.06)]


def puma(base_z: float = 0.0):
    base = np.eye(4)
    base[2, 3] = base_z
    return robot_from_urdf(ASSETS / "robots" / "puma560.urdf", "panda_hand_tcp", name="puma560", drop_geometry=HAND, base=base)


def extrude(outline: list[tuple[float, float]], caps: list[tuple[int, int, int]], depth: float) -> trimesh.Trimesh:
    """A watertight prism: the x-z polygon `outline` (triangulated by `caps`) extruded along y, centred."""
    n = len(outline)
    verts = [(x, -depth / 2, z) for x, z in outline] + [(x, depth / 2, z) for x, z in outline]
    faces = []
    for k in range(n):
        a, b = k, (k + 1) % n
        faces += [(a, b, n + b), (a, n + b, n + a)]
    for a, b, c in caps:
        faces += [(a, c, b), (n + a, n + b, n + c)]
    mesh = trimesh.Trimesh(np.array(verts, dtype=np.float64), np.array(faces), process=True)
    trimesh.repair.fix_normals(mesh)
    assert mesh.is_watertight and mesh.volume > 0
    return mesh


def l_part():
    """The L-shaped part of Fig. 1: legs 60 x 20 mm and 20 x 60 mm in x-z, 30 mm deep along y."""
    return from_trimesh(extrude(L_OUTLINE, [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)], 0.03), "L")


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
