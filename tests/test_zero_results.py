"""Zero is a result, never a crash (issue 10): every command on a part no parallel jaw can grasp exits 0 with a
warning that names the stage that removed the last candidate, and every stage stores its zero rows."""

from __future__ import annotations

import subprocess
import sys

import pytest
import trimesh

from workbench.benchmarks.organic import blob
from workbench.geometry.objects import from_trimesh
from workbench.grasping.grasps import GraspParams, plan_grasps


def _cli(*args: str, cwd) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "workbench.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=900)


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
    out = run("fingers", "bigcube.stl", "--db", "f.duckdb", "--faces", "0", "--clusters", "8", "--samples", "20",
              "--picks", "2", "--queries", "2")
    assert out.returncode == 0, out.stderr


def test_each_grasp_filter_is_named_when_it_removes_the_last_candidate(hand):
    """Force each stage in turn to be the one that empties the set, and check the message names it."""
    box = from_trimesh(trimesh.creation.box((0.05, 0.04, 0.03)), "box")
    ball = from_trimesh(blob(seed=4, rows=12, cols=14, radius=0.028), "ball")
    cases = [("facet_samples_distance", box, GraspParams(dist_min=0.0, dist_max=1e-9, lengths="fixed")),
             ("pads_cone", ball, GraspParams(friction=1e-6)),  # a bumpy ball: no two normals exactly opposite
             ("pads_com", box, GraspParams(com_max=1e-6, lengths="fixed"))]
    for stage, obj, params in cases:
        plan = plan_grasps(obj, hand, params)
        assert len(plan.grasps) == 0 and plan.empty_reason.startswith(stage), (stage, plan.counts, plan.empty_reason)
    ok = plan_grasps(box, hand, GraspParams())
    assert len(ok.grasps) > 0 and ok.empty_reason is None


def test_a_card_lying_flat_is_named_too_thin_to_grip(tmp_path):
    """A 0.8 mm card has grasps in free air but none that reaches it on the table: `build` exits 0, stores its
    placements and says the part is too thin, with its height."""
    trimesh.creation.box((0.05, 0.04, 0.0008)).export(tmp_path / "card.stl")
    out = _cli("build", "card.stl", "--db", "c.duckdb", "--robot", "panda", "--workers", "1", "--x=0.4,0.6,2",
               "--y=-0.1,0.1,2", "--angles", "2", cwd=tmp_path)
    assert out.returncode == 0 and "Traceback" not in out.stderr, out.stderr
    assert "2 stable placements" in out.stdout
    assert "stage free tabletop grips" in out.stderr and "card stands at most 0.8 mm above the table" in out.stderr
