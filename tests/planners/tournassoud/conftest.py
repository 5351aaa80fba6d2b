"""Objects and the PUMA 560 for the grasp-placement table tests."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.planners.tournassoud.shapes import l_part, prism
from workbench.robots.model import get_robot


@pytest.fixture(scope="session")
def make_puma():
    """The built-in PUMA 560 with its base raised or lowered by base_z (m)."""
    def make(base_z: float = 0.0):
        base = np.eye(4)
        base[2, 3] = base_z
        return get_robot("puma560", base=base)
    return make


@pytest.fixture(scope="session")
def extrude():
    """A watertight prism from an x-z outline (checked watertight)."""
    def make(outline, caps, depth):
        mesh = prism(outline, caps, depth)
        assert mesh.is_watertight and mesh.volume > 0
        return mesh
    return make


@pytest.fixture(scope="session")
def lpart():
    return l_part()


@pytest.fixture(scope="session")
def puma560():
    return get_robot("puma560")
