"""Contact points of the five-finger planner (Phoka & Sudsang, Section III) on meshes coarser than the budget."""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.geometry.objects import from_trimesh
from workbench.planners.phoka_sudsang.contacts import ContactParams, contact_points


def test_a_twelve_triangle_box_is_subdivided_into_contact_points_on_its_faces():
    """A CAD box is 12 triangles: its contact points come from the box split until half the budget, every one on a
    face of the box with that face's inward normal, and every face gets its share."""
    box = from_trimesh(trimesh.creation.box((0.006, 0.004, 0.003)), "tiny_box")
    c = contact_points(box, ContactParams(faces=500))
    assert 250 <= len(c) <= 1000
    half = np.array([0.003, 0.002, 0.0015])
    axis = np.argmax(np.abs(c.normals), axis=1)
    assert np.allclose(np.abs(c.normals[np.arange(len(c)), axis]), 1.0)
    # on the face the normal points into: |coordinate| = half size there, inside the box elsewhere
    on_face = np.abs(np.abs(c.points[np.arange(len(c)), axis]) - half[axis]) < 1e-12
    assert on_face.all()
    assert (np.sign(c.points[np.arange(len(c)), axis]) == -np.sign(c.normals[np.arange(len(c)), axis])).all()
    assert (np.abs(c.points) <= half + 1e-12).all()
    assert len(np.unique(np.c_[axis, np.sign(c.normals[np.arange(len(c)), axis])], axis=0)) == 6
    # the total area the contact triangles stand for is the box's
    assert np.isclose(c.mesh.area, box.mesh.area)
