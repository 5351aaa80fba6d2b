"""Zero is a result, never a crash (issue 10): every command on a part no parallel jaw can grasp exits 0 with a
warning that names the stage that removed the last candidate, and every stage stores its zero rows."""

from __future__ import annotations

import json
import re
import subprocess

import duckdb
import numpy as np
import pytest
import trimesh

from workbench.benchmarks.organic import blob
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps


_SERVER: list = []


@pytest.fixture(scope="module", autouse=True)
def _server(cli_server):
    _SERVER.append(cli_server)
    yield
    _SERVER.clear()


def _cli(*args: str, cwd) -> subprocess.CompletedProcess:
    """`workbench ARGS` in its own process (forked from the session's command server)."""
    return _SERVER[0].run(list(args), cwd)


@pytest.fixture(scope="module")
def big_cube(tmp_path_factory):
    """A 150 mm cube: wider than the Franka hand's 80 mm opening in every direction."""
    folder = tmp_path_factory.mktemp("zero")
    trimesh.creation.box((0.15, 0.15, 0.15)).subdivide_to_size(0.03).export(folder / "bigcube.stl")
    return folder


def test_every_command_on_an_ungraspable_part_exits_0_and_names_the_stage(big_cube):
    run = lambda *a: _cli(*a, cwd=big_cube)  # noqa: E731
    grid = ["--x=0.4,0.6,2", "--y=-0.1,0.1,2", "--angles", "2"]
    out = run("grasps", "bigcube.stl", "--db", "z.duckdb")
    assert out.returncode == 0, out.stderr
    assert "stored 0 free-air grasps" in out.stdout
    assert "pads_width: every contact pair is wider than the gripper's 80 mm opening" in out.stderr
    again = run("grasps", "bigcube.stl", "--db", "z.duckdb")  # reused zero rows: the same warning
    assert again.returncode == 0 and "reused 0 free-air grasps" in again.stdout and "pads_width" in again.stderr
    steps = [("placements", "--db", "z.duckdb", "--object", "bigcube", *grid),
             ("ik", "--db", "z.duckdb", "--object", "bigcube", "--robot", "panda", "--workers", "1", "--no-progress"),
             ("plan", "--db", "z.duckdb", "--object", "bigcube", "--robot", "panda", "--start", "1,0.45,-0.1,0",
              "--goal", "2,0.55,0.1,1.57"),
             ("build", "bigcube.stl", "--db", "b.duckdb", "--robot", "panda", "--workers", "1", *grid)]
    for args in steps:
        out = run(*args)
        assert out.returncode == 0, (args[0], out.stderr)
        assert "Traceback" not in out.stderr
        warning = [line for line in out.stderr.splitlines() if line.startswith("warning:")]
        assert len(warning) == 1 and ("stage grasps" in warning[0] or "stage pads_width" in warning[0]), (args[0], out.stderr)
    # the five-finger planner is not limited by the jaw: it runs and exits 0 as well
    out = run("fingers", "bigcube.stl", "--db", "f.duckdb", "--faces", "120", "--clusters", "8", "--samples", "20",
              "--picks", "2", "--queries", "2")
    assert out.returncode == 0, out.stderr
    assert re.search(r"^ +2/2 ", out.stdout.split("Table III")[1], re.M), out.stdout  # both queries connected


def test_each_grasp_filter_is_named_when_it_removes_the_last_candidate(hand):
    """Force each stage in turn to be the one that empties the set, and check the message names it."""
    box = from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")
    ball = from_trimesh(blob(seed=4, rows=12, cols=14, radius=0.028), "ball")
    cases = [("facet_samples_distance", box, GraspParams(dist_min=0.0, dist_max=1e-9, lengths="fixed")),
             ("pads_left", ball, GraspParams(friction=1e-6)),  # a bumpy ball: no normal exactly on its jaw axis
             ("pads_com", box, GraspParams(com_max=1e-6, lengths="fixed"))]
    for stage, obj, params in cases:
        plan = plan_grasps(obj, hand, params)
        assert len(plan.grasps) == 0 and plan.empty_reason.startswith(stage), (stage, plan.counts, plan.empty_reason)
    ok = plan_grasps(box, hand, GraspParams())
    assert len(ok.grasps) > 0 and ok.empty_reason is None


def test_a_part_thinner_than_the_closed_jaw_is_named_narrower_not_wider(tmp_path):
    """A 10 mm rod and a gripper that closes only to 30 mm: the message says the part is narrower than the smallest
    opening, with its widest contact pair, not that it is wider than the full opening."""
    import yaml

    from workbench.robots.gripper import load_gripper

    spec = tmp_path / "narrow.yaml"
    spec.write_text(yaml.safe_dump({"name": "closes-to-30", "stroke": [0.03, 0.12], "tcp": [0.0, 0.0, 0.15],
                                    "pad": {"size": [0.022, 0.038], "thickness": 0.007},
                                    "finger": {"size": [0.022, 0.012, 0.07]},
                                    "palm": {"size": [0.1, 0.2, 0.1], "offset": [0.0, 0.0, 0.05]}}))
    rod = from_trimesh(trimesh.creation.box((0.2, 0.01, 0.01)), "rod")
    plan = plan_grasps(rod, load_gripper(str(spec)), GraspParams())
    assert len(plan.grasps) == 0
    assert plan.empty_reason.startswith("pads_width: every contact pair is narrower than the gripper's 30 mm smallest "
                                        "opening (the widest is 10 mm)"), plan.empty_reason


def test_a_card_lying_flat_is_named_too_thin_to_grip(tmp_path):
    """A 0.8 mm card has grasps in free air but none that reaches it on the table: `build` exits 0, stores its
    placements and says the part is too thin, with its height. Built with an 80 mm retraction (`--handx 0.08`), its
    grasps are swept 80 mm back along the approach (the grasp stage's stored parameters say so)."""
    trimesh.creation.box((0.05, 0.04, 0.0008)).export(tmp_path / "card.stl")
    out = _cli("build", "card.stl", "--db", "c.duckdb", "--robot", "panda", "--workers", "1", "--x=0.4,0.6,2",
               "--y=-0.1,0.1,2", "--angles", "2", "--handx", "0.08", cwd=tmp_path)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert "2 stable placements" in out.stdout
    assert "stage free tabletop grips" in out.stderr and "card stands at most 0.8 mm above the table" in out.stderr
    con = duckdb.connect(str(tmp_path / "c.duckdb"), read_only=True)
    stored = [json.loads(r[0]) for r in con.execute("SELECT params FROM paramset WHERE stage = 'grasps'").fetchall()]
    handx = [r[0] for r in con.execute("SELECT handx FROM ikret").fetchall()]
    grasps = [np.array(r[0]).reshape(4, 4) for r in con.execute("SELECT rotmat FROM freeairgrip").fetchall()]
    places = [np.array(r[0]).reshape(4, 4) for r in con.execute("SELECT rotmat FROM freetabletopplacement").fetchall()]
    con.close()
    assert [p["approach_length"] for p in stored] == [0.08] and handx == [0.08], (stored, handx)
    # how far the best grasp reaches into the table, and that no --clearance helps, as the hand's mesh placed here
    # by each stored placement and grasp gives it
    from workbench.robots.gripper import franka_hand

    hand = franka_hand().collision_mesh()
    lowest = max(float(hand.copy().apply_transform(p @ g).bounds[0, 2]) for p in places for g in grasps)
    said = re.search(r"the best grasp puts the hand ([0-9.]+) mm into the table, so no --clearance keeps one", out.stderr)
    assert said and lowest < 0 and abs(float(said.group(1)) + lowest * 1e3) < 0.01 * abs(lowest * 1e3), out.stderr


def test_a_longer_approach_sweep_meets_what_lies_further_back(hand):
    """The hand's sweep along the approach (`approach_collides`) covers `length` behind its body: a plate 65 mm behind
    the hand body's back face (found here from the body's vertices) is met by an 80 mm sweep, not by a 50 mm one."""
    from workbench.grasping.grasps import approach_collides

    back = float(hand.body.vertices[:, 2].min())  # the body's far end along -z, behind the TCP
    plate = trimesh.creation.box((0.05, 0.05, 0.004))
    plate.apply_translation((0.0, 0.0, back - 0.065))
    hits = [bool(approach_collides(hand, np.eye(4)[None], np.array([hand.jaw_max]), plate, length, 0.0)[0])
            for length in (0.05, 0.08)]
    assert hits == [False, True]


def test_a_cone_names_the_friction_its_most_opposed_pads_need(hand):
    """A cone's sides are tilted by its half-angle atan(r / h) from the jaw: with less friction there is no grasp,
    and the message's lower bound on the friction needed is tan(half-angle), computed here from r and h."""
    obj = from_trimesh(trimesh.creation.cone(0.03, 0.08, sections=48), "cone")
    plan = plan_grasps(obj, hand, GraspParams(friction=0.3))
    assert len(plan.grasps) == 0 and plan.empty_reason.startswith("pads_cone"), plan.empty_reason
    need = float(re.search(r"needs at least ([0-9.]+)", plan.empty_reason).group(1))
    assert abs(need - 0.03 / 0.08) <= 0.01, plan.empty_reason
    assert len(plan_grasps(obj, hand, GraspParams(friction=0.45)).grasps) > 0


def test_a_ball_without_stable_placement_is_told_the_threshold_that_keeps_one(tmp_path):
    """A ball's convex hull is small triangles, each a support too small for --min-stability 0.1: `placements`
    exits 0 naming the steadiest support's score and a lower threshold, and that threshold keeps what it says."""
    trimesh.creation.icosphere(2, 0.025).export(tmp_path / "ball.stl")
    grid = ["--x=0.4,0.6,2", "--y=-0.1,0.1,2", "--angles", "2"]
    assert _cli("grasps", "ball.stl", "--db", "b.duckdb", cwd=tmp_path).returncode == 0
    out = _cli("placements", "--db", "b.duckdb", "--object", "ball", *grid, cwd=tmp_path)
    assert out.returncode == 0 and "ball: 0 stable placements" in out.stdout, out.stderr
    m = re.search(r"steadiest support of ball scores ([0-9.]+) .*--min-stability ([0-9.]+) keeps (\d+)", out.stderr)
    assert m, out.stderr
    best, lower, kept = float(m.group(1)), float(m.group(2)), int(m.group(3))
    # independently: an icosphere's faces are near-equal triangles; the centre of mass projects on the face's centre,
    # whose distance to the edges (the inradius) over the radius to the face plane is the stability
    ball = trimesh.creation.icosphere(2, 0.025)
    tri = ball.triangles
    a, b, c = (np.linalg.norm(tri[:, i] - tri[:, (i + 1) % 3], axis=1) for i in range(3))
    inradius = 2 * ball.area_faces / (a + b + c)
    height = np.abs(np.einsum("ij,ij->i", ball.face_normals, tri[:, 0]))
    assert abs(best - (inradius / height).max()) <= 0.05 * best
    assert lower < best
    again = _cli("placements", "--db", "b.duckdb", "--object", "ball", "--min-stability", str(lower), *grid, cwd=tmp_path)
    assert again.returncode == 0 and f"ball: {kept} stable placements" in again.stdout, again.stdout + again.stderr


def test_a_disc_cannot_be_flipped_and_plan_says_no_robot_could(tmp_path):
    """A disc lying on one face or the other: every grasp that clears the table in one has its approach from below
    in the other, so no chain of placements links them. `plan` exits 0 with 0 plans and says so; the placements'
    link is cross-checked on the store's rows by a search written here."""
    trimesh.creation.cylinder(radius=0.03, height=0.012, sections=64).export(tmp_path / "disc.stl")
    grid = ["--x=0.45,0.55,2", "--y=-0.1,0.1,2", "--angles", "2"]
    out = _cli("build", "disc.stl", "--db", "d.duckdb", "--robot", "panda", "--workers", "1", *grid, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    con = duckdb.connect(str(tmp_path / "d.duckdb"), read_only=True)
    rows = con.sql("SELECT idfreetabletopplacement, idfreeairgrip FROM freetabletopgrip").fetchall()
    places = sorted({int(r[0]) for r in con.sql("SELECT idfreetabletopplacement FROM freetabletopplacement").fetchall()})
    con.close()
    assert len(places) == 2
    grasps_of = {p: {g for q, g in rows if q == p} for p in places}
    assert all(grasps_of.values()) and not grasps_of[places[0]] & grasps_of[places[1]]
    res = _cli("plan", "--db", "d.duckdb", "--object", "disc", "--robot", "panda", "--start", f"{places[0]},0.45,0.1,0",
               "--goal", f"{places[1]},0.55,-0.1,90", "--json", "p.json", cwd=tmp_path)
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr
    assert "disc with panda: 0 plans (unconnected)" in res.stdout
    warning = [line for line in res.stderr.splitlines() if line.startswith("warning:")]
    assert len(warning) == 1 and "no robot could" in warning[0] and "90 deg" in warning[0], res.stderr
    data = json.loads((tmp_path / "p.json").read_text())
    assert data["plan"] is None and data["reason"] == "unconnected"
    con = duckdb.connect(str(tmp_path / "d.duckdb"), read_only=True)
    assert con.execute("SELECT count(*) FROM plan").fetchall()[0][0] == 0
    con.close()


def test_the_friction_hint_is_a_friction_that_passes_within_the_declared_range(hand):
    """The cone's empty friction stage names a --friction within its declared range that passes the cone test for
    the jaw axes tried (planned again with it, some contacts pass), beside the bound no jaw axis beats."""
    from workbench.params import bounds

    bound = bounds(GraspParams)["friction"][0]
    obj = from_trimesh(trimesh.creation.cone(0.03, 0.08, sections=48), "cone")
    reason = plan_grasps(obj, hand, GraspParams(friction=0.3)).empty_reason
    assert f"({bound.describe(True)})" in reason, reason
    tried = float(re.search(r"--friction ([0-9.]+) passes the cone", reason).group(1))
    least = float(re.search(r"needs at least ([0-9.]+)", reason).group(1))
    assert bound.problem(tried) is None and 0.3 < least <= tried
    again = plan_grasps(obj, hand, GraspParams(friction=tried))
    assert again.counts["pads_cone"] > 0 and len(again.grasps) > 0


def test_a_friction_beyond_the_declared_range_is_named_as_none_would_do():
    """Contacts whose normals point the same way (no jaw axis has them opposed): no friction in --friction's range
    passes, and the hint says so rather than asking to raise it."""
    from workbench.grasping.grasps import ContactPairs, friction_hint
    from workbench.params import bounds

    n = np.tile([[0.0, 1.0, 0.0]], (3, 1)) + np.array([[0.0, 0.0, 0.05], [0.05, 0.0, 0.0], [0.0, 0.0, -0.05]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ok = np.ones(3, dtype=bool)
    pairs = ContactPairs(sample=np.arange(3), facet0=np.zeros(3, int), facet1=np.zeros(3, int), point0=np.zeros((3, 3)),
                         point1=np.zeros((3, 3)), normal0=n, normal1=n, width=np.full(3, 0.03), width_ok=ok,
                         com_ok=ok, level1_ok=ok, axis=np.tile([[0.0, 1.0, 0.0]], (3, 1)))
    hint = friction_hint(0.3, pairs)
    assert hint.startswith(f"no --friction in its range ({bounds(GraspParams)['friction'][0].describe(True)}) would do")
    assert "raise --friction" not in hint


def test_a_flange_lying_flat_is_told_the_friction_its_rim_grips_need(tmp_path):
    """A 120 mm flange 8 mm thick with a 50 mm bore, lying flat, is gripped from above across its rim, one pad in
    the bore. A flat pad meets the bore at its own edges, 20 degrees or more off the jaw axis: no grip at friction
    0.3, and the placements' warning names the --friction that gives some. Planned again at it, the stored grips
    are across the rim: one contact on the bore, the other on the outer wall (radii from the contacts)."""
    import manifold3d

    disc = manifold3d.Manifold.cylinder(0.008, 0.06, 0.06, 96) - manifold3d.Manifold.cylinder(
        0.02, 0.025, 0.025, 96).translate([0.0, 0.0, -0.005])
    m = disc.to_mesh()
    trimesh.Trimesh(m.vert_properties[:, :3], m.tri_verts).export(tmp_path / "flange.stl")
    assert _cli("grasps", "flange.stl", "--db", "f.duckdb", cwd=tmp_path).returncode == 0
    out = _cli("placements", "--db", "f.duckdb", "--object", "flange", cwd=tmp_path)
    assert out.returncode == 0 and "stage free tabletop grips" in out.stderr, out.stderr
    need = re.search(r"--friction ([0-9.]+) \(`workbench grasps` or `build`\) keeps ([0-9]+) grasps", out.stderr)
    assert need is not None, out.stderr
    mu = float(need.group(1))
    assert 0.3 < mu <= 1.0
    assert _cli("grasps", "flange.stl", "--db", "g.duckdb", "--friction", need.group(1), cwd=tmp_path).returncode == 0
    out = _cli("placements", "--db", "g.duckdb", "--object", "flange", cwd=tmp_path)
    assert out.returncode == 0 and "no tabletop grip" not in out.stderr, out.stderr
    con = duckdb.connect(str(tmp_path / "g.duckdb"), read_only=True)
    rows = con.execute("SELECT DISTINCT g.contactpoint0, g.contactpoint1, g.contactnormal0, g.contactnormal1, g.rotmat "
                       "FROM freetabletopgrip t JOIN freeairgrip g USING (idfreeairgrip)").fetchall()
    con.close()
    assert len(rows) == int(need.group(2)), (len(rows), need.group(0))
    for c0, c1, n0, n1, rot in rows:
        radii = sorted(np.hypot(*np.array(c)[:2]) for c in (c0, c1))
        assert abs(radii[0] - 0.025) <= 1e-3 and abs(radii[1] - 0.06) <= 1e-3, radii
        y = np.array(rot).reshape(4, 4)[:3, 1]
        off = np.degrees(np.arccos(np.clip([np.dot(n0, y), -np.dot(n1, y)], -1, 1)))
        assert off.max() <= np.degrees(np.arctan(mu)) + 1e-6 and off.max() > np.degrees(np.arctan(0.3)), off


def test_the_zero_placement_hint_quotes_the_settled_stability_and_the_filter_that_removed_the_rest():
    """A capsule lying on its faceted side: no support reaches --min-stability 0.1. The hint quotes the best support's
    stability as `stable_placements` scores the settled part (below the threshold, and the highest of the placements
    a lower threshold keeps), and the lower threshold it names keeps the count it says. A box whose faces all pass
    the stability filter but not --min-probability 0.5 is told that filter and its likeliest face's probability."""
    from dataclasses import replace

    from workbench.grasping.placements import PlacementParams, stability_hint, stable_placements

    capsule = from_trimesh(trimesh.creation.capsule(0.06, 0.012), "capsule")
    assert len(stable_placements(capsule)) == 0
    text = stability_hint(capsule)
    best = float(re.search(r"scores ([0-9.]+)", text).group(1))
    lower, kept = re.search(r"--min-stability ([0-9.]+) keeps ([0-9]+)", text).groups()
    some = stable_placements(capsule, PlacementParams(min_stability=float(lower)))
    assert best < 0.1 and len(some) == int(kept) > 0
    assert abs(some.stability.max() - best) <= 1e-3 * best, (some.stability.max(), text)
    box = from_trimesh(trimesh.creation.box((0.04, 0.03, 0.02)), "box")
    strict = PlacementParams(min_probability=0.5)
    assert len(stable_placements(box, strict)) == 0
    text = stability_hint(box, strict)
    likeliest = float(re.search(r"the likeliest has ([0-9.]+)", text).group(1))
    assert "--min-probability 0.5" in text and "--reject-rocking" not in text
    assert abs(likeliest - stable_placements(box, replace(strict, min_probability=0.0)).probability.max()) <= 0.01
