"""The simulation stage against a store: a stored plan replayed in MuJoCo (CONVENTIONS.md, Simulation), its
result stored in `simulation` / `simulationstep` keyed by the plan and the digest of every simulation parameter,
and reused when the same plan is simulated again with the same parameters. This is the only module of the
simulation that talks to the store; the convex decomposition runs (and may fail) before anything is written.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from workbench.geometry.symmetry import Symmetry, part_symmetry
from workbench.planners.wan_harada.stages import get_object, load_plan, stored_robot
from workbench.robots.selfcollision import AllowedPairs, allowed_pairs
from workbench.simulation.decomposition import convex_parts
from workbench.simulation.replay import SimParams, SimResult, resolve, simulate
from workbench.store import Store
from workbench.store import simulation as sql
from workbench.store.objects import gripper_row
from workbench.store.robots import robot_row, scene_row


@dataclass
class StoredSimulation:
    """A simulation in the store: its id, whether it was reused, the verdict and the result (None when reused)."""

    idsimulation: int
    reused: bool
    confirmed: bool
    failure: str | None
    failure_step: int | None
    message: str
    final_error: float
    final_angle: float
    result: SimResult | None


def plan_gripper(store: Store, idplan: int) -> list[dict]:
    """The gripper stored plan `idplan`'s robot was built with (a list of one dict: name, digest; empty when none)."""
    row = robot_row(store, sql.plan_inputs(store, idplan)["idrobot"])
    return [] if row["idgripper"] is None else [gripper_row(store, row["idgripper"])]


def simulate_stored(store: Store, idplan: int, params: SimParams = SimParams(),
                    plan=None, robot=None, save: bool = True, gripper=None) -> StoredSimulation:
    """Simulate stored plan `idplan` (or reuse its stored simulation with the same parameters) and store the result.
    `plan` and `robot` may be given when already loaded (a plan just made by `workbench plan`); else the robot is
    rebuilt from its row with `gripper` (the planning gripper it was stored with; default the Franka hand)."""
    inputs = sql.plan_inputs(store, idplan)
    plan = plan if plan is not None else load_plan(store, idplan)
    robot = robot if robot is not None else stored_robot(store, inputs["idrobot"], gripper)
    _, obj = get_object(store, inputs["object"])
    scene = scene_row(store, inputs["idscene"]).scene
    digest = params.digest(*resolve(params, robot.gripper, inputs["friction"]))
    found = sql.find_simulation(store, idplan, digest) if save else None
    if found is not None:
        row, _ = sql.load_simulation(store, found)
        return StoredSimulation(found, True, bool(row["confirmed"]), row["failure"], row["failure_step"], row["message"] or "",
                                float(row["final_error"]), float(row["final_angle"]), None)
    hulls = convex_parts(obj.mesh, obj.digest, obj.name, params.decomposition)
    res = simulate(plan, robot, obj.mesh, scene, inputs["friction"], hulls, params,
                   self_pairs(store, inputs["idrobot"], robot))
    f = res.failure
    sid = -1
    if save:
        row = {"idplan": int(idplan), "digest": res.digest, "params": json.dumps(res.params, sort_keys=True),
               "confirmed": res.confirmed, "failure": f.kind if f else None, "failure_step": f.step if f else None,
               "failure_t": f.t if f else None, "message": f.message if f else res.summary(), "final_error": res.final_error,
               "final_angle": res.final_angle, "simulated": res.simulated, "seconds": res.seconds, "hulls": len(hulls),
               "playback_t": res.playback_t.tolist(), "playback_pose": res.playback_pose.reshape(-1, 16).tolist()}
        sid = sql.save_simulation(store, row, res.steps)
    return StoredSimulation(sid, False, res.confirmed, f.kind if f else None, f.step if f else None,
                            f.message if f else res.summary(), res.final_error, res.final_angle, res)


def simulate_in_memory(store: Store, plan, robot, params: SimParams = SimParams(),
                       symmetry: Symmetry | None = None) -> SimResult:
    """Simulate a plan that is not stored (its object, scene and grasp friction from the store); nothing written.
    `symmetry`: the part's (`part_symmetry` of its mesh), when several plans of one part are simulated."""
    _, obj = get_object(store, plan.object)
    hulls = convex_parts(obj.mesh, obj.digest, obj.name, params.decomposition)
    friction = sql.grasp_friction(store, plan.steps[0].idfreeairgrip)
    return simulate(plan, robot, obj.mesh, scene_row(store, plan.ids["idscene"]).scene, friction, hulls, params,
                    self_pairs(store, plan.ids["idrobot"], robot), symmetry)


def self_pairs(store: Store, idrobot: int, robot) -> list[tuple[str, str]]:
    """The link pairs the self-collision check tests for a stored robot (its row's allowed pairs; computed for
    rows stored without them)."""
    text = robot_row(store, int(idrobot))["allowed_pairs"]
    return (AllowedPairs.from_json(text) if text else allowed_pairs(robot)).checked


def physics_check(store: Store, robot, params: SimParams = SimParams()) -> Callable[[object], tuple[int, str] | None]:
    """For the planner's search (`plan --require-physics`): a function of a plan that simulates it and returns None
    when it is confirmed, else (the failing step, why); the failing step's roadmap node or grip is then removed."""
    symmetry: list[Symmetry] = []  # the part's, found on the first plan

    def check(plan) -> tuple[int, str] | None:
        if not symmetry:
            symmetry.append(part_symmetry(get_object(store, plan.object)[1].mesh))
        res = simulate_in_memory(store, plan, robot, params, symmetry[0])
        return None if res.confirmed else (res.failure.step, f"physics: {res.failure.kind}: {res.failure.message}")

    return check


def stored_playback(store: Store, idplan: int) -> tuple[np.ndarray, np.ndarray] | None:
    """The simulated part's poses of a plan's newest stored simulation, (t (K,), poses (K, 4, 4)), or None."""
    ids = sql.simulations_of_plan(store, idplan)
    if not ids:
        return None
    row, _ = sql.load_simulation(store, ids[0])
    return np.asarray(row["playback_t"], dtype=np.float64), np.asarray(row["playback_pose"], dtype=np.float64).reshape(-1, 4, 4)
