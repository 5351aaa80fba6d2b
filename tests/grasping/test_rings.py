"""Rings and frames lying flat are gripped as a person grips them: across the tube or rim from above, jaw level."""

from __future__ import annotations

import coal
import numpy as np
import pytest
import trimesh

from workbench.benchmarks.graspcheck import hand_intrudes, hand_placements
from workbench.benchmarks.organic import torus, washer
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.grasping.placements import free_tabletop_grips, stable_placements


def _table_clearance(grip_poses: np.ndarray, openings: np.ndarray) -> np.ndarray:
    """The least distance (m) from the hand's collision geometry (pinocchio's Franka hand, with coal) to the table
    (the half-space z <= 0, as a large box) for each TCP pose in the table frame."""
    table = coal.Box(4.0, 4.0, 1.0)
    at = coal.Transform3s(np.eye(3), np.array([0.0, 0.0, -0.5]))
    out = np.full(len(grip_poses), np.inf)
    for k, (pose, w) in enumerate(zip(grip_poses, openings)):
        for geom, local in hand_placements(float(w)):
            m = pose @ local
            res = coal.DistanceResult()
            d = coal.distance(geom, coal.Transform3s(m[:3, :3], m[:3, 3]), table, at, coal.DistanceRequest(), res)
            out[k] = min(out[k], d)
    return out


def _square_frame(outer: float, bar: float, thickness: float) -> trimesh.Trimesh:
    """A square picture frame lying in the xy plane (manifold3d's difference of two boxes)."""
    import manifold3d

    solid = (manifold3d.Manifold.cube([outer, outer, thickness], True)
             - manifold3d.Manifold.cube([outer - 2 * bar, outer - 2 * bar, 2 * thickness], True))
    m = solid.to_mesh()
    return trimesh.Trimesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts), process=True)


@pytest.mark.parametrize("name, mesh, width", [
    ("130 mm ring of a 30 mm tube", torus(major=0.05, minor=0.015, sections=128, minor_sections=24), 0.030),
    # the same ring in other tessellations: 64 and 96 facets round, 24 or 32 about the tube, the jaw axis's phase
    # against the inner wall's facets decides whether the inner pad's edge touch lies inside the friction cone
    ("130 mm ring, 64 x 24 facets", torus(major=0.05, minor=0.015, sections=64, minor_sections=24), 0.030),
    ("130 mm ring, 96 x 32 facets", torus(major=0.05, minor=0.015, sections=96, minor_sections=32), 0.030),
    ("130 mm ring, 48 x 24 facets", torus(major=0.05, minor=0.015, sections=48, minor_sections=24), 0.030),
    ("132 mm ring of a 28.8 mm tube", torus(major=0.0516, minor=0.0144, sections=64, minor_sections=24), 0.0288),
    ("100 mm ring 10 mm thick", washer(outer=0.05, inner=0.04, thickness=0.01, sections=96), 0.010),
    # wider than twice the centre-of-mass distance (52 mm here): every grasp lies farther than it from the centre of
    # mass, which sits in the hole, so the bound is raised to keep the grasps across the material nearest it
    ("140 mm ring of a 20 mm tube", torus(major=0.06, minor=0.01, sections=128, minor_sections=24), 0.020),
    ("140 mm square frame of 12 mm bars, 8 mm thick", _square_frame(0.14, 0.012, 0.008), 0.012),
])
def test_ring_lying_flat_is_gripped_across_its_tube_from_above(hand, name, mesh, width):
    obj = from_trimesh(mesh, name)
    plan = plan_grasps(obj, hand, GraspParams())
    places = stable_placements(obj)
    flat = np.flatnonzero(np.abs(places.normals[:, 2]) > 0.999)  # lying on a flat side (the ring's axis is z)
    assert len(flat) >= 1
    p, g, poses = free_tabletop_grips(places, plan.grasps.poses, hand)
    on_flat = np.isin(p, flat)
    y, z, o = poses[:, :3, 1], poses[:, :3, 2], plan.grasps.poses[g, :3, 3]
    radial = o[:, :2] / np.linalg.norm(o[:, :2], axis=1, keepdims=True)
    across = (on_flat & (np.abs(y[:, 2]) < np.sin(np.radians(5))) & (z[:, 2] < -np.cos(np.radians(5)))
              & (np.abs(np.einsum("ij,ij->i", plan.grasps.poses[g, :2, 1], radial)) > np.cos(np.radians(10))))
    k = np.flatnonzero(across)
    assert len(k) >= 2, f"{name}: {len(p)} tabletop grips, none across the tube from above"
    w = plan.grasps.jawwidth[g[k]]
    assert np.allclose(w, width, atol=2e-3)  # the pads close across the tube or rim, not across the ring
    # checked with coal on the hand pinocchio loads: clear of the table, and not into the part
    assert (_table_clearance(poses[k], w) >= 1e-3).all()
    assert not hand_intrudes(obj.mesh, plan.grasps.poses[g[k]], w).any()


def test_the_centre_of_mass_bound_is_raised_only_where_the_centre_of_mass_lies_in_a_hole(hand):
    """`com_bound`: a washer's centre of mass lies in its hole, its inner radius from the part (coal's distance from a
    tiny sphere there agrees), so the bound becomes that plus half the stroke; a solid box's bound stays
    the scaled value, as does every bound with fixed lengths."""
    from workbench.grasping.grasps import com_bound

    ring = from_trimesh(washer(outer=0.07, inner=0.06, thickness=0.01, sections=128), "ring")
    got = com_bound(ring, hand, GraspParams(), 0.05)
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(ring.mesh.faces), len(ring.mesh.vertices))
    model.addVertices(np.asarray(ring.mesh.vertices, dtype=np.float64))
    model.addTriangles(np.asarray(ring.mesh.faces, dtype=np.int64))
    model.endModel()
    probe = coal.Transform3s(np.eye(3), np.asarray(ring.com, dtype=np.float64))
    coal_d = coal.distance(coal.Sphere(1e-9), probe, model, coal.Transform3s(), coal.DistanceRequest(),
                           coal.DistanceResult()) + 1e-9
    assert abs(got["com_hole"] - coal_d) < 1e-9 and 0.0599 < coal_d <= 0.06
    assert got["com_max"] == pytest.approx(coal_d + hand.jaw_max / 2, abs=1e-12)
    assert com_bound(ring, hand, GraspParams(lengths="fixed"), 0.05) == {"com_max": 0.05, "com_hole": 0.0}
    box = from_trimesh(trimesh.creation.box((0.12, 0.1, 0.08)), "box")  # its centre 40 mm from every side
    assert com_bound(box, hand, GraspParams(), 0.05) == {"com_max": 0.05, "com_hole": 0.0}
