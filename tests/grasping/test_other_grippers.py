"""The Robotiq-like spec and the URDF gripper plan grasps on a bundled part and an organic one: every jaw width
within that gripper's stroke, and every checked grasp valid by the independent check (contacts on the surface,
normals in the cone, contacts on the pads), and no box of the hand, built from its own URDF or from the spec file's
numbers, meeting the part in coal beyond the 0.5 mm tolerance."""

from __future__ import annotations

import coal
import numpy as np
import pytest

from workbench.benchmarks.graspcheck import check_grasps, hand_placements
from workbench.benchmarks.organic import ORGANIC
from workbench.geometry.objects import from_trimesh, load_object
from workbench.grasping.grasps import GraspParams, plan_grasps
from workbench.resources import bundled_objects
from workbench.robots.gripper import BUNDLED, load_gripper

HANDS = {"robotiq-2f85": str(BUNDLED["robotiq-2f85"]), "parallel60": "parallel60"}


def boxes_hit(mesh, poses, widths, hand: str, shrink: float) -> np.ndarray:
    """Per grasp: does any box of the hand (from its URDF or spec file), shrunk by `shrink` on every side, meet the
    part's surface (coal, boolean)?"""
    part = coal.BVHModelOBBRSS()
    part.beginModel(len(mesh.faces), len(mesh.vertices))
    part.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    part.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    part.endModel()
    out = np.zeros(len(poses), dtype=bool)
    for i, (pose, w) in enumerate(zip(poses, widths)):
        for box, local in hand_placements(float(w), hand):
            m = pose @ local
            small = coal.Box(*np.maximum(2 * np.asarray(box.halfSide) - 2 * shrink, 1e-6))
            out[i] |= coal.collide(part, coal.Transform3s(), small, coal.Transform3s(m[:3, :3], m[:3, 3]),
                                   coal.CollisionRequest(), coal.CollisionResult()) > 0
    return out


@pytest.mark.parametrize("name", sorted(HANDS))
@pytest.mark.parametrize("part", ["tube", "blob_coarse"])
def test_grasps_of_another_gripper_are_valid_by_an_independent_check(name, part):
    obj = load_object(bundled_objects()[part]) if part in bundled_objects() else from_trimesh(ORGANIC[part](), part)
    gripper = load_gripper(name)
    plan = plan_grasps(obj, gripper, GraspParams())
    g = plan.grasps
    assert len(g) >= 20
    assert (g.jawwidth >= gripper.jaw_min - 1e-9).all() and (g.jawwidth <= gripper.jaw_max + 1e-9).all()
    pick = np.unique(np.linspace(0, len(g) - 1, 25).astype(int))
    v = check_grasps(obj.mesh, g.poses[pick], g.jawwidth[pick], g.contact0[pick], g.contact1[pick], g.normal0[pick],
                     g.normal1[pick], plan.params.friction_coefficient, hand=HANDS[name])
    assert v.ok.all(), (int(v.ok.sum()), len(pick), int((~v.clear).sum()))
    tol = GraspParams().finger_clearance + 1e-6
    for widths in (g.jawwidth[pick], np.full(len(pick), gripper.jaw_max)):  # at the grasp and fully open
        assert not boxes_hit(obj.mesh, g.poses[pick], widths, HANDS[name], tol).any()


def test_the_boxes_check_sees_pads_closed_into_the_part():
    """The same boxes, with the pads 6 mm closer than the grasp's opening, meet the part at every grasp."""
    obj = load_object(bundled_objects()["tube"])
    g = plan_grasps(obj, load_gripper("robotiq-2f85"), GraspParams()).grasps
    pick = np.unique(np.linspace(0, len(g) - 1, 10).astype(int))
    assert boxes_hit(obj.mesh, g.poses[pick], g.jawwidth[pick] - 0.006, HANDS["robotiq-2f85"], 5e-4).all()


# A gripper the workbench has never seen, written here: a 100 mm stroke from 10 mm, wide short pads, long fingers,
# a flat palm, its TCP turned 0.3 rad about the approach.
WIDE = {"name": "wide110", "source": "written for this test", "stroke": [0.01, 0.11], "tcp": [0.0, 0.0, 0.12],
        "rpy": [0.0, 0.0, 0.3], "pad": {"size": [0.03, 0.02], "thickness": 0.005}, "finger": {"size": [0.03, 0.01, 0.085]},
        "palm": {"size": [0.07, 0.16, 0.05], "offset": [0.0, 0.0, 0.025]}, "max_force": 150.0}


@pytest.mark.parametrize("part", ["tube", "blob_coarse"])
def test_a_gripper_never_seen_before_plans_stores_and_checks(tmp_path, part, capsys):
    import duckdb
    import yaml

    from workbench.cli.main import main

    spec = tmp_path / "wide110.yaml"
    spec.write_text(yaml.safe_dump(WIDE))
    obj = load_object(bundled_objects()[part]) if part in bundled_objects() else from_trimesh(ORGANIC[part](), part)
    mesh, db = tmp_path / f"{part}.stl", tmp_path / "w.duckdb"
    obj.mesh.export(mesh)
    assert main(["grasps", str(mesh), "--db", str(db), "--gripper", str(spec)]) == 0
    con = duckdb.connect(str(db), read_only=True)
    name, lo, hi = con.execute("SELECT name, jaw_min, jaw_max FROM gripper").fetchone()
    rows = con.execute("SELECT rotmat, jawwidth, contactpoint0, contactpoint1, contactnormal0, contactnormal1 "
                       "FROM freeairgrip ORDER BY idfreeairgrip").fetchall()
    con.close()
    assert (name, lo, hi) == ("wide110", 0.01, 0.11) and len(rows) >= 20
    poses = np.array([np.reshape(r[0], (4, 4)) for r in rows])
    widths = np.array([r[1] for r in rows])
    assert (widths >= 0.01 - 1e-9).all() and (widths <= 0.11 + 1e-9).all()
    pick = np.unique(np.linspace(0, len(rows) - 1, 25).astype(int))
    c0, c1, n0, n1 = (np.array([rows[i][k] for i in pick]) for k in (2, 3, 4, 5))
    v = check_grasps(obj.mesh, poses[pick], widths[pick], c0, c1, n0, n1, GraspParams().friction_coefficient,
                     hand=str(spec))
    assert v.ok.all(), (int(v.ok.sum()), len(pick), int((~v.clear).sum()), int((~v.pads).sum()))
    for w in (widths[pick], np.full(len(pick), 0.11)):  # the stored grasps clear the part at the grasp and fully open
        assert not boxes_hit(obj.mesh, poses[pick], w, str(spec), GraspParams().finger_clearance + 1e-6).any()
    # without --gripper a command on the stored grasps names the spec-file gripper they need, in one line
    capsys.readouterr()
    assert main(["placements", "--db", str(db), "--object", part]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gripper 'wide110'" in err[0] and "--gripper FILE" in err[0], err


def test_a_spec_stating_its_pad_friction_plans_with_it_unless_told_otherwise(tmp_path, capsys):
    """A spec's `friction` is the friction cone grasp planning uses when none is given (the default, on the command
    line and in the library): its grasps are those of that friction given outright, more than a 0.3 cone keeps,
    each with both normals inside its cone and some outside the 0.3 cone; the parameter set stores the friction
    used; --friction overrides the spec, and a spec stating none plans with 0.3."""
    import json

    import duckdb
    import yaml

    from workbench.cli.main import main

    stated = {**WIDE, "name": "rubber", "friction": 0.8}
    spec = tmp_path / "rubber.yaml"
    spec.write_text(yaml.safe_dump(stated))
    hand = load_gripper(str(spec))
    obj = load_object(bundled_objects()["tail"])
    left = plan_grasps(obj, hand, GraspParams()).grasps
    given = plan_grasps(obj, hand, GraspParams(friction=0.8)).grasps
    narrow = plan_grasps(obj, hand, GraspParams(friction=0.3)).grasps
    for f in left.__dataclass_fields__:
        assert np.array_equal(getattr(left, f), getattr(given, f)), f
    assert len(left) > len(narrow) > 0
    y = left.poses[:, :3, 1]
    cos0, cos1 = np.einsum("ij,ij->i", left.normal0, y), np.einsum("ij,ij->i", left.normal1, -y)
    assert (np.minimum(cos0, cos1) >= np.cos(np.arctan(0.8)) - 1e-9).all()
    assert (np.minimum(cos0, cos1) < np.cos(np.arctan(0.3))).any()

    mesh = tmp_path / "tail.stl"
    obj.mesh.export(mesh)
    frictions = {}
    for label, extra in (("spec", []), ("override", ["--friction", "0.3"])):
        db = tmp_path / f"{label}.duckdb"
        capsys.readouterr()
        assert main(["grasps", str(mesh), "--db", str(db), "--gripper", str(spec), *extra]) == 0
        out = capsys.readouterr().out
        assert ("friction 0.8: the friction gripper rubber's spec states" in out) == (label == "spec"), out
        con = duckdb.connect(str(db), read_only=True)
        frictions[label] = [json.loads(r[0])["friction"] for r in con.execute("SELECT params FROM paramset").fetchall()]
        count = con.execute("SELECT count(*) FROM freeairgrip").fetchone()[0]
        con.close()
        assert count == len(left if label == "spec" else narrow)
    assert frictions == {"spec": [0.8], "override": [0.3]}
    plain = {k: v for k, v in stated.items() if k != "friction"}
    spec.write_text(yaml.safe_dump({**plain, "name": "plain"}))
    assert GraspParams(friction=None).for_gripper(load_gripper(str(spec))).friction == 0.3
