"""ipywidgets front-ends for grasp planning and placements (notebooks 01 and 02). Logic stays in the stages;
these classes only read widgets, call the library and draw with `workbench.viewer`.
"""

from __future__ import annotations

from dataclasses import replace

import ipywidgets as W
import numpy as np

from workbench.geometry.objects import ObjectModel
from workbench.grasping.grasps import GraspParams, GraspPlan, plan_grasps
from workbench.grasping.memo import remember
from workbench.robots.gripper import BUNDLED, Gripper, load_gripper
from workbench.viewer import scenes as viz
from workbench.viewer.live import (
    FirstHands,
    HandOutlines,
    OneAtATime,
    SolidHand,
    Switches,
    finger_corners,
    pick_evenly,
    points_object,
    spread_order,
    triangles_object,
)
from workbench.widgets.panel import BesideView, Busy, StageCache, digest

HAND_COLOR = 0x55AA77


def counts_table(counts: dict, title: str = "") -> str:
    """An HTML table of stage counts."""
    rows = "".join(f"<tr><td>{k.replace('_', ' ')}</td><td style='text-align:right'>{v if isinstance(v, str) else f'{v:,}'}</td></tr>"
                   for k, v in counts.items())
    return f"<b>{title}</b><table>{rows}</table>"


class GraspExplorer(BesideView):
    """Tune segmentation, sampling, filters and rotations; see facets, samples, pairs and hands (Section III).

    A parameter slider replans (results cached by parameter digest: going back to a value is instant; the part's
    first touches and hand checks are remembered row by row, `grasping.memo`) and sends the scene's geometry once; the layer boxes, the highlighted facet, the number of hands and the selected grasp only
    show, hide and move what was sent."""

    LAYERS = (("facets", True), ("all samples", False), ("after neighbour filter", False),
              ("after distance filter", True), ("contact pairs", True), ("collided hands", False))

    def __init__(self, obj: ObjectModel, gripper: Gripper, params: GraspParams = GraspParams(), vis=None,
                 max_hands: int = 40):
        self.obj, self.gripper, self.max_hands = obj, gripper, max_hands
        remember(obj.mesh)  # a new threshold recomputes only the jaw axes of facets whose normal changed
        self.base = params  # parameters without a widget (merge_angle, parallel_angle, com_max, seed, ...) stay as given
        self.vis = vis if vis is not None else viz.new_scene()
        self.plan: GraspPlan | None = None
        self.cache = StageCache()
        self.switches = Switches(self.vis)
        self.solid: SolidHand | None = None
        self.outlines = HandOutlines(gripper)
        label = {"style": {"description_width": "initial"}, "layout": W.Layout(width="420px"), "continuous_update": False}
        self.tau = W.FloatSlider(value=np.degrees(params.tau), min=2, max=45, step=1,
                                 description="segmentation threshold τ (deg)", **label)
        self.method = W.ToggleButtons(options=[("over-segmentation", "over"), ("conventional", "conventional")],
                                      value=params.segmentation, style={"button_width": "140px"})
        # the library's default density (samples per neighbour disc) unless the parameters give one
        self.density = W.FloatLogSlider(value=params.density or 8.0 / params.neighbour_radius**2, base=10, min=3, max=6,
                                        description="sampling density (samples/m²)", **label)
        self.density_given, self._quiet = params.density is not None, False
        self.dist = W.FloatRangeSlider(value=(params.dist_min * 1e3, params.dist_max * 1e3), min=0, max=50, step=0.5,
                                       description="distance to facet boundary (mm)", **label)
        self.radius = W.FloatSlider(value=params.neighbour_radius * 1e3, min=0, max=30, step=0.5,
                                    description="near-neighbour radius (mm)", **label)
        self.rotations = W.IntSlider(value=params.rotations, min=1, max=24, description="hand rotations per pair", **label)
        self.facet = W.IntSlider(value=0, min=0, max=0, description="highlighted facet", **label)
        self.hands = W.IntSlider(value=3, min=0, max=max_hands, description="hands drawn (outlines)", **label)
        self.selected = W.IntSlider(value=0, min=0, max=0, description="selected grasp (solid)", **label)
        self.layers = {name: W.Checkbox(value=on, description=name, indent=False, layout=W.Layout(width="200px"))
                       for name, on in self.LAYERS}
        given = [] if gripper.name in BUNDLED or gripper.name == "franka_hand" else [(gripper.name, gripper)]
        self.grippers = W.Dropdown(options=given + [(name, name) for name in BUNDLED],
                                   value=given[0][1] if given else ("franka" if gripper.name == "franka_hand" else gripper.name),
                                   description="gripper", style=label["style"], layout=W.Layout(width="420px"))
        self.grippers.observe(lambda change: self.set_gripper(change["new"]), names="value")
        self.button = W.Button(description="plan grasps", button_style="primary")
        self.busy = Busy()
        self.counts = W.HTML()
        self.key = W.HTML()
        self.about = W.HTML()
        self.button.on_click(lambda _: self.run())
        for w in (self.tau, self.method, self.radius, self.dist, self.rotations):
            w.observe(lambda _: self.run(), names="value")
        self.density.observe(self._density_moved, names="value")
        for w in (self.facet, self.hands, self.selected, *self.layers.values()):
            w.observe(lambda _: self.show(), names="value")
        controls = [self.grippers, self.tau, self.method, self.density, self.radius, self.dist, self.rotations,
                    W.HTML("<b>view</b>"), self.facet, self.hands, self.selected,
                    W.GridBox(list(self.layers.values()), layout=W.Layout(grid_template_columns="200px 200px")),
                    W.HBox([self.button, self.busy.widget]), self.about, self.counts]
        self.controls = W.VBox(controls)
        self._widget = None


    def set_gripper(self, choice: Gripper | str) -> None:
        """Plan with another gripper (a bundled name or a loaded Gripper) and show its grasps."""
        self.gripper = choice if isinstance(choice, Gripper) else load_gripper(choice)
        self.outlines = HandOutlines(self.gripper)
        self.run()

    def _density_moved(self, _) -> None:
        if not self._quiet:
            self.density_given = True
            self.run()

    def params(self) -> GraspParams:
        """The given parameters with the widgets' values; the others are kept."""
        density = self.density.value if self.density_given else self.base.density
        return replace(self.base, tau=float(np.radians(self.tau.value)), segmentation=self.method.value,
                       density=density, neighbour_radius=self.radius.value / 1e3,
                       dist_min=self.dist.value[0] / 1e3, dist_max=self.dist.value[1] / 1e3, rotations=self.rotations.value)

    def run(self) -> GraspPlan:
        """Replan with the widgets' parameters (or take the cached plan for them) and send its scene."""
        params = self.params()
        with self.busy.running("planning grasps"):
            self.plan = self.cache.get(digest(self.obj.digest or self.obj.name, self.gripper.digest, params),
                                       lambda: plan_grasps(self.obj, self.gripper, params))
            self.send()
        plan = self.plan
        if not self.density_given:  # show the density the library chose (its default scales with the part)
            self._quiet = True
            self.density.value = 8.0 / plan.lengths["neighbour_radius"] ** 2
            self._quiet = False
        self.counts.value = counts_table(plan.counts, "counts at every stage") + \
            counts_table({k: f"{v * 1e3:.1f} ms" for k, v in plan.timings.items()}, "time per stage (when computed)")
        return plan

    def send(self) -> None:
        """Send the plan's geometry: everything any view setting can show, hidden where it is off."""
        plan, vis, mesh = self.plan, self.vis, self.obj.mesh
        vis["grasps"].delete()
        self.switches.forget("grasps")
        fid, tid = plan.facets.membership()
        first = np.full(len(mesh.faces), -1)
        first[tid[::-1]] = fid[::-1]  # colour each triangle by the first facet holding it
        viz.show_face_colors(vis, "grasps/part/facets", mesh, viz.palette(len(plan.facets))[first])
        viz.show_mesh(vis, "grasps/part/plain", mesh, color=viz.GREY, opacity=0.5)
        s, p = plan.samples, plan.pairs
        viz.show_points(vis, "grasps/layers/all samples", s.points, viz.WHITE, size=0.002)
        viz.show_points(vis, "grasps/layers/after neighbour filter", s.points[s.kept], viz.BLUE, size=0.003)
        viz.show_points(vis, "grasps/layers/after distance filter", s.points[np.unique(s.pair_sample[s.pair_ok])],
                        viz.GREEN, size=0.004)
        live = p.level1_ok
        dead = (p.width_ok & p.com_ok) & ~live
        viz.show_segments(vis, "grasps/layers/contact pairs/free", p.point0[live], p.point1[live], viz.GREEN)
        viz.show_segments(vis, "grasps/layers/contact pairs/level1", p.point0[dead], p.point1[dead], viz.RED)
        # a few hands as outlines, the first `hands` of an evenly spread order shown, free ones and collided ones
        collided = np.flatnonzero(~plan.candidate_free)
        pick = collided[pick_evenly(len(collided), self.max_hands)]
        pick = pick[spread_order(len(pick))]
        self.collided_view = FirstHands(vis, "grasps/layers/collided hands", self.outlines.placed(
            plan.candidate_poses[pick], p.width[plan.candidate_pair[pick]]), viz.RED)
        g = plan.grasps
        self.hand_pick = pick_evenly(len(g), self.max_hands)
        self.hand_pick = self.hand_pick[spread_order(len(self.hand_pick))]
        self.hands_view = FirstHands(vis, "grasps/hands", self.outlines.placed(g.poses[self.hand_pick],
                                                                               g.jawwidth[self.hand_pick]), HAND_COLOR)
        if self.solid is None or self.solid.gripper is not self.gripper:  # sent once per gripper, moved by transforms
            vis["selected hand"].delete()
            self.solid = SolidHand(vis, "selected hand", self.gripper, viz.GREEN)
        # each facet lifted in magenta with its samples (kept green, removed white), one at a time by the slider
        lift = 0.004 * float(mesh.scale) * np.asarray(plan.facets.normals).reshape(-1, 3)
        kept = s.pair_ok.astype(bool)
        self.facet_view = OneAtATime(vis, "grasps/facet", len(plan.facets), [
            (mesh.vertices[mesh.faces[tid]] + lift[fid][:, None], np.repeat(fid, 3),
             lambda v: triangles_object(v, viz.HIGHLIGHT)),
            (s.points[s.pair_sample] + 2 * lift[s.pair_facet], s.pair_facet,
             lambda v: points_object(v, np.where(kept, viz.GREEN, viz.WHITE), 0.02 * float(mesh.scale)))])
        self.facet.max = max(len(plan.facets) - 1, 0)
        self.selected.max = max(len(g) - 1, 0)
        self.show()
        jaw = [finger_corners(self.gripper, g.poses[i], g.jawwidth[i]) for i in range(min(len(g), 1))]
        # the part and the selected hand's jaw, seen from beside the hand rather than through its body
        viz.frame_points(vis, np.vstack([mesh.bounds, *jaw]), viz.beside_hand(g.poses[0][:3, 2]) if len(g) else None)

    def show(self) -> None:
        """View-only: which layers, facet, hands and grasp are visible; no geometry is sent."""
        plan = self.plan
        if plan is None:
            return
        on = {k: w.value for k, w in self.layers.items()}
        sw = self.switches
        sw.show("grasps/part/facets", on["facets"])
        sw.show("grasps/part/plain", not on["facets"])
        for name in list(self.layers)[1:]:
            sw.show(f"grasps/layers/{name}", on[name])
        shown = self.hands_view.show(self.hands.value)
        self.collided_view.show(self.hands.value)
        f = self.facet.value
        self.facet_view.choose(f)
        g = plan.grasps
        i = self.selected.value
        self.solid.place(g.poses[i] if len(g) else None, g.jawwidth[i] if len(g) else None)
        self.key.value = viz.legend(
            [(viz.HIGHLIGHT, f"facet {f} (slider)"), (viz.GREEN, "its samples kept / contact pairs kept"),
             (viz.WHITE, "its samples removed by the distance filter"), (viz.RED, "pairs removed by the swept-pad check"),
             (viz.BLUE, "samples after the neighbour filter"),
             (HAND_COLOR, f"hands: {shown} outlines of {len(g):,} grasps"), (viz.GREEN, "the selected grasp")],
            "colour key:") + "<small>other facets: one colour each on the part</small>"
        self.about.value = (f"<small>selected grasp {i}: jaw {g.jawwidth[i] * 1e3:.1f} mm, facets {int(g.facet0[i])} and "
                            f"{int(g.facet1[i])}</small>" if len(g) else "<small>no grasp</small>")
