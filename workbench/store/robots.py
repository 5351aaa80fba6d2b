"""SQL of the `robot`, `scene`, `ikret` and `ik` tables (Wan & Harada Section IV; CONVENTIONS.md, Store).

- robot: URDF text, TCP frame, tip frame, mount (tip to TCP), base pose in the world, joint names (the order of
  stored joint vectors) and a digest of the kinematics. A stored joint vector q is checked without the library:
  load the URDF text with pinocchio (every other joint at 0), set q by joint name, TCP = base @ oMf(tip) @ mount.
  A robot whose name is taken by other kinematics (another base, say) is stored as `name-<digest[:8]>`.
- scene: the table, workspace box and solver options of an IK run, plus the robot's locked joint values and
  replaced collision links (JSON `params`; keys: the Scene fields, `ik` (IKOptions), `robot`).
- ikret: retraction distances (handx, worldz, worlda) in metres, reused when equal.
- ik: one row per (robot, tabletop grip, ikret, scene): the five feasibility flags (FEASIBILITY, in the order of
  `robots.ik.KINDS`) and the joint vectors (JOINTS; NULL where infeasible).

Robot, scene and ikret rows of a run are written in one transaction; the `ik` rows chunk by chunk, each chunk in
its own transaction, so an interrupted run keeps its finished chunks and a re-run computes only the rest.
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
import pyarrow as pa
from scipy.spatial.transform import Rotation

from workbench.errors import StoreError
from workbench.robots.collider import Scene
from workbench.robots.ik import IKOptions
from workbench.robots.model import Robot
from workbench.store import Store, from_arrow
from workbench.store.identity import IK_STAGE, ik_runkey
from workbench.store.objects import put_gripper


def put_robot(store: Store, robot: Robot, allowed_pairs: str | Callable[[], str] | None = None) -> int:
    """The id of the robot's row (created if new; `allowed_pairs` JSON stored when given and missing, computed by
    calling it only then when it is a function); call inside a transaction."""
    digest = robot.spec.digest
    row = store.one("SELECT idrobot, allowed_pairs FROM robot WHERE digest = ?", [digest])
    if row is not None:
        if row[1] is None and allowed_pairs is not None:
            store.run("UPDATE robot SET allowed_pairs = ? WHERE idrobot = ?",
                      [allowed_pairs() if callable(allowed_pairs) else allowed_pairs, int(row[0])])
        return int(row[0])
    if callable(allowed_pairs):
        allowed_pairs = allowed_pairs()
    name = robot.name
    if store.one("SELECT idrobot FROM robot WHERE name = ?", [name]) is not None:
        name = f"{robot.name}-{digest[:8]}"
    rid = store.next_id("robot", "idrobot")
    gid = put_gripper(store, robot.gripper)
    store.run("INSERT INTO robot (idrobot, name, urdf, tcp_frame, tip_frame, mount, base, joint_names, locked, "
              "drop_geometry, digest, package_dirs, idgripper, allowed_pairs) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
              [rid, name, with_tcp_link(robot.spec.urdf, robot.spec.tip_frame, robot.spec.tcp_frame, robot.mount),
               robot.spec.tcp_frame, robot.spec.tip_frame, robot.mount.ravel().tolist(),
               robot.base.ravel().tolist(), list(robot.joint_names),
               json.dumps({k: float(v) for k, v in robot.spec.locked}, sort_keys=True), list(robot.spec.drop_geometry),
               digest, list(robot.package_dirs),
               gid, allowed_pairs])
    return rid


_TCP_BEGIN = "<!-- workbench: the TCP frame, fixed to the tip at the mount -->"
_TCP_END = "<!-- workbench: end of the TCP frame -->"


def with_tcp_link(urdf: str, tip: str, tcp: str, mount: np.ndarray) -> str:
    """The URDF text as stored: where it has no link named `tcp`, one is added, fixed to the link `tip` at `mount`
    (4, 4), so that the TCP is found by its name in the stored URDF alone (CONVENTIONS.md, Store). Unchanged when
    the TCP is the tip, the URDF has it, or the tip is not a link."""
    def has_link(name: str) -> bool:
        return re.search(rf"<link\s+name\s*=\s*[\"']{re.escape(name)}[\"']", urdf) is not None

    if tcp == tip or has_link(tcp) or not has_link(tip) or "</robot>" not in urdf:
        return urdf
    mount = np.asarray(mount, dtype=np.float64).reshape(4, 4)
    xyz = " ".join(repr(float(v)) for v in mount[:3, 3])
    # URDF's roll, pitch, yaw: fixed axes x, y, z
    rpy = " ".join(repr(float(v)) for v in Rotation.from_matrix(mount[:3, :3]).as_euler("xyz"))
    block = (f"  {_TCP_BEGIN}\n  <link name=\"{tcp}\"/>\n  <joint name=\"{tcp}_fixed\" type=\"fixed\">\n"
             f"    <parent link=\"{tip}\"/>\n    <child link=\"{tcp}\"/>\n    <origin xyz=\"{xyz}\" rpy=\"{rpy}\"/>\n"
             f"  </joint>\n  {_TCP_END}\n")
    at = urdf.rindex("</robot>")
    return urdf[:at] + block + urdf[at:]


def without_tcp_link(urdf: str) -> str:
    """The URDF text the robot was given (`with_tcp_link` undone): the library adds the TCP frame itself."""
    begin = urdf.find(f"  {_TCP_BEGIN}")
    if begin < 0:
        return urdf
    end = urdf.index(_TCP_END, begin) + len(_TCP_END) + 1
    return urdf[:begin] + urdf[end:]


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


FEASIBILITY = ("feasibility", "feasibility_handx", "feasibility_handxworldz", "feasibility_worlda", "feasibility_worldaworldz")
JOINTS = ("jnt_grasp", "jnt_handx", "jnt_handxworldz", "jnt_worlda", "jnt_worldaworldz")
ALL_FEASIBLE = " AND ".join(f"k.{c}" for c in FEASIBILITY)


def put_ikret(store: Store, handx: float, worldz: float, worlda: float) -> int:
    """The id of the retraction set (handx, worldz, worlda) in metres (created if new); call inside a transaction."""
    args = [float(handx), float(worldz), float(worlda)]
    row = store.one("SELECT idikret FROM ikret WHERE handx = ? AND worldz = ? AND worlda = ?", args)
    if row is not None:
        return int(row[0])
    kid = store.next_id("ikret", "idikret")
    store.run("INSERT INTO ikret (idikret, handx, worldz, worlda) VALUES (?, ?, ?, ?)", [kid, *args])
    return kid


def prepare_run(store: Store, robot: Robot, scene_params: dict[str, Any], handx: float, worldz: float,
                worlda: float, allowed_pairs: str | Callable[[], str] | None = None) -> tuple[int, int, int]:
    """Robot (with its allowed self-collision pairs, JSON), scene and ikret rows of one IK run in one transaction:
    (idrobot, idscene, idikret)."""
    with store.transaction():
        return (put_robot(store, robot, allowed_pairs), put_scene(store, scene_params),
                put_ikret(store, handx, worldz, worlda))


def robot_name(store: Store, idrobot: int) -> str:
    """The stored name of robot `idrobot`."""
    return str(store.one("SELECT name FROM robot WHERE idrobot = ?", [int(idrobot)])[0])


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
    """Write one chunk of `ik` rows in its own transaction, leaving out grips whose row another process running the
    same IK run stored meanwhile; returns the number of rows written."""
    grip_ids = np.asarray(grip_ids, dtype=np.int64)
    k = len(FEASIBILITY)
    feasible = np.asarray(feasible, dtype=bool).reshape(len(grip_ids), k)
    joints = np.asarray(joints, dtype=np.float64).reshape(len(grip_ids), k, -1)
    if len(grip_ids) == 0:
        return 0
    with store.transaction():
        stored = store.query_arrays("SELECT idtabletopgrips FROM ik WHERE idrobot = ? AND idscene = ? AND idikret = ? AND "
                                    "idtabletopgrips BETWEEN ? AND ?", [idrobot, idscene, idikret, int(grip_ids.min()),
                                                                          int(grip_ids.max())])["idtabletopgrips"]
        new = ~np.isin(grip_ids, np.asarray(stored, dtype=np.int64))
        n = int(new.sum())
        if n == 0:
            return 0
        # ids in the given order; rows appended in key order, which DuckDB's key and index checks take ~2x faster
        take = np.flatnonzero(new)
        take = take[np.argsort(grip_ids[take], kind="stable")]
        ids = store.new_ids("ik", n)[(np.cumsum(new) - 1)[take]]
        grip_ids, feasible, joints = grip_ids[take], feasible[take], joints[take]
        store.insert("ik", {
            "idik": ids, "idrobot": np.full(n, idrobot, dtype=np.int64),
            "idtabletopgrips": grip_ids, "idikret": np.full(n, idikret, dtype=np.int64),
            "idscene": np.full(n, idscene, dtype=np.int64),
            **{c: feasible[:, i] for i, c in enumerate(FEASIBILITY)},
            **{c: _joint_lists(joints[:, i], feasible[:, i]) for i, c in enumerate(JOINTS)}})
    return n


def ik_progress(store: Store, idtabletop: int, idrobot: int, idscene: int, idikret: int) -> tuple[int, int, bool]:
    """(rows stored, tabletop grips, complete) of one IK run; complete when its completion is recorded or every grip
    has its row (the IK stage writes chunk by chunk, so a killed run leaves some chunks)."""
    rows = store.one("SELECT count(*) FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) "
                     "JOIN tabletopplacements p USING (idtabletopplacements) "
                     "WHERE k.idrobot = ? AND k.idscene = ? AND k.idikret = ? AND p.idparamset = ?",
                     [idrobot, idscene, idikret, idtabletop])[0]
    grips = store.one("SELECT count(*) FROM tabletopgrips g JOIN tabletopplacements p USING (idtabletopplacements) "
                      "WHERE p.idparamset = ?", [idtabletop])[0]
    done = store.is_complete(IK_STAGE, ik_runkey(idtabletop, idrobot, idscene, idikret)) or rows == grips
    return int(rows), int(grips), bool(done)


def mark_ik_complete(store: Store, idtabletop: int, idrobot: int, idscene: int, idikret: int) -> bool:
    """Record the run complete when every tabletop grip has its row; returns whether it is."""
    rows, grips, _ = ik_progress(store, idtabletop, idrobot, idscene, idikret)
    if rows == grips:
        store.mark_complete(IK_STAGE, ik_runkey(idtabletop, idrobot, idscene, idikret), rows)
    return rows == grips


def run_counts(store: Store, idrobot: int, idscene: int, idikret: int, idtabletop: int) -> tuple[int, int]:
    """(feasible at the grasp, feasible at all five poses) of one IK run over a tabletop parameter set."""
    row = store.one("SELECT count(*) FILTER (WHERE k.feasibility), "
                    f"count(*) FILTER (WHERE {ALL_FEASIBLE}) "
                    "FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
                    "WHERE k.idrobot = ? AND k.idscene = ? AND k.idikret = ? AND p.idparamset = ?",
                    [idrobot, idscene, idikret, idtabletop])
    return int(row[0] or 0), int(row[1] or 0)


def ikret_row(store: Store, idikret: int) -> dict[str, float]:
    """The distances of a retraction set, metres: {"handx", "worldz", "worlda"}."""
    row = store.one("SELECT handx, worldz, worlda FROM ikret WHERE idikret = ?", [idikret])
    if row is None:
        raise StoreError(f"store {store.path} has no ikret {idikret}; run `workbench ik` first")
    return {"handx": float(row[0]), "worldz": float(row[1]), "worlda": float(row[2])}


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
    return {"idrobot": int(rid), "name": name, "urdf": without_tcp_link(urdf), "tcp_frame": tcp, "tip_frame": tip,
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

def load_ik(store: Store, idrobot: int, idscene: int, idikret: int, idobject: int | None = None,
            idtabletop: int | None = None) -> dict[str, np.ndarray]:
    """The `ik` rows of a run (of one object's, of one tabletop grid's grips) joined with their tabletop grips,
    ordered by idtabletopgrips: idik, idtabletopgrips,
    idtabletopplacements, idfreeairgrip, rotmat (N, 4, 4), placement_rotmat (N, 4, 4), tabletopposition (N, 3),
    idangle, feasible (N, 5) and joints (N, 5, nq) for the five poses (`robots.ik.KINDS`), NaN where infeasible."""
    nq = len(robot_row(store, idrobot)["joint_names"])
    sql = ("SELECT k.idik, k.idtabletopgrips, g.idtabletopplacements, g.idfreeairgrip, g.rotmat, g.jawwidth, "
           "p.rotmat AS placement_rotmat, p.tabletopposition, p.idangle, "
           + ", ".join(f"k.{c}" for c in FEASIBILITY + JOINTS) + " "
           "FROM ik k JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
           "JOIN freetabletopplacement f USING (idfreetabletopplacement) "
           "WHERE k.idrobot = ? AND k.idscene = ? AND k.idikret = ?")
    params: list[Any] = [idrobot, idscene, idikret]
    if idobject is not None:
        sql += " AND f.idobject = ?"
        params.append(idobject)
    if idtabletop is not None:
        sql += " AND p.idparamset = ?"
        params.append(idtabletop)
    table = store.arrow(sql + " ORDER BY k.idtabletopgrips", params)

    out = {c: from_arrow(table.column(c)) for c in ("idik", "idtabletopgrips", "idtabletopplacements", "idfreeairgrip",
                                                      "jawwidth", "idangle")}
    n = len(out["idik"])
    out["rotmat"] = np.asarray(from_arrow(table.column("rotmat")), dtype=np.float64).reshape(n, 4, 4)
    out["placement_rotmat"] = np.asarray(from_arrow(table.column("placement_rotmat")), dtype=np.float64).reshape(n, 4, 4)
    out["tabletopposition"] = np.asarray(from_arrow(table.column("tabletopposition")), dtype=np.float64).reshape(n, 3)
    out["feasible"], out["joints"] = feasibility_arrays(table, n, nq)
    return out


def list_column(table: pa.Table, name: str, width: int) -> np.ndarray:
    """A DOUBLE[] column as an (N, width) float array, NaN rows for NULL (no per-row Python)."""
    col = table.column(name).combine_chunks()
    n = len(col)
    out = np.full((n, width), np.nan)
    if n == 0 or width == 0:
        return out
    if pa.types.is_fixed_size_list(col.type) or pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
        valid = ~np.asarray(col.is_null().to_numpy(zero_copy_only=False), dtype=bool)
        if valid.any():
            sub = col.filter(pa.array(valid))
            flat = np.asarray(sub.flatten().to_numpy(zero_copy_only=False), dtype=np.float64)
            if len(flat) != len(sub) * width:
                raise StoreError(f"joint vectors in column {name} do not all have {width} entries; rebuild the ik stage")
            out[valid] = flat.reshape(-1, width)
    return out


def feasibility_arrays(table: pa.Table, n: int, nq: int, names: tuple[tuple[str, ...], tuple[str, ...]] = (FEASIBILITY, JOINTS)
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(feasible (N, 5), joints (N, 5, nq), NaN where NULL) from the feasibility and joint columns of an Arrow table
    (NULL feasibility reads as False)."""
    fcols, jcols = names
    feasible = np.stack([np.asarray(table.column(c).fill_null(False).to_numpy(zero_copy_only=False), dtype=bool)
                         for c in fcols], axis=1).reshape(n, len(fcols))
    joints = np.stack([list_column(table, c, nq) for c in jcols], axis=1) if n else np.full((0, len(jcols), nq), np.nan)
    return feasible, joints


def ik_runs(store: Store, idobject: int | None = None, idtabletop: int | None = None,
            idrobot: int | None = None) -> list[dict[str, Any]]:
    """Stored IK runs, optionally of one object, tabletop parameter set and robot: idrobot, robot name, idscene,
    idikret, handx, worldz, worlda, rows, feasible counts (grasp, all five poses) and the newest idik (`last`)."""
    sql = ("SELECT k.idrobot, r.name, k.idscene, k.idikret, i.handx, i.worldz, i.worlda, count(*) AS n, "
           "count(*) FILTER (WHERE k.feasibility) AS f0, "
           f"count(*) FILTER (WHERE {ALL_FEASIBLE}) AS f5, "
           "max(k.idik) AS last "
           "FROM ik k JOIN robot r USING (idrobot) JOIN ikret i USING (idikret) "
           "JOIN tabletopgrips g USING (idtabletopgrips) JOIN tabletopplacements p USING (idtabletopplacements) "
           "JOIN freetabletopplacement f USING (idfreetabletopplacement) WHERE true")
    params: list[Any] = []
    for column, value in (("f.idobject", idobject), ("p.idparamset", idtabletop), ("k.idrobot", idrobot)):
        if value is not None:
            sql += f" AND {column} = ?"
            params.append(int(value))
    sql += " GROUP BY k.idrobot, r.name, k.idscene, k.idikret, i.handx, i.worldz, i.worlda ORDER BY k.idrobot, k.idscene, k.idikret"
    keys = ("idrobot", "robot", "idscene", "idikret", "handx", "worldz", "worlda", "rows", "feasible", "feasible_all", "last")
    return [dict(zip(keys, r)) for r in store.run(sql, params)]


def robot_with_gripper(store: Store, name: str, digest: str) -> str | None:
    """The stored name of robot `name` planned with the gripper of this digest (NAME itself, or NAME-DIGEST when
    another gripper or base took the name first), the newest; None when there is none."""
    row = store.one("SELECT r.name FROM robot r JOIN gripper g ON r.idgripper = g.idgripper WHERE (r.name = ? OR "
                    "starts_with(r.name, ?)) AND g.digest = ? ORDER BY r.idrobot DESC LIMIT 1", [name, f"{name}-", digest])
    return None if row is None else str(row[0])


def robot_grippers(store: Store, name: str) -> list[str]:
    """The names of the grippers robot `name` (or NAME-DIGEST) is stored with."""
    rows = store.run("SELECT DISTINCT g.name FROM robot r JOIN gripper g ON r.idgripper = g.idgripper WHERE r.name = ? OR "
                     "starts_with(r.name, ?) ORDER BY g.name", [name, f"{name}-"])
    return [str(r[0]) for r in rows]


def robot_ids(store: Store, name: str) -> list[int]:
    """The ids of robot `name` and of its NAME-DIGEST rows (the same name with another gripper, base or mount), the
    newest first."""
    rows = store.run("SELECT idrobot FROM robot WHERE name = ? OR starts_with(name, ?) ORDER BY idrobot DESC",
                     [name, f"{name}-"])
    return [int(r[0]) for r in rows]
