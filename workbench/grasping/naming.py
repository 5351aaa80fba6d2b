"""Placements as a person names them: numbered per part from 1 (the store's ids count across every part in a store)
and described by how the part rests, read from the supporting face's outward normal in the part's own frame (its
+z is "up" as the part was modelled)."""

from __future__ import annotations

import numpy as np

TOLERANCE_DEG = 15.0  # how far from vertical or level a resting face may be and still be "upright" / "on its side"


def rest_name(normal: np.ndarray) -> str:
    """"upright", "upside down", "on its side" or "tilted N deg" for a supporting face's outward normal (part frame):
    upright rests on the face whose normal is the part's -z."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / max(np.linalg.norm(n), 1e-12)
    tilt = float(np.degrees(np.arccos(np.clip(-n[2], -1.0, 1.0))))  # 0: the part's -z points down
    if tilt <= TOLERANCE_DEG:
        return "upright"
    if tilt >= 180.0 - TOLERANCE_DEG:
        return "upside down"
    if abs(tilt - 90.0) <= TOLERANCE_DEG:
        return "on its side"
    return f"tilted {tilt:.0f} deg"


def describe_placement(number: int, normal: np.ndarray, stability: float | None = None) -> str:
    """One line: "placement 2: on its side, face normal (+1.00, +0.00, +0.00)" (and the stability when given)."""
    n = np.asarray(normal, dtype=np.float64)
    n = np.round(n / max(np.linalg.norm(n), 1e-12), 2) + 0.0  # no "-0.00"
    text = f"placement {number}: {rest_name(n)}, face normal ({n[0]:+.2f}, {n[1]:+.2f}, {n[2]:+.2f})"
    return text if stability is None else f"{text}, stability {stability:.3f}"


def per_part_numbers(ids: np.ndarray) -> dict[int, int]:
    """Store placement id -> its number within the part (1, 2, ... in id order)."""
    return {int(i): k + 1 for k, i in enumerate(np.sort(np.asarray(ids, dtype=np.int64)))}


def resting_normal(rotmat: np.ndarray) -> np.ndarray:
    """The supporting face's outward normal in the part's frame for a placement rotation (part frame -> table):
    the part's direction that the placement turns to point straight down."""
    return np.asarray(rotmat, dtype=np.float64)[:3, :3].T @ np.array([0.0, 0.0, -1.0])


def placement_lines(rotmats: dict[int, np.ndarray], rocking: dict[int, bool] | None = None) -> list[str]:
    """One description per placement (store id -> rotation), numbered within the part: "placement 1: upright, ...",
    ending ", rocks" where `rocking` flags it (a small tilt rolls the part onto the next hull face)."""
    numbers = per_part_numbers(np.array(list(rotmats), dtype=np.int64))
    rocking = rocking or {}
    return [describe_placement(numbers[i], resting_normal(rotmats[i])) + (", rocks" if rocking.get(i) else "")
            for i in sorted(rotmats)]
