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


class Recorder:
    """A meshcat stand-in recording every call as (method, path, args)."""

    def __init__(self, path: str = "", log: list | None = None):
        self.path, self.log = path, [] if log is None else log

    def __getitem__(self, key):
        return Recorder(f"{self.path}/{key}".lstrip("/"), self.log)

    def url(self):
        return "http://127.0.0.1:7001/static/"

    def __getattr__(self, name):
        return lambda *a, **k: self.log.append((name, self.path, a))


def test_view_only_changes_move_what_the_scene_holds(tmp_path):
    """Theta, placement and phi only move and recolour the hands and the part at H (no geometry sent); the part sent
    at (P_j, phi) rests on the table at H (its lowest point at z = 0, its centre of mass above H) and the hand's
    TCP sits on the class's grasp point; another class sends its geometry again."""
    db = str(tmp_path / "t.duckdb")
    params = TableParams(theta_step=np.radians(30), phi_step=np.radians(30), table_point=(0.45, 0.1))
    vis = Recorder()
    ex = TableExplorer(db, l_part(), get_robot("puma560"), params, vis=vis)
    vis.log.clear()
    ex.theta.value, ex.phi.value, ex.place.value = 200.0, 90.0, 1
    assert vis.log and not any(name in ("set_object", "delete") for name, _, _ in vis.log), vis.log
    assert {p for _, p, _ in vis.log} <= {"class/hand", "conjunction/hand", "conjunction/object"}
    last = {p: a[0] for name, p, a in vis.log if name == "set_transform"}
    obj = np.asarray(last["conjunction/object"])
    run = ex.run
    world = run.obj.mesh.vertices @ obj[:3, :3].T + obj[:3, 3]
    assert abs(world[:, 2].min()) < 1e-9
    assert np.allclose(obj[:3, :3] @ run.obj.com + obj[:3, 3], [0.45, 0.1, obj[:3, :3][2] @ run.obj.com + obj[2, 3]])
    c = run.classes[int(ex.cls.value)]
    assert np.allclose(np.asarray(last["conjunction/hand"])[:3, 3], obj[:3, :3] @ c.point + obj[:3, 3])
    vis.log.clear()
    ex.cls.value = 1
    assert any(name == "set_object" and p.startswith("class/") for name, p, _ in vis.log)
