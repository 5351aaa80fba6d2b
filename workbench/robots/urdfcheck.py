"""A user's URDF checked before pinocchio reads it: each fault named in one line (a RobotError).

urdfdom and pinocchio trust their input: a joint loop (a link with two parent joints) crashes pinocchio's model
builder, NaN limits print several lines of parser output, and inverted or empty limits or a joint given as the
tip frame only show up later as "nothing is reachable". Here the kinematic tree is checked to be a tree (one
root, every link reached from it once), the tip to be a link, no joint between the root and the tip to mimic
another (pinocchio would read it as a joint of its own), and every moving joint's limits and every origin to be
finite, with lower below upper.
"""

from __future__ import annotations

import math
from xml.etree.ElementTree import Element

from workbench.errors import RobotError

MOVING = ("revolute", "prismatic", "continuous")
TYPES = MOVING + ("fixed", "floating", "planar")


def _numbers(text: str | None) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(v) for v in text.split()]
    except ValueError:
        return [math.nan]


def check_urdf(root: Element, tip_frame: str, label: str = "robot URDF") -> None:
    """Refuse a URDF (its parsed root element) that pinocchio cannot load safely or that cannot plan to `tip_frame`."""
    links = [lk.get("name", "") for lk in root.findall("link")]
    joints = root.findall("joint")
    if not links:
        raise RobotError(f"{label} has no <link>; check the file")
    for kind, names in (("link", links), ("joint", [j.get("name", "") for j in joints])):
        seen: set[str] = set()
        for n in names:
            if not n:
                raise RobotError(f"{label} has a {kind} without a name; name every {kind}")
            if n in seen:
                raise RobotError(f"{label} names two {kind}s {n!r}; give each {kind} its own name")
            seen.add(n)
    known = set(links)
    parent_of: dict[str, str] = {}
    for j in joints:
        name, kind = j.get("name", ""), j.get("type", "")
        if kind not in TYPES:
            raise RobotError(f"{label}: joint {name!r} has type {kind!r}; a URDF joint is one of {', '.join(TYPES)}")
        p, c = j.find("parent"), j.find("child")
        if p is None or c is None:
            raise RobotError(f"{label}: joint {name!r} lacks its <parent> or <child> link")
        parent, child = p.get("link", ""), c.get("link", "")
        for end in (parent, child):
            if end not in known:
                raise RobotError(f"{label}: joint {name!r} names link {end!r}, which the URDF does not define")
        if child in parent_of:
            raise RobotError(f"{label} is not a tree: link {child!r} is the child of two joints ({parent_of[child]!r} and "
                             f"{name!r}), a closed loop; a URDF describes a tree, so remove one of them")
        parent_of[child] = name
        _check_numbers(j, name, kind, label)
    child_link = {j.get("name", ""): j.find("child").get("link", "") for j in joints}
    parent_link = {j.find("child").get("link", ""): j.find("parent").get("link", "") for j in joints}
    roots = [lk for lk in links if lk not in parent_link]
    if len(roots) != 1:
        what = f"{len(roots)} root links ({', '.join(roots[:4])})" if roots else "no root link (every link has a parent)"
        raise RobotError(f"{label} is not a tree: it has {what}; a URDF describes one tree, joined by joints")
    for lk in links:  # with one root and one parent per link, a cycle is a chain that never reaches the root
        seen, at = set(), lk
        while at in parent_link:
            if at in seen:
                raise RobotError(f"{label} is not a tree: the joints above link {lk!r} form a closed loop")
            seen.add(at)
            at = parent_link[at]
    if tip_frame not in known:
        if tip_frame in child_link:
            raise RobotError(f"{label}: --tip {tip_frame!r} is a joint, not a link; give a link, e.g. its child "
                             f"{child_link[tip_frame]!r}")
        raise RobotError(f"{label} has no link {tip_frame!r} for --tip (links: {', '.join(links[-6:])})")
    chain, at = [], tip_frame
    by_child = {j.find("child").get("link", ""): j for j in joints}
    while at in by_child:
        chain.append(by_child[at])
        at = parent_link[at]
    moving = [j for j in chain if j.get("type") in MOVING]  # none: the model says the tip is not moved by any joint
    for j in moving:
        mimic = j.find("mimic")
        if mimic is not None:
            raise RobotError(f"{label}: arm joint {j.get('name')!r} (on the chain to {tip_frame!r}) mimics joint "
                             f"{mimic.get('joint', '')!r}; the planner moves every arm joint on its own, so it would "
                             f"plan poses the coupled arm cannot take (a mimic joint in the hand past the tip is fine)")
    ranges = [_range(j) for j in moving if j.get("type") != "continuous"]
    if moving and len(ranges) == len(moving) and all(hi - lo <= 0 for lo, hi in ranges):
        raise RobotError(f"{label}: every joint from the root to {tip_frame!r} has an empty range (lower = upper), so the "
                         f"arm cannot move; give its joints' <limit lower=... upper=...>")


def _range(joint: Element) -> tuple[float, float]:
    limit = joint.find("limit")
    lo = _numbers(limit.get("lower", "0")) if limit is not None else [0.0]
    hi = _numbers(limit.get("upper", "0")) if limit is not None else [0.0]
    return lo[0], hi[0]


def _check_numbers(joint: Element, name: str, kind: str, label: str) -> None:
    """Finite origins, axes and limits; a moving joint's lower limit at most its upper."""
    for tag, attrs in (("origin", ("xyz", "rpy")), ("axis", ("xyz",)),
                       ("limit", ("lower", "upper", "velocity", "effort")), ("mimic", ("multiplier", "offset"))):
        el = joint.find(tag)
        if el is None:
            continue
        for a in attrs:
            values = _numbers(el.get(a))
            if values is not None and not all(math.isfinite(v) for v in values):
                raise RobotError(f"{label}: joint {name!r} has {tag} {a}={el.get(a)!r}, not finite numbers; give numbers "
                                 f"({'radians or metres' if tag == 'limit' else 'metres and radians'})")
    if kind in ("revolute", "prismatic"):
        limit = joint.find("limit")
        if limit is None:
            raise RobotError(f"{label}: {kind} joint {name!r} has no <limit>; give lower, upper, velocity and effort")
        lo, hi = _range(joint)
        if lo > hi:
            raise RobotError(f"{label}: joint {name!r} has its limits inverted (lower {lo:g} > upper {hi:g}); swap them")
