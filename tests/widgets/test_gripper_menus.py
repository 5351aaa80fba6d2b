"""The explorers' gripper menu: the grippers a store holds (by name and digest) and the ones to build for, with a
gripper the workbench has never seen (a spec written here); the placement, regrasp and table explorers plan with
the one chosen."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from workbench.errors import GripperError
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams, free_tabletop_grips, stable_placements
from workbench.planners.tournassoud.shapes import l_part
from workbench.planners.tournassoud.table import TableParams
from workbench.planners.wan_harada.stages import ensure_grasps
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.gripper import BUNDLED, load_gripper
from workbench.robots.model import get_robot
from workbench.widgets.grippers import GripperMenu
from workbench.widgets.tournassoud import TableExplorer
from workbench.widgets.wan_harada import PlacementExplorer, RegraspExplorer

# A 46 mm-stroke gripper with long thin fingers and a narrow palm, written for these tests only.
NEW = {"name": "slim46", "source": "written for the widget tests", "stroke": [0.004, 0.046], "tcp": [0.0, 0.0, 0.118],
       "pad": {"size": [0.012, 0.024], "thickness": 0.004}, "finger": {"size": [0.014, 0.008, 0.07]},
       "palm": {"size": [0.05, 0.07, 0.06], "offset": [0.0, 0.0, 0.03]}, "max_force": 80.0}


class Sink:
    """A meshcat stand-in that records nothing: the tests read what the widgets computed."""

    def __getitem__(self, key):
        return self

    def __getattr__(self, name):
        return lambda *a, **k: None


@pytest.fixture()
def slim(tmp_path):
    path = tmp_path / "slim46.yaml"
    path.write_text(yaml.safe_dump(NEW))
    return load_gripper(str(path))


def test_the_menu_lists_the_stores_grippers_then_those_to_build(tmp_path, box, hand, slim):
    db = tmp_path / "m.duckdb"
    ensure_grasps(db, box, slim, GraspParams(rotations=4))
    menu = GripperMenu(db)  # the new gripper is in the store but was not given: listed, refused when chosen
    labels = [label for label, _ in menu.widget.options]
    assert labels[0].startswith("slim46 (in store") and "box" in labels[0] and "not loaded" in labels[0]
    assert [lb.split(" (")[0] for lb in labels[1:]] == ["franka_hand", "robotiq-2f85", "parallel60"]
    assert all(lb.endswith("(build)") for lb in labels[1:])
    assert menu.widget.value == slim.digest
    with pytest.raises(GripperError, match="slim46"):
        menu.gripper
    chosen = []
    given = GripperMenu(db, [slim], value=hand, on_change=chosen.append)
    assert given.gripper is hand
    given.widget.value = slim.digest
    assert chosen == [given.known[slim.digest]] and chosen[0].digest == slim.digest
    ensure_grasps(db, box, hand, GraspParams(rotations=4))
    given.refresh()  # after a build: the Franka hand is in the store too, the choice kept
    assert sum("in store" in lb for lb, _ in given.widget.options) == 2 and given.widget.value == slim.digest


def test_placement_explorer_switches_to_the_chosen_grippers_grasps(tmp_path, box, hand, slim):
    db = tmp_path / "p.duckdb"
    asked = []

    def grasps_for(gripper):
        asked.append(gripper.name)
        g = ensure_grasps(db, box, gripper, GraspParams(rotations=4))
        return g.poses, g.widths

    poses, widths = grasps_for(hand)
    ex = PlacementExplorer(box, hand, poses, widths, vis=Sink(), tabletop=TabletopParams(nx=2, ny=1, angles=2, max_grasps=8),
                           grasps_for=grasps_for, db=db, grippers=[slim])
    ex.run()
    franka_ok = ex.ok.copy()
    ex.grippers.widget.value = slim.digest
    assert asked == ["franka_hand", "slim46"] and ex.gripper.digest == slim.digest
    new_poses, new_widths = grasps_for(slim)
    assert np.array_equal(ex.grasp_poses, new_poses) and new_widths.max() <= NEW["stroke"][1] + 1e-9
    # the explorer's kept grips are the library's for the new gripper's grasps
    pl = stable_placements(box, PlacementParams())
    p, g, _ = free_tabletop_grips(pl, new_poses, slim, PlacementParams())
    want = np.zeros((len(pl), len(new_poses)), dtype=bool)
    want[p, g] = True
    assert np.array_equal(ex.ok, want) and ex.ok.shape != franka_ok.shape


def test_regrasp_explorer_builds_and_loads_for_the_chosen_gripper(tmp_path, box, slim):
    db = tmp_path / "r.duckdb"
    mesh = tmp_path / "box.stl"
    box.mesh.export(mesh)
    built = []

    def build(db, obj, robot, gripper):
        built.append((robot, gripper.name))
        from workbench.planners.wan_harada.stages import build_all

        grid = TabletopParams(x_min=0.45, x_max=0.55, nx=2, y_min=-0.05, y_max=0.05, ny=1, angles=2, max_grasps=10)
        return build_all(db, obj, get_robot(robot, gripper=gripper), GraspParams(rotations=4), tparams=grid,
                         workers=1, progress=False)

    ex = RegraspExplorer(db, {"box": mesh}, robots=("panda",), vis=Sink(), build=build, grippers=[slim])
    ex.grippers.widget.value = slim.digest
    planner = ex.load()
    assert built == [("panda", "slim46")]
    assert planner.robot.gripper.digest == slim.digest and planner.rows["gripper"]["name"] == "slim46"
    assert planner.rows["gripper"]["jaw_max"] == pytest.approx(NEW["stroke"][1])
    assert ex.grippers.widget.options[0][0].startswith("slim46 (in store")


def test_table_explorer_rebuilds_its_table_for_the_chosen_gripper(tmp_path):
    db = str(tmp_path / "t.duckdb")
    params = TableParams(theta_step=np.radians(30), phi_step=np.radians(30), table_point=(0.45, 0.1))
    ex = TableExplorer(db, l_part(), get_robot("puma560"), params, vis=Sink())
    franka = ex.run
    robotiq = load_gripper("robotiq-2f85")
    ex.grippers.widget.value = robotiq.digest
    assert ex.robot.gripper.digest == robotiq.digest and ex.run.gripper.digest == robotiq.digest
    assert ex.run.robot.spec.digest != franka.robot.spec.digest
    assert all(c.opening <= robotiq.jaw_max + 1e-9 for c in ex.run.classes)
    assert sum("in store" in lb for lb, _ in ex.grippers.widget.options) == 2
    assert BUNDLED["robotiq-2f85"].is_file()
