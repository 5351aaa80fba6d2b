"""Plans replayed in MuJoCo: the demo plan is confirmed, a grip without force or friction loses the part at the
first transfer (or
squeeze it out as they close), a placement on a rounded base that rolls is reported, the verdict is deterministic,
results round-trip through the store, and a part whose convex decomposition fails is refused in one line."""

from __future__ import annotations

import base64
import re
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from workbench.cli.main import main
from workbench.errors import PlanningError, SimulationError
from workbench.geometry.objects import from_arrays, load_object
from workbench.grasping.placements import PlacementParams, stable_placements
from workbench.planners.wan_harada.stages import DEMO_GRID, build_all, choose_task, load_plan, load_planner, save_plan
from workbench.resources import bundled_objects
from workbench.simulation.decomposition import convex_parts
from workbench.robots.collider import Scene
from workbench.simulation.replay import SimParams, pose_error, rest_on_table
from workbench.planners.wan_harada.motions import ExecOptions
from workbench.simulation.stages import physics_check, simulate_in_memory, simulate_stored
from workbench.store import Store
from workbench.store.simulation import load_simulation

pytest.importorskip("mujoco")
pytest.importorskip("coacd")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo's store and plan (`workbench demo`, seed 0)."""
    db = tmp_path_factory.mktemp("sim") / "regrasp.duckdb"
    build_all(db, load_object(bundled_objects()["tube"]), "panda", tparams=DEMO_GRID, workers=1, progress=False)
    with Store(db) as store:
        planner = load_planner(store, "tube", "panda")
        start, goal = choose_task(planner, 0)
        plan = planner.plan(start, goal, alternatives=0)[0]
        idplan = save_plan(store, plan)
    return db, idplan, plan


def test_the_demo_plan_is_confirmed_and_stored(demo):
    db, idplan, plan = demo
    with Store(db) as store:
        out = simulate_stored(store, idplan)
        row, steps = load_simulation(store, out.idsimulation)
        again = simulate_stored(store, idplan)
    assert out.confirmed and not out.reused, out.message
    assert out.final_error <= 0.005 and out.final_angle <= np.radians(5)
    assert again.reused and again.idsimulation == out.idsimulation  # the same plan and parameters: not simulated again
    assert bool(row["confirmed"]) and row["failure"] is None
    # one row per motion; the last simulated pose, recomputed here against the plan's goal, matches the stored error
    assert len(steps["seq"]) == len(plan.segments)
    final = np.asarray(row["playback_pose"][-1], dtype=np.float64).reshape(4, 4)
    com = load_object(bundled_objects()["tube"]).mesh.center_mass
    e_t, _ = pose_error(final, plan.goal_pose, com)
    assert abs(e_t - row["final_error"]) < 1e-9
    # the part was never teleported: its playback starts at the start pose and moves under 1.5 m/s between samples
    poses = np.asarray(row["playback_pose"], dtype=np.float64).reshape(-1, 4, 4)
    assert np.allclose(poses[0], plan.start_pose)
    assert np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).max() < 1.5 / 30
    # the stored plan read back is the plan simulated
    with Store(db) as store:
        back = load_plan(store, idplan)
    assert np.allclose(back.segments[-1].traj.q, plan.segments[-1].traj.q) and back.duration == pytest.approx(plan.duration)


@pytest.mark.parametrize("change", [{"grip_force": 0.01}, {"friction": 0.001}])
def test_a_grip_without_force_or_friction_loses_the_part_at_the_first_transfer(demo, change):
    db, idplan, plan = demo
    with Store(db) as store:
        out = simulate_stored(store, idplan, SimParams(**change))
    assert not out.confirmed
    # without friction the closing pads squeeze the part out of the hand (their normals are never exactly opposed)
    assert out.failure in ("drop", "slip", "shove"), out.message
    assert out.failure_step == 0 and "step 1 (pick" in out.message  # the pick and its carry, before the first release


def test_the_same_parameters_give_the_same_verdict(demo):
    db, idplan, _ = demo
    with Store(db) as store:
        a = simulate_stored(store, idplan, SimParams(grip_force=20.0), save=False)
        b = simulate_stored(store, idplan, SimParams(grip_force=20.0), save=False)
    assert a.confirmed == b.confirmed and a.failure == b.failure and a.final_error == b.final_error
    assert np.array_equal(a.result.steps["simulated"], b.result.steps["simulated"])
    assert np.array_equal(a.result.playback_pose, b.result.playback_pose)


def test_a_failing_decomposition_is_refused_in_one_line_naming_the_mesh(tmp_path):
    flat = trimesh.creation.box(extents=(0.05, 0.05, 0.02))
    flat.vertices[:, 2] = 0.0  # a box pressed flat: no volume to decompose
    with pytest.raises(SimulationError, match="convex decomposition of mesh 'pressed'") as err:
        convex_parts(flat, "flatdigest", "pressed", folder=tmp_path)
    assert "\n" not in str(err.value)
    assert not list(tmp_path.iterdir())  # nothing cached


def test_simulate_refuses_an_unknown_plan_in_one_line(demo, capsys):
    db, _, _ = demo
    with Store(db) as store:
        before = store.one("SELECT count(*) FROM simulation")[0]
    assert main(["simulate", "--db", str(db), "--plan", "999"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "no plan 999" in err
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM simulation")[0] == before


def _duck() -> trimesh.Trimesh:
    """A duck-like part: a rounded ellipsoid body with a head forward and up (its centre of mass off the body's)."""
    body = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    body.apply_scale((0.045, 0.032, 0.028))
    head = trimesh.creation.icosphere(subdivisions=3, radius=0.018)
    head.apply_translation((0.032, 0.0, 0.030))
    return trimesh.boolean.union([body, head], engine="manifold")


def test_a_part_far_from_its_mesh_origin_falls_as_the_same_part_at_the_origin():
    """A CAD part exported in assembly coordinates, 5 m from its mesh's origin, dropped tilted onto the table: it
    tips over and comes to rest exactly as the same box with its origin inside it (the free body turns about its
    centre of mass, not about a point metres away, where each step's small turn became a large unstable move)."""
    from scipy.spatial.transform import Rotation

    rest = {}
    for far in (False, True):
        shift = np.array([5.0, -3.0, 2.0]) if far else np.zeros(3)
        box = trimesh.creation.box((0.04, 0.03, 0.02)).apply_translation(shift)
        at = np.eye(4)
        at[:3, :3] = Rotation.from_euler("xy", [25, 10], degrees=True).as_matrix()
        at[:3, 3] = np.array([0.5, 0.0, 0.03]) - at[:3, :3] @ shift
        what, final = rest_on_table(box, [(box.vertices, box.faces)], at, Scene())
        rest[far] = (what, final[:3, :3] @ shift + final[:3, 3], final[:3, :3])
    assert rest[False][0] is not None and "rolled" in rest[False][0]  # it tips from 25 degrees onto a face
    assert rest[True][0] == rest[False][0]
    assert np.allclose(rest[True][1], rest[False][1], atol=1e-7) and np.allclose(rest[True][2], rest[False][2], atol=1e-7)
    assert abs(rest[True][1][2] - 0.01) < 1e-4  # on its 20 mm side, centre 10 mm above the table


def test_a_placement_on_the_rounded_base_that_rolls_is_reported():
    sys.path.insert(0, str(Path(__file__).parents[1] / "grasping"))
    from physics import drop_test  # the placement tests' own MuJoCo drop test, written without our scene

    duck = from_arrays(_duck().vertices, _duck().faces, scale=1.0, name="duck", source="duck")
    placements = stable_placements(duck, PlacementParams(min_stability=0.02))  # accepted by the stability score
    hulls = convex_parts(duck.mesh, duck.digest, "duck")
    verdicts = []
    for pose in placements.poses:
        at = pose.copy()
        at[:2, 3] += (0.5, 0.0)
        what, final = rest_on_table(duck.mesh, hulls, at, Scene())
        moved = np.degrees(pose_error(final, at, duck.mesh.center_mass)[1])
        verdicts.append((what, moved, drop_test(duck.mesh, pose, seconds=1.0)[0]))
    rolled = [v for v in verdicts if v[0] is not None]
    assert rolled, "some accepted placement on the rounded base rolls"
    assert all("settle" in w or "rolled" in w for w, _, _ in rolled)
    # the reported ones turned beyond the tolerance, the others stayed; an independent drop test (the mesh's hull,
    # an unlevel table) sees the reported ones turn too
    assert all(moved > 5 for _, moved, _ in rolled) and all(moved < 5 for w, moved, _ in verdicts if w is None)
    assert all(drop > 5 for _, _, drop in rolled)


def test_require_physics_removes_the_failing_step_and_searches_again(demo):
    """A plan that drops the part counts as a failed motion: the node or grip of the failing step is removed and the
    graph searched again, until --max-removed."""
    db, _, plan = demo
    with Store(db) as store:
        planner = load_planner(store, "tube", "panda")
        check = physics_check(store, planner.robot, SimParams(grip_force=0.01))
        with pytest.raises(PlanningError, match="after removing 1 node.*1 of them after failing in simulation") as err:
            planner.plan(plan.start, plan.goal, alternatives=0, exec_opts=ExecOptions(max_removed=1), physics=check)
    assert err.value.reason == "exhausted"
    assert any(f"physics: {kind}: step 1 (pick" in str(err.value) for kind in ("drop", "slip", "shove")), str(err.value)


def _table_hits(urdf: str, dirs, joint_names, q: np.ndarray, scene: Scene) -> set[str]:
    """Links of the full URDF (pinocchio FK, coal) whose collision geometry cuts into the table slab at joint
    vector `q`: written here without the workbench's robot model, collider or scene."""
    import coal
    import pinocchio as pin

    full = pin.buildModelFromXML(urdf)
    geom = pin.buildGeomFromUrdfString(full, urdf, pin.COLLISION, package_dirs=list(dirs))
    data, gdata = full.createData(), geom.createData()
    x = pin.neutral(full)
    for name, v in zip(joint_names, q):
        x[full.joints[full.getJointId(name)].idx_q] = v
    pin.updateGeometryPlacements(full, data, geom, gdata, x)
    lo, hi, th = np.asarray(scene.table_min), np.asarray(scene.table_max), scene.table_thickness
    table = coal.Box(*(hi - lo), th)
    at = coal.Transform3s(np.eye(3), np.array([*(0.5 * (lo + hi)), -th / 2]))
    out = set()
    for k, go in enumerate(geom.geometryObjects):
        m = gdata.oMg[k]
        if coal.collide(go.geometry, coal.Transform3s(m.rotation, m.translation), table, at, coal.CollisionRequest(),
                        coal.CollisionResult()):
            out.add(full.frames[go.parentFrame].name)
    return out


def test_an_arm_driven_into_the_table_is_a_collision_where_fk_and_coal_find_it(demo):
    """The demo plan with its regrasp transit bent down through the table (shoulder and elbow 1.1 rad further): the
    simulation reports a collision at that step, at the time and with the link that FK + coal find first along the
    commanded motion; the plan as planned has no robot contact with the table, the part or itself at all."""
    import copy
    import dataclasses

    from workbench.robots.timing import time_stops

    db, _, plan = demo
    with Store(db) as store:
        robot = load_planner(store, "tube", "panda").robot
        clean = simulate_in_memory(store, plan, robot, SimParams(collision_depth=1e-6))
        k = next(i for i, s in enumerate(plan.segments) if s.kind == "transit" and not s.holding)
        seg = plan.segments[k]
        qa, qb = seg.traj.q[0], seg.traj.q[-1]
        low = qa.copy()
        low[1] += 1.1
        low[3] = min(low[3] + 1.1, robot.upper[3])
        bent = time_stops(np.array([qa, low, qb]), np.full(robot.nq, 1.0), np.full(robot.nq, 3.0))
        bad = copy.deepcopy(plan)
        bad.segments[k] = dataclasses.replace(seg, traj=bent)
        for s in bad.segments[k + 1:]:
            s.t0 += bent.duration - seg.duration
        out = simulate_in_memory(store, bad, robot, SimParams())
    assert clean.confirmed and not any(f.kind == "collision" for f in clean.failures), clean.failures
    f = out.failure
    assert not out.confirmed and f.kind == "collision" and f.step == seg.step, out.failures
    # independently: the first time along the commanded bent motion that a moving link cuts into the table
    spec, scene = robot.spec, Scene()
    ts = np.arange(0.0, bent.duration, 0.005)
    first = next((t, hits) for t, q in zip(ts, bent.sample(ts)[0])
                 if (hits := _table_hits(spec.urdf, robot.package_dirs, robot.joint_names, q, scene) - {"panda_link0"}))
    assert abs(f.t - (seg.t0 + first[0])) < 0.05, (f.t, seg.t0 + first[0])
    urdf_name = {"gripper_hand": "panda_hand", "gripper_fingers": "panda_leftfinger"}
    assert f.links and {urdf_name.get(x, x) for x in f.links} <= first[1] | {"panda_rightfinger"}, (f.links, first)
    assert "the table" in f.message and "\n" not in f.message


def _table_rows(db) -> dict[str, int]:
    with Store(db) as store:
        names = [r[0] for r in store.run("SELECT table_name FROM information_schema.tables ORDER BY table_name")]
        return {n: store.one(f'SELECT count(*) FROM "{n}"')[0] for n in names}


def test_a_decomposition_that_fails_leaves_the_store_as_it_was(demo, capsys, tmp_path, monkeypatch):
    """Through the command line against the demo's store: CoACD aborts on the tube remeshed at resolution 2; the
    command prints one line naming the mesh, exits 2, and no table of the store gains or loses a row."""
    db, idplan, _ = demo
    monkeypatch.setenv("WORKBENCH_CACHE", str(tmp_path / "cache"))
    before = _table_rows(db)
    assert main(["simulate", "--db", str(db), "--plan", str(idplan), "--hull-resolution", "2"]) == 2
    out, err = capsys.readouterr()
    assert err.strip().count("\n") == 0 and "convex decomposition of mesh 'tube' failed" in err, err
    assert "Traceback" not in out + err and "stored in" not in out
    assert _table_rows(db) == before
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").rglob("*.npz"))


def test_plan_simulate_and_require_physics_from_the_command_line(demo, capsys, tmp_path):
    """`plan --simulate` stores the verdict of the best plan and plays the simulated part in the HTML; with
    `--require-physics` and no grip force every plan drops the part, so nodes are removed and none is left."""
    from workbench.grasping.naming import per_part_numbers

    db, idplan, plan = demo
    with Store(db) as store:
        numbers = per_part_numbers(load_planner(store, "tube", "panda").free["idfreetabletopplacement"])

    def query(q) -> str:
        return f"{numbers[q.idfreetabletopplacement]},{q.x!r},{q.y!r},{float(np.degrees(q.yaw))!r}"

    task = ["plan", "--db", str(db), "--object", "tube", "--robot", "panda", "--start", query(plan.start),
            "--goal", query(plan.goal), "--alternatives", "0"]
    html = tmp_path / "plan.html"
    assert main([*task, "--simulate", "--html", str(html)]) == 0
    out = capsys.readouterr().out
    assert f"plan {idplan}: confirmed" in out, out
    with Store(db) as store:
        assert store.one("SELECT count(*) FROM simulation WHERE idplan = ? AND confirmed", [idplan])[0] >= 1
    # the meshcat commands are embedded base64: the simulated part is among the animated objects
    blobs = re.findall(r"base64,([A-Za-z0-9+/=]+)", html.read_text())
    assert any(b"/simulated" in base64.b64decode(b) for b in blobs)
    assert main([*task, "--require-physics", "--grip-force", "0.01", "--max-removed", "1", "--no-save"]) == 0
    out = capsys.readouterr()
    assert "0 plans (exhausted)" in out.out and "physics:" in out.err + out.out, out


def test_links_far_from_convex_take_no_part_in_self_collision():
    """MuJoCo collides meshes as hulls: the UR5's forearm hull touches the hand where the meshes keep 2 mm apart, so
    bent links (hull volume > 1.1 x mesh volume, measured here with trimesh) leave the self-collision pairs; the
    Panda's convex links keep theirs, and every robot link still collides with the table."""
    from workbench.geometry.collision import pinocchio_geometry
    from workbench.robots.model import get_robot
    from workbench.robots.selfcollision import allowed_pairs
    from workbench.simulation.scene import build_scene

    box = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    for name in ("panda", "ur5"):
        robot = get_robot(name)
        bent = set()
        for k in robot.arm_geometry():
            go = robot.geom.geometryObjects[k]
            _, mesh = pinocchio_geometry(go)
            if mesh.convex_hull.volume > 1.1 * mesh.volume:
                bent.add(robot.model.frames[go.parentFrame].name)
        ss = build_scene(robot, robot.gripper, Scene(), box, [(box.vertices, box.faces)], 1000.0, 70.0, 0.3, 0.3, 0.002,
                         self_pairs=allowed_pairs(robot).checked)
        in_pairs = {ss.robot_geoms[g] for pair in ss.self_pairs for g in pair}
        assert (name == "ur5") == bool(bent), bent
        assert not bent & in_pairs and in_pairs, (bent, in_pairs)
        m = ss.model
        arm = [g for g in ss.robot_geoms if g not in ss.gripper_geoms]
        assert all(m.geom_contype[ss.table_geom] & m.geom_conaffinity[g] for g in arm)


def _xor_volume(mesh: trimesh.Trimesh, turn: np.ndarray, centre: np.ndarray) -> float:
    """Volume (m^3) of the mesh and the mesh turned by `turn` about `centre` that is not shared, by manifold3d's
    booleans (not our symmetry code)."""
    moved = mesh.copy()
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = turn, centre - turn @ centre
    moved.apply_transform(t)
    both = trimesh.boolean.intersection([mesh, moved], engine="manifold")
    return float(mesh.volume + moved.volume - 2 * both.volume)


def test_the_goal_check_counts_poses_the_same_up_to_the_parts_symmetry(demo):
    """The T-shaped tube maps onto itself by a half turn about its branch (and by nothing else): manifold3d's
    booleans agree. The demo plan with its goal turned by that half turn is still confirmed; a 10 degree turn about
    the run's axis (the branch then tilts) or a half turn about the run is not a symmetry and still counts. A
    cylinder is a body of revolution: any turn about its axis, or end for end, is no error; a tilt is."""
    import copy

    from workbench.geometry.symmetry import part_symmetry, rotation

    db, _, plan = demo
    tube = load_object(bundled_objects()["tube"]).mesh
    sym = part_symmetry(tube)
    c = sym.centre
    half_z, tilt_y, half_y = rotation([0, 0, 1], np.pi), rotation([0, 1, 0], np.radians(10)), rotation([0, 1, 0], np.pi)
    assert sym.axis is None and len(sym.turns) == 2 and np.allclose(sym.turns[1], half_z, atol=1e-6)
    assert _xor_volume(tube, half_z, c) < 1e-3 * tube.volume
    assert min(_xor_volume(tube, r, c) for r in (tilt_y, half_y)) > 0.05 * tube.volume

    def turned(pose, r):
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = r, c - r @ c
        return pose @ t

    goal = np.asarray(plan.goal_pose, dtype=np.float64)
    for r, expect in ((half_z, 0.0), (tilt_y, 10.0), (half_y, 180.0)):
        e_t, e_r = pose_error(turned(goal, r), goal, c, sym)
        assert e_t < 1e-9 and abs(np.degrees(e_r) - expect) < 1e-4, (expect, np.degrees(e_r))
    with Store(db) as store:
        robot = load_planner(store, "tube", "panda").robot
        other = copy.deepcopy(plan)
        other.goal_pose = turned(goal, half_z)
        out = simulate_in_memory(store, other, robot, SimParams())
    assert out.confirmed and out.final_angle <= np.radians(5), out.failures

    cyl = trimesh.creation.cylinder(radius=0.02, height=0.07, sections=48)
    s = part_symmetry(cyl)
    assert s.axis is not None and abs(abs(s.axis[2]) - 1) < 1e-9 and len(s.turns) == 2  # about z, and end for end
    for r, expect in ((rotation([0, 0, 1], 0.3), 0.0), (rotation([1, 0, 0], np.pi), 0.0),
                      (rotation([1, 0, 0], 0.2) @ rotation([0, 0, 1], 1.0), np.degrees(0.2))):
        assert abs(np.degrees(s.angle(r, np.eye(3))) - expect) < 1e-4, (expect, np.degrees(s.angle(r, np.eye(3))))
    assert _xor_volume(cyl, rotation([0, 0, 1], 0.3), s.centre) < 1e-2 * cyl.volume  # its 48 facets aside
    assert _xor_volume(cyl, rotation([1, 0, 0], 0.2), s.centre) > 0.05 * cyl.volume


def test_a_part_placed_beside_the_table_drops_to_the_floor_at_once(demo):
    """The demo plan on a table that ends beside the start: the part set down at the goal, past the table's edge,
    falls onto the floor; the replay reports a drop at the place step as it lands, a free fall of 0.75 m after the
    fingers open (sqrt(2 h / g), at least), and stops there."""
    from workbench.robots.collider import Scene
    from workbench.simulation.replay import simulate
    from workbench.simulation.scene import FLOOR_Z
    from workbench.simulation.stages import self_pairs
    from workbench.store import simulation as sql

    db, idplan, plan = demo
    obj = load_object(bundled_objects()["tube"])
    sx, sy = plan.start_pose[:2, 3]
    small = Scene(table_min=(sx - 0.08, sy - 0.08), table_max=(sx + 0.08, sy + 0.08))
    assert (np.abs(plan.goal_pose[:2, 3] - (sx, sy)) > 0.08).any()  # the goal is off that table
    with Store(db) as store:
        inputs = sql.plan_inputs(store, idplan)
        robot = load_planner(store, "tube", "panda").robot
        res = simulate(plan, robot, obj.mesh, small, inputs["friction"], convex_parts(obj.mesh, obj.digest, obj.name),
                       SimParams(), self_pairs(store, inputs["idrobot"], robot))
    f = res.failure
    assert f.kind == "drop" and plan.steps[f.step].kind == "place" and "floor" in f.message, res.failures
    release = [s for s in plan.segments if s.kind == "gripper" and not s.holding and s.t0 < f.t][-1]
    fall = np.sqrt(2 * -FLOOR_Z / 9.81)
    assert fall <= f.t - release.t0 <= release.duration + fall + 0.1, (f.t, release.t0)
    assert res.simulated == pytest.approx(f.t, abs=0.003) and res.playback_t[-1] == pytest.approx(f.t, abs=0.003)
    low = (res.playback_pose[-1][:3, :3] @ obj.mesh.vertices.T).T[:, 2] + res.playback_pose[-1][2, 3]
    # it lies on the floor: the replay stops at the step whose contacts first reach it, a step's fall (about 3.8
    # m/s for 2 ms) past the first touch at most
    assert abs(low.min() - FLOOR_Z) < np.sqrt(2 * 9.81 * -FLOOR_Z) * SimParams().timestep + 1e-3


def test_a_urdf_link_inertia_that_is_no_rigid_bodys_is_made_one_that_mujoco_takes():
    """A URDF may give a link principal moments with A + B < C, which no rigid body has and MuJoCo refuses; the scene
    raises the two smaller moments just enough, about the same principal axes, and MuJoCo compiles the body."""
    import mujoco

    from workbench.simulation.scene import physical_inertia

    turn = Rotation.from_euler("xyz", [0.3, -0.5, 1.1]).as_matrix()
    bad = turn @ np.diag([0.001, 0.002, 0.005]) @ turn.T  # 0.001 + 0.002 < 0.005

    def compiles(inertia: np.ndarray) -> bool:
        spec = mujoco.MjSpec()
        body = spec.worldbody.add_body(name="link")
        body.explicitinertial = True
        body.mass = 1.0
        body.fullinertia = [inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2], inertia[1, 2]]
        body.add_joint(type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1])
        try:
            spec.compile()
        except ValueError:
            return False
        return True

    assert not compiles(bad)
    fixed, changed = physical_inertia(bad, 1.0)
    assert changed and compiles(fixed)
    e, v = np.linalg.eigh(fixed)
    assert e[0] + e[1] >= e[2] and e[2] == pytest.approx(0.005)
    assert np.allclose(np.abs(v.T @ turn), np.eye(3), atol=1e-9)  # the same principal axes, in the same order
    good = turn @ np.diag([0.002, 0.003, 0.004]) @ turn.T
    same, changed = physical_inertia(good, 1.0)
    assert not changed and np.allclose(same, good)
