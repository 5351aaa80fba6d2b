"""ipywidgets front-end of the grasp-placement table planner (notebook 06; Tournassoud et al. 1987).

Widgets pick a grasp class, theta, a placement class, phi and both resolutions; changing a resolution rebuilds the
table through the planner's stages (reused from the store when already built, a busy line while it runs); the
Fig. 5 plot updates and the meshcat view follows. The controls sit in a column beside the live view and its colour
key (`widgets.panel.BesideView`). No planning logic lives here.
"""

from __future__ import annotations

import io
from dataclasses import replace
from typing import Callable, Sequence

import ipywidgets as W
import matplotlib.pyplot as plt
import numpy as np

from workbench.geometry.objects import ObjectModel
from workbench.planners.tournassoud.figures import table_figure
from workbench.planners.tournassoud.stages import TableRun, table_stage_at
from workbench.planners.tournassoud.table import TableParams
from workbench.robots.gripper import Gripper
from workbench.robots.model import Robot, get_robot
from workbench.viewer import scenes as viewer
from workbench.viewer.scenes import BLUE, GREEN, GREY, ORANGE, RED
from workbench.viewer.tournassoud import BESIDE, PART_AT_H, TableView
from workbench.widgets.grippers import GripperMenu
from workbench.widgets.panel import BesideView, Busy


class TableExplorer(BesideView):
    """The table of `obj` for `robot` stored in `db`; `widget` holds the controls beside the meshcat scene `vis`."""

    def __init__(self, db: str, obj: ObjectModel, robot: Robot, params: TableParams = TableParams(), vis=None,
                 grippers: Sequence[Gripper] = (), robot_for: Callable[[Gripper], Robot] | None = None):
        self.db, self.obj, self.robot, self.params, self.robot_for = db, obj, robot, params, robot_for
        self.vis = vis if vis is not None else viewer.new_scene()
        self.run: TableRun | None = None
        self.view: TableView | None = None
        self.cls = W.Dropdown(description="class G_i")
        self.theta = W.FloatSlider(value=90.0, min=0.0, max=359.0, step=1.0, description="theta (deg)", continuous_update=False)
        self.place = W.Dropdown(description="placement P_j")
        self.phi = W.FloatSlider(value=0.0, min=0.0, max=359.0, step=1.0, description="phi (deg)", continuous_update=False)
        self.theta_step = W.FloatSlider(value=float(np.degrees(params.theta_step)), min=1.0, max=30.0, step=1.0,
                                        description="theta step", continuous_update=False)
        self.phi_step = W.FloatSlider(value=float(np.degrees(params.phi_step)), min=1.0, max=30.0, step=1.0,
                                      description="phi step", continuous_update=False)
        self.info = W.HTML()
        self.busy = Busy()
        self.key = W.HTML(viewer.legend([(GREY, "the class's part (features red, grasp point and normal blue)"),
                                         (RED, "its hand: theta illegal on the part"), (PART_AT_H, "the part at H"),
                                         (GREEN, "hand legal"), (ORANGE, "hand: (theta, phi) not in Q_ij"),
                                         (BLUE, "the table point H")]))
        self.plot = W.Image(format="png", layout=W.Layout(width="100%"))
        for w in (self.cls, self.theta, self.place, self.phi):
            w.observe(lambda _: self.show(), names="value")
        for w in (self.theta_step, self.phi_step):
            w.observe(lambda _: self.build(), names="value")
        # the store's grippers or another to build for: the robot with it (`robot_for`, default a built-in robot's)
        self.grippers = GripperMenu(db, grippers, value=robot.gripper, on_change=self.set_gripper)
        self.controls = W.VBox([self.grippers.widget, self.grippers.note, self.cls, self.theta, self.place, self.phi,
                                W.HTML("<b>table resolution</b>"), self.theta_step, self.phi_step, self.busy.widget,
                                self.info, self.plot])
        self.build()

    def set_gripper(self, gripper: Gripper) -> TableRun:
        """The table with another gripper on the same robot and base."""
        self.robot = (self.robot_for(gripper) if self.robot_for is not None else
                      get_robot(self.robot.name, base=self.robot.base, gripper=gripper))
        run = self.build()
        self.grippers.refresh(gripper.digest)
        return run

    def build(self) -> TableRun:
        """(Re)build or load the table at the current resolutions and redraw."""
        p = replace(self.params, theta_step=float(np.radians(self.theta_step.value)), phi_step=float(np.radians(self.phi_step.value)))
        with self.busy.running("building the grasp-placement table"):
            self.run = table_stage_at(self.db, self.obj, self.robot, params=p)
        r = self.run
        self.view = TableView(self.vis, r.obj.mesh, r.table, r.classes, r.gripper)
        size = float(r.obj.mesh.scale)  # camera on the part beside the table and the part at the table point
        x, y = self.params.table_point
        viewer.frame_points(self.vis, np.array([BESIDE[:3, 3], [x, y, 0.0]]) + [[-size, -size, -size], [size, size, size]])
        self.cls.options = [(f"G{i} {c.kind} ({c.opening * 1000:.0f} mm)", i) for i, c in enumerate(r.classes)]
        self.place.options = [(f"P{j}", j) for j in range(len(r.table.placements))]
        for box in (self.cls, self.place):  # the view opens on the first class and placement, not empty
            if box.value is None and box.options:
                box.index = 0
        fig = table_figure(r.table, r.classes)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90, bbox_inches="tight")
        plt.close(fig)
        self.plot.value = buf.getvalue()
        self.show()
        return r

    def show(self) -> bool | None:
        """The hand at (G_i, theta) on the object, and the object at (P_j, phi) with the hand on the table."""
        r = self.run
        if r is None or not r.classes or self.cls.value is None or self.place.value is None:
            self.info.value = "no grasp class or placement class: nothing to show"
            return None
        i, j = int(self.cls.value), int(self.place.value)
        th, ph = float(np.radians(self.theta.value)), float(np.radians(self.phi.value))
        c = r.classes[i]
        legal = self.view.pose(i, th, j, ph)  # moves and recolours what the scene holds; a new class sends its geometry
        self.info.value = (f"G{i}: {c.kind}, opening {c.opening * 1000:.1f} mm, e = {c.eccentricity * 1000:.1f} mm, legal theta "
                           f"{np.degrees(c.legal_range):.0f} deg; (theta, phi) in Q_{i}{j}: <b>{'yes' if legal else 'no'}</b>")
        return legal
