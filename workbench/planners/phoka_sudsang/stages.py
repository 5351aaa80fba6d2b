"""Stage runners of the five-finger planner (Phoka & Sudsang): contacts, the representative roadmap and the
local-planning experiments, each computed once per object and parameters and reused from the store.

Only this module of the planner talks to the store; every computation runs outside the store's write
transactions, and each stage's rows are written in one transaction."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from workbench.errors import WorkbenchError
from workbench.geometry.objects import ObjectModel
from workbench.planners.phoka_sudsang.clustering import ClusterParams
from workbench.planners.phoka_sudsang.contacts import (
    ContactParams,
    ContactSet,
    contact_points,
)
from workbench.planners.phoka_sudsang.experiments import (
    LocalStats,
    local_planning_stats,
    random_queries,
    sample_grasps,
)
from workbench.planners.phoka_sudsang.forceclosure import ForceClosure
from workbench.planners.phoka_sudsang.linking import Extension
from workbench.planners.phoka_sudsang.switching import (
    FingerPlanner,
    build_planner,
)
from workbench.store import Store
from workbench.store import phoka_sudsang as fstore
from workbench.store.objects import put_object
from workbench.store.phoka_sudsang import ContactIds


@dataclass
class FingerRun:
    """What one `fingers` run produced (or reused from the store)."""

    name: str
    idobject: int
    idcontacts: int
    idroadmap: int
    idqueries: int | None
    planner: FingerPlanner
    ids: ContactIds
    stats: LocalStats | None
    reused: tuple[bool, bool]


def run_pipeline(db: str, obj, contact: ContactParams, params: ClusterParams, samples: int, picks: int,
                 queries: int, progress: bool = False, persistent: bool = True) -> FingerRun:
    """All stages against a store: contacts, roadmap, then (when `queries` or `picks`) Tables II and III.

    `persistent` (the paper's Algorithm 3): queries update R for good; the updates are stored with the queries and
    applied whenever the roadmap is loaded again, so later runs reuse them. False: each query forgets its update.
    """

    if samples < 2 and (queries or picks):
        raise WorkbenchError(f"--samples {samples} is too few; give at least 2 sampled grasps for queries")
    for label, value in (("--samples", samples), ("--picks", picks), ("--queries", queries)):
        if value < 0:
            raise WorkbenchError(f"{label} {value} must be zero or more")
    with Store(db) as store:
        idobject = put_object(store, obj)
        idc, contacts, ids = contacts_stage(store, idobject, obj, contact)
        idr, planner, reused = roadmap_stage(store, idobject, idc, contacts, ids, params, progress=progress)
        planner.persistent = persistent
        stats, idq, reused_q = None, None, False
        if queries or picks:
            def compute() -> tuple[LocalStats, list[Extension]]:
                s = sample_grasps(planner.tester, samples, seed=params.seed)
                st = local_planning_stats(planner, s, picks=picks, seed=params.seed, progress=progress)
                before = len(planner.updates)
                st.queries = random_queries(planner, s, queries, seed=params.seed, progress=progress)
                return st, planner.updates[before:]

            key = {"samples": samples, "picks": picks, "queries": queries, "seed": params.seed,
                   "algorithm3": "update" if persistent else "one-off"}
            idq, stats, reused_q = queries_stage(store, idobject, idr, ids, key, compute)
    return FingerRun(obj.name, idobject, idc, idr, idq, planner, ids, stats, (reused, reused_q))


def tables(run: FingerRun) -> dict:
    """Tables I-III as plain numbers."""
    rm, st = run.planner.base, run.stats
    out = {"table1": {"vertex": len(rm), "edges": int(len(rm.edges)), "cc": int(rm.ncomponents),
                      "vertex_updated": len(run.planner.roadmap), "updates": len(run.planner.updates),
                      "seconds_clustering": run.planner.times.get("clustering"),
                      "seconds_roadmap": run.planner.times.get("roadmap")}}
    if st is not None:
        out["table2"] = {"samples": st.samples, "alg1_run": float(st.alg1_run), "alg1_connect": st.alg1_connect,
                         "alg1_picked": st.alg1_picked, "alg2_run": float(st.alg2_run), "alg2_connect": st.alg2_connect,
                         "alg2_picked": st.alg2_picked, "alg3_connect": st.alg3_connect, "alg3_picked": st.alg3_picked}
        t = [q.seconds for q in st.queries]
        out["table3"] = {"queries": len(st.queries), "connect": sum(q.connected for q in st.queries),
                         "min": min(t) if t else None, "max": max(t) if t else None,
                         "average": float(np.mean(t)) if t else None}
    return out


def contacts_stage(store: Store, idobject: int, obj: ObjectModel, params: ContactParams) -> tuple[int, ContactSet, ContactIds]:
    """T_O of an object (decimated to `params.faces`), computed once per object and parameters (Section III.A)."""
    params.validate()
    key = {"faces": params.faces, "resolution": params.resolution}
    pid = store.find_paramset("fingers.contacts", key, idobject)
    if pid is None:  # compute outside the write transaction, then write in one
        pid = fstore.save_contacts(store, idobject, key, contact_points(obj, params))
    cs, ids = fstore.load_contacts(store, pid)
    return pid, cs, ids


def roadmap_stage(store: Store, idobject: int, idcontacts: int, contacts: ContactSet, ids: ContactIds,
                  params: ClusterParams, progress: bool = False) -> tuple[int, FingerPlanner, bool]:
    """Clusters, T_R, E and R for the contacts and parameters (Sections IV-V); (paramset, planner, reused)."""
    params.validate(len(contacts))
    key = fstore.roadmap_params(params, idcontacts)
    pid = store.find_paramset("fingers.roadmap", key, idobject)
    if pid is None:
        planner = build_planner(contacts, params, progress=progress)
        pid = fstore.save_roadmap(store, idobject, idcontacts, key, planner, ids)
        return pid, planner, False
    return pid, load_planner(store, pid, contacts, ids, params), True


def queries_stage(store: Store, idobject: int, idroadmap: int, ids: ContactIds, params: dict,
                  compute: Callable[[], tuple[LocalStats, list[Extension]]]) -> tuple[int, LocalStats, bool]:
    """Local-planning stats and queries for a roadmap (Tables II and III); `compute()` returns a LocalStats and the
    persistent Algorithm 3 updates of R its queries made (stored with them).

    `params` (samples, picks, queries, seed) identify the run together with the roadmap's paramset.
    """
    key = {**params, "roadmap": idroadmap}
    pid = store.find_paramset("fingers.queries", key, idobject)
    if pid is None:
        stats, updates = compute()
        pid = fstore.save_queries(store, idobject, idroadmap, key, ids, stats, updates)
        return pid, stats, False
    return pid, fstore.load_queries(store, pid, ids), True


def load_planner(store: Store, pid: int, contacts: ContactSet, ids: ContactIds, params: ClusterParams) -> FingerPlanner:
    """Rebuild the planner of roadmap paramset `pid` from its rows (no clustering or force closure recomputed)."""
    clustering, roadmap, times = fstore.load_roadmap(store, pid, ids, len(contacts))
    tester = ForceClosure(contacts.points, contacts.normals, params.friction, ref=contacts.com, length=contacts.radius)
    planner = FingerPlanner(contacts, clustering, tester, roadmap, times=times)
    for ext in fstore.load_updates(store, pid, ids):      # persistent Algorithm 3 updates of earlier queries
        planner.apply(ext)
    return planner
