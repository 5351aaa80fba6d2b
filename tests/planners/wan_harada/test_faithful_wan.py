"""Wan & Harada where the paper's reading changes results (issue 16): the roadmap keeps every grasp unless a cap is
asked for, and the lift retractions (worlda, worlda + worldz) gate the roadmap and shape the plans' waypoints.

Independent checks: counts from the free tabletop grips times the grid, pinocchio forward kinematics on the stored
robot row (not workbench's kinematics) for the plans' joint vectors."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from workbench.cli.main import main as cli_main
from workbench.errors import PlanningError
from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.planners.wan_harada.query import PoseQuery
from workbench.planners.wan_harada.roadmap import build_roadmap
from workbench.planners.wan_harada.stages import ensure_grasps, ensure_placements
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.gripper import franka_hand
from workbench.robots.ik import KINDS, retract

GRID = dict(x_min=0.4, x_max=0.6, nx=2, y_min=-0.1, y_max=0.1, ny=1, angles=2)


# ---------------------------------------------------------------------------------------------------------- all grasps

def test_roadmap_keeps_every_grasp_and_a_cap_changes_counts_only_when_asked(tmp_path, bundled):
    obj, hand = bundled["tube"], franka_hand()
    assert TabletopParams().max_grasps is None
    db = tmp_path / "t.duckdb"
    g = ensure_grasps(db, obj, hand, GraspParams())
    full = ensure_placements(db, g.idobject, obj, g.idparamset, hand, PlacementParams(), TabletopParams(**GRID))
    per_tp = 2 * 1 * 2
    # every free tabletop grip of every placement at every grid position and angle (Table I: #-tpg = 168 x sum #-fpg)
    assert full.n_tabletop_grips == per_tp * int(full.n_free_grips.sum())
    assert full.n_tabletop_placements == per_tp * len(full.n_free_grips)
    assert full.n_roadmap_grasps == full.n_usable_grasps > 80
    big = ensure_placements(db, g.idobject, obj, g.idparamset, hand, PlacementParams(), TabletopParams(**GRID, max_grasps=10_000))
    assert big.n_tabletop_grips == full.n_tabletop_grips and big.n_roadmap_grasps == full.n_roadmap_grasps
    capped = ensure_placements(db, g.idobject, obj, g.idparamset, hand, PlacementParams(), TabletopParams(**GRID, max_grasps=20))
    assert capped.n_roadmap_grasps < full.n_roadmap_grasps and capped.n_tabletop_grips < full.n_tabletop_grips
    assert "all" in TabletopParams().grasps_label() and "capped at 20" in TabletopParams(max_grasps=20).grasps_label()


def test_placements_command_names_the_cap(tmp_path, bundled, capsys):
    db = tmp_path / "c.duckdb"
    mesh = tmp_path / "tube.stl"
    bundled["tube"].mesh.export(mesh)
    assert cli_main(["grasps", str(mesh), "--db", str(db), "--name", "tube"]) == 0
    grid = ["--x", "0.4,0.6,2", "--y=-0.1,0.1,1", "--angles", "2"]
    capsys.readouterr()
    assert cli_main(["placements", "--db", str(db), "--object", "tube", *grid]) == 0
    out = capsys.readouterr().out
    assert "all" in out and "capped" not in out
    assert cli_main(["placements", "--db", str(db), "--object", "tube", *grid, "--max-grasps", "15"]) == 0
    assert "capped at 15" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------------------- retractions

def test_five_poses_per_grip():
    rng = np.random.default_rng(0)
    from scipy.spatial.transform import Rotation

    poses = np.repeat(np.eye(4)[None], 5, axis=0)
    poses[:, :3, :3] = Rotation.random(5, random_state=1).as_matrix()
    poses[:, :3, 3] = rng.uniform(-0.5, 0.5, (5, 3))
    assert KINDS == ("grasp", "handx", "handxworldz", "worlda", "worldaworldz")
    out = retract(poses, 0.05, 0.1, 0.07)
    assert out.shape == (5, 5, 4, 4)
    assert np.allclose(out[:, :, :3, :3], poses[:, None, :3, :3])            # orientation never changes
    z = poses[:, :3, 2]
    up = np.array([0.0, 0.0, 1.0])
    assert np.allclose(out[:, 0], poses)
    assert np.allclose(out[:, 1, :3, 3], poses[:, :3, 3] - 0.05 * z)         # handx: back along the TCP's -z
    assert np.allclose(out[:, 2, :3, 3], poses[:, :3, 3] - 0.05 * z + 0.1 * up)
    assert np.allclose(out[:, 3, :3, 3], poses[:, :3, 3] + 0.07 * up)        # worlda: the held object straight up
    assert np.allclose(out[:, 4, :3, 3], poses[:, :3, 3] + 0.17 * up)


def test_roadmap_nodes_need_all_five_feasibilities():
    n = 6
    eye = np.repeat(np.eye(4)[None], n, axis=0)
    rows = {"idtabletopgrips": np.arange(1, n + 1), "idtabletopplacements": np.array([1, 1, 2, 2, 3, 3]),
            "idfreeairgrip": np.array([7, 8, 7, 8, 7, 8]), "rotmat": eye, "placement_rotmat": eye,
            "tabletopposition": np.zeros((n, 3)), "jawwidth": np.full(n, 0.03)}
    feas = np.ones((n, 5), dtype=bool)
    feas[1, 3] = False          # worlda infeasible
    feas[4, 4] = False          # worlda + worldz infeasible
    rm = build_roadmap(rows, feas)
    assert sorted(rm.idtabletopgrips.tolist()) == [1, 3, 4, 6]


# ---------------------------------------------------------------------------------------------------------- stored rows and plans

SMALL = TabletopParams(x_min=0.4, x_max=0.6, nx=3, y_min=-0.15, y_max=0.15, ny=2, angles=4, max_grasps=12)


@pytest.fixture(scope="module")
def small_store(tmp_path_factory, bundled):
    from workbench.planners.wan_harada.stages import build_all

    db = tmp_path_factory.mktemp("faithful") / "small.duckdb"
    build_all(db, bundled["tube"], "panda", tparams=SMALL, workers=1, progress=False)
    return db


@pytest.fixture(scope="module")
def planner(small_store):
    from workbench.planners.wan_harada.stages import load_planner

    return load_planner(small_store, "tube", "panda")


def test_ik_rows_store_the_lift_feasibilities_and_the_roadmap_gates_on_them(small_store, planner):
    from workbench.store import Store
    from workbench.store import robots as rsql
    from workbench.store import wan_harada as sql

    ids = planner.ids
    with Store(small_store, read_only=True) as store:
        cols = {r[0] for r in store.run("SELECT column_name FROM information_schema.columns WHERE table_name = 'ik'")}
        assert {"feasibility_worlda", "feasibility_worldaworldz", "jnt_worlda", "jnt_worldaworldz"} <= cols
        ret = rsql.ikret_row(store, ids["idikret"])
        rows = sql.roadmap_rows(store, ids["idtabletop"], ids["idrobot"], ids["idscene"], ids["idikret"], planner.robot.nq)
    assert set(ret) == {"handx", "worldz", "worlda"} and ret["worlda"] > 0
    assert rows["feasible"].shape[1] == 5 and rows["joints"].shape[1] == 5
    assert planner.roadmap.n_nodes == rows["feasible"].all(axis=1).sum() > 0
    # the lifts are not implied by the other three: some grips fail only on them
    three = rows["feasible"][:, :3].all(axis=1)
    assert rows["feasible"].all(axis=1).sum() <= three.sum()


def _fk(store_path, planner):
    """TCP pose from joint vectors by pinocchio on the stored robot row."""
    from workbench.store import Store
    from workbench.store import robots as rsql

    with Store(store_path, read_only=True) as store:
        row = rsql.robot_row(store, planner.ids["idrobot"])
    model = pin.buildModelFromXML(row["urdf"])
    data = model.createData()
    fid = model.getFrameId(row["tip_frame"])
    idx = [model.joints[model.getJointId(n)].idx_q for n in row["joint_names"]]

    def fk(qv: np.ndarray) -> np.ndarray:
        q = pin.neutral(model)
        for name, value in row["locked"].items():
            q[model.joints[model.getJointId(name)].idx_q] = value
        q[idx] = qv
        pin.framesForwardKinematics(model, data, q)
        return row["base"] @ np.asarray(data.oMf[fid].homogeneous) @ row["mount"]
    return fk


def _plans(planner, n=40, seed=2):
    rng = np.random.default_rng(seed)
    ids = planner.placement_ids()
    for _ in range(n):
        start, goal = (PoseQuery(int(rng.choice(ids)), float(rng.uniform(0.4, 0.6)), float(rng.uniform(-0.15, 0.15)),
                                 float(rng.uniform(-np.pi, np.pi))) for _ in range(2))
        try:
            yield from planner.plan(start, goal, alternatives=2)
        except PlanningError:
            continue


def test_pick_lifts_straight_up_and_place_lowers_straight_down(small_store, planner):
    """While the part touches the table it moves only vertically: a pick closes, then lifts by worlda along world z
    (never backs off along the TCP's -z with the part); a place lowers along world z, opens, then backs off along -z.
    Checked on side grasps (approach axis within 45 degrees of horizontal), where the two differ."""
    fk = _fk(small_store, planner)
    worlda, worldz, handx = planner.worlda, planner.worldz, planner.handx
    side = 0
    for plan in _plans(planner):
        for step in plan.steps:
            wps = step.waypoints()
            names = [w.name for w in wps]
            holding = [w.holding for w in wps]
            if step.kind in ("pick", "regrasp"):
                assert names == ["handxworldz", "handx", "grasp", "grasp", "worlda", "worldaworldz"]
                assert holding == [False, False, False, True, True, True]       # closes at the grasp
            else:
                assert names == ["worldaworldz", "worlda", "grasp", "grasp", "handx", "handxworldz"]
                assert holding == [True, True, True, False, False, False]       # opens at the grasp
            if abs(step.tcp[2, 2]) > np.cos(np.radians(45)):
                continue
            side += 1
            grasp_obj = np.linalg.inv(step.grasp)
            poses = {w.name: fk(w.q) for w in wps}
            obj = {k: v @ grasp_obj for k, v in poses.items()}
            # the held part: at the grasp it is where it rests; at worlda it is straight above, by worlda
            assert np.allclose(obj["grasp"], step.object_pose, atol=2e-3)
            d = obj["worlda"][:3, 3] - obj["grasp"][:3, 3]
            assert np.linalg.norm(d[:2]) < 1e-3 and d[2] == pytest.approx(worlda, abs=1e-3)
            d = obj["worldaworldz"][:3, 3] - obj["grasp"][:3, 3]
            assert np.linalg.norm(d[:2]) < 1e-3 and d[2] == pytest.approx(worlda + worldz, abs=1e-3)
            assert np.allclose(obj["worlda"][:3, :3], obj["grasp"][:3, :3], atol=2e-3)
            # the empty hand backs off along its own -z, away from the resting part
            back = poses["grasp"][:3, 3] - handx * poses["grasp"][:3, 2]
            assert np.linalg.norm(poses["handx"][:3, 3] - back) < 1e-3
        if side >= 2:
            break
    assert side >= 2, "no side grasp in the plans of the small store"
