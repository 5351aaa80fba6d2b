"""The grasp-placement table widget (notebook 06) shows the library's table and keeps its parameters."""

from __future__ import annotations

import numpy as np

from workbench.planners.tournassoud.shapes import l_part
from workbench.planners.tournassoud.stages import load_planner
from workbench.planners.tournassoud.table import TableParams
from workbench.robots.model import get_robot
from workbench.widgets.tournassoud import TableExplorer


class Sink:
    """A meshcat stand-in that records nothing."""

    def __getitem__(self, key):
        return self

    def __getattr__(self, name):
        return lambda *a, **k: None


def test_table_explorer_rebuilds_at_new_resolutions_and_keeps_parameters(tmp_path):
    db = str(tmp_path / "t.duckdb")
    given = TableParams(theta_step=np.radians(15), phi_step=np.radians(15), table_point=(0.45, 0.1), clearance=0.004)
    ex = TableExplorer(db, l_part(), get_robot("puma560"), given, vis=Sink())
    assert ex.run.table.q.shape[2:] == (24, 24)
    ex.phi_step.value = 10.0
    assert ex.run.table.q.shape[2:] == (24, 36)
    stored = load_planner(db, "L", "puma560")
    assert np.array_equal(stored.table.q, ex.run.table.q)
    ex.cls.value, ex.place.value, ex.theta.value, ex.phi.value = 0, 0, 180.0, 0.0
    legal = ex.show()
    i = int(round(np.radians(180.0) / (2 * np.pi / 24))) % 24
    assert legal == bool(ex.run.table.q[0, 0, i, 0])
    assert "G0: face/face" in ex.info.value


class View(Sink):
    """A meshcat stand-in with a server address (for the live view's widget)."""

    def url(self):
        return "http://127.0.0.1:7001/static/"


def test_table_explorer_puts_its_controls_beside_its_view(tmp_path):
    """One output: the controls (the table plot and a busy line among them) in a column, the live view and its colour
    key beside them; the busy line names the rebuild while a resolution change rebuilds the table, then clears."""
    import ipywidgets as W

    db = str(tmp_path / "t.duckdb")
    params = TableParams(theta_step=np.radians(30), phi_step=np.radians(30), table_point=(0.45, 0.1))
    ex = TableExplorer(db, l_part(), get_robot("puma560"), params, vis=View())
    w = ex.widget
    assert isinstance(w, W.HBox) and ex.widget is w
    column, right = w.children
    for c in (ex.cls, ex.theta, ex.place, ex.phi, ex.theta_step, ex.phi_step, ex.busy.widget, ex.info, ex.plot):
        assert c in column.children
    assert "7001" in right.children[0].value and right.children[-1] is ex.key and "the part at H" in ex.key.value
    seen = []
    ex.busy.widget.observe(lambda ch: seen.append(ch["new"]), names="value")
    ex.theta_step.value = 20.0
    assert ex.run.table.q.shape[2] == 18
    assert any("building the grasp-placement table" in v for v in seen) and ex.busy.widget.value == ""
