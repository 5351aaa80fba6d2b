"""Self-collision of the arm and its planning gripper (CONVENTIONS.md, Plans and motions).

The collision parts are the URDF's collision geometry of the arm (pinocchio's reduced model: links moved by the
arm's joints and the fixed ones, without the robot's own hand, `RobotSpec.drop_geometry`) plus the planning
gripper (hand body and both fingers at full opening) rigidly attached to the last joint at the TCP. Parts are
grouped by link; the planning gripper is two pseudo-links, `gripper_hand` (body) and `gripper_fingers`.

Allowed pairs (never checked), computed once per robot (`allowed_pairs`, JSON-serialisable so it can be stored
with the robot row):
- links whose relative pose never changes (same parent joint, or both fixed);
- adjacent links (one joint between their parent joints);
- the SRDF's `disable_collisions` pairs where example-robot-data ships an SRDF beside the URDF
  (`<pkg>/srdf/<urdf stem>.srdf`, e.g. the Panda's). A pair with the planning gripper is allowed when the SRDF
  allows it for every link the gripper replaces (the Panda's hand and both fingers);
- for pairs the SRDF does not cover (or no SRDF): pairs never in collision over a seeded uniform sample of
  configurations within the joint limits ("never"), and pairs always in collision ("always", modelling overlaps).

Checks run in pinocchio + coal (`computeCollisions`, stop at first) per configuration; batches loop in C++ calls.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import coal
import numpy as np
import pinocchio as pin
import trimesh

from workbench.errors import RobotError
from workbench.robots.model import Robot

GRIPPER_HAND = "gripper_hand"
GRIPPER_FINGERS = "gripper_fingers"
"""Pseudo-link names of the planning gripper's body and fingers."""


def coal_mesh(mesh: trimesh.Trimesh) -> coal.BVHModelOBBRSS:
    """A coal BVH of a triangle mesh."""
    model = coal.BVHModelOBBRSS()
    model.beginModel(len(mesh.faces), len(mesh.vertices))
    model.addVertices(np.asarray(mesh.vertices, dtype=np.float64))
    model.addTriangles(np.asarray(mesh.faces, dtype=np.int64))
    model.endModel()
    return model


@dataclass(frozen=True)
class Part:
    """One collision part: name, link (or a gripper pseudo-link), the reduced model's parent joint (0 = fixed), pose in that joint."""

    name: str
    link: str
    joint: int
    placement: np.ndarray
    geometry: object = field(repr=False, compare=False)


def robot_parts(robot: Robot, gripper_width: float | None = None) -> list[Part]:
    """The arm's URDF collision parts (without the robot's own hand) and the planning gripper's parts on the last joint."""
    parts = []
    for k, go in enumerate(robot.geom.geometryObjects):
        if go.parentJoint > 0 and robot.dropped(go):
            continue
        link = robot.model.frames[go.parentFrame].name
        parts.append(Part(go.name, link, int(go.parentJoint), np.asarray(go.placement.homogeneous).copy(), go.geometry))
    g = robot.gripper
    width = g.jaw_max if gripper_width is None else gripper_width
    last = robot.nq  # the reduced model's joints are 1..nq
    parts.append(Part(GRIPPER_HAND, GRIPPER_HAND, last, robot.tip_in_joint.copy(), coal_mesh(g.body)))
    for i, (ext, pose) in enumerate(g.finger_poses(width)):
        parts.append(Part(f"{GRIPPER_FINGERS}_{i}", GRIPPER_FINGERS, last, robot.tip_in_joint @ pose, coal.Box(*np.asarray(ext, dtype=np.float64))))
    return parts


def srdf_for(robot: Robot) -> Path | None:
    """The SRDF example-robot-data ships beside the robot's URDF: `../srdf/<stem>.srdf`, else the longest
    `../srdf/<name>.srdf` whose name starts the URDF's stem (talos_reduced -> talos, ur5_robot -> ur5), if any."""
    if not robot.spec.urdf_path:
        return None
    p = Path(robot.spec.urdf_path)
    folder = p.parent.parent / "srdf"
    if not folder.is_dir():
        return None
    names = sorted((c for c in folder.glob("*.srdf") if p.stem.startswith(c.stem)), key=lambda c: -len(c.stem))
    return names[0] if names else None


def _replaced_links(robot: Robot, known: set[str]) -> dict[str, list[str]]:
    """The SRDF links the planning gripper's body and fingers stand for, when the gripper is the robot's own hand
    (loaded from the same URDF): the dropped link nearest the root is the hand, the other dropped links the fingers."""
    gpath = getattr(robot.gripper, "urdf", "")
    if not gpath or not robot.spec.urdf_path or Path(gpath).resolve() != Path(robot.spec.urdf_path).resolve():
        return {}
    root = ET.fromstring(robot.spec.urdf)
    parent = {j.find("child").get("link"): j.find("parent").get("link") for j in root.iter("joint")
              if j.find("child") is not None and j.find("parent") is not None}
    dropped = [lk.get("name") for lk in root.iter("link") if any(lk.get("name", "").startswith(h) for h in robot.spec.drop_geometry)]
    dropped = [d for d in dropped if d in known]
    if not dropped:
        return {}

    def depth(link: str) -> int:
        n = 0
        while link in parent and n < 1000:
            link, n = parent[link], n + 1
        return n

    hand = min(dropped, key=depth)
    return {GRIPPER_HAND: [hand], GRIPPER_FINGERS: [d for d in dropped if d != hand] or [hand]}


def _srdf_pairs(text: str) -> tuple[set[frozenset], set[str]]:
    root = ET.fromstring(text)
    pairs, links = set(), set()
    for e in root.iter("disable_collisions"):
        a, b = e.get("link1"), e.get("link2")
        if a and b:
            pairs.add(frozenset((a, b)))
            links.update((a, b))
    return pairs, links


@dataclass
class AllowedPairs:
    """Link pairs never checked, with the reason of each (`rigid`, `adjacent`, `srdf`, `never`, `always`), and the
    link pairs that are checked. `samples` and `seed` describe the sampling; `source` the SRDF used (or "")."""

    allowed: dict[tuple[str, str], str]
    checked: list[tuple[str, str]]
    samples: int = 0
    seed: int = 0
    source: str = ""

    def to_json(self) -> str:
        return json.dumps({"allowed": [[a, b, r] for (a, b), r in sorted(self.allowed.items())],
                           "checked": [list(p) for p in self.checked], "samples": self.samples, "seed": self.seed,
                           "source": self.source})

    @classmethod
    def from_json(cls, text: str) -> "AllowedPairs":
        d = json.loads(text)
        return cls({(a, b): r for a, b, r in d["allowed"]}, [tuple(p) for p in d["checked"]], int(d.get("samples", 0)),
                   int(d.get("seed", 0)), d.get("source", ""))

    def is_allowed(self, a: str, b: str) -> bool:
        return _key(a, b) in self.allowed


def _key(a: str, b: str) -> tuple[str, str]:
    return (a, b) if a <= b else (b, a)


def _link_joints(parts: list[Part]) -> dict[str, int]:
    return {p.link: p.joint for p in parts}


def allowed_pairs(robot: Robot, srdf: str | Path | None | bool = True, samples: int = 2000, seed: int = 0) -> AllowedPairs:
    """The link pairs exempt from self-collision checks (see the module docstring); computed once per robot.

    `srdf`: True looks for example-robot-data's SRDF beside the URDF, a path uses that file, False/None ignores SRDFs."""
    parts = robot_parts(robot)
    joint_of = _link_joints(parts)
    parents = np.asarray(robot.model.parents)
    links = sorted(joint_of)
    allowed: dict[tuple[str, str], str] = {}
    candidates = []
    for i, a in enumerate(links):
        for b in links[i + 1:]:
            ja, jb = joint_of[a], joint_of[b]
            if ja == jb:
                allowed[_key(a, b)] = "rigid"
            elif (jb > 0 and parents[jb] == ja) or (ja > 0 and parents[ja] == jb):
                allowed[_key(a, b)] = "adjacent"
            else:
                candidates.append(_key(a, b))
    source = ""
    path = srdf_for(robot) if srdf is True else (Path(srdf) if srdf else None)
    uncovered = candidates
    if path is not None:
        try:
            disabled, known = _srdf_pairs(Path(path).read_text())
        except (OSError, ET.ParseError) as exc:
            raise RobotError(f"SRDF {path} cannot be read ({type(exc).__name__}); fix it or pass srdf=False") from None
        source = str(path)
        replaced = _replaced_links(robot, known)
        uncovered = []
        for a, b in candidates:
            ra, rb = replaced.get(a, [a]), replaced.get(b, [b])
            if not all(x in known for x in ra + rb):
                uncovered.append((a, b))
            elif all(frozenset((x, y)) in disabled for x in ra for y in rb):
                allowed[(a, b)] = "srdf"
    if uncovered and samples > 0:
        counts = _sample_counts(robot, parts, uncovered, samples, seed)
        for pair, c in zip(uncovered, counts):
            if c == 0:
                allowed[pair] = "never"
            elif c == samples:
                allowed[pair] = "always"
    checked = [p for p in candidates if p not in allowed]
    return AllowedPairs(allowed, checked, samples if uncovered else 0, seed, source)


def _geometry_model(parts: list[Part]) -> pin.GeometryModel:
    gm = pin.GeometryModel()
    for p in parts:
        gm.addGeometryObject(pin.GeometryObject(p.name, p.joint, pin.SE3(p.placement[:3, :3].copy(), p.placement[:3, 3].copy()), p.geometry))
    return gm


def _add_pairs(gm: pin.GeometryModel, parts: list[Part], link_pairs) -> None:
    want = {frozenset(p) if p[0] != p[1] else frozenset((p[0],)) for p in link_pairs}
    for i, a in enumerate(parts):
        for j in range(i + 1, len(parts)):
            b = parts[j]
            if a.link != b.link and frozenset((a.link, b.link)) in want:
                gm.addCollisionPair(pin.CollisionPair(i, j))


def _sample_counts(robot: Robot, parts: list[Part], pairs: list[tuple[str, str]], samples: int, seed: int) -> np.ndarray:
    """Per link pair, in how many of `samples` seeded uniform configurations some of their parts collide."""
    gm = _geometry_model(parts)
    _add_pairs(gm, parts, pairs)
    gd = pin.GeometryData(gm)
    data = robot.model.createData()
    index = {p: k for k, p in enumerate(pairs)}
    cp_pair = np.array([index[_key(parts[cp.first].link, parts[cp.second].link)] for cp in gm.collisionPairs], dtype=np.int64)
    rng = np.random.default_rng(seed)
    qs = rng.uniform(robot.lower, robot.upper, size=(samples, robot.nq))
    counts = np.zeros(len(pairs), dtype=np.int64)
    for q in qs:
        pin.computeCollisions(robot.model, data, gm, gd, q, False)
        hit = np.array([r.isCollision() for r in gd.collisionResults], dtype=bool)
        if hit.any():
            counts += np.bincount(cp_pair[hit], minlength=len(pairs)) > 0
    return counts


class SelfCollision:
    """Self-collision checker of a robot and its planning gripper with the given allowed pairs (pinocchio + coal).

    `collides(q)` is (B,) for joint vectors (B, n); `colliding(q)` names the colliding link pairs of one vector."""

    def __init__(self, robot: Robot, allowed: AllowedPairs | None = None, gripper_width: float | None = None):
        self.robot = robot
        self.allowed = allowed if allowed is not None else allowed_pairs(robot)
        self.parts = robot_parts(robot, gripper_width)
        self.gm = _geometry_model(self.parts)
        _add_pairs(self.gm, self.parts, self.allowed.checked)
        self.gd = pin.GeometryData(self.gm)
        self.data = robot.model.createData()
        self.broad = pin.BroadPhaseManager_DynamicAABBTreeCollisionManager(robot.model, self.gm, self.gd)

    def collides(self, q: np.ndarray) -> np.ndarray:
        """(B,) True where the arm or gripper collides with itself, for joint vectors q (B, n) or (n,)."""
        q = np.atleast_2d(np.asarray(q, dtype=np.float64))
        out = np.zeros(len(q), dtype=bool)
        m, d, broad = self.robot.model, self.data, self.broad
        for i, qi in enumerate(q):
            out[i] = pin.computeCollisions(m, d, broad, qi, True)
        return out

    def colliding(self, q: np.ndarray) -> list[tuple[str, str]]:
        """The link pairs in collision at one joint vector."""
        pin.computeCollisions(self.robot.model, self.data, self.gm, self.gd, np.asarray(q, dtype=np.float64), False)
        out = set()
        for cp, r in zip(self.gm.collisionPairs, self.gd.collisionResults):
            if r.isCollision():
                out.add(_key(self.parts[cp.first].link, self.parts[cp.second].link))
        return sorted(out)
