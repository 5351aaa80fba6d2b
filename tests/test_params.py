"""Parameter ranges: one mechanism (workbench.params) on every parameters dataclass, shared by the command line."""

from __future__ import annotations

import argparse
import dataclasses
import typing

import numpy as np
import pytest

from workbench.grasping.grasps import GraspParams
from workbench.grasping.placements import PlacementParams
from workbench.params import (
    MemoryBudgetError,
    ParameterError,
    Params,
    add_param,
    bounds,
    check_memory,
    from_cli,
    memory_budget,
    parse_size,
)
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.phoka_sudsang.contacts import ContactParams
from workbench.planners.phoka_sudsang.forceclosure import FrictionParams
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.collider import Scene
from workbench.robots.ik import IKOptions

ALL = [GraspParams, PlacementParams, TabletopParams, ContactParams, FrictionParams, ClusterParams, Scene, IKOptions]


def _numeric(tp) -> bool:
    text = str(tp)
    return any(w in text for w in ("int", "float")) and "bool" not in text


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_every_numeric_field_has_a_documented_range(cls):
    assert issubclass(cls, Params)
    hints = typing.get_type_hints(cls)
    declared = bounds(cls)
    for f in dataclasses.fields(cls):
        if _numeric(hints[f.name]):
            assert f.name in declared, f"{cls.__name__}.{f.name} has no declared range"
            b = declared[f.name][0]
            assert b.help, f"{cls.__name__}.{f.name} has no meaning for its messages"
            assert b.lo is not None or b.hi is not None
    cls()  # the defaults are valid


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_out_of_range_values_are_refused_with_the_range(cls):
    for name, (b, default) in bounds(cls).items():
        bad = []
        if b.lo is not None:
            bad.append(b.lo - (1 if b.integer else max(1e-6, abs(b.lo) * 1e-3)) if not b.lo_open else b.lo)
        if b.hi is not None:
            bad.append(b.hi + (1 if b.integer else max(1e-6, abs(b.hi) * 1e-3)) if not b.hi_open else b.hi)
        bad.append(float("nan"))
        for v in bad:
            value = tuple(v for _ in default) if isinstance(default, tuple) else v
            with pytest.raises(ParameterError, match=name):
                cls(**{name: value})


def test_relations_name_both_fields():
    with pytest.raises(ParameterError, match="dist_min.*dist_max"):
        GraspParams(dist_min=0.05, dist_max=0.01)
    with pytest.raises(ParameterError, match="x_min.*x_max"):
        TabletopParams(x_min=0.6, x_max=0.3)


def test_cli_shares_the_ranges():
    parser = argparse.ArgumentParser(prog="t", exit_on_error=False)
    add_param(parser, GraspParams, "rotations")
    add_param(parser, GraspParams, "tau", flag="--tau-deg")
    args = parser.parse_args(["--rotations", "12", "--tau-deg", "30"])
    assert args.rotations == 12 and isinstance(args.rotations, int)
    assert np.isclose(from_cli(GraspParams, "tau", args.tau_deg), np.radians(30))
    with pytest.raises(argparse.ArgumentError, match=r"\[1, 360\]"):
        parser.parse_args(["--rotations", "1000000"])
    with pytest.raises(argparse.ArgumentError, match=r"deg"):
        parser.parse_args(["--tau-deg", "95"])
    assert "[1, 360]" in " ".join(parser.format_help().split())


def test_memory_budget(monkeypatch):
    monkeypatch.delenv("WORKBENCH_MEMORY_BUDGET", raising=False)
    assert 0 < memory_budget() < 2**50
    assert parse_size("2GiB") == 2 * 2**30 and parse_size("512M") == 512 * 2**20
    monkeypatch.setenv("WORKBENCH_MEMORY_BUDGET", "1MiB")
    check_memory(2**19, "work", "lower it")
    with pytest.raises(MemoryBudgetError, match="1.0 MiB.*lower it"):
        check_memory(2**21, "work", "lower it")
    with pytest.raises(ParameterError):
        parse_size("lots")


def test_single_blas_holds_the_blas_pool_to_one_thread_and_gives_it_back():
    """Inside a stage that `single_blas` wraps (grasp planning, placements, loading a part), numpy's BLAS runs one
    thread, whose pool cannot spin on the core the stage's own second thread needs; the pool is given back after,
    also when the stage raises."""
    import trimesh
    from threadpoolctl import threadpool_info, threadpool_limits

    import workbench.grasping.grasps as grasps
    from workbench.geometry.objects import from_trimesh
    from workbench.params import single_blas
    from workbench.robots.gripper import franka_hand

    def blas_threads() -> list[int]:
        return [p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]

    assert blas_threads(), "numpy has a BLAS"
    with threadpool_limits(2, user_api="blas"):
        seen = []
        original = grasps.segment

        def probe(*args, **kwargs):
            seen.append(blas_threads())
            return original(*args, **kwargs)

        grasps.segment = probe
        try:
            grasps.plan_grasps(from_trimesh(trimesh.creation.box((0.04, 0.03, 0.02)), "box"), franka_hand(),
                               GraspParams(rotations=2))
        finally:
            grasps.segment = original
        assert seen and all(n == [1] * len(n) for n in seen), seen
        assert blas_threads() == [2] * len(blas_threads())

        @single_blas
        def fails():
            assert blas_threads() == [1] * len(blas_threads())
            raise ValueError("inside")

        with pytest.raises(ValueError, match="inside"):
            fails()
        assert blas_threads() == [2] * len(blas_threads())
