"""ipywidgets and matplotlib front-ends of the roadmap planner (notebooks 02-04): placements and the tabletop
roadmap, IK feasibility of tabletop grips, and regrasp queries. They read widgets, call the library (stages and
stage functions) and draw with `workbench.viewer`; no planning logic lives here.
"""

from __future__ import annotations

import html
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

import ipywidgets as W
import meshcat
import numpy as np
import trimesh

from workbench.errors import PlanningError
from workbench.geometry.hull import part_hull
from workbench.geometry.objects import ObjectModel, load_object
from workbench.grasping.naming import describe_placement, per_part_numbers
from workbench.grasping.placements import (
    PlacementParams,
    free_tabletop_grips,
    stability_hint,
    stable_placements,
)
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.stages import load_planner, robot_name_for
from workbench.planners.wan_harada.tabletop import TabletopParams, plan_tabletop
from workbench.robots.gripper import Gripper
from workbench.robots.ik import KINDS
from workbench.robots.model import Robot
from workbench.viewer import scenes as viz
from workbench.viewer.robot import (
    FEASIBLE_ALL,
    FEASIBLE_GRASP,
    INFEASIBLE,
    RobotView,
)
from workbench.viewer.robot import show_roadmap as show_ik_roadmap
from workbench.viewer.scenes import legend, new_scene, show_mesh, table_mesh
from workbench.viewer.wan_harada import (
    GOAL_COLOR,
    OBJECT_COLOR,
    START_COLOR,
    TABLE_COLOR,
    MOVES_TO_NEXT,
    PLAN_VIEW,
    STEP_NAMES,
    PlanView,
    caption_track,
    scene_table,
    show_roadmap,
)
from workbench.viewer.live import HandOutlines, Switches, pick_evenly
from workbench.widgets.grasping import counts_table
from workbench.widgets.grippers import GripperMenu
from workbench.widgets.panel import BesideView, Busy, StageCache, digest


class RegraspExplorer(BesideView):
    """ipywidgets front-end of notebook 04: choose object, robot, start and goal (placement, x, y, yaw in degrees),
    search, animate the plan in meshcat, and report the graph (size, components, where start and goal attach).

    Loading draws the table, robot, part and its ghosts once (`PlanView`); a search or another alternative then only
    moves them and sets the animation. Placements are numbered within the part and named by how it rests."""

    captions = True  # the step's caption and footer over the view

    def __init__(self, db, objects: dict, robots=("panda", "ur5", "talos"), tparams=None, vis=None, build=None,
                 grippers: Sequence[Gripper] = ()):
        self.db, self.objects, self.tparams, self.build = Path(db), dict(objects), tparams, build
        self.vis = vis if vis is not None else new_scene()
        self.planner, self.plans, self.result, self.scene = None, [], None, None
        self.reports, self.attach = {}, {}
        names = list(self.objects)
        wide = {"style": {"description_width": "initial"}, "layout": W.Layout(width="420px")}
        self.object = W.Dropdown(options=names, value="tube" if "tube" in names else names[0], description="object", **wide)
        self.robot = W.Dropdown(options=list(robots), description="robot", **wide)
        # the store's grippers, or another to build for (`build(db, obj, robot, gripper)`); loading plans with it
        self.grippers = GripperMenu(self.db, grippers)
        self.load_button = W.Button(description="build / load graph", button_style="info")
        self.ends = {}
        for label in ("start", "goal"):
            self.ends[label] = (W.Dropdown(options=[], description=f"{label} placement", **wide),
                                W.FloatSlider(value=0.5, min=0.3, max=0.7, step=0.005, description=f"{label} x (m)",
                                              continuous_update=False, **wide),
                                W.FloatSlider(value=0.0, min=-0.25, max=0.25, step=0.005, description=f"{label} y (m)",
                                              continuous_update=False, **wide),
                                W.FloatSlider(value=0.0, min=-180, max=180, step=1, description=f"{label} yaw (deg)",
                                              continuous_update=False, **wide))
        self.alternatives = W.IntSlider(value=2, min=0, max=5, description="alternative plans", **wide)
        self.full = W.Checkbox(value=False, description="evaluate every start/goal grip (not lazy)", indent=False)
        self.nodes = W.Checkbox(value=False, description="show the graph's nodes", indent=False)
        self.plan_button = W.Button(description="search", button_style="primary")
        self.check_button = W.Button(description="validate", tooltip="check the shown plan with the independent validator")
        self.which = W.Dropdown(options=[], description="animate", **wide)
        self.busy = Busy()
        self.key = W.HTML(legend([(OBJECT_COLOR, "the part (animated)"), (START_COLOR, "start pose"),
                                  (GOAL_COLOR, "goal pose"), (0x999999, "intermediate placements"), (TABLE_COLOR, "table")],
                                 "colour key:") + "<small>graph nodes (when shown): dots at their TCPs, one grey shade per "
                          "component; yellow: nodes the start attaches to, blue: the goal's</small>")
        self.info = W.HTML()
        self.load_button.on_click(lambda _: self.load())
        self.plan_button.on_click(lambda _: self.run())
        self.check_button.on_click(lambda _: self.check())
        self._listing, self.shown_at = False, None
        self.which.observe(lambda _: None if self._listing else self.animate(), names="value")
        self.nodes.observe(lambda _: self.vis["roadmap"].set_property("visible", bool(self.nodes.value)), names="value")
        self.controls = W.VBox([self.object, self.robot, self.grippers.widget, self.grippers.note, W.HBox([self.load_button]),
                                *self.ends["start"], *self.ends["goal"],
                                self.alternatives, self.full, W.HBox([self.plan_button, self.check_button, self.busy.widget]), self.which,
                                self.nodes, self.info])
        self._widget = None


    def placement_options(self) -> list[tuple[str, int]]:
        """(label, store id) per stable placement with a grip: numbered within the part, named by how it rests."""
        free = self.planner.free
        ids = self.planner.placement_ids(gripped=True) or self.planner.placement_ids()
        number = per_part_numbers(free["idfreetabletopplacement"])
        rot = {int(i): np.asarray(m) for i, m in zip(free["idfreetabletopplacement"], free["rotmat"])}
        return [(describe_placement(number[i], rot[i][:3, :3].T @ [0.0, 0.0, -1.0]).split(", face")[0], i) for i in ids]

    def load(self):  # -> regrasp.Planner
        """Build (or reuse) the store's stages for the chosen object, robot and gripper, load the regrasp graph and
        draw its scene once (table, robot, part and ghosts)."""

        obj = load_object(self.objects[self.object.value])
        gripper = self.grippers.gripper
        with self.busy.running(f"building / loading {obj.name} for {self.robot.value} with {gripper.name}"):
            if self.build is not None:
                self.build(self.db, obj, self.robot.value, gripper)
                self.grippers.refresh()
            robot = robot_name_for(self.db, self.robot.value, gripper)
            self.planner = load_planner(self.db, obj.name, robot, gripper=gripper)
            options = self.placement_options()
            for label in ("start", "goal"):
                self.ends[label][0].options = options
            self.ends["start"][0].value = options[0][1]
            self.ends["goal"][0].value = options[-1][1]
            # framed now, before a view of the scene opens (a view replays the camera it finds; later moves may not apply)
            (x0, y0), (x1, y1), _ = scene_table(self.planner)
            if self.tparams is not None:
                x0, x1, y0, y1 = self.tparams.x_min, self.tparams.x_max, self.tparams.y_min, self.tparams.y_max
            base = self.planner.robot.base[:3, 3]
            self.vis.delete()
            self.scene = PlanView(self.vis, self.planner.robot, self.planner.object.mesh, scene_table(self.planner))
            self.scene.robot_view.show(self.planner.robot.neutral())
            viz.frame_points(self.vis, np.array([base, base + [0, 0, 0.6], [x0, y0, 0], [x1, y1, 0]]), PLAN_VIEW)
            self.info.value = self.graph_html()
        return self.planner

    def set_query(self, start, goal) -> None:
        """Put two PoseQuery values into the widgets."""
        for label, q in (("start", start), ("goal", goal)):
            p, x, y, yaw = self.ends[label]
            p.value, x.value, y.value, yaw.value = q.idfreetabletopplacement, q.x, q.y, float(np.degrees(q.yaw))

    def query(self, label: str) -> PoseQuery:
        """The widgets' pose (yaw in degrees there, radians in the library)."""
        p, x, y, yaw = self.ends[label]
        return PoseQuery(int(p.value), float(x.value), float(y.value), float(np.radians(yaw.value)))

    def run(self) -> list:
        """Search (Section V) from the widgets' start to their goal; animate the best plan at once. The independent
        validator checks the shown plan when asked (`check`, the *validate* button), as the command line's `plan`
        checks every plan it writes."""

        if self.planner is None:
            self.load()
        self.shown_at = None
        try:
            with self.busy.running("searching"):
                self.plans = self.planner.plan(self.query("start"), self.query("goal"), alternatives=self.alternatives.value,
                                               lazy=not self.full.value, validate=False, on_best=self._show_best)
            self.result = self.planner.last
        except PlanningError as exc:
            self.plans, self.result = [], None
            self.info.value = self.graph_html() + f"<p style='color:#b00'><b>no plan:</b> {exc}</p>"
            return []
        if self.shown_at is None:  # (a planner that does not report its best plan early)
            self._show_best(self.plans[0], self.result)
        self._list_plans()
        return self.plans

    def _show_best(self, plan, result) -> None:
        """The best plan, shown as soon as its motions are timed (its alternatives are planned after it)."""
        self.plans, self.result, self.reports = [plan], result, {}
        self.attach = show_roadmap(self.vis, self.planner, result)  # the graph's nodes, sent once per search
        self.vis["roadmap"].set_property("visible", bool(self.nodes.value))  # node clouds hide the part: off by default
        self._list_plans()
        self.animate()
        self.shown_at = time.perf_counter()
        if self.alternatives.value:
            self.busy.widget.value = "<span style='color:#b60'>&#9203; alternative plans ...</span>"

    def _list_plans(self) -> None:
        """The plans found so far in the *animate* menu, the best chosen (without replaying it)."""
        self._listing = True
        try:
            self.which.options = [(f"{'best' if p.rank == 0 else f'alternative {p.rank}'}: {p.regrasps} regrasp(s)", p.rank)
                                  for p in self.plans]
            self.which.value = 0
        finally:
            self._listing = False

    def animate(self) -> None:
        """Play the chosen plan (the best or an alternative) and describe it, with its verdict once validated."""
        if not self.plans:
            return
        plan = self.plans[self.which.value or 0]
        self.scene.play(plan, numbers=per_part_numbers(self.planner.free["idfreetabletopplacement"]))
        self.info.value = self.graph_html(self.attach) + self.verdict_html(plan) + self.plan_html(plan)

    def check(self):  # -> ValidationReport | None
        """Validate the shown plan with the independent validator (once per plan) and show the verdict."""
        if not self.plans:
            return None
        plan = self.plans[self.which.value or 0]
        if plan.rank not in self.reports:
            with self.busy.running("validating the plan"):
                self.reports[plan.rank] = self.planner.validate(plan, require_motion=bool(plan.segments))
        self.info.value = self.graph_html(self.attach) + self.verdict_html(plan) + self.plan_html(plan)
        return self.reports[plan.rank]

    def verdict_html(self, plan) -> str:
        """The validator's verdict on `plan`, or how to get it."""
        rep = self.reports.get(plan.rank)
        if rep is None:
            return "<p style='color:#666'>validation: not run yet (<i>validate</i> checks the shown plan)</p>"
        return (f"<p style='color:#185'><b>validation: ok</b> ({rep.checks:,} checks)</p>" if rep.ok else
                f"<p style='color:#b00'><b>validation failed:</b> {html.escape('; '.join(rep.errors[:3]))}</p>")

    def graph_html(self, attach: dict | None = None) -> str:

        rm = self.planner.roadmap
        s = rm.summary()
        sizes = rm.component_sizes()
        counts = {"tabletop grips": s["grips"], "nodes (IK-feasible)": s["nodes"], "transfer edges": s["transfer_edges"],
                  "transit edges": s["transit_edges"], "grasps": s["grasps"], "placements": s["placements"],
                  "components": s["components"], "component sizes": ", ".join(f"{int(n):,}" for n in sizes[:8])}
        html = counts_table(counts, f"regrasp graph of {self.planner.object.name} for {self.planner.robot.name}")
        if attach:
            rows = {}
            for label, side in (("start", self.result.start), ("goal", self.result.goal)):
                a = attach[label]
                rows[f"{label}: grips evaluated / feasible / all"] = f"{side.n_evaluated} / {side.n_feasible} / {len(side.grasp)}"
                rows[f"{label}: attached nodes (transfer edges)"] = f"{len(a['nodes']):,}"
                comps = list(a["components"])
                rows[f"{label}: components reached"] = (f"{len(comps)} (component id {', '.join(map(str, comps))})"
                                                        if comps else "0")
            html += counts_table(rows, "where start and goal attach")
        return html

    def plan_html(self, plan) -> str:
        """The plan's steps (as the view's footer names them) and what the search and motions took."""
        t = plan.timings
        numbers = per_part_numbers(self.planner.free["idfreetabletopplacement"])
        lines = "<br>".join(html.escape(f) for f in caption_track(plan, [], numbers=numbers)["footers"][1:])
        motion = (f"; motions planned in {t.get('motion', 0):.2f} s: {len(plan.segments)} timed segments, trajectory "
                  f"{plan.duration:.1f} s (the animation plays it at real speed), {plan.removed} node(s) or grip(s) removed"
                  if plan.segments else "")
        return (f"<p><b>{plan.regrasps} regrasp(s), {plan.transfers} transfer(s)</b>; connect {t.get('connect', 0) * 1e3:.1f} ms, "
                f"search {t.get('search', 0) * 1e3:.1f} ms{motion}</p><pre>{lines}</pre>")


class IKBrowser:
    """The robot at the feasible tabletop grips: a slider over them, a choice of grasp / handx / handxworldz, and the
    object at the grip's placement. `controls` and `key` are its widgets (`widget` both); `set_rows` switches robot
    and rows in place. The slider and the pose choice only move the robot and the part."""

    def __init__(self, vis: meshcat.Visualizer, robot: Robot, rows: dict[str, np.ndarray], obj_mesh, kind: str = "visual"):
        self.vis, self.kind_meshes = vis, kind
        self.slider = W.IntSlider(min=0, max=0, value=0, description="feasible grip", continuous_update=False,
                                  style={"description_width": "initial"}, layout=W.Layout(width="420px"))
        self.kind = W.ToggleButtons(options=list(KINDS), value="grasp", style={"button_width": "80px"})
        self.label = W.HTML()
        self.key = W.HTML(viz.legend([(FEASIBLE_ALL, "feasible at all five poses"),
                                      (FEASIBLE_GRASP, "grasp only"), (INFEASIBLE, "grasp out of reach or in collision"),
                                      (0x4477CC, "the part at the grip's placement"), (0xC8A878, "table")],
                                     "colour key (points: tabletop grips' TCPs):"))
        self.slider.observe(lambda _: self.update(), names="value")
        self.kind.observe(lambda _: self.update(), names="value")
        self.controls = W.VBox([self.slider, self.kind, self.label])
        self.widget = W.VBox([self.controls, self.key])
        self.view = None
        self.switches = Switches(vis)
        self.set_rows(robot, rows, obj_mesh)

    def set_rows(self, robot: Robot, rows: dict[str, np.ndarray], obj_mesh) -> None:
        """Show another robot's (or object's) IK rows: the roadmap points, the robot, the camera framed on both."""
        self.robot, self.rows, self.mesh = robot, rows, obj_mesh
        self.vis["robot"].delete()
        self.view = RobotView(self.vis, robot, "robot", self.kind_meshes)
        show_ik_roadmap(self.vis, rows)
        show_mesh(self.vis, "object", obj_mesh, color=0x4477CC)
        self.switches.forget("object")
        self.feasible = np.flatnonzero(np.asarray(rows["feasible"])[:, 0])
        self.slider.value = 0
        self.slider.max = max(len(self.feasible) - 1, 0)
        tcp = np.asarray(rows["rotmat"])[:, :3, 3]
        viz.frame_points(self.vis, np.vstack([tcp, robot.base[:3, 3][None]]))
        self.update()

    def update(self) -> int | None:
        """Show the selected grip; returns its row index (None when no grip is feasible)."""
        if len(self.feasible) == 0:
            self.label.value = "no feasible grip"
            return None
        i = int(self.feasible[self.slider.value])
        k = list(KINDS).index(self.kind.value)
        q = self.rows["joints"][i, k]
        ok = bool(self.rows["feasible"][i, k])
        if not ok:
            q = self.rows["joints"][i, 0]
        self.view.show(q, float(self.rows["jawwidth"][i]) if k == 0 else None)
        self.switches.move("object", self.rows["placement_rotmat"][i])
        self.label.value = (f"{self.robot.name}: tabletop grip {int(self.rows['idtabletopgrips'][i])}, free-air grasp "
                            f"{int(self.rows['idfreeairgrip'][i])}, position "
                            f"{np.round(self.rows['tabletopposition'][i][:2], 3).tolist()} m; {self.kind.value}: "
                            f"{'feasible' if ok else 'infeasible (showing the grasp)'}; joints {np.round(np.degrees(q), 1).tolist()} deg")
        return i


def plot_feasibility(rows: dict[str, np.ndarray], title: str = ""):
    """Feasible counts per placement (tabletop placement's free placement and angle) and per grid position."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    f = np.asarray(rows["feasible"], dtype=bool)
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.6))
    key = np.asarray(rows["idtabletopplacements"])
    pos = np.round(np.asarray(rows["tabletopposition"])[:, :2], 4)
    # per free placement and angle: the tabletop placements share the placement's rotation
    rot = np.round(np.asarray(rows["placement_rotmat"])[:, :3, :3].reshape(len(key), 9), 5)
    _, group = np.unique(rot, axis=0, return_inverse=True)
    group = group.ravel()
    n = group.max() + 1 if len(group) else 0
    total = np.bincount(group, minlength=n)
    grasp = np.bincount(group, weights=f[:, 0], minlength=n)
    both = np.bincount(group, weights=f.all(1), minlength=n)
    ax[0].bar(np.arange(n), total, color="#dddddd", label="tabletop grips")
    ax[0].bar(np.arange(n), grasp, color="#e8b400", label="IK feasible (grasp)")
    ax[0].bar(np.arange(n), both, color="#33aa55", label="at all five poses (retractions, lifts)")
    ax[0].set(xlabel="placement x rotation (group)", ylabel="grips", title="per placement and angle (summed over positions)")
    ax[0].xaxis.set_major_locator(MaxNLocator(integer=True))  # groups are whole numbers
    ax[0].legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.22), ncol=3, frameon=False)
    xs, ix = np.unique(pos[:, 0], return_inverse=True)
    ys, iy = np.unique(pos[:, 1], return_inverse=True)
    cnt = np.zeros((len(xs), len(ys)))
    tot = np.zeros((len(xs), len(ys)))
    np.add.at(cnt, (ix.ravel(), iy.ravel()), f.all(1))
    np.add.at(tot, (ix.ravel(), iy.ravel()), 1)
    dx = np.diff(xs).min() / 2 if len(xs) > 1 else 0.025
    dy = np.diff(ys).min() / 2 if len(ys) > 1 else 0.025
    im = ax[1].imshow(np.divide(cnt, tot, out=np.zeros_like(cnt), where=tot > 0).T, origin="lower", vmin=0, vmax=1,
                      cmap="RdYlGn", extent=[xs[0] - dx, xs[-1] + dx, ys[0] - dy, ys[-1] + dy], aspect="auto")
    fig.colorbar(im, ax=ax[1], label="feasible share (all five poses)")
    ax[1].set(xlabel="x (m)", ylabel="y (m)", title="per position")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


class PlacementExplorer(BesideView):
    """Tune the stability threshold and the table grid; inspect placements, their grips and the roadmap (Section IV).

    The threshold reruns the placement and free-grip stages, the grid sliders only the tabletop roadmap (each cached
    by parameter digest); the selected placement, the grips drawn and the roadmap box only show, hide and recolour
    what was sent."""

    def __init__(self, obj: ObjectModel, gripper: Gripper, grasp_poses: np.ndarray, grasp_widths: np.ndarray, vis=None,
                 max_hands: int = 30, params: PlacementParams = PlacementParams(), tabletop: TabletopParams = TabletopParams(),
                 grasps_for: Callable[[Gripper], tuple[np.ndarray, np.ndarray]] | None = None, db=None,
                 grippers: Sequence[Gripper] = ()):
        self.obj, self.max_hands, self.grasps_for = obj, max_hands, grasps_for
        self.vis = vis if vis is not None else viz.new_scene()
        self.base, self.base_grid = params, tabletop  # parameters without a widget stay as given
        self.switches = Switches(self.vis)
        self.stage_cache, self.tabletop_cache = StageCache(), StageCache()
        self._use(gripper, grasp_poses, grasp_widths)
        t = tabletop
        label = {"style": {"description_width": "initial"}, "layout": W.Layout(width="420px"), "continuous_update": False}
        self.stability = W.FloatSlider(value=params.min_stability, min=0, max=1.5, step=0.01,
                                       description="minimum stability (margin / COM height)", **label)
        self.angles = W.IntSlider(value=t.angles, min=1, max=16, description="rotations per position", **label)
        self.nx = W.IntSlider(value=t.nx, min=1, max=15, description="table grid positions along x", **label)
        self.ny = W.IntSlider(value=t.ny, min=1, max=15, description="table grid positions along y", **label)
        self.which = W.Dropdown(options=[], description="selected placement", style=label["style"],
                                layout=W.Layout(width="420px"))
        self.hands = W.IntSlider(value=min(8, max_hands), min=0, max=max_hands, description="grips drawn (outlines)", **label)
        self.roadmap = W.Checkbox(value=False, description="every placement on the roadmap (faint)", indent=False)
        self.busy = Busy()
        self.key = W.HTML()
        self.info = W.HTML()
        self.stability.observe(lambda _: self.run(), names="value")
        for w in (self.angles, self.nx, self.ny):
            w.observe(lambda _: self.run_tabletop(), names="value")
        for w in (self.which, self.hands, self.roadmap):
            w.observe(lambda _: self.show(), names="value")
        # with `grasps_for(gripper)` (the free-air grasps of another gripper, e.g. from the store): a gripper menu
        self.grippers = None if grasps_for is None else GripperMenu(db, grippers, value=gripper, on_change=self.set_gripper)
        menu = [] if self.grippers is None else [self.grippers.widget, self.grippers.note]
        self.controls = W.VBox([*menu, self.stability, self.which, self.hands, self.roadmap, W.HTML("<b>table grid</b>"),
                                self.nx, self.ny, self.angles, self.busy.widget, self.info])
        self.placements, self.params, self.tt, self._widget = None, self.base, None, None

    def _use(self, gripper: Gripper, poses: np.ndarray, widths: np.ndarray) -> None:
        self.gripper, self.grasp_poses, self.grasp_widths = gripper, poses, widths
        self.outlines = HandOutlines(gripper)
        self.source = digest(self.obj.digest or self.obj.name, gripper.digest, np.asarray(poses).round(9).tobytes().hex()[:4096])

    def set_gripper(self, gripper: Gripper):
        """Placements and grips with another gripper's free-air grasps (from `grasps_for`)."""
        with self.busy.running(f"free-air grasps with {gripper.name}"):
            poses, widths = self.grasps_for(gripper)
        self._use(gripper, poses, widths)
        if self.grippers is not None:
            self.grippers.refresh(gripper.digest)
        return self.run()


    def grid(self) -> TabletopParams:
        return replace(self.base_grid, nx=self.nx.value, ny=self.ny.value, angles=self.angles.value)

    def names(self) -> list[str]:
        """Each placement numbered within the part (from 1) and described by how it rests."""
        pl = self.placements
        return [describe_placement(k + 1, pl.normals[k], float(pl.stability[k])) for k in range(len(pl))]

    def run(self):
        """Placements and free tabletop grips with the library's stages (the numbers the store would hold)."""
        params = replace(self.base, min_stability=self.stability.value)

        def compute():
            pl = stable_placements(self.obj, params)
            return pl, free_tabletop_grips(pl, self.grasp_poses, self.gripper, params)

        with self.busy.running("placements and free grips"):
            (self.placements, self.ftg), self.params = self.stage_cache.get(digest(self.source, params), compute), params
            self.ok = np.zeros((len(self.placements), len(self.grasp_poses)), dtype=bool)
            self.ok[self.ftg[0], self.ftg[1]] = True
            self.send_placements()
            self.run_tabletop()
        return self.placements

    def run_tabletop(self) -> None:
        """The tabletop roadmap of the current placements on the grid (cached), sent once per placement."""
        pl, grid = self.placements, self.grid()
        if pl is None:
            return
        with self.busy.running("tabletop roadmap"):
            self.tt = self.tabletop_cache.get(
                digest(self.source, self.params, grid),
                lambda: plan_tabletop(pl.poses, self.ftg[0], self.ftg[1], self.ftg[2], self.grasp_poses, grid))
            self.vis["placements/roadmap"].delete()
            self.switches.forget("placements/roadmap")
            hull, colors = part_hull(self.obj.mesh), viz.palette(max(len(pl), 1))
            for p in range(len(pl)):
                parts = [hull.copy().apply_transform(m) for m in self.tt.poses[self.tt.placement == p]]
                if parts:
                    viz.show_mesh(self.vis, f"placements/roadmap/{p}", trimesh.util.concatenate(parts),
                                  color=int(colors[p]), opacity=0.999)
        self.show()

    def send_placements(self) -> None:
        """Every placement beside the table (part, support polygon, grip outlines), hidden but the selected one."""
        pl, vis = self.placements, self.vis
        vis["placements"].delete()
        self.switches.forget("placements")
        grid = self.grid()
        viz.show_mesh(vis, "placements/table", table_mesh(), color=0x8B6B4A, opacity=0.6)
        self.show_at = np.eye(4)
        self.show_at[:3, 3] = (grid.x_min - 0.25, 0.0, 0.0)  # the selected placement beside the grid
        self.grip_pick = pick_evenly(len(self.grasp_poses), self.max_hands)
        for k in range(len(pl)):
            pose = self.show_at @ pl.poses[k]
            viz.show_mesh(vis, f"placements/selected/{k}/object", self.obj.mesh, color=0xE0C040, pose=pose)
            ring = pl.supports[k] + self.show_at[:3, 3] + [0, 0, 1e-4]
            viz.show_segments(vis, f"placements/selected/{k}/support", ring, np.roll(ring, -1, axis=0), viz.RED)
            grips = pose @ self.grasp_poses[self.grip_pick]
            ok = self.ok[k, self.grip_pick]
            self.outlines.send(vis, f"placements/selected/{k}/kept", grips[ok], self.grasp_widths[self.grip_pick][ok], viz.GREEN)
            self.outlines.send(vis, f"placements/selected/{k}/hit", grips[~ok], self.grasp_widths[self.grip_pick][~ok], viz.RED)
            self.switches.show(f"placements/selected/{k}", False)
        options = [(name.split(", stability")[0], k) for k, name in enumerate(self.names())]
        self.which.unobserve_all("value")
        self.which.options = options
        self.which.value = options[0][1] if options else None
        self.which.observe(lambda _: self.show(), names="value")
        if len(pl):  # the work: the selected placement and its grips beside the table, the nearest grid corner
            pose = self.show_at @ pl.poses[0]
            grips = pose @ self.grasp_poses[self.grip_pick]
            corner = np.array([[grid.x_min, grid.y_min, 0.0]])
            viz.frame_points(vis, np.vstack([trimesh.transform_points(self.obj.mesh.bounds, pose), grips[:, :3, 3], corner]))

    def show(self) -> None:
        """View-only: the selected placement, how many of its grips, and the roadmap's colours."""
        pl, tt, sw = self.placements, self.tt, self.switches
        if pl is None or tt is None:
            return
        counts = {"stable placements": len(pl), "rejected faces": len(pl.rejected_stability),
                  "tabletop placements": len(tt.poses), "tabletop grips": len(tt.grip_poses)}
        if len(pl) == 0:
            why = html.escape(stability_hint(self.obj, self.params))
            self.info.value = counts_table(counts, "no stable placement at this threshold") + f"<p>{why}</p>"
            self.key.value = ""
            return
        k = self.which.value or 0
        shown = set(pick_evenly(len(self.grip_pick), self.hands.value).tolist())
        colors = viz.palette(len(pl))
        for p in range(len(pl)):
            sw.show(f"placements/selected/{p}", p == k)
            ok = self.ok[p, self.grip_pick]
            for name, members in (("kept", np.flatnonzero(ok)), ("hit", np.flatnonzero(~ok))):
                for i, j in enumerate(members):
                    sw.show(f"placements/selected/{p}/{name}/{i}", p == k and int(j) in shown)
            if (tt.placement == p).any():
                sw.show(f"placements/roadmap/{p}", p == k or self.roadmap.value)
                rgb = [((int(colors[p]) >> s) & 255) / 255 for s in (16, 8, 0)]
                sw.set(f"placements/roadmap/{p}", "color", rgb + [1.0 if p == k else 0.15])
        n_shown = len(shown)
        self.key.value = viz.legend(
            [(0xE0C040, f"placement {k + 1} beside the table"), (viz.RED, "its support polygon"),
             (viz.GREEN, "grips kept above the table"), (viz.RED, "grips hitting the table"),
             (0x8B6B4A, "table")], "colour key:") + \
            f"<small>{n_shown} of {len(self.grasp_poses):,} grips drawn as outlines; on the table, the roadmap: the " \
            f"selected placement's convex hull at each grid position and rotation (tick the box for every placement, " \
            f"faint)</small>"
        counts["selected"] = html.escape(self.names()[k])
        counts["selected grips kept / collided"] = f"{int(self.ok[k].sum())} / {int((~self.ok[k]).sum())}"
        self.info.value = counts_table(counts, "placements and the tabletop roadmap")


def plot_placements(obj: ObjectModel, placements, columns: int = 6):
    """A thumbnail per placement: the part resting on the table as it would stand, seen from the front, numbered
    within the part and named by how it rests (upright, on its side, ...)."""
    import matplotlib.pyplot as plt

    n = len(placements)
    cols = max(1, min(columns, n))
    rows = max(1, -(-n // cols))
    fig = plt.figure(figsize=(2.3 * cols, 2.5 * rows))
    size = float(np.ptp(obj.mesh.vertices, axis=0).max())
    for k in range(n):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        v = trimesh.transform_points(obj.mesh.vertices, placements.poses[k])
        ax.plot_trisurf(v[:, 0], v[:, 1], v[:, 2], triangles=obj.mesh.faces, color="#E0A030", linewidth=0, shade=True)
        ax.plot([-size / 2, size / 2, size / 2, -size / 2, -size / 2], [-size / 2, -size / 2, size / 2, size / 2, -size / 2],
                [0] * 5, color="#8B6B4A", lw=1)
        ax.set(xlim=(-size / 2, size / 2), ylim=(-size / 2, size / 2), zlim=(0, size))
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=18, azim=-60)
        ax.set_axis_off()
        name = describe_placement(k + 1, placements.normals[k]).split(", face normal")
        ax.set_title(f"{name[0]}\nnormal{name[1]}", fontsize=8)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.02, top=0.86, wspace=0.05, hspace=0.3)
    return fig


def plot_trajectory(plan, joint_names: list[str] | None = None):
    """Joint positions (deg) and velocities (deg/s) of a timed plan against time, each plan step shaded and named
    (a transfer or transit is shaded with the step it moves to, as the animation's caption counts it)."""
    import matplotlib.pyplot as plt

    if not plan.segments:
        raise PlanningError("the plan has no timed motions to plot (plan it with motions)")
    t = np.concatenate([s.t0 + s.traj.t for s in plan.segments])
    q = np.degrees(np.vstack([s.traj.q for s in plan.segments]))
    qd = np.degrees(np.vstack([s.traj.qd for s in plan.segments]))
    names = joint_names or [f"joint {j + 1}" for j in range(q.shape[1])]
    fig, ax = plt.subplots(2, 1, figsize=(11, 5.6), sharex=True)
    spans: dict[int, list[float]] = {}
    for s in plan.segments:
        k = min(int(s.step) + (s.kind in MOVES_TO_NEXT), len(plan.steps) - 1)
        lo, hi = spans.get(k, [s.t0, s.t0])
        spans[k] = [min(lo, s.t0), max(hi, s.t0 + s.duration)]
    shades = ("#f3e3c3", "#dde8f3")
    for k, (lo, hi) in sorted(spans.items()):
        for a in ax:
            a.axvspan(lo, hi, color=shades[k % 2], zorder=0)
        ax[0].text(0.5 * (lo + hi), 1.01, f"{k + 1} {STEP_NAMES.get(plan.steps[k].kind, plan.steps[k].kind)}",
                   transform=ax[0].get_xaxis_transform(), ha="center", va="bottom", fontsize=8)
    for j, name in enumerate(names):
        ax[0].plot(t, q[:, j], lw=1.2, label=name)
        ax[1].plot(t, qd[:, j], lw=1.2)
    ax[0].set(ylabel="position (deg)")
    ax[1].set(ylabel="velocity (deg/s)", xlabel="time from the plan's start (s)")
    ax[0].legend(fontsize=7, ncol=min(len(names), 9), loc="upper center", bbox_to_anchor=(0.5, -1.35), frameon=False)
    fig.suptitle(f"{plan.object} with {plan.robot}: {plan.duration:.1f} s, steps shaded and named", y=0.995)
    fig.subplots_adjust(left=0.07, right=0.99, top=0.9, bottom=0.17, hspace=0.08)
    return fig
