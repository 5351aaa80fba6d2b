"""Animation data of a timed plan: frames at the trajectory's real speed with the step they belong to (issue 12).

`timed_frames` samples the timed segments at `fps` frames per second of plan time (so a player at `fps` plays
the motion at its real speed): joint vector, jaw opening, whether the object is held, its pose in the world, and a
caption naming the step (pick, transfer, release, regrasp, place). `caption_png` renders a caption or the colour
key as a PNG for a textured plane in meshcat (which has no text).
"""

from __future__ import annotations

import io

import numpy as np

from .timing import TimedSegment

CAPTIONS = ("pick", "transfer", "release", "regrasp", "place")
CAPTION_TEXT = {"pick": "pick: grasp the part at its start pose", "transfer": "transfer: carry the part",
                "release": "release: put the part down to regrasp it", "regrasp": "regrasp: take it with another grasp",
                "place": "place: put the part down at its goal pose"}


def _inv(m: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = m[:3, :3].T
    out[:3, 3] = -m[:3, :3].T @ m[:3, 3]
    return out


def timed_frames(plan, segments: list[TimedSegment], tcp_pose, fps: float = 30.0, jaw_open: float = 0.08) -> list[dict]:
    """Frames of a timed plan: t, q, jaw, held, object (4x4 world pose), caption, segment index.

    `tcp_pose(q)` gives the TCP pose in the world (the robot's forward kinematics)."""
    if not segments:
        return []
    total = segments[-1].t0 + segments[-1].duration
    times = np.arange(0.0, total + 0.5 / fps, 1.0 / fps)
    times[-1] = min(times[-1], total)
    out = []
    k = 0
    jaw_before = jaw_open
    for t in times:
        while k + 1 < len(segments) and t > segments[k].t0 + segments[k].duration + 1e-9:
            if segments[k].kind == "gripper":
                jaw_before = segments[k].jaw
            k += 1
        seg = segments[k]
        local = min(max(t - seg.t0, 0.0), seg.duration)
        q = seg.traj.sample(np.array([local]))[0][0]
        if seg.kind == "gripper":
            f = local / seg.duration if seg.duration > 0 else 1.0
            jaw = (1 - f) * jaw_before + f * seg.jaw
        else:
            jaw = seg.jaw
        step = plan.steps[seg.step]
        if seg.holding:
            obj = tcp_pose(q) @ _inv(np.asarray(step.grasp, dtype=np.float64))
        else:
            obj = np.asarray(step.object_pose, dtype=np.float64)
        out.append({"t": float(t), "q": q, "jaw": float(jaw), "held": bool(seg.holding), "object": obj, "caption": seg.caption,
                    "segment": k})
    return out


def caption_png(lines: list[tuple[str, int | None]], width: int = 900, line_height: int = 56) -> bytes:
    """A PNG with lines of text, each with an optional colour swatch (0xRRGGBB) before it, on a white panel."""
    from PIL import Image, ImageDraw, ImageFont

    height = line_height * len(lines) + 16
    img = Image.new("RGBA", (width, height), (255, 255, 255, 235))
    draw = ImageDraw.Draw(img)
    try:
        font = ImageFont.load_default(size=int(line_height * 0.62))
    except TypeError:  # older Pillow: fixed-size bitmap font
        font = ImageFont.load_default()
    for i, (text, color) in enumerate(lines):
        y = 8 + i * line_height
        x = 12
        if color is not None:
            rgb = ((color >> 16) & 255, (color >> 8) & 255, color & 255, 255)
            draw.rectangle([x, y + 8, x + line_height - 16, y + line_height - 8], fill=rgb, outline=(60, 60, 60, 255))
            x += line_height
        draw.text((x, y + 6), text, fill=(20, 20, 20, 255), font=font)
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()
