"""ipywidgets front-ends for grasp planning and placements (notebooks 01 and 02). Logic stays in the stages;
these classes only read widgets, call the library and draw with `workbench.viewer`.
"""

from __future__ import annotations

import re
from dataclasses import replace

import ipywidgets as W
import numpy as np
import trimesh

from workbench.geometry.objects import ObjectModel
from workbench.grasping.grasps import GraspParams, GraspPlan, plan_grasps
from workbench.robots.gripper import BUNDLED, Gripper, load_gripper
from workbench.viewer import scenes as viz


def counts_table(counts: dict, title: str = "") -> str:
    """An HTML table of stage counts."""
    rows = "".join(f"<tr><td>{k.replace('_', ' ')}</td><td style='text-align:right'>{v if isinstance(v, str) else f'{v:,}'}</td></tr>"
                   for k, v in counts.items())
    return f"<b>{title}</b><table>{rows}</table>"


class GraspExplorer:
    """Tune segmentation, sampling, filters and rotations; see facets, samples, pairs and hands (Section III)."""

    def __init__(self, obj: ObjectModel, gripper: Gripper, params: GraspParams = GraspParams(), vis=None,
                 max_hands: int = 40):
        self.obj, self.gripper, self.max_hands = obj, gripper, max_hands
        self.base = params  # parameters without a widget (merge_angle, parallel_angle, com_max, seed, ...) stay as given
        self.vis = vis if vis is not None else viz.new_scene()
        self.plan: GraspPlan | None = None
        label = {"style": {"description_width": "initial"}, "layout": W.Layout(width="430px")}
        self.tau = W.FloatSlider(value=np.degrees(params.tau), min=2, max=45, step=1,
                                 description="segmentation threshold τ (deg)", **label)
        self.method = W.ToggleButtons(options=[("over-segmentation", "over"), ("conventional", "conventional")],
                                      value=params.segmentation)
        self.density = W.FloatLogSlider(value=params.density or 8.0 / params.neighbour_radius**2, base=10, min=3, max=6,
                                        description="sampling density (samples/m²)", **label)
        self.dist = W.FloatRangeSlider(value=(params.dist_min * 1e3, params.dist_max * 1e3), min=0, max=50, step=0.5,
                                       description="distance to facet boundary (mm)", **label)
        self.radius = W.FloatSlider(value=params.neighbour_radius * 1e3, min=0, max=30, step=0.5,
                                    description="near-neighbour radius (mm)", **label)
        self.rotations = W.IntSlider(value=params.rotations, min=1, max=24, description="hand rotations per pair", **label)
        self.facet = W.IntSlider(value=0, min=0, max=0, description="highlighted facet", **label)
        self.hands = W.IntSlider(value=3, min=0, max=max_hands, description="free hands drawn", **label)
        self.layers = {name: W.Checkbox(value=on, description=name, indent=False, layout=W.Layout(width="auto", margin="0 14px 0 0"))
                       for name, on in (("facets", True), ("all samples", False), ("after neighbour filter", False),
                                        ("after distance filter", True), ("contact pairs", True), ("collided hands", False))}
        given = [] if gripper.name in BUNDLED or gripper.name == "franka_hand" else [(gripper.name, gripper)]
        self.grippers = W.Dropdown(options=given + [(name, name) for name in BUNDLED],
                                   value=given[0][1] if given else ("franka" if gripper.name == "franka_hand" else gripper.name),
                                   description="gripper", layout=W.Layout(width="260px"))
        self.grippers.observe(lambda change: self.set_gripper(change["new"]), names="value")
        self.button = W.Button(description="plan grasps", button_style="primary")
        self.counts = W.HTML()
        self.key = W.HTML()
        self.button.on_click(lambda _: self.run())
        self.facet.observe(lambda _: self.draw_facet(), names="value")
        self.hands.observe(lambda _: self.draw(), names="value")
        for box in self.layers.values():
            box.observe(lambda _: self.draw(), names="value")
        self.widget = W.VBox([W.HBox([self.tau, self.method]), W.HBox([self.density, self.radius]),
                              W.HBox([self.dist, self.rotations]), W.HBox(list(self.layers.values())),
                              W.HBox([self.grippers, self.button, self.facet, self.hands]), self.key, self.counts])

    def set_gripper(self, choice: Gripper | str) -> None:
        """Plan with another gripper (a bundled name or a loaded Gripper); press plan grasps to see its grasps."""
        self.gripper = choice if isinstance(choice, Gripper) else load_gripper(choice)

    def params(self) -> GraspParams:
        """The given parameters with the widgets' values; the others are kept."""
        return replace(self.base, tau=float(np.radians(self.tau.value)), segmentation=self.method.value,
                       density=self.density.value, neighbour_radius=self.radius.value / 1e3,
                       dist_min=self.dist.value[0] / 1e3, dist_max=self.dist.value[1] / 1e3, rotations=self.rotations.value)

    def run(self) -> GraspPlan:
        self.plan = plan_grasps(self.obj, self.gripper, self.params())
        self.facet.max = max(len(self.plan.facets) - 1, 0)
        self.counts.value = counts_table(self.plan.counts, "counts at every stage") + \
            counts_table({k: f"{v * 1e3:.1f} ms" for k, v in self.plan.timings.items()}, "time per stage")
        self.draw()
        return self.plan

    def draw(self) -> None:
        plan, vis, on = self.plan, self.vis, {k: w.value for k, w in self.layers.items()}
        if plan is None:
            return
        vis["grasps"].delete()
        mesh = self.obj.mesh
        if on["facets"]:
            fid, tid = plan.facets.membership()
            first = np.full(len(mesh.faces), -1)
            first[tid[::-1]] = fid[::-1]  # colour each triangle by the first facet holding it
            viz.show_face_colors(vis, "grasps/facets", mesh, viz.palette(len(plan.facets))[first])
        else:
            viz.show_mesh(vis, "grasps/facets", mesh, color=viz.GREY, opacity=0.5)
        s = plan.samples
        if on["all samples"]:
            viz.show_points(vis, "grasps/samples/all", s.points, viz.WHITE, size=0.002)
        if on["after neighbour filter"]:
            viz.show_points(vis, "grasps/samples/neighbour", s.points[s.kept], viz.BLUE, size=0.003)
        if on["after distance filter"]:
            viz.show_points(vis, "grasps/samples/distance", s.points[np.unique(s.pair_sample[s.pair_ok])], viz.GREEN, size=0.004)
        p = plan.pairs
        live = p.level1_ok
        if on["contact pairs"]:
            viz.show_segments(vis, "grasps/pairs/free", p.point0[live], p.point1[live], viz.GREEN)
            dead = (p.width_ok & p.com_ok) & ~live
            viz.show_segments(vis, "grasps/pairs/level1", p.point0[dead], p.point1[dead], viz.RED)
        if on["collided hands"]:
            viz.show_grippers(vis, "grasps/hands/collided", self.gripper, plan.candidate_poses[~plan.candidate_free],
                              p.width[plan.candidate_pair[~plan.candidate_free]], viz.RED, 0.12, self.hands.value)
        g = plan.grasps
        shown = min(self.hands.value, len(g.poses))
        if shown:  # a few hands, evenly picked, light and translucent: the part stays visible
            viz.show_grippers(vis, "grasps/hands/free", self.gripper, g.poses, g.jawwidth, viz.GREEN, 0.12, shown)
        self.draw_facet()
        viz.frame_points(vis, mesh.bounds)
        self.key.value = viz.legend(
            [(viz.HIGHLIGHT, f"facet {self.facet.value} (slider)"), (viz.GREEN, "its samples kept / contact pairs kept"),
             (viz.WHITE, "its samples removed by the distance filter"), (viz.RED, "pairs removed by the swept-pad check"),
             (viz.BLUE, "samples after the neighbour filter"),
             (0x88CC99, f"free hands: {shown} drawn of {len(g.poses):,}")],
            "colour key:") + "<small>other facets: one colour each (over-segmentation) on the part</small>"

    def draw_facet(self) -> None:
        """The slider's facet in magenta, lifted off the surface, with its samples: kept by the distance filter
        (green) or removed (white)."""
        plan = self.plan
        if plan is None or len(plan.facets) == 0:
            return
        f = self.facet.value
        tris = plan.facets.triangles_of(f)
        sub = trimesh.Trimesh(self.obj.mesh.vertices, self.obj.mesh.faces[tris], process=False)
        lift = 0.004 * float(self.obj.mesh.scale) * np.asarray(plan.facets.normals[f])
        viz.show_mesh(self.vis, "grasps/facet/mesh", sub.copy().apply_translation(lift), color=viz.HIGHLIGHT)
        s = plan.samples
        mine = s.pair_facet == f
        size = 0.02 * float(self.obj.mesh.scale)
        viz.show_points(self.vis, "grasps/facet/kept", s.points[s.pair_sample[mine & s.pair_ok]] + 2 * lift, viz.GREEN, size)
        viz.show_points(self.vis, "grasps/facet/removed", s.points[s.pair_sample[mine & ~s.pair_ok]] + 2 * lift, viz.WHITE, size)
        if self.key.value:
            self.key.value = re.sub(r"facet \d+ \(slider\)", f"facet {f} (slider)", self.key.value)
