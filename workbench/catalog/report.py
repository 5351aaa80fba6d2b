"""The catalogue as a parts x robots table (`workbench catalog report`): per part its free-air grasps and stable
placements (Wan & Harada Sections III-IV), per robot its reachable grips (tabletop grips IK-feasible at all five
poses, Section IV) and its regrasp graph's connected share (the nodes in its largest component, Section V); and the
same as an HTML page with a thumbnail of each part."""

from __future__ import annotations

import base64
import html
import io

import numpy as np

def wide_table(rows: list[dict]) -> tuple[list[str], list[tuple]]:
    """Headers and one row per part: part, grasps (per gripper when the catalogue has several), placements, then per
    (robot, gripper) column its reachable grips (of the tabletop grips) and the graph's connected share."""
    grippers = sorted({r.get("gripper") or "-" for r in rows})
    several = len(grippers) > 1
    columns = sorted({(r["robot"], r.get("gripper") or "-") for r in rows if r["robot"]})
    parts: dict[str, dict] = {}
    for r in rows:
        p = parts.setdefault(r["part"], {"grasps": {}, "placements": r["placements"], "columns": {}})
        p["grasps"][r.get("gripper") or "-"] = r["grasps"]
        if r["robot"]:
            p["columns"][r["robot"], r.get("gripper") or "-"] = r
    headers = ["part", *([f"{g} grasps" for g in grippers] if several else ["grasps"]), "placements"]
    for robot, gripper in columns:
        label = f"{robot} + {gripper}" if several else robot
        headers += [f"{label} reachable", f"{label} connected"]
    out = []
    for name in sorted(parts):
        p = parts[name]
        row: list = [name, *(p["grasps"].get(g, "-") for g in grippers), p["placements"]]
        for column in columns:
            r = p["columns"].get(column)
            if r is None:
                row += ["-", "-"]
                continue
            row.append(f"{r['ik_feasible']:,}/{r['tabletop_grips']:,}")
            g = r["graph"]
            nodes, largest = g.get("nodes"), g.get("largest_component")
            row.append(f"{largest / nodes:.0%}" if nodes and largest is not None else "-")
        out.append(tuple(row))
    return headers, out


def thumbnail(vertices: np.ndarray, faces: np.ndarray, size: float = 1.6, max_faces: int = 4000) -> str:
    """A small shaded picture of a mesh (PNG, base64) seen from above at an angle."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) > max_faces:  # a thumbnail needs no more
        f = f[np.linspace(0, len(f) - 1, max_faces).astype(np.int64)]
    fig = plt.figure(figsize=(size, size), dpi=80)
    ax = fig.add_subplot(projection="3d")
    ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=f, color=(0.55, 0.65, 0.85), shade=True, linewidth=0)
    lo, hi = v.min(axis=0), v.max(axis=0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2 or 1.0
    for axis, m in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid):
        axis(m - half, m + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=25, azim=-60)
    ax.set_axis_off()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight", pad_inches=0.02, transparent=True)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


def html_page(rows: list[dict], failures: list[dict], meshes: dict[str, tuple[np.ndarray, np.ndarray]], title: str) -> str:
    """The parts x robots table as a page, a thumbnail beside each part, then the failed units with their reasons."""
    headers, table = wide_table(rows)
    cells = []
    for row in table:
        name = row[0]
        img = ""
        if name in meshes:
            img = f'<img src="data:image/png;base64,{thumbnail(*meshes[name])}" alt="{html.escape(name)}">'
        tds = "".join(f"<td>{html.escape(str(c))}</td>" for c in row[1:])
        cells.append(f"<tr><td class=part>{img}<span>{html.escape(name)}</span></td>{tds}</tr>")
    fails = "".join(f"<li><b>{html.escape(f['part'])}</b> {html.escape(f['kind'])}"
                    f"{' x ' + html.escape(f['robot']) if f['robot'] else ''}"
                    f"{' with ' + html.escape(f['gripper']) if f.get('gripper') else ''}: {html.escape(f['error'] or '')}</li>"
                    for f in failures)
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(title)}</title><style>
body {{ font-family: sans-serif; margin: 1.5em; }}
table {{ border-collapse: collapse; }}
th, td {{ border-bottom: 1px solid #ddd; padding: 4px 10px; text-align: right; }}
th {{ background: #f4f4f4; }}
td.part {{ text-align: left; display: flex; align-items: center; gap: 8px; }}
td.part img {{ width: 96px; height: 96px; }}
p.key {{ color: #555; max-width: 60em; }}
</style></head><body><h1>{html.escape(title)}</h1>
<p class="key">Per part: free-air grasps and stable placements. Per robot: reachable grips (tabletop grips with IK at
the grasp, after the retraction along the hand, lifted, and the part lifted straight up: all five poses) of all its
tabletop grips, and the regrasp graph's connected share (its nodes in the largest connected component).</p>
<table><tr>{head}</tr>{''.join(cells)}</table>
{f'<h2>Failed</h2><ul>{fails}</ul>' if fails else ''}
</body></html>"""
