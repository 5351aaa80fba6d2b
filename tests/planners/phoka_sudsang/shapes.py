"""Shared test geometry of the five-finger tests."""

import numpy as np
import trimesh


def pebble() -> trimesh.Trimesh:
    """An irregular convex-ish pebble of 320 triangles, 10 x 7 x 5 cm (generic geometry, seeded)."""
    m = trimesh.creation.icosphere(subdivisions=2)
    rng = np.random.default_rng(7)
    m.vertices = m.vertices * (1 + 0.08 * rng.normal(size=(len(m.vertices), 1)))
    m.vertices = m.vertices * np.array([0.05, 0.035, 0.025])
    return m
