"""Captions and a colour key in meshcat scenes: meshcat draws no text, so `caption_png` renders text
(with colour swatches) as a PNG and `add_overlays` shows it on thin textured boxes facing the camera, one caption
panel per plan step name (pick, transfer, release, regrasp, place) shown while the animation is in that step.
"""

from __future__ import annotations

import io

import numpy as np

CAPTIONS = ("pick", "transfer", "release", "regrasp", "place")
CAPTION_TEXT = {"pick": "pick: grasp the part at its start pose", "transfer": "transfer: carry the part",
                "release": "release: put the part down to regrasp it", "regrasp": "regrasp: take it with another grasp",
                "place": "place: put the part down at its goal pose"}


def caption_png(lines: list[tuple[str, int | None]], width: int = 900, line_height: int = 56) -> bytes:
    """A PNG with lines of text, each with an optional colour swatch (0xRRGGBB) before it, on a white panel
    (rendered with matplotlib's Agg backend)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle

    height = line_height * len(lines) + 16
    dpi = 100
    fig = Figure(figsize=(width / dpi, height / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.axis("off")
    for i, (text, color) in enumerate(lines):
        y, x = 8 + i * line_height, 12
        if color is not None:
            rgb = (((color >> 16) & 255) / 255, ((color >> 8) & 255) / 255, (color & 255) / 255)
            ax.add_patch(Rectangle((x, y + 8), line_height - 16, line_height - 16, facecolor=rgb, edgecolor="0.25"))
            x += line_height
        ax.text(x, y + line_height / 2, text, va="center", ha="left", fontsize=line_height * 0.6 * 72 / dpi, color="0.08")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, facecolor="white")
    return buf.getvalue()


def _panel_pose(anchor: np.ndarray, facing: np.ndarray) -> np.ndarray:
    """A pose whose +z points along `facing` (horizontal), +y up (world z), at `anchor`."""
    z = np.array([facing[0], facing[1], 0.0])
    z /= max(np.linalg.norm(z), 1e-12)
    y = np.array([0.0, 0.0, 1.0])
    x = np.cross(y, z)
    out = np.eye(4)
    out[:3, 0], out[:3, 1], out[:3, 2], out[:3, 3] = x, y, z, anchor
    return out


KEY_WIDTH = 0.28  # m, the colour-key panel


def _key_pose(pose: np.ndarray, width: float) -> np.ndarray:
    """The colour key's pose beside the caption panel at `pose`: below left of it, clear of it in perspective."""
    out = pose.copy()
    out[:3, 3] -= pose[:3, 0] * (0.5 * width + 0.22) + pose[:3, 1] * 0.16
    return out


def overlay_corners(anchor: np.ndarray, facing: np.ndarray, width: float = 0.6, margin: float = 0.08) -> np.ndarray:
    """(8, 3) corners of the caption and key panels of `add_overlays`, `margin` metres out, for framing the camera."""
    pose = _panel_pose(np.asarray(anchor, dtype=np.float64), np.asarray(facing, dtype=np.float64))
    out = []
    for at, half_w, half_h in ((pose, width / 2, 0.03), (_key_pose(pose, width), KEY_WIDTH / 2, 0.09)):
        for sx in (-1, 1):
            for sy in (-1, 1):
                out.append(at[:3, 3] + at[:3, 0] * sx * (half_w + margin) + at[:3, 1] * sy * (half_h + margin))
    return np.array(out)


def add_overlays(vis, anim, frames: list[dict], path: str, anchor: np.ndarray, facing: np.ndarray,
                 key: list[tuple[str, int | None]], width: float = 0.6) -> None:
    """Caption panels (one per step name, shown while a frame belongs to that step) and a colour-key panel, as thin
    textured boxes standing at `anchor` and facing the camera direction `facing` (meshcat draws no text)."""
    import meshcat.geometry as g

    pose = _panel_pose(np.asarray(anchor, dtype=np.float64), np.asarray(facing, dtype=np.float64))
    hidden = pose.copy()
    hidden[2, 3] -= 100.0

    def panel(name: str, png: bytes, px: tuple[int, int], at: np.ndarray, w: float) -> None:
        h = w * px[1] / px[0]
        tex = g.ImageTexture(image=g.PngImage(png))
        vis[f"{path}/{name}"].set_object(g.Box([w, h, 1e-4]), g.MeshBasicMaterial(map=tex, transparent=False))
        vis[f"{path}/{name}"].set_transform(at)

    key_png = caption_png(key, width=480)
    panel("key", key_png, (480, 56 * len(key) + 16), _key_pose(pose, width), KEY_WIDTH)
    used = [c for c in CAPTIONS if any(f["caption"] == c for f in frames)]
    for c in used:
        panel(f"caption_{c}", caption_png([(CAPTION_TEXT[c], None)], width=820), (820, 72), hidden, width)
    for i, fr in enumerate(frames):
        with anim.at_frame(vis, i) as f:
            for c in used:
                f[f"{path}/caption_{c}"].set_transform(pose if fr["caption"] == c else hidden)
