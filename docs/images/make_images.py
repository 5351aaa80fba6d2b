"""Make the documentation's pictures from the library: `python docs/images/make_images.py [OUTDIR]`.

grasps.png (matplotlib: the bundled tube and the contact pairs of a sample of its grasps), grippers.png (the
bundled bracket with a few grasps of the Franka hand and of the Robotiq 2F-85-like spec), gptable.png (the
grasp-placement table of the L part with a chained sequence, as the paper's Fig. 6) and, when Chromium and
Playwright are installed, plan.png (a screenshot of `workbench demo`'s plan.html).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

OUT = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent


def grasps_png() -> None:
    from workbench.geometry.objects import load_object
    from workbench.grasping.grasps import GraspParams, plan_grasps
    from workbench.resources import bundled_objects
    from workbench.robots.gripper import franka_hand

    part = load_object(bundled_objects()["tube"])
    g = plan_grasps(part, franka_hand(), GraspParams()).grasps
    pick = np.random.default_rng(0).choice(len(g.poses), size=min(60, len(g.poses)), replace=False)
    fig = plt.figure(figsize=(7, 5))
    ax = fig.add_subplot(projection="3d")
    m = part.mesh
    ax.add_collection3d(Poly3DCollection(m.vertices[m.faces], facecolor=(0.85, 0.6, 0.25, 0.18), edgecolor="none"))
    for k in pick:
        a, b = g.contact0[k], g.contact1[k]
        ax.plot(*np.c_[a, b], color="tab:blue", lw=1.2)
        ax.scatter(*np.c_[a, b], color="tab:red", s=10, depthshade=False)
    lo, hi = m.bounds
    c, r = (lo + hi) / 2, (hi - lo).max() * 0.36
    ax.set(xlim=(c[0] - r, c[0] + r), ylim=(c[1] - r, c[1] + r), zlim=(c[2] - r, c[2] + r))
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(28, -55)
    ax.set_axis_off()
    ax.set_title(f"tube: {len(g.poses)} grasps; 60 of them as contact pairs (red) and jaw axes (blue)", fontsize=9)
    fig.savefig(OUT / "grasps.png", dpi=90, bbox_inches="tight")


def grippers_png() -> None:
    from workbench.geometry.objects import load_object
    from workbench.grasping.grasps import GraspParams, plan_grasps
    from workbench.resources import bundled_objects
    from workbench.robots.gripper import franka_hand, load_gripper
    from workbench.viewer.grippers import compare_figure

    part = load_object(bundled_objects()["bracket"])
    sets = []
    for gripper in (franka_hand(), load_gripper("robotiq-2f85")):
        g = plan_grasps(part, gripper, GraspParams()).grasps
        sets.append((gripper, g.poses, g.jawwidth))
    compare_figure(part, sets, hands=3, size=(9.0, 4.0)).savefig(OUT / "grippers.png", dpi=90, bbox_inches="tight")


def gptable_png() -> None:
    from workbench.planners.tournassoud.chaining import grasp_query
    from workbench.planners.tournassoud.figures import table_figure
    from workbench.planners.tournassoud.shapes import l_part
    from workbench.planners.tournassoud.stages import table_stage_at
    from workbench.planners.tournassoud.table import TableParams
    from workbench.robots.model import get_robot, pose_xyz_yaw

    robot = get_robot("puma560", base=pose_xyz_yaw(0.0, 0.0, -0.3, 0.0))
    with tempfile.TemporaryDirectory() as tmp:
        run = table_stage_at(str(Path(tmp) / "gp.duckdb"), l_part(), robot, params=TableParams(table_point=(0.45, 0.1)))
    legal = np.flatnonzero(run.table.hand_object[0])
    seq = grasp_query(run.table, (0, float(run.table.theta[legal[len(legal) // 2]])), 3, (np.radians(60), np.radians(120)))
    ax = table_figure(run.table, run.classes, seq)
    ax.figure.savefig(OUT / "gptable.png", dpi=90, bbox_inches="tight")


def plan_png() -> None:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        print("plan.png skipped: playwright is not installed")
        return
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run([sys.executable, "-m", "workbench", "demo", "--out", tmp], check=True)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=[
                "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--disable-background-networking", "--disable-component-update", "--no-first-run"])
            page = browser.new_page(viewport={"width": 1100, "height": 620})
            page.goto(f"file://{tmp}/plan.html")
            page.wait_for_timeout(12000)
            page.screenshot(path=str(OUT / "plan.png"))
            browser.close()


if __name__ == "__main__":
    for make in (grasps_png, grippers_png, gptable_png, plan_png) if len(sys.argv) < 3 else [globals()[n] for n in sys.argv[2:]]:
        make()
