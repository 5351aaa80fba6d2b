"""python-fcl helpers: BVH models from meshes and one geometry tested at many poses against a fixed object."""

from __future__ import annotations

import fcl
import numpy as np
import trimesh


def bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """An fcl BVH (OBBRSS) model of a triangle mesh."""
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


def collide_at_poses(geometry: fcl.CollisionGeometry, poses: np.ndarray, target: fcl.CollisionObject) -> np.ndarray:
    """For each 4x4 pose, whether `geometry` placed there intersects `target` (N,) bool."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 4, 4)
    out = np.zeros(len(poses), dtype=bool)
    obj = fcl.CollisionObject(geometry)
    req = fcl.CollisionRequest()
    for k, pose in enumerate(poses):
        obj.setTransform(fcl.Transform(pose[:3, :3], pose[:3, 3]))
        out[k] = fcl.collide(obj, target, req, fcl.CollisionResult()) > 0
    return out


def object_collider(mesh: trimesh.Trimesh, pose: np.ndarray | None = None) -> fcl.CollisionObject:
    """The object as an fcl collision object at `pose` (identity by default)."""
    obj = fcl.CollisionObject(bvh(mesh))
    if pose is not None:
        obj.setTransform(fcl.Transform(pose[:3, :3], pose[:3, 3]))
    return obj
