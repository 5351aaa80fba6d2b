"""Schema and SQL of the grasp-placement table planner (Tournassoud, Lozano-Perez & Mazer 1987).

Tables (created on first use, idempotent; angles in radians, lengths in metres, poses DOUBLE[16] row-major):

- `tgraspclass`: one row per grasp class G_i of a `tournassoud.classes` parameter set: `idx` (its index in the
  table), `kind` (face/face, face/edge, face/vertex), `features` (JSON: face indices, edge end points, vertex), the
  grasp-plane normal `normal` n_i (the jaw axis, object frame), the plane basis `u`, `v`, the grasp point `point`
  C_i, `eccentricity` e_i = n_i . (C_i - centre of mass), `opening` (m), and the legal theta intervals against
  hand-object collision as parallel lists `theta_lo`, `theta_hi` (Section 5.1). The TCP in the object frame at
  angle theta is: y = n_i, z = cos(theta) u + sin(theta) v, x = y x z, origin C_i. Classes dropped as narrower
  than the parameter set's `min_range` are kept with negative `idx` (-1, -2, ...): they are not in the table.
- `tgptable`: one row per grasp-placement table (`tournassoud.table` parameter set): object, robot, the grasp
  class parameter set `idclasses`, the theta and phi grids (`ntheta`, `nphi` samples k * 2 pi / n), the table
  point H (`table_point`, world x, y on z = 0), build timings and counts.
- `tplacementclass`: the placement classes P_j of a table (Section 3): `idx`, the outward normal of the supporting
  convex-hull face (object frame), `rotmat` the object in the table frame (centre of mass above the origin, lowest
  point on z = 0, as `freetabletopplacement.rotmat`), `stability`. The object is in the world at
  translate(H) @ Rz(phi) @ rotmat.
- `tgpcell`: Q_ij sampled: one row per (table, grasp class, placement class, theta sample `itheta`): whether theta
  passes hand-object (`hand_object`) and hand-table (`hand_table`) collision, and the phi values with an IK
  solution as closed intervals of sample values `phi_lo[k]`..`phi_hi[k]` (Section 5.2); a run across 2 pi is
  two intervals. Empty lists: no phi.

Plans of this planner go into the roadmap planner's `plan`, `planstep` (and `plansegment`) tables with
`plan.planner` = 'tournassoud' and `plan.idtabletop` the table's paramset. Their foreign keys point at rows of the
paper's tables written for them (`placement_rows`, `grasp_rows`): one `freetabletopplacement` row per placement
class (idparamset = the table's paramset; rotmat, stability as `tplacementclass`) and one `freeairgrip` row per grasp
(G_i, theta) a plan uses (idparamset = the class set's paramset, `idcontactpair` = the class index, `rotation` =
theta; rotmat the TCP in the object frame; contactpoint0/1 = C_i +/- opening/2 n_i on the contacts, contactnormal0/1
= +/- n_i, the contacts' outward normals along the jaw axis).

Reuse: each stage's parameter set is digested (`paramset`); `find_*` return a stored set, `save_*` write a whole
stage in one transaction (the caller computes first, outside it).
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa

from workbench.errors import StoreError
from workbench.store import Store

TABLES: tuple[str, ...] = (
    """CREATE TABLE IF NOT EXISTS tgraspclass (
        idtgraspclass BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL REFERENCES paramset(idparamset),
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idx INTEGER NOT NULL,
        kind VARCHAR NOT NULL,
        features VARCHAR NOT NULL,
        normal DOUBLE[3] NOT NULL,
        u DOUBLE[3] NOT NULL,
        v DOUBLE[3] NOT NULL,
        point DOUBLE[3] NOT NULL,
        eccentricity DOUBLE NOT NULL,
        opening DOUBLE NOT NULL,
        theta_lo DOUBLE[] NOT NULL,
        theta_hi DOUBLE[] NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS tgptable (
        idtgptable BIGINT PRIMARY KEY,
        idparamset BIGINT NOT NULL UNIQUE REFERENCES paramset(idparamset),
        idobject BIGINT NOT NULL REFERENCES object(idobject),
        idrobot BIGINT NOT NULL REFERENCES robot(idrobot),
        idclasses BIGINT NOT NULL REFERENCES paramset(idparamset),
        ntheta INTEGER NOT NULL,
        nphi INTEGER NOT NULL,
        table_point DOUBLE[2] NOT NULL,
        nclasses INTEGER NOT NULL,
        nplacements INTEGER NOT NULL,
        nonempty_cells INTEGER NOT NULL,
        seconds_hand_object DOUBLE,
        seconds_hand_table DOUBLE,
        seconds_ik DOUBLE,
        ik_poses BIGINT
    )""",
    """CREATE TABLE IF NOT EXISTS tplacementclass (
        idtplacementclass BIGINT PRIMARY KEY,
        idtgptable BIGINT NOT NULL REFERENCES tgptable(idtgptable),
        idx INTEGER NOT NULL,
        normal DOUBLE[3] NOT NULL,
        rotmat DOUBLE[16] NOT NULL,
        stability DOUBLE NOT NULL
    )""",
    """CREATE TABLE IF NOT EXISTS tgpcell (
        idtgpcell BIGINT PRIMARY KEY,
        idtgptable BIGINT NOT NULL REFERENCES tgptable(idtgptable),
        idtgraspclass BIGINT NOT NULL REFERENCES tgraspclass(idtgraspclass),
        idtplacementclass BIGINT NOT NULL REFERENCES tplacementclass(idtplacementclass),
        itheta INTEGER NOT NULL,
        theta DOUBLE NOT NULL,
        hand_object BOOLEAN NOT NULL,
        hand_table BOOLEAN NOT NULL,
        phi_lo DOUBLE[] NOT NULL,
        phi_hi DOUBLE[] NOT NULL
    )""",
)


def ensure_schema(store: Store) -> None:
    """Create this planner's tables if missing."""
    if store.read_only:
        return
    with store.transaction():
        for ddl in TABLES:
            store.run(ddl)


def _lists(values: list[np.ndarray]) -> pa.Array:
    offsets = np.concatenate([[0], np.cumsum([len(v) for v in values])]).astype(np.int32)
    flat = np.concatenate(values) if values else np.zeros(0)
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(np.asarray(flat, dtype=np.float64)))


# -- grasp classes -------------------------------------------------------------------------------------------------


def save_classes(store: Store, stage: str, params: dict, idobject: int, classes: list, dropped: list = ()) -> int:
    """Write the grasp classes of one parameter set in one transaction, the `dropped` narrow ones with negative
    indices; returns its paramset id."""
    with store.transaction():
        pid, existed = store.paramset(stage, params, idobject)
        if existed:
            return pid
        idx = np.concatenate([np.arange(len(classes)), -1 - np.arange(len(dropped))]).astype(np.int32)
        classes = list(classes) + list(dropped)
        n = len(classes)
        if n:
            store.insert("tgraspclass", {
                "idtgraspclass": store.new_ids("tgraspclass", n),
                "idparamset": np.full(n, pid, dtype=np.int64),
                "idobject": np.full(n, idobject, dtype=np.int64),
                "idx": idx,
                "kind": np.array([c.kind for c in classes], dtype=object),
                "features": np.array([json.dumps(c.features) for c in classes], dtype=object),
                "normal": np.array([c.normal for c in classes]),
                "u": np.array([c.u for c in classes]),
                "v": np.array([c.v for c in classes]),
                "point": np.array([c.point for c in classes]),
                "eccentricity": np.array([c.eccentricity for c in classes]),
                "opening": np.array([c.opening for c in classes]),
                "theta_lo": _lists([np.array([a for a, _ in c.intervals]) for c in classes]),
                "theta_hi": _lists([np.array([b for _, b in c.intervals]) for c in classes]),
            })
    return pid


def load_classes(store: Store, pid: int) -> list[dict]:
    """The stored grasp classes of paramset `pid` as dicts of GraspClass fields, in index order."""
    rows = store.run("SELECT kind, features, normal, u, v, point, eccentricity, opening, theta_lo, theta_hi "
                     "FROM tgraspclass WHERE idparamset = ? AND idx >= 0 ORDER BY idx", [pid])
    out = []
    for kind, feats, n, u, v, p, e, w, lo, hi in rows:
        out.append(dict(kind=kind, features=json.loads(feats), normal=np.asarray(n, dtype=np.float64),
                        u=np.asarray(u, dtype=np.float64), v=np.asarray(v, dtype=np.float64), point=np.asarray(p, dtype=np.float64),
                        eccentricity=float(e), opening=float(w), intervals=[(float(a), float(b)) for a, b in zip(lo, hi)]))
    return out


def class_ids(store: Store, pid: int) -> np.ndarray:
    """The ids of a class parameter set's grasp classes, in their index order."""
    return np.array([r[0] for r in store.run("SELECT idtgraspclass FROM tgraspclass WHERE idparamset = ? AND idx >= 0 "
                                             "ORDER BY idx", [pid])], dtype=np.int64)


def dropped_classes(store: Store, pid: int) -> tuple[int, float]:
    """How many classes paramset `pid` dropped as narrow, and the widest of their legal ranges (radians; 0 if none)."""
    rows = store.run("SELECT theta_lo, theta_hi FROM tgraspclass WHERE idparamset = ? AND idx < 0", [pid])
    widths = [sum(b - a for a, b in zip(lo, hi)) for lo, hi in rows]
    return len(widths), float(max(widths, default=0.0))


# -- the table -----------------------------------------------------------------------------------------------------


def find_paramset(store: Store, stage: str, params: dict, idobject: int) -> int | None:
    """The id of a stored parameter set of `stage` for this object, if any."""
    return store.find_paramset(stage, params, idobject)


def save_table(store: Store, stage: str, params: dict, idobject: int, idrobot: int, idclasses: int, table,
               normals: np.ndarray, stability: np.ndarray) -> int:
    """Write a grasp-placement table (row, placement classes, cells) in one transaction; returns its paramset id."""
    c_n, p_n, t_n, f_n = table.q.shape
    cids = class_ids(store, idclasses)
    if len(cids) != c_n:
        raise StoreError(f"store {store.path}: grasp class set {idclasses} has {len(cids)} rows, the table {c_n}")
    # phi runs of every (class, placement, theta) row, not wrapped: vectorised with diff
    mask = table.q.reshape(-1, f_n)
    pad = np.zeros((len(mask), f_n + 2), dtype=np.int8)
    pad[:, 1:-1] = mask
    d = np.diff(pad, axis=1)
    rs, cs = np.nonzero(d == 1)
    re, ce = np.nonzero(d == -1)
    counts = np.bincount(rs, minlength=len(mask))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int32)
    lo = pa.ListArray.from_arrays(pa.array(offsets), pa.array(table.phi[cs]))
    hi = pa.ListArray.from_arrays(pa.array(offsets), pa.array(table.phi[ce - 1]))
    with store.transaction():
        pid, existed = store.paramset(stage, params, idobject)
        if existed:
            return pid
        tid = store.new_ids("tgptable", 1)[0]
        store.run("INSERT INTO tgptable (idtgptable, idparamset, idobject, idrobot, idclasses, ntheta, nphi, table_point, nclasses, "
                  "nplacements, nonempty_cells, seconds_hand_object, seconds_hand_table, seconds_ik, ik_poses) "
                  "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                  [int(tid), pid, idobject, idrobot, idclasses, t_n, f_n, table.frame[:2, 3].tolist(), c_n, p_n,
                   int(table.q.any(axis=(2, 3)).sum()), table.timings.get("hand_object"), table.timings.get("hand_table"),
                   table.timings.get("ik"), int(table.timings.get("ik_poses", 0))])
        pids = store.new_ids("tplacementclass", p_n)
        if p_n == 0:
            return pid
        store.insert("tplacementclass", {"idtplacementclass": pids, "idtgptable": np.full(p_n, tid, dtype=np.int64),
                                         "idx": np.arange(p_n, dtype=np.int32), "normal": np.asarray(normals).reshape(p_n, 3),
                                         "rotmat": table.placements.reshape(p_n, 16), "stability": np.asarray(stability, dtype=np.float64)})
        ci, pj, tk = np.meshgrid(np.arange(c_n), np.arange(p_n), np.arange(t_n), indexing="ij")
        n = c_n * p_n * t_n
        if n == 0:
            return pid
        store.insert("tgpcell", {
            "idtgpcell": store.new_ids("tgpcell", n),
            "idtgptable": np.full(n, tid, dtype=np.int64),
            "idtgraspclass": cids[ci.ravel()],
            "idtplacementclass": pids[pj.ravel()],
            "itheta": tk.ravel().astype(np.int32),
            "theta": table.theta[tk.ravel()],
            "hand_object": np.broadcast_to(table.hand_object[:, None, :], (c_n, p_n, t_n)).ravel(),
            "hand_table": table.hand_table.ravel(),
            "phi_lo": lo,
            "phi_hi": hi,
        })
    return pid


def load_table(store: Store, pid: int) -> dict:
    """A stored table: its row, placement classes and the arrays q (C, P, T, F), hand_object (C, T), hand_table (C, P, T)."""
    row = store.one("SELECT idtgptable, idobject, idrobot, idclasses, ntheta, nphi, table_point, nclasses, nplacements, "
                    "seconds_hand_object, seconds_hand_table, seconds_ik, ik_poses FROM tgptable WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no grasp-placement table for paramset {pid}; run `workbench gptable` first")
    tid, oid, rid, cpid, t_n, f_n, point, c_n, p_n, s1, s2, s3, nik = row
    pl = store.query_arrays("SELECT idx, normal, rotmat, stability FROM tplacementclass WHERE idtgptable = ? ORDER BY idx", [tid])
    cells = store.arrow("SELECT g.idx AS ci, p.idx AS pj, c.itheta, c.hand_object, c.hand_table, c.phi_lo, c.phi_hi "
                        "FROM tgpcell c JOIN tgraspclass g USING (idtgraspclass) JOIN tplacementclass p USING (idtplacementclass) "
                        "WHERE c.idtgptable = ?", [int(tid)])
    ci = cells.column("ci").to_numpy()
    pj = cells.column("pj").to_numpy()
    tk = cells.column("itheta").to_numpy()
    ho = np.zeros((c_n, t_n), dtype=bool)
    ht = np.zeros((c_n, p_n, t_n), dtype=bool)
    ho[ci, tk] = cells.column("hand_object").to_numpy(zero_copy_only=False)
    ht[ci, pj, tk] = cells.column("hand_table").to_numpy(zero_copy_only=False)
    q = np.zeros((c_n, p_n, t_n, f_n + 1), dtype=np.int32)
    step = 2 * np.pi / f_n
    for name, sign, shift in (("phi_lo", 1, 0), ("phi_hi", -1, 1)):
        col = cells.column(name).combine_chunks()
        vals = col.flatten().to_numpy()
        counts = np.diff(col.offsets.to_numpy())
        rows = np.repeat(np.arange(len(counts)), counts)
        idx = np.round(vals / step).astype(np.int64) + shift
        np.add.at(q, (ci[rows], pj[rows], tk[rows], idx), sign)
    q = np.cumsum(q, axis=3)[..., :f_n] > 0
    return {"idtgptable": int(tid), "idobject": int(oid), "idrobot": int(rid), "idclasses": int(cpid), "table_point": tuple(point),
            "ntheta": int(t_n), "nphi": int(f_n), "placements": pl["rotmat"].reshape(-1, 4, 4), "normals": pl["normal"],
            "stability": pl["stability"], "q": q, "hand_object": ho, "hand_table": ht,
            "timings": {"hand_object": s1, "hand_table": s2, "ik": s3, "ik_poses": nik}}


def latest_table(store: Store, idobject: int, idrobot: int | None = None) -> int:
    """The paramset id of the newest table of an object (and robot), or a StoreError."""
    sql = "SELECT idparamset FROM tgptable WHERE idobject = ?" + (" AND idrobot = ?" if idrobot is not None else "")
    row = store.one(sql + " ORDER BY idtgptable DESC LIMIT 1", [idobject] + ([idrobot] if idrobot is not None else []))
    if row is None:
        raise StoreError(f"store {store.path} has no grasp-placement table for this object and robot; run `workbench gptable` first")
    return int(row[0])


def table_robot(store: Store, pid: int) -> int:
    """The idrobot of the table with paramset `pid`."""
    row = store.one("SELECT idrobot FROM tgptable WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no grasp-placement table for paramset {pid}; run `workbench gptable` first")
    return int(row[0])


def gripper_id(store: Store, digest: str) -> int:
    """The idgripper of the stored gripper with this digest."""
    row = store.one("SELECT idgripper FROM gripper WHERE digest = ?", [digest])
    if row is None:
        raise StoreError(f"store {store.path} has no row of this gripper; rebuild the table with `workbench gptable`")
    return int(row[0])


# -- rows of the paper's tables for plans (the `plan` / `planstep` tables of store.wan_harada) ------------------------


def placement_rows(store: Store, idtable: int, idobject: int, placements: np.ndarray, stability: np.ndarray) -> np.ndarray:
    """The `freetabletopplacement` ids of a table's placement classes in index order (idparamset = the table's
    `tournassoud.table` paramset), written on first use; call inside a transaction."""
    have = store.query_arrays("SELECT idfreetabletopplacement FROM freetabletopplacement WHERE idparamset = ? "
                              "ORDER BY idfreetabletopplacement", [idtable])["idfreetabletopplacement"]
    p_n = len(placements)
    if len(have) == p_n:
        return np.asarray(have, dtype=np.int64)
    if len(have):
        raise StoreError(f"store {store.path}: table {idtable} has {len(have)} placement rows, not {p_n}; rebuild it in a new store")
    ids = store.new_ids("freetabletopplacement", p_n)
    if p_n:
        store.insert("freetabletopplacement", {"idfreetabletopplacement": ids, "idobject": np.full(p_n, idobject, dtype=np.int64),
                                               "idparamset": np.full(p_n, idtable, dtype=np.int64),
                                               "rotmat": np.asarray(placements, dtype=np.float64).reshape(p_n, 16),
                                               "stability": np.asarray(stability, dtype=np.float64)})
    return ids


def grasp_rows(store: Store, idclasses: int, idobject: int, idgripper: int, grasps: dict[str, np.ndarray]) -> np.ndarray:
    """The `freeairgrip` ids of grasps (G_i, theta) of a class set: `grasps` holds arrays `cls` (class index, stored
    in `idcontactpair`), `theta` (radians in [0, 2 pi), stored in `rotation`), `rotmat` (N, 4, 4) TCP in the object
    frame, `jawwidth`, `contactpoint0/1`, `contactnormal0/1` (N, 3). A grasp already stored (same class, theta to
    1e-12) keeps its id; the others are written. Call inside a transaction."""
    n = len(grasps["cls"])
    out = np.zeros(n, dtype=np.int64)
    have = store.query_arrays("SELECT idfreeairgrip, idcontactpair, rotation FROM freeairgrip WHERE idparamset = ? "
                              "ORDER BY idfreeairgrip", [idclasses])
    new: list[int] = []
    for k in range(n):
        c, th = int(grasps["cls"][k]), float(grasps["theta"][k])
        hit = np.flatnonzero((have["idcontactpair"] == c) & (np.abs(have["rotation"] - th) < 1e-12))
        if len(hit):
            out[k] = int(have["idfreeairgrip"][hit[0]])
            continue
        dup = [j for j in new if int(grasps["cls"][j]) == c and abs(float(grasps["theta"][j]) - th) < 1e-12]
        out[k] = -1 - (dup[0] if dup else k)
        if not dup:
            new.append(k)
    if new:
        ids = store.new_ids("freeairgrip", len(new))
        sel = np.array(new)
        m = len(sel)
        store.insert("freeairgrip", {
            "idfreeairgrip": ids, "idobject": np.full(m, idobject, dtype=np.int64),
            "idparamset": np.full(m, idclasses, dtype=np.int64), "idgripper": np.full(m, idgripper, dtype=np.int64),
            **{c: np.asarray(grasps[c], dtype=np.float64)[sel].reshape(m, 3)
               for c in ("contactpoint0", "contactpoint1", "contactnormal0", "contactnormal1")},
            "rotmat": np.asarray(grasps["rotmat"], dtype=np.float64)[sel].reshape(m, 16),
            "jawwidth": np.asarray(grasps["jawwidth"], dtype=np.float64)[sel],
            "idcontactpair": np.asarray(grasps["cls"], dtype=np.int64)[sel],
            "rotation": np.asarray(grasps["theta"], dtype=np.float64)[sel]})
        where = {k: i for k, i in zip(new, ids)}
        for k in range(n):
            if out[k] < 0:
                out[k] = where[-1 - out[k]]
    return out


def table_ids(store: Store, pid: int) -> dict[str, int]:
    """idobject, idrobot and idclasses of the table with paramset `pid`."""
    row = store.one("SELECT idobject, idrobot, idclasses FROM tgptable WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no grasp-placement table for paramset {pid}; run `workbench gptable` first")
    return {"idobject": int(row[0]), "idrobot": int(row[1]), "idclasses": int(row[2])}


def stored_placements(store: Store, idtable: int) -> dict[int, np.ndarray]:
    """{idfreetabletopplacement: rotmat (4, 4)} of a table's placement rows (empty before its first stored plan)."""
    rows = store.query_arrays("SELECT idfreetabletopplacement, rotmat FROM freetabletopplacement WHERE idparamset = ? "
                              "ORDER BY idfreetabletopplacement", [idtable])
    return {int(i): np.asarray(m, dtype=np.float64).reshape(4, 4) for i, m in zip(rows["idfreetabletopplacement"], rows["rotmat"])}


def plan_scene(store: Store, idplan: int) -> int:
    """The idscene of a stored plan."""
    row = store.one("SELECT idscene FROM plan WHERE idplan = ?", [idplan])
    if row is None:
        raise StoreError(f"store {store.path} has no plan {idplan}")
    return int(row[0])


def placement_stability(store: Store, pid: int) -> np.ndarray:
    """The stability of a table's placement classes in index order."""
    row = store.one("SELECT idtgptable FROM tgptable WHERE idparamset = ?", [pid])
    if row is None:
        raise StoreError(f"store {store.path} has no grasp-placement table for paramset {pid}; run `workbench gptable` first")
    return store.query_arrays("SELECT stability FROM tplacementclass WHERE idtgptable = ? ORDER BY idx", [int(row[0])])["stability"]
