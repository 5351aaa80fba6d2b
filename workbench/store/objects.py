"""SQL of the `object` and `gripper` tables."""

from __future__ import annotations

import hashlib

import numpy as np

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
        store.run(
            "INSERT INTO object (idobject, name, digest, source, scale, com, com_method, ntriangles, vertices, faces) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            [oid, obj.name, obj.digest, obj.source, obj.scale, obj.com.tolist(), obj.com_method, obj.n_triangles,
             obj.mesh.vertices.tolist(), obj.mesh.faces.tolist()])
    return oid


def object_id(store: Store, name: str) -> int:
    """The id of the object called `name`, or a StoreError naming the objects the store has."""
    row = store.one("SELECT idobject FROM object WHERE name = ?", [name])
    if row is None:
        names = [r[0] for r in store.run("SELECT name FROM object ORDER BY name")]
        raise StoreError(f"store {store.path} has no object {name!r} (it has: {', '.join(names) or 'none'}); "
                         f"run `workbench grasps MESH --db {store.path}` first")
    return int(row[0])


def object_row(store: Store, name: str) -> tuple[int, dict]:
    """The stored object `name`: its id and its row (source, scale, com, com_method, vertices, faces, digest)."""
    oid = object_id(store, name)
    cols = ("source", "scale", "com", "com_method", "vertices", "faces", "digest")
    row = store.one(f"SELECT {', '.join(cols)} FROM object WHERE idobject = ?", [oid])
    return oid, dict(zip(cols, row))


def gripper_digest(gripper: Gripper) -> str:
    """Identifies a gripper's geometry: body mesh, finger boxes and jaw range."""
    h = hashlib.sha256()
    h.update(np.round(gripper.body.vertices, 9).tobytes())
    for ext, pose in gripper.finger_boxes:
        h.update(np.round(ext, 9).tobytes() + np.round(pose, 9).tobytes())
    h.update(np.array([gripper.jaw_min, gripper.jaw_max]).tobytes())
    return h.hexdigest()[:24]


def put_gripper(store: Store, gripper: Gripper) -> int:
    """Store a gripper (reused when its geometry is already stored); call inside the stage's transaction."""
    digest = gripper_digest(gripper)
    row = store.one("SELECT idgripper FROM gripper WHERE digest = ?", [digest])
    if row is not None:
        return int(row[0])
    gid = store.next_id("gripper", "idgripper")
    store.run("INSERT INTO gripper (idgripper, name, urdf, jaw_min, jaw_max, digest) VALUES (?, ?, ?, ?, ?, ?)",
                      [gid, gripper.name, gripper.urdf, gripper.jaw_min, gripper.jaw_max, digest])
    return gid
