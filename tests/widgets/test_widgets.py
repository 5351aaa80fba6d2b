"""Widgets call the library and show its numbers (issue 9): no parameter silently reset, no counts of their own."""

from __future__ import annotations

import re

from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.stages import ensure_grasps, ensure_placements
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.widgets.grasping import GraspExplorer
from workbench.widgets.wan_harada import PlacementExplorer


def test_grasp_explorer_keeps_parameters_it_has_no_widget_for(box, hand):
    given = GraspParams(merge_angle=0.0, parallel_angle=0.05, com_max=0.03, seed=7, rotations=6)
    ex = GraspExplorer(box, hand, given, vis=object())
    got = ex.params()
    assert (got.merge_angle, got.parallel_angle, got.com_max, got.seed) == (0.0, 0.05, 0.03, 7)
    assert got.rotations == 6 and abs(got.tau - given.tau) < 1e-9


def test_placement_explorer_counts_equal_the_stored_ones(tmp_path, box, hand):
    grid = TabletopParams(nx=3, ny=2, angles=4, max_grasps=12)
    g = ensure_grasps(tmp_path / "w.duckdb", box, hand, GraspParams(rotations=6))
    p = ensure_placements(tmp_path / "w.duckdb", g.idobject, box, g.idparamset, hand, PlacementParams(), grid)

    class Sink:  # a meshcat stand-in that records nothing: the test reads the numbers the widget shows
        def __getitem__(self, key):
            return self

        def __getattr__(self, name):
            return lambda *a, **k: None

    ex = PlacementExplorer(box, hand, g.poses, g.widths, vis=Sink(), tabletop=grid)
    ex.roadmap.value = False
    ex.run()
    text = re.sub(r"<[^>]+>", " ", ex.info.value)
    numbers = dict(re.findall(r"(tabletop grips|tabletop placements)\s+([\d,]+)", text))
    assert int(numbers["tabletop grips"].replace(",", "")) == p.n_tabletop_grips
    assert int(numbers["tabletop placements"].replace(",", "")) == p.n_tabletop_placements
    # a threshold above every support: no placement, and the widget says what threshold keeps one
    ex.stability.value = 1.5
    text = re.sub(r"<[^>]+>", " ", ex.info.value)
    assert "no stable placement at this threshold" in text and "--min-stability" in text
    lower = float(re.search(r"--min-stability ([0-9.]+) keeps", text).group(1))
    ex.stability.value = lower
    assert len(ex.placements) > 0
