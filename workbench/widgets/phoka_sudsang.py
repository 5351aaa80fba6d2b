"""ipywidgets front-end of five-finger regrasping by contact-point clustering (notebook 05).

Reads the widgets (k, friction coefficient, pyramid sides), calls `workbench.planners.phoka_sudsang` and draws with
`workbench.viewer.phoka_sudsang`; no planning logic lives here.
"""

from __future__ import annotations

import ipywidgets as W
import numpy as np

from workbench.geometry.objects import ObjectModel
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.phoka_sudsang.contacts import (
    ContactParams,
    ContactSet,
    contact_points,
)
from workbench.planners.phoka_sudsang.experiments import sample_grasps
from workbench.planners.phoka_sudsang.query import QueryResult, finger_assignment, query
from workbench.planners.phoka_sudsang.switching import FingerPlanner, build_planner
from workbench.viewer import phoka_sudsang as vf
from workbench.viewer import scenes as viz
from workbench.widgets.panel import BesideView


class FingersExplorer(BesideView):
    """Build the clusters and the representative-level roadmap, run a query, step through the finger switches."""

    def __init__(self, obj: ObjectModel, params: ClusterParams = ClusterParams(), faces: int = 500, vis=None,
                 samples: int = 400):
        self.obj = obj
        self.contacts: ContactSet = contact_points(obj, ContactParams(faces=faces))
        self.vis = vis if vis is not None else viz.new_scene()
        self.samples = samples
        self.planner: FingerPlanner | None = None
        self.result: QueryResult | None = None
        self._grasps: np.ndarray | None = None
        self.hand: vf.FingerView | None = None
        n = len(self.contacts)
        label = {"style": {"description_width": "initial"}, "layout": W.Layout(width="380px")}
        self.k = W.IntSlider(value=min(params.k, n), min=4, max=min(120, n), description="clusters k", **label)
        self.mu = W.FloatSlider(value=params.mu, min=0.05, max=1.0, step=0.05, description="friction coefficient μ", **label)
        self.sides = W.IntSlider(value=params.sides, min=3, max=16, description="friction pyramid sides m", **label)
        self.seed = W.IntText(value=params.seed, description="seed", style={"description_width": "initial"},
                              layout=W.Layout(width="160px"))
        self.build_button = W.Button(description="build roadmap", button_style="primary")
        self.query_button = W.Button(description="random query")
        self.step = W.IntSlider(value=0, min=0, max=0, description="switch", **label)
        self.key = W.HTML(viz.legend([(vf.FINGER, "finger on a contact"), (vf.PLACED, "finger just placed"),
                                      (vf.LIFTED, "finger just lifted (off the surface)"),
                                      (vf.FREE, "fifth finger waiting above the part"), (vf.REP, "cluster representatives")],
                                     "colour key:") + "<small>faces: one colour per cluster</small>")
        self.info = W.HTML()
        self.step_info = W.HTML()
        self.build_button.on_click(lambda _: self.build())
        self.query_button.on_click(lambda _: self.run_query())
        self.step.observe(lambda _: self.show_step(self.step.value), names="value")
        self.controls = W.VBox([self.k, self.mu, self.sides, self.seed, W.HBox([self.build_button, self.query_button]),
                                self.step, self.info, self.step_info])
        self._widget = None


    def params(self) -> ClusterParams:
        return ClusterParams(k=self.k.value, mu=self.mu.value, sides=self.sides.value, seed=self.seed.value)

    def build(self) -> FingerPlanner:
        """Cluster the contacts, pick the representatives and build R; colour the contacts by cluster."""
        self.planner = build_planner(self.contacts, self.params())
        self._grasps, self.result = None, None
        rm, cl = self.planner.roadmap, self.planner.clustering
        sizes = np.bincount(rm.components, minlength=rm.ncomponents) if len(rm) else np.zeros(0, dtype=int)
        self.info.value = (f"<b>{self.obj.name}</b>: {len(self.contacts)} contact points, k = {cl.k} clusters "
                           f"(sizes {int(np.bincount(cl.labels).min())}-{int(np.bincount(cl.labels).max())})<br>"
                           f"roadmap R: <b>{len(rm):,}</b> force-closure grasps of representatives, "
                           f"{len(rm.edges):,} switching edges, <b>{rm.ncomponents}</b> connected component(s)"
                           + (f" (largest {int(sizes.max()):,})" if len(sizes) else "") + "<br>"
                           f"clustering {self.planner.times['clustering']:.2f} s, roadmap {self.planner.times['roadmap']:.2f} s")
        self.vis["fingers"].delete()
        self.hand = None
        vf.show_clusters(self.vis, "fingers/clusters", self.contacts, cl.labels, cl.reps)
        viz.frame_points(self.vis, self.contacts.mesh.bounds)
        self.step.max, self.step.value = 0, 0
        return self.planner

    def run_query(self, seed: int | None = None, start: np.ndarray | None = None, goal: np.ndarray | None = None) -> QueryResult:
        """A regrasp query between two random force-closure grasps (or the given ones); shows its first grasp."""
        if self.planner is None:
            self.build()
        assert self.planner is not None
        if start is None or goal is None:
            if self._grasps is None:
                self._grasps = sample_grasps(self.planner.tester, self.samples, seed=self.seed.value)
            rng = np.random.default_rng(self.seed.value if seed is None else seed)
            i, j = rng.choice(len(self._grasps), size=2, replace=False)
            start, goal = self._grasps[i], self._grasps[j]
        self.result = query(self.planner, start, goal)
        r = self.result
        if r.sequence is None:
            self.step.max, self.step.value = 0, 0
            self.step_info.value = f"query {r.start.tolist()} → {r.goal.tolist()}: <b>not connected</b>"
            return r
        self._fingers, self._placed, self._lifted = finger_assignment(r.sequence)
        self.step.max = len(r.sequence) - 1
        if self.step.value == 0:
            self.show_step(0)
        else:
            self.step.value = 0
        return r

    def show_step(self, i: int) -> None:
        """Grasp i of the sequence: four fingers on contacts, the placed finger green, the lifted one red."""
        if self.result is None or self.result.sequence is None:
            return
        r, fingers = self.result, self._fingers
        placed, lifted = int(self._placed[i]), int(self._lifted[i])
        lifted_from = np.full(5, -1)
        if lifted >= 0:
            lifted_from[lifted] = fingers[i - 1][lifted]
        if self.hand is None:
            self.hand = vf.FingerView(self.vis, "fingers/hand", self.contacts)
        self.hand.show(fingers[i], placed=placed, lifted=lifted, lifted_from=lifted_from)
        grasp = r.sequence[i].tolist()
        move = "start grasp" if i == 0 else (f"finger {placed} placed on contact {int(fingers[i][placed])}, "
                                              f"finger {lifted} lifted from contact {int(lifted_from[lifted])}")
        self.step_info.value = (f"query linked by {r.start_method} / {r.goal_method}, {len(r.sequence) - 1} switches, "
                                f"{r.seconds:.3f} s<br>grasp {i}: contacts {grasp} — {move}")
