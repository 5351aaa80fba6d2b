"""Plots of a plan replayed in physics (`workbench.simulation`): the part's error against the plan at every
waypoint, with the tolerances and the first failure."""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np


def error_figure(result, title: str = "") -> plt.Figure:
    """Translation (mm) and rotation (deg) error of the simulated part at every waypoint of a `SimResult`, the slip
    in the hand during transfers, the waypoint tolerances (dashed) and the first failure (red)."""
    s, p = result.steps, result.params
    x = np.arange(len(s["seq"]))
    labels = [f"{st + 1} {cap} {kind}" for st, cap, kind in zip(s["step"], s["caption"], s["kind"])]
    fig, (ax_t, ax_r) = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    ax_t.plot(x, s["error"] * 1000, "o-", color="#d03060", label="part vs plan")
    ax_t.plot(x, s["slip"] * 1000, "s--", color="#3366dd", label="slip in the hand")
    ax_t.axhline(p["waypoint_tol"] * 1000, color="grey", ls=":", label="waypoint tolerance")
    ax_t.set_ylabel("translation error (mm)")
    ax_r.plot(x, np.degrees(s["angle"]), "o-", color="#d03060", label="part vs plan")
    ax_r.plot(x, np.degrees(s["slip_angle"]), "s--", color="#3366dd", label="slip in the hand")
    ax_r.axhline(math.degrees(p["waypoint_tol_angle"]), color="grey", ls=":", label="waypoint tolerance")
    ax_r.set_ylabel("rotation error (deg)")
    f = result.failure
    if f is not None:
        k = int(np.flatnonzero(s["step"] == f.step)[0])
        hit = np.flatnonzero((s["step"] == f.step) & (s["t"] >= f.t - 1e-9))
        k = int(hit[0]) if len(hit) else k
        for ax in (ax_t, ax_r):
            ax.axvline(k, color="red", lw=2, alpha=0.5, label=f"first failure: {f.kind}")
    for ax in (ax_t, ax_r):
        ax.grid(alpha=0.3)
        ax.legend(loc="upper left", fontsize=8)
    ax_r.set_xticks(x, labels, rotation=70, ha="right", fontsize=7)
    verdict = (f"confirmed: {result.final_error * 1000:.1f} mm, {math.degrees(result.final_angle):.1f} deg from the goal"
               if result.confirmed else f"not confirmed: {f.kind} at step {f.step + 1}")
    fig.suptitle(title or f"The part in physics against the plan, per waypoint ({verdict})")
    fig.tight_layout()
    return fig
