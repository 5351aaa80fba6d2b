"""Figures of the grasp-placement table (Tournassoud, Lozano-Perez & Mazer 1987, Figs. 5 and 6), matplotlib.

The table is drawn as one image: grasp classes are rows, placement classes columns; inside each cell the legal
(theta, phi) samples of Q_ij, theta upward and phi rightward, both over [0, 360) degrees. Samples removed by
hand-object collision are dark grey, by hand-table collision light grey, by IK white, and legal ones blue. A
sequence is overlaid as in Fig. 6: vertical jumps are regrasps (same placement and phi, another grasp), horizontal
moves are transfers (same grasp, another placement).
"""

from __future__ import annotations

import base64
import html
import io

import numpy as np

from workbench.planners.tournassoud.chaining import Sequence
from workbench.planners.tournassoud.classes import GraspClass
from workbench.planners.tournassoud.table import GraspPlacementTable

COLOURS = np.array([[0.35, 0.35, 0.35], [0.8, 0.8, 0.8], [1.0, 1.0, 1.0], [0.2, 0.45, 0.85]])


def table_image(table: GraspPlacementTable) -> np.ndarray:
    """(C T, P F, 3) RGB image of the table with the stage of Section 5 that removed each sample; row 0 is the
    bottom (class C-1, theta 0), for `imshow(origin="lower")`."""
    c_n, p_n, t_n, f_n = table.q.shape
    code = np.full((c_n, p_n, t_n, f_n), 2, dtype=np.int8)
    code[~np.broadcast_to(table.hand_table[..., None], code.shape)] = 1
    code[~np.broadcast_to(table.hand_object[:, None, :, None], code.shape)] = 0
    code[table.q] = 3
    return COLOURS[code.transpose(0, 2, 1, 3)[::-1].reshape(c_n * t_n, p_n * f_n)]


def _xy(table: GraspPlacementTable, grasp: tuple[int, int], placement: tuple[int, int]) -> tuple[float, float]:
    """Centre of a (grasp, placement) sample in the image's data coordinates (cells of unit size)."""
    c_n, p_n, t_n, f_n = table.q.shape
    (c, t), (j, f) = grasp, placement
    return j + (f + 0.5) / f_n, c_n - 1 - c + (t + 0.5) / t_n


def table_figure(table: GraspPlacementTable, classes: list[GraspClass], seq: Sequence | None = None, ax=None,
                 title: str = ""):
    """Fig. 5 (and Fig. 6 with `seq`): the table as an image, classes as rows, placements as columns."""
    import matplotlib.pyplot as plt

    c_n, p_n, _, _ = table.q.shape
    if ax is None:
        fig, ax = plt.subplots(figsize=(min(2 + 1.2 * p_n, 16), min(1.5 + 0.6 * c_n, 14)))
    else:
        fig = ax.figure
    if c_n and p_n:
        ax.imshow(table_image(table), extent=(0, p_n, 0, c_n), origin="lower", aspect="auto", interpolation="nearest")
    ax.set_xticks(np.arange(p_n) + 0.5, [f"P{j}" for j in range(p_n)])
    ax.set_yticks(np.arange(c_n) + 0.5, [f"G{c_n - 1 - i} {classes[c_n - 1 - i].kind}" for i in range(c_n)] if classes else [])
    for k in range(1, p_n):
        ax.axvline(k, color="k", lw=0.8)
    for k in range(1, c_n):
        ax.axhline(k, color="k", lw=0.8)
    ax.set_xlabel("placement class P_j (phi 0..360 deg within each column)")
    ax.set_ylabel("grasp class G_i (theta 0..360 deg upward within each row)")
    if seq is not None:
        pts = [_xy(table, g, p) for g, p in seq.conjunctions()]
        if pts:
            x, y = np.array(pts).T
            ax.plot(x, y, "-", color="crimson", lw=1.8)
            ax.plot(x, y, "o", color="crimson", ms=4)
            ax.plot(x[:1], y[:1], "s", color="green", ms=8, label="start")
            ax.plot(x[-1:], y[-1:], "*", color="orange", ms=12, label="goal")
            ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    ax.set_title(title or "grasp-placement table (blue: legal; white: no IK; light grey: hand-table; dark: hand-object)",
                 fontsize=9)
    return fig


def table_html(table: GraspPlacementTable, classes: list[GraspClass], seq: Sequence | None = None, title: str = "") -> str:
    """A standalone HTML page with the Fig. 5/6 image and the sequence as text."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig = table_figure(table, classes, seq, title=title)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)
    img = base64.b64encode(buf.getvalue()).decode()
    rows = []
    if seq is not None:
        for k, ((c, t), (j, f)) in enumerate(seq.conjunctions()):
            rows.append(f"<tr><td>{k}</td><td>G{c} ({html.escape(classes[c].kind)})</td><td>{np.degrees(table.theta[t]):.1f}</td>"
                        f"<td>P{j}</td><td>{np.degrees(table.phi[f]):.1f}</td></tr>")
    body = ("<table border=1 cellpadding=3><tr><th>#</th><th>grasp class</th><th>theta (deg)</th><th>placement</th>"
            f"<th>phi (deg)</th></tr>{''.join(rows)}</table>") if rows else ""
    return (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title></head><body>"
            f"<h3>{html.escape(title)}</h3><img src='data:image/png;base64,{img}'/>{body}</body></html>")
