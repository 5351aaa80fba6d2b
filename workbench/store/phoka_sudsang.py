"""SQL of the five-finger tables (schema: FINGER_TABLES): contacts, clusters, R, local-planning stats, queries.

Each `save_*` writes one stage's rows in one transaction keyed by its paramset: contacts (T_O), clusters, T_R, E
and R, and Tables II and III. The stage runners (`planners.phoka_sudsang.stages`) compute, then call these.
Contacts are indices 0..N-1 in the library and `idfingercontact` ids in the store; `ContactIds` maps both ways.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import trimesh

from workbench.errors import StoreError
from workbench.planners.phoka_sudsang.clustering import Clustering, ClusterParams
from workbench.planners.phoka_sudsang.contacts import (
    ContactSet,
)
from workbench.planners.phoka_sudsang.experiments import LocalStats
from workbench.planners.phoka_sudsang.linking import Extension
from workbench.planners.phoka_sudsang.query import QueryResult
from workbench.planners.phoka_sudsang.switching import FingerPlanner, Roadmap
from workbench.store import Store


@dataclass(frozen=True)
class ContactIds:
    """`ids[i]` is the idfingercontact of contact index i."""

    ids: np.ndarray

    def to_ids(self, idx: np.ndarray) -> np.ndarray:
        return self.ids[np.asarray(idx, dtype=np.int64)]

    def to_index(self, ids: np.ndarray | list[int], what: str = "contact id") -> np.ndarray:
        ids = np.asarray(ids, dtype=np.int64)
        pos = np.searchsorted(self.ids, ids)
        pos = np.minimum(pos, len(self.ids) - 1)
        bad = self.ids[pos] != ids
        if bad.any():
            raise StoreError(f"{what} {int(ids[bad][0])} is not a stored contact of this object "
                             f"(ids {int(self.ids[0])}..{int(self.ids[-1])})")
        return pos


# ----------------------------------------------------------------------------------------------------------
# contacts


def save_contacts(store: Store, idobject: int, key: dict, cs: ContactSet) -> int:
    """Write T_O under a new paramset in one transaction; returns the paramset id."""
    with store.transaction():
        pid, existed = store.paramset("fingers.contacts", key, idobject)
        if not existed:
            _put_contacts(store, pid, idobject, cs)
    return pid


def _put_contacts(store: Store, pid: int, idobject: int, cs: ContactSet) -> None:
    mid = store.next_id("fingermesh", "idfingermesh")
    store.run("INSERT INTO fingermesh (idfingermesh, idobject, idparamset, ntriangles, vertices, faces, com, radius) "
                      "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                      [mid, idobject, pid, len(cs.mesh.faces), cs.mesh.vertices.tolist(), cs.mesh.faces.tolist(),
                       cs.com.tolist(), cs.radius])
    n = len(cs)
    store.insert("fingercontact", {
        "idfingercontact": store.new_ids("fingercontact", n),
        "idfingermesh": np.full(n, mid, dtype=np.int64),
        "idparamset": np.full(n, pid, dtype=np.int64),
        "idx": cs.face.astype(np.int32),
        "position": cs.points,
        "normal": cs.normals,
    })


def load_contacts(store: Store, pid: int) -> tuple[ContactSet, ContactIds]:
    """The stored T_O of contacts paramset `pid` and its contact ids."""
    row = store.one("SELECT vertices, faces, com, radius FROM fingermesh WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no five-finger contacts for paramset {pid}; run `workbench fingers` first")
    mesh = trimesh.Trimesh(np.asarray(row[0], dtype=np.float64), np.asarray(row[1], dtype=np.int64), process=False)
    c = store.query_arrays("SELECT idfingercontact, idx, position, normal FROM fingercontact WHERE idparamset = ? ORDER BY idx", [pid])
    cs = ContactSet(points=c["position"], normals=c["normal"], face=c["idx"].astype(np.int64), mesh=mesh,
                    com=np.asarray(row[2], dtype=np.float64), radius=float(row[3]))
    return cs, ContactIds(c["idfingercontact"].astype(np.int64))


# ----------------------------------------------------------------------------------------------------------
# clusters and the representative-level roadmap


def roadmap_params(params: ClusterParams, idcontacts: int) -> dict:
    """The representative roadmap's parameter set as stored: the contacts it is built on and the clustering."""
    return {"contacts": idcontacts, "k": params.k, "mu": params.mu, "sides": params.sides, "seed": params.seed,
            "n_init": params.n_init, "torque_scale": params.torque_scale}


def save_roadmap(store: Store, idobject: int, idcontacts: int, key: dict, planner: FingerPlanner, ids: ContactIds) -> int:
    """Write clusters, T_R, E and R in one transaction; returns the paramset id."""
    with store.transaction():
        pid, existed = store.paramset("fingers.roadmap", key, idobject)
        if not existed:
            _put_roadmap(store, pid, idobject, idcontacts, planner, ids)
    return pid


def _put_roadmap(store: Store, pid: int, idobject: int, idcontacts: int, planner: FingerPlanner, ids: ContactIds) -> None:
    cl, rm = planner.clustering, planner.roadmap
    rid = store.next_id("fingerroadmap", "idfingerroadmap")
    store.run("INSERT INTO fingerroadmap (idfingerroadmap, idparamset, idobject, idcontacts, sigma, nvertex, nedge, "
                      "ncomponent, seconds_clustering, seconds_roadmap) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                      [rid, pid, idobject, idcontacts, cl.sigma, len(rm), len(rm.edges), rm.ncomponents,
                       planner.times.get("clustering", 0.0), planner.times.get("roadmap", 0.0)])
    k, n = cl.k, len(cl.labels)
    cluster_ids = store.new_ids("fingercluster", k)
    store.insert("fingercluster", {
        "idfingercluster": cluster_ids,
        "idparamset": np.full(k, pid, dtype=np.int64),
        "label": np.arange(k, dtype=np.int32),
        "idrepresentative": ids.to_ids(cl.reps),
        "center": _lists(cl.centers),
        "size": np.bincount(cl.labels, minlength=k).astype(np.int32),
    })
    store.insert("fingermember", {
        "idfingermember": store.new_ids("fingermember", n),
        "idparamset": np.full(n, pid, dtype=np.int64),
        "idfingercontact": ids.ids,
        "idfingercluster": cluster_ids[cl.labels],
        "embedding": _lists(cl.embedding),
        "distances": _lists(cl.E),
    })
    v = len(rm)
    grasp_ids = store.new_ids("fingergrasp", v)
    cid = ids.to_ids(rm.grasps) if v else np.zeros((0, 4), dtype=np.int64)
    store.insert("fingergrasp", {
        "idfingergrasp": grasp_ids,
        "idparamset": np.full(v, pid, dtype=np.int64),
        **{f"idcontact{i}": cid[:, i] for i in range(4)},
        "component": rm.components.astype(np.int32),
    })
    e = len(rm.edges)
    store.insert("fingeredge", {
        "idfingeredge": store.new_ids("fingeredge", e),
        "idparamset": np.full(e, pid, dtype=np.int64),
        "idfingergrasp0": grasp_ids[rm.edges[:, 0]],
        "idfingergrasp1": grasp_ids[rm.edges[:, 1]],
        "idlifted": ids.to_ids(rm.moves[:, 0]) if e else np.zeros(0, dtype=np.int64),
        "idplaced": ids.to_ids(rm.moves[:, 1]) if e else np.zeros(0, dtype=np.int64),
    })


def _lists(a: np.ndarray) -> object:
    """Rows of a 2-D array as a variable-length DOUBLE[] column."""

    a = np.ascontiguousarray(a, dtype=np.float64)
    offsets = np.arange(0, a.size + 1, a.shape[1], dtype=np.int32)
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(a.ravel()))


def load_roadmap(store: Store, pid: int, ids: ContactIds, n_contacts: int) -> tuple[Clustering, Roadmap, dict]:
    """The stored clustering, representative roadmap R and timings of roadmap paramset `pid`."""
    row = store.one("SELECT sigma, seconds_clustering, seconds_roadmap FROM fingerroadmap WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no five-finger roadmap for paramset {pid}; run `workbench fingers` first")
    cl = store.query_arrays("SELECT label, idrepresentative, center FROM fingercluster WHERE idparamset = ? ORDER BY label", [pid])
    mem = store.query_arrays(
        "SELECT c.idx, k.label, m.embedding, m.distances FROM fingermember m "
        "JOIN fingercontact c ON c.idfingercontact = m.idfingercontact "
        "JOIN fingercluster k ON k.idfingercluster = m.idfingercluster WHERE m.idparamset = ? ORDER BY c.idx", [pid])
    clustering = Clustering(labels=mem["label"].astype(np.int64), reps=ids.to_index(cl["idrepresentative"]),
                            embedding=np.vstack(mem["embedding"]), centers=np.vstack(cl["center"]),
                            E=np.vstack(mem["distances"]), sigma=float(row[0]))
    g = store.query_arrays("SELECT idfingergrasp, idcontact0, idcontact1, idcontact2, idcontact3 FROM fingergrasp "
                           "WHERE idparamset = ? ORDER BY idfingergrasp", [pid])
    grasps = ids.to_index(np.stack([g[f"idcontact{i}"] for i in range(4)], axis=1)) if len(g["idfingergrasp"]) else np.zeros((0, 4), dtype=np.int64)
    e = store.query_arrays("SELECT idfingergrasp0, idfingergrasp1, idlifted, idplaced FROM fingeredge "
                           "WHERE idparamset = ? ORDER BY idfingeredge", [pid])
    gid = g["idfingergrasp"].astype(np.int64)
    edges = np.stack([np.searchsorted(gid, e["idfingergrasp0"]), np.searchsorted(gid, e["idfingergrasp1"])], axis=1)
    moves = ids.to_index(np.stack([e["idlifted"], e["idplaced"]], axis=1)) if len(edges) else np.zeros((0, 2), dtype=np.int64)
    roadmap = Roadmap(grasps.reshape(-1, 4), n_contacts, edges=edges.reshape(-1, 2).astype(np.int64), moves=moves.reshape(-1, 2))
    return clustering, roadmap, {"clustering": float(row[1]), "roadmap": float(row[2])}


def roadmap_summary(store: Store, pid: int) -> dict:
    """Table I numbers of a stored roadmap: vertices, edges, components, seconds."""
    row = store.one("SELECT nvertex, nedge, ncomponent, seconds_clustering, seconds_roadmap FROM fingerroadmap "
                            "WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no five-finger roadmap for paramset {pid}")
    return dict(zip(("nvertex", "nedge", "ncomponent", "seconds_clustering", "seconds_roadmap"), row))


# ----------------------------------------------------------------------------------------------------------
# Tables II and III


def save_queries(store: Store, idobject: int, idroadmap: int, key: dict, ids: ContactIds, stats: LocalStats,
                 updates: list[Extension] | None = None) -> int:
    """Write Tables II and III of a run, and the persistent Algorithm 3 updates of R its queries made, in one
    transaction; returns the paramset id."""
    with store.transaction():
        pid, existed = store.paramset("fingers.queries", key, idobject)
        if not existed:
            _put_queries(store, pid, idroadmap, ids, stats)
            _put_updates(store, idroadmap, pid, updates or [], ids)
    return pid


def _put_updates(store: Store, idroadmap: int, idqueries: int, updates: list[Extension], ids: ContactIds) -> None:
    """Append Algorithm 3 updates of a roadmap (T_G and the vertices each added), after those already stored."""
    if not updates:
        return
    first = int(store.one("SELECT coalesce(max(seq) + 1, 0) FROM fingerupdate WHERE idroadmap = ?", [idroadmap])[0])
    uids = store.new_ids("fingerupdate", len(updates))
    store.insert("fingerupdate", {
        "idfingerupdate": uids,
        "idroadmap": np.full(len(updates), idroadmap, dtype=np.int64),
        "idqueries": np.full(len(updates), idqueries, dtype=np.int64),
        "seq": np.arange(first, first + len(updates), dtype=np.int32),
        "tg": pa.array([ids.to_ids(u.tg).tolist() for u in updates], type=pa.list_(pa.int64())),
    })
    sizes = np.array([len(u.grasps) for u in updates])
    if sizes.sum() == 0:
        return
    grasps = ids.to_ids(np.vstack([u.grasps.reshape(-1, 4) for u in updates]))
    store.insert("fingerupdategrasp", {
        "idfingerupdategrasp": store.new_ids("fingerupdategrasp", int(sizes.sum())),
        "idfingerupdate": np.repeat(uids, sizes),
        **{f"idcontact{i}": grasps[:, i] for i in range(4)},
    })


def load_updates(store: Store, idroadmap: int, ids: ContactIds) -> list[Extension]:
    """The persistent Algorithm 3 updates of a roadmap in the order they were made (T_G, the vertices added)."""
    u = store.query_arrays("SELECT idfingerupdate, tg FROM fingerupdate WHERE idroadmap = ? ORDER BY seq", [idroadmap])
    if len(u["idfingerupdate"]) == 0:
        return []
    g = store.query_arrays("SELECT g.idfingerupdate, g.idcontact0, g.idcontact1, g.idcontact2, g.idcontact3 "
                           "FROM fingerupdategrasp g JOIN fingerupdate u USING (idfingerupdate) WHERE u.idroadmap = ? "
                           "ORDER BY g.idfingerupdategrasp", [idroadmap])
    owner = np.asarray(g["idfingerupdate"], dtype=np.int64)
    grasps = (ids.to_index(np.stack([g[f"idcontact{i}"] for i in range(4)], axis=1)) if len(owner)
              else np.zeros((0, 4), dtype=np.int64))
    none = np.zeros((0, 2), dtype=np.int64)
    return [Extension(grasps[owner == uid].reshape(-1, 4), none, none, ids.to_index(np.asarray(tg, dtype=np.int64)))
            for uid, tg in zip(np.asarray(u["idfingerupdate"]).tolist(), u["tg"])]


def _put_queries(store: Store, pid: int, idroadmap: int, ids: ContactIds, st: LocalStats) -> None:
    sid = store.next_id("fingerlocalstats", "idfingerlocalstats")
    store.run(
        "INSERT INTO fingerlocalstats (idfingerlocalstats, idparamset, idroadmap, samples, alg1_run, alg1_connect, alg1_picked, "
        "alg2_run, alg2_connect, alg2_picked, alg3_connect, alg3_picked) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        [sid, pid, idroadmap, st.samples, float(st.alg1_run), st.alg1_connect, st.alg1_picked, float(st.alg2_run),
         st.alg2_connect, st.alg2_picked, st.alg3_connect, st.alg3_picked])
    q = st.queries
    if not q:
        return

    seqs = [None if r.sequence is None else ids.to_ids(r.sequence).tolist() for r in q]
    store.insert("fingerquery", {
        "idfingerquery": store.new_ids("fingerquery", len(q)),
        "idparamset": np.full(len(q), pid, dtype=np.int64),
        "idroadmap": np.full(len(q), idroadmap, dtype=np.int64),
        "seq": np.arange(len(q), dtype=np.int32),
        "start": pa.array([ids.to_ids(r.start).tolist() for r in q], type=pa.list_(pa.int64())),
        "goal": pa.array([ids.to_ids(r.goal).tolist() for r in q], type=pa.list_(pa.int64())),
        "connected": np.array([r.connected for r in q]),
        "start_method": np.array([r.start_method for r in q], dtype=object),
        "goal_method": np.array([r.goal_method for r in q], dtype=object),
        "seconds": np.array([r.seconds for r in q]),
        "sequence": pa.array(seqs, type=pa.list_(pa.list_(pa.int64()))),
    })


def load_queries(store: Store, pid: int, ids: ContactIds) -> LocalStats:
    """The stored Table II numbers and Table III queries of queries paramset `pid`."""
    row = store.one("SELECT samples, alg1_run, alg1_connect, alg1_picked, alg2_run, alg2_connect, alg2_picked, "
                            "alg3_connect, alg3_picked FROM fingerlocalstats WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no five-finger queries for paramset {pid}")
    st = LocalStats(*row)
    rows = store.run("SELECT start, goal, connected, start_method, goal_method, seconds, sequence FROM fingerquery "
                             "WHERE idparamset = ? ORDER BY seq", [pid])
    for start, goal, connected, sm, gm, sec, seq in rows:
        st.queries.append(QueryResult(ids.to_index(start), ids.to_index(goal),
                                      None if seq is None else ids.to_index(np.asarray(seq, dtype=np.int64)),
                                      sm, gm, float(sec)))
    return st
