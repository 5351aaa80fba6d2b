"""SQL of the `robot`, `scene`, `ikret` and `ik` tables (Wan & Harada Section IV; CONVENTIONS.md, Store).

- robot: URDF text, TCP frame, tip frame, mount (tip to TCP), base pose in the world, joint names (the order of
  stored joint vectors) and a digest of the kinematics. A stored joint vector q is checked without the library:
  load the URDF text with pinocchio (every other joint at 0), set q by joint name, TCP = base @ oMf(tip) @ mount.
  A robot whose name is taken by other kinematics (another base, say) is stored as `name-<digest[:8]>`.
- scene: the table, workspace box and solver options of an IK run, plus the robot's locked joint values and
  replaced collision links (JSON `params`; keys: the Scene fields, `ik` (IKOptions), `robot`).
- ikret: retraction distances (handx, worldz) in metres, reused when equal.
- ik: one row per (robot, tabletop grip, ikret, scene): the three feasibility flags and the joint vectors
  (jnt_grasp, jnt_handx, jnt_handxworldz; NULL where infeasible).

Robot, scene and ikret rows of a run are written in one transaction; the `ik` rows chunk by chunk, each chunk in
its own transaction, so an interrupted run keeps its finished chunks and a re-run computes only the rest.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from workbench.errors import StoreError
from workbench.robots.collider import Scene
from workbench.robots.ik import IKOptions
from workbench.robots.model import Robot
from workbench.store import Store, from_arrow
from workbench.store.objects import put_gripper


def put_robot(store: Store, robot: Robot, allowed_pairs: str | None = None) -> int:
    """The id of the robot's row (created if new; `allowed_pairs` JSON stored when given and missing); call inside a
    transaction."""
    digest = robot.spec.digest
    row = store.one("SELECT idrobot, allowed_pairs FROM robot WHERE digest = ?", [digest])
    if row is not None:
        if row[1] is None and allowed_pairs is not None:
            store.run("UPDATE robot SET allowed_pairs = ? WHERE idrobot = ?", [allowed_pairs, int(row[0])])
        return int(row[0])
    name = robot.name
    if store.one("SELECT idrobot FROM robot WHERE name = ?", [name]) is not None:
        name = f"{robot.name}-{digest[:8]}"
    rid = store.next_id("robot", "idrobot")
    gid = put_gripper(store, robot.gripper)
    store.run("INSERT INTO robot (idrobot, name, urdf, tcp_frame, tip_frame, mount, base, joint_names, locked, "
              "drop_geometry, digest, package_dirs, idgripper, allowed_pairs) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
              [rid, name, robot.spec.urdf, robot.spec.tcp_frame, robot.spec.tip_frame, robot.mount.ravel().tolist(),
               robot.base.ravel().tolist(), list(robot.joint_names),
               json.dumps({k: float(v) for k, v in robot.spec.locked}, sort_keys=True), list(robot.spec.drop_geometry),
               digest, list(robot.spec.package_dirs) + ([str(Path(robot.spec.urdf_path).parent)] if robot.spec.urdf_path else []),
               gid, allowed_pairs])
    return rid


def put_scene(store: Store, params: dict[str, Any]) -> int:
    """The id of the scene with these parameters (created if new); call inside a transaction."""
    text = json.dumps(params, sort_keys=True)
    digest = hashlib.sha256(text.encode()).hexdigest()[:24]
    row = store.one("SELECT idscene FROM scene WHERE digest = ?", [digest])
    if row is not None:
        return int(row[0])
    sid = store.next_id("scene", "idscene")
    store.run("INSERT INTO scene (idscene, digest, params) VALUES (?, ?, ?)", [sid, digest, text])
    return sid


def put_ikret(store: Store, handx: float, worldz: float) -> int:
    """The id of the retraction set (handx, worldz) in metres (created if new); call inside a transaction."""
    row = store.one("SELECT idikret FROM ikret WHERE handx = ? AND worldz = ?", [float(handx), float(worldz)])
    if row is not None:
        return int(row[0])
    kid = store.next_id("ikret", "idikret")
    store.run("INSERT INTO ikret (idikret, handx, worldz) VALUES (?, ?, ?)", [kid, float(handx), float(worldz)])
    return kid


def prepare_run(store: Store, robot: Robot, scene_params: dict[str, Any], handx: float, worldz: float,
                allowed_pairs: str | None = None) -> tuple[int, int, int]:
    """Robot (with its allowed self-collision pairs, JSON), scene and ikret rows of one IK run in one transaction:
    (idrobot, idscene, idikret)."""
    with store.transaction():
        return put_robot(store, robot, allowed_pairs), put_scene(store, scene_params), put_ikret(store, handx, worldz)


def stored_grips(store: Store, idrobot: int, idscene: int, idikret: int) -> np.ndarray:
    """The idtabletopgrips that already have an `ik` row for this robot, scene and retraction set (sorted)."""
    out = store.query_arrays("SELECT idtabletopgrips FROM ik WHERE idrobot = ? AND idscene = ? AND idikret = ? "
                             "ORDER BY idtabletopgrips", [idrobot, idscene, idikret])
    return np.asarray(out["idtabletopgrips"], dtype=np.int64)


def _joint_lists(joints: np.ndarray, feasible: np.ndarray) -> pa.Array:
    """(N, n) joints to a DOUBLE[] Arrow column, NULL where not feasible (no per-row Python)."""
    n, width = joints.shape
    rows = np.flatnonzero(feasible)
    offsets = np.zeros(n + 1, dtype=np.int32)
    offsets[1:] = np.cumsum(np.where(feasible, width, 0))
    values = pa.array(np.ascontiguousarray(joints[rows]).ravel(), type=pa.float64())
    mask = pa.array(~np.asarray(feasible, dtype=bool))
    return pa.ListArray.from_arrays(pa.array(offsets), values, mask=mask)


def insert_ik(store: Store, idrobot: int, idscene: int, idikret: int, grip_ids: np.ndarray, feasible: np.ndarray,
              joints: np.ndarray) -> int:
    """Write one chunk of `ik` rows in its own transaction; returns the number of rows."""
    grip_ids = np.asarray(grip_ids, dtype=np.int64)
    feasible = np.asarray(feasible, dtype=bool).reshape(len(grip_ids), 3)
    joints = np.asarray(joints, dtype=np.float64).reshape(len(grip_ids), 3, -1)
    n = len(grip_ids)
    if n == 0:
        return 0
    with store.transaction():
        store.insert("ik", {
            "idik": store.new_ids("ik", n), "idrobot": np.full(n, idrobot, dtype=np.int64),
            "idtabletopgrips": grip_ids, "idikret": np.full(n, idikret, dtype=np.int64),
            "idscene": np.full(n, idscene, dtype=np.int64), "feasibility": feasible[:, 0],
            "feasibility_handx": feasible[:, 1], "feasibility_handxworldz": feasible[:, 2],
            "jnt_grasp": _joint_lists(joints[:, 0], feasible[:, 0]), "jnt_handx": _joint_lists(joints[:, 1], feasible[:, 1]),
            "jnt_handxworldz": _joint_lists(joints[:, 2], feasible[:, 2])})
    return n


def run_counts(store: Store, idrobot: int, idscene: int, idikret: int, idtabletop: int) -> tuple[int, int]:
    """(feasible at the grasp, feasible with both retractions) of one IK run over a tabletop parameter set."""
    row = store.one("SELECT count(*) FILTER (WHERE k.feasibility), "
                    "count(*) FILTER (WHERE k.feasibility AND k.feasibility_handx AND k.feasibility_handxworldz) "
                    "FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
                    "WHERE k.idrobot = ? AND k.idscene = ? AND k.idikret = ? AND p.idparamset = ?",
                    [idrobot, idscene, idikret, idtabletop])
    return int(row[0] or 0), int(row[1] or 0)


def ikret_row(store: Store, idikret: int) -> tuple[float, float]:
    """(handx, worldz) of a retraction set, metres."""
    row = store.one("SELECT handx, worldz FROM ikret WHERE idikret = ?", [idikret])
    if row is None:
        raise StoreError(f"store {store.path} has no ikret {idikret}; run `workbench ik` first")
    return float(row[0]), float(row[1])


def robot_row(store: Store, robot: int | str) -> dict[str, Any]:
    """The stored robot with this id (int) or name: urdf, tcp_frame, tip_frame, mount (4, 4), base (4, 4),
    joint_names, locked ({joint: value}), drop_geometry, digest, allowed_pairs (JSON or None); a StoreError naming the stored robots if none."""
    by_id = isinstance(robot, (int, np.integer))
    row = store.one("SELECT idrobot, name, urdf, tcp_frame, tip_frame, mount, base, joint_names, locked, drop_geometry, "
                    f"digest, package_dirs, idgripper, allowed_pairs FROM robot WHERE {'idrobot' if by_id else 'name'} = ?",
                    [int(robot) if by_id else robot])
    if row is None:
        names = [r[0] for r in store.run("SELECT name FROM robot ORDER BY name")]
        raise StoreError(f"store {store.path} has no robot {robot!r} (it has: {', '.join(names) or 'none'}); "
                         f"run `workbench ik --robot NAME` or `workbench build --robot NAME` first")
    rid, name, urdf, tcp, tip, mount, base, joints, locked, drop, digest, dirs, gid, allowed = row
    return {"idrobot": int(rid), "name": name, "urdf": urdf, "tcp_frame": tcp, "tip_frame": tip,
            "mount": np.asarray(mount, dtype=np.float64).reshape(4, 4), "base": np.asarray(base, dtype=np.float64).reshape(4, 4),
            "joint_names": list(joints), "locked": json.loads(locked), "drop_geometry": list(drop), "digest": digest,
            "package_dirs": list(dirs or []), "idgripper": None if gid is None else int(gid), "allowed_pairs": allowed}


@dataclass(frozen=True)
class StoredScene:
    """A stored `scene` row, typed: the table and workspace, the IK solver settings and the robot's extras
    (locked joints, dropped hand geometry, gripper digest) that entered the `ik` rows."""

    idscene: int
    scene: Scene
    ik: IKOptions
    robot: dict


def scene_row(store: Store, idscene: int) -> StoredScene:
    """The one reader of a stored scene's parameters (written by `stages.scene_params`)."""
    row = store.one("SELECT params FROM scene WHERE idscene = ?", [idscene])
    if row is None:
        raise StoreError(f"store {store.path} has no scene {idscene}; run `workbench ik` first")
    d = json.loads(row[0])

    def pick(cls, values: dict) -> dict:
        names = {f.name for f in fields(cls)}
        return {k: (tuple(v) if isinstance(v, list) else v) for k, v in values.items() if k in names}

    return StoredScene(int(idscene), Scene(**pick(Scene, d)), IKOptions(**pick(IKOptions, d.get("ik") or {})),
                       dict(d.get("robot") or {}))

def load_ik(store: Store, idrobot: int, idscene: int, idikret: int, idobject: int | None = None) -> dict[str, np.ndarray]:
    """The `ik` rows of a run joined with their tabletop grips, ordered by idtabletopgrips: idik, idtabletopgrips,
    idtabletopplacements, idfreeairgrip, rotmat (N, 4, 4), placement_rotmat (N, 4, 4), tabletopposition (N, 3),
    idangle, feasible (N, 3) and joints (N, 3, nq), NaN where infeasible."""
    nq = len(robot_row(store, idrobot)["joint_names"])
    sql = ("SELECT k.idik, k.idtabletopgrips, g.idtabletopplacements, g.idfreeairgrip, g.rotmat, g.jawwidth, "
           "p.rotmat AS placement_rotmat, p.tabletopposition, p.idangle, "
           "k.feasibility, k.feasibility_handx, k.feasibility_handxworldz, k.jnt_grasp, k.jnt_handx, k.jnt_handxworldz "
           "FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
           "JOIN freetabletopplacement f USING (idfreetabletopplacement) "
           "WHERE k.idrobot = ? AND k.idscene = ? AND k.idikret = ?")
    params: list[Any] = [idrobot, idscene, idikret]
    if idobject is not None:
        sql += " AND f.idobject = ?"
        params.append(idobject)
    table = store.con.sql(sql + " ORDER BY k.idtabletopgrips", params=params).to_arrow_table()

    out = {c: from_arrow(table.column(c)) for c in ("idik", "idtabletopgrips", "idtabletopplacements", "idfreeairgrip",
                                                      "jawwidth", "idangle")}
    n = len(out["idik"])
    out["rotmat"] = np.asarray(from_arrow(table.column("rotmat")), dtype=np.float64).reshape(n, 4, 4)
    out["placement_rotmat"] = np.asarray(from_arrow(table.column("placement_rotmat")), dtype=np.float64).reshape(n, 4, 4)
    out["tabletopposition"] = np.asarray(from_arrow(table.column("tabletopposition")), dtype=np.float64).reshape(n, 3)
    out["feasible"] = np.stack([np.asarray(from_arrow(table.column(c)), dtype=bool) for c in
                                ("feasibility", "feasibility_handx", "feasibility_handxworldz")], axis=1).reshape(n, 3)
    joints = np.full((n, 3, nq), np.nan)
    for k, c in enumerate(("jnt_grasp", "jnt_handx", "jnt_handxworldz")):
        col = table.column(c).combine_chunks()
        valid = ~np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
        if valid.any():
            flat = np.asarray(col.filter(pa.array(valid)).flatten().to_numpy(zero_copy_only=False), dtype=np.float64)
            joints[valid, k] = flat.reshape(-1, nq)
    out["joints"] = joints
    return out


def ik_runs(store: Store, idobject: int | None = None, idtabletop: int | None = None,
            idrobot: int | None = None) -> list[dict[str, Any]]:
    """Stored IK runs, optionally of one object, tabletop parameter set and robot: idrobot, robot name, idscene,
    idikret, handx, worldz, rows, feasible counts (grasp, all three) and the newest idik (`last`)."""
    sql = ("SELECT k.idrobot, r.name, k.idscene, k.idikret, i.handx, i.worldz, count(*) AS n, "
           "count(*) FILTER (WHERE k.feasibility) AS f0, "
           "count(*) FILTER (WHERE k.feasibility AND k.feasibility_handx AND k.feasibility_handxworldz) AS f3, "
           "max(k.idik) AS last "
           "FROM ik k JOIN robot r USING (idrobot) JOIN ikret i USING (idikret) "
           "JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
           "JOIN freetabletopplacement f USING (idfreetabletopplacement) WHERE true")
    params: list[Any] = []
    for column, value in (("f.idobject", idobject), ("p.idparamset", idtabletop), ("k.idrobot", idrobot)):
        if value is not None:
            sql += f" AND {column} = ?"
            params.append(int(value))
    sql += " GROUP BY k.idrobot, r.name, k.idscene, k.idikret, i.handx, i.worldz ORDER BY k.idrobot, k.idscene, k.idikret"
    keys = ("idrobot", "robot", "idscene", "idikret", "handx", "worldz", "rows", "feasible", "feasible_all", "last")
    return [dict(zip(keys, r)) for r in store.run(sql, params)]
