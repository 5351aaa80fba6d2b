"""SQL of the `object` and `gripper` tables."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from workbench.errors import StoreError
from workbench.geometry.objects import ObjectModel
from workbench.robots.gripper import Gripper
from workbench.store import Store


def put_object(store: Store, obj: ObjectModel) -> int:
    """Store an object (mesh, centre of mass) and return its id; the same name and geometry reuse the row."""
    row = store.one("SELECT idobject, digest FROM object WHERE name = ?", [obj.name])
    if row is not None:
        if row[1] != obj.digest:
            raise StoreError(f"store {store.path} already has an object named {obj.name!r} with other geometry; "
                             f"choose another --name or a new store")
        return int(row[0])
    with store.transaction():
        oid = store.next_id("object", "idobject")
        store.insert("object", {  # the mesh through Arrow: binding a large mesh as Python lists takes seconds
            "idobject": np.array([oid], dtype=np.int64), "name": np.array([obj.name], dtype=object),
            "digest": np.array([obj.digest], dtype=object), "source": np.array([obj.source], dtype=object),
            "scale": np.array([obj.scale], dtype=np.float64), "com": np.asarray(obj.com, dtype=np.float64)[None],
            "com_method": np.array([obj.com_method], dtype=object), "ntriangles": np.array([obj.n_triangles], dtype=np.int64),
            "vertices": _one_row_of_triples(np.asarray(obj.mesh.vertices, dtype=np.float64)),
            "faces": _one_row_of_triples(np.asarray(obj.mesh.faces, dtype=np.int32))})
    return oid


def _one_row_of_triples(arr: np.ndarray) -> pa.Array:
    """An (N, 3) array as one row of a list-of-triples column (DOUBLE[3][] or INTEGER[3][])."""
    triples = pa.FixedSizeListArray.from_arrays(pa.array(np.ascontiguousarray(arr).ravel()), 3)
    return pa.ListArray.from_arrays(pa.array([0, len(arr)], type=pa.int32()), triples)


def object_id(store: Store, name: str) -> int:
    """The id of the object called `name`, or a StoreError naming the objects the store has."""
    row = store.one("SELECT idobject FROM object WHERE name = ?", [name])
    if row is None:
        names = [r[0] for r in store.run("SELECT name FROM object ORDER BY name")]
        raise StoreError(f"store {store.path} has no object {name!r} (it has: {', '.join(names) or 'none'}); "
                         f"run `workbench grasps MESH --db {store.path}` first")
    return int(row[0])


def object_row(store: Store, name: str) -> tuple[int, dict]:
    """The stored object `name`: its id and its row (source, scale, com, com_method, digest, and the mesh's vertices
    and faces as (N, 3) arrays)."""
    oid = object_id(store, name)
    cols = ("source", "scale", "com", "com_method", "digest")
    row = dict(zip(cols, store.one(f"SELECT {', '.join(cols)} FROM object WHERE idobject = ?", [oid])))
    # the mesh through Arrow, as it was written: a million triangles as Python lists take seconds
    mesh = store.arrow("SELECT vertices, faces FROM object WHERE idobject = ?", [oid])
    for col, dtype in (("vertices", np.float64), ("faces", np.int64)):
        flat = mesh.column(col).combine_chunks().flatten().flatten()
        row[col] = np.asarray(flat.to_numpy(zero_copy_only=False), dtype=dtype).reshape(-1, 3)
    return oid, row


def put_gripper(store: Store, gripper: Gripper) -> int:
    """Store a gripper (reused when its geometry is already stored) and return its id."""
    digest = gripper.digest
    row = store.one("SELECT idgripper, body_faces FROM gripper WHERE digest = ?", [digest])
    body_faces = len(gripper.body.faces)  # collision_mesh() puts the body first, then the finger boxes
    if row is not None:
        if row[1] is None:  # a row written before body_faces existed
            store.run("UPDATE gripper SET body_faces = ? WHERE idgripper = ?", [body_faces, int(row[0])])
        return int(row[0])
    mesh = gripper.collision_mesh()
    with store.transaction():
        gid = store.next_id("gripper", "idgripper")
        store.run("INSERT INTO gripper (idgripper, name, urdf, jaw_min, jaw_max, digest, collision_vertices, collision_faces, "
                  "body_faces) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                  [gid, gripper.name, gripper.urdf, gripper.jaw_min, gripper.jaw_max, digest, mesh.vertices.tolist(),
                   mesh.faces.tolist(), body_faces])
    return gid


def gripper_row(store: Store, idgripper: int) -> dict:
    """A stored gripper: name, jaw range, digest and its collision mesh at full opening (vertices, faces)."""
    row = store.one("SELECT name, jaw_min, jaw_max, digest, collision_vertices, collision_faces, body_faces FROM gripper "
                    "WHERE idgripper = ?", [idgripper])
    if row is None:
        raise StoreError(f"store {store.path} has no gripper {idgripper}")
    name, lo, hi, digest, verts, faces, body_faces = row
    return {"idgripper": int(idgripper), "name": name, "jaw_min": lo, "jaw_max": hi, "digest": digest,
            "collision_vertices": None if verts is None else np.asarray(verts, dtype=np.float64),
            "collision_faces": None if faces is None else np.asarray(faces, dtype=np.int64),
            "body_faces": None if body_faces is None else int(body_faces)}


def stored_grippers(store: Store) -> list[dict]:
    """Every gripper with grasps or a robot in the store, in the order stored: name, digest, and the names of the
    objects it has grasps of and of the robots stored with it."""
    rows = store.run("SELECT g.name, g.digest, (SELECT list(DISTINCT o.name ORDER BY o.name) FROM object o WHERE o.idobject "
                     "IN (SELECT f.idobject FROM freeairgrip f WHERE f.idgripper = g.idgripper)), (SELECT list(r.name "
                     "ORDER BY r.name) FROM robot r WHERE r.idgripper = g.idgripper) FROM gripper g ORDER BY g.idgripper")
    out = [{"name": str(n), "digest": str(d), "objects": list(objs or []), "robots": list(robots or [])}
           for n, d, objs, robots in rows]
    return [g for g in out if g["objects"] or g["robots"]]


def object_name(store: Store, idobject: int) -> str:
    """The name of the stored object with this id."""
    row = store.one("SELECT name FROM object WHERE idobject = ?", [int(idobject)])
    if row is None:
        raise StoreError(f"store {store.path} has no object {idobject}")
    return str(row[0])
