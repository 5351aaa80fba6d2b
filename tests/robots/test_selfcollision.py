"""Self-collision of the arm and the planning gripper (issue 12), cross-checked with python-fcl on the URDF."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import fcl
import numpy as np
import pinocchio as pin
import pytest
import trimesh

from workbench.robots.model import builtin_robot
from workbench.robots.selfcollision import (
    AllowedPairs,
    SelfCollision,
    allowed_pairs,
    srdf_for,
)

HOME = np.array([0.0, -0.785398, 0.0, -2.35619, 0.0, 1.5707, 0.785398])  # the Panda SRDF's "default" state
FOLDED = np.array([0.0, 1.0, 0.0, -3.0, 0.0, 0.5, 0.785])  # shoulder forward, elbow fully bent: the hand in the base


@pytest.fixture(scope="module")
def panda():
    return builtin_robot("panda")


@pytest.fixture(scope="module")
def panda_self(panda):
    return SelfCollision(panda)


def test_panda_uses_its_srdf(panda):
    a = allowed_pairs(panda)
    assert srdf_for(panda).name == "panda.srdf" and a.source.endswith("panda.srdf")
    assert a.samples == 0  # every pair is covered by the SRDF
    assert a.allowed[("panda_link0", "panda_link1")] == "adjacent"
    assert a.allowed[("panda_link3", "panda_link5")] == "srdf"
    assert ("panda_link1", "panda_link7") in a.checked
    # JSON round trip (stored with the robot row)
    b = AllowedPairs.from_json(a.to_json())
    assert b.allowed == a.allowed and b.checked == a.checked


def test_folded_collides_home_does_not(panda_self):
    assert not panda_self.collides(HOME)[0]
    assert panda_self.colliding(HOME) == []
    assert panda_self.collides(FOLDED)[0]
    hit = panda_self.colliding(FOLDED)
    assert any("gripper" in a or "gripper" in b for a, b in hit)  # the hand reaches the shoulder


def _fcl_geom(go):
    if go.meshPath and not go.meshPath.upper().startswith("BOX"):
        m = trimesh.load(go.meshPath, force="mesh")
        m.apply_scale(np.asarray(go.meshScale))
        b = fcl.BVHModel()
        b.beginModel(len(m.vertices), len(m.faces))
        b.addSubModel(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int32))
        b.endModel()
        return b
    return fcl.Box(*(2 * np.asarray(go.geometry.halfSide)))


def test_cross_check_with_fcl_on_the_full_urdf(panda, panda_self):
    """Independent: the full Panda URDF (own hand, fingers opened to their limit) in python-fcl, pinocchio FK on the
    full model, the SRDF's disabled pairs and adjacency read here from the XML."""
    urdf = panda.spec.urdf
    model = pin.buildModelFromXML(urdf)
    geom = pin.buildGeomFromUrdfString(model, urdf, pin.COLLISION, package_dirs=list(panda.package_dirs))
    data, gdata = model.createData(), pin.GeometryData(geom)
    srdf = ET.parse(srdf_for(panda)).getroot()
    disabled = {frozenset((e.get("link1"), e.get("link2"))) for e in srdf.iter("disable_collisions")}
    root = ET.fromstring(urdf)
    parent = {j.find("child").get("link"): j.find("parent").get("link") for j in root.iter("joint")}
    link_of = [model.frames[go.parentFrame].name for go in geom.geometryObjects]
    objs = [fcl.CollisionObject(_fcl_geom(go), fcl.Transform()) for go in geom.geometryObjects]
    hand = {"panda_hand", "panda_leftfinger", "panda_rightfinger"}

    def rigid(a, b):  # same body once fixed joints are merged (hand, fingers at a fixed opening, link8)
        def body(x):
            while x in parent and (x in hand or x == "panda_link8"):
                x = parent[x]
            return x
        return body(a) == body(b)

    pairs = []
    for i in range(len(objs)):
        for j in range(i + 1, len(objs)):
            a, b = link_of[i], link_of[j]
            if a == b or rigid(a, b) or frozenset((a, b)) in disabled or parent.get(a) == b or parent.get(b) == a:
                continue
            pairs.append((i, j))
    finger = [model.joints[model.getJointId(n)].idx_q for n in ("panda_finger_joint1", "panda_finger_joint2")]
    rng = np.random.default_rng(7)
    qs = np.vstack([rng.uniform(panda.lower, panda.upper, size=(300, 7)), HOME, FOLDED])
    ours = panda_self.collides(qs)
    theirs = np.zeros(len(qs), dtype=bool)
    req = fcl.CollisionRequest()
    for k, q in enumerate(qs):
        full = pin.neutral(model)
        full[:7] = q
        full[finger] = model.upperPositionLimit[finger]
        pin.forwardKinematics(model, data, full)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        for o, m in zip(objs, gdata.oMg):
            o.setTransform(fcl.Transform(m.rotation, m.translation))
        theirs[k] = any(fcl.collide(objs[i], objs[j], req, fcl.CollisionResult()) for i, j in pairs)
    assert theirs.sum() >= 10  # the sample does exercise self-collision
    assert theirs[-1] and not theirs[-2]
    assert (ours == theirs).mean() >= 0.99, np.flatnonzero(ours != theirs)


def test_sampled_pairs_without_srdf_are_deterministic(panda):
    a = allowed_pairs(panda, srdf=False, samples=300, seed=3)
    b = allowed_pairs(panda, srdf=False, samples=300, seed=3)
    assert a.allowed == b.allowed and a.samples == 300
    assert set(a.allowed.values()) <= {"rigid", "adjacent", "never", "always"}
    # the folded pose still self-collides with sampled pairs
    assert SelfCollision(panda, a).collides(FOLDED)[0]


def test_a_self_colliding_ik_solution_is_not_feasible(panda):
    """The IK solver with self_collide (as the roadmap's IK stage runs it) rejects a converged solution that
    self-collides; the same solver without it accepts it (the folded pose clears the table)."""
    from workbench.robots.collider import default_scene
    from workbench.robots.ik import IKOptions, IKSolver

    target = panda.tcp_pose(FOLDED)[None]
    place = np.eye(4)[None]
    on = IKSolver(panda, default_scene("panda"), IKOptions(self_collide=True, library=64, solver="numerical"))
    off = IKSolver(panda, default_scene("panda"), IKOptions(self_collide=False, library=64, solver="numerical"))
    q, ok = off.solve(target, place, FOLDED[None], 30)
    assert ok[0] and np.abs(q[0] - FOLDED).max() < 1e-3  # IK converges to the folded configuration
    _, ok = on.solve(target, place, FOLDED[None], 30)
    assert not ok[0]
    home = panda.tcp_pose(HOME)[None]
    _, ok = on.solve(home, place, HOME[None], 30)
    assert ok[0]
