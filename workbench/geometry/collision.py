"""Every python-fcl call of the planners: BVH models from meshes, shapes from pinocchio collision geometry,
collision objects at poses, one geometry tested at many poses against a fixed object, swept cylinders.

(The independent plan validator keeps its own collision code on purpose, so that it shares none with the
planners it checks.)"""

from __future__ import annotations

import fcl
import numpy as np
import trimesh

from workbench.errors import WorkbenchError

REQUEST = fcl.CollisionRequest()  # stateless: a boolean contact query


def bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """An fcl BVH (OBBRSS) model of a triangle mesh."""
    model = fcl.BVHModel()
    model.beginModel(len(mesh.vertices), len(mesh.faces))
    model.addSubModel(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32))
    model.endModel()
    return model


def mesh_distance(a: trimesh.Trimesh, b: trimesh.Trimesh) -> float:
    """The least distance between two meshes' surfaces (0 where they touch or cross)."""
    oa, ob = fcl.CollisionObject(bvh(a), fcl.Transform()), fcl.CollisionObject(bvh(b), fcl.Transform())
    return max(float(fcl.distance(oa, ob, fcl.DistanceRequest(), fcl.DistanceResult())), 0.0)


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


def mesh_bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """The fcl BVH of `mesh`, built once per mesh and kept in its trimesh cache (dropped when the mesh changes): a
    full-resolution part's hierarchy takes seconds to build, and every stage that collides with it shares one."""
    model = mesh._cache["workbench_fcl_bvh"]
    if model is None:
        model = mesh._cache["workbench_fcl_bvh"] = bvh(mesh)
    return model


def object_collider(mesh: trimesh.Trimesh, pose: np.ndarray | None = None) -> fcl.CollisionObject:
    """The object as an fcl collision object at `pose` (identity by default), on its cached BVH (`mesh_bvh`)."""
    obj = fcl.CollisionObject(mesh_bvh(mesh))
    if pose is not None:
        obj.setTransform(fcl.Transform(pose[:3, :3], pose[:3, 3]))
    return obj


def collision_object(geometry: fcl.CollisionGeometry, pose: np.ndarray | None = None) -> fcl.CollisionObject:
    """An fcl collision object of `geometry` at a 4x4 `pose` (identity by default)."""
    if pose is None:
        return fcl.CollisionObject(geometry, fcl.Transform())
    return fcl.CollisionObject(geometry, fcl.Transform(np.asarray(pose[:3, :3]), np.asarray(pose[:3, 3])))


def box(extents: np.ndarray) -> fcl.Box:
    """An fcl box of full `extents` (3,), centred on its frame."""
    return fcl.Box(*np.asarray(extents, dtype=np.float64))


def set_pose(obj: fcl.CollisionObject, rotation: np.ndarray, translation: np.ndarray) -> None:
    """Move a collision object to a rotation (3, 3) and translation (3,)."""
    obj.setRotation(rotation)
    obj.setTranslation(translation)


def collide(a: fcl.CollisionObject, b: fcl.CollisionObject) -> bool:
    """Whether two placed collision objects intersect."""
    return fcl.collide(a, b, REQUEST, fcl.CollisionResult()) > 0


def pinocchio_geometry(go) -> tuple[fcl.CollisionGeometry, trimesh.Trimesh]:
    """An fcl geometry and a trimesh of one pinocchio GeometryObject (in the geometry's own frame)."""
    geom = go.geometry
    kind = type(geom).__name__
    if kind == "Box" or hasattr(geom, "halfSide"):
        ext = 2 * np.asarray(geom.halfSide, dtype=np.float64)
        return fcl.Box(*ext), trimesh.creation.box(extents=ext)
    if kind == "Cylinder":
        r, h = float(geom.radius), 2 * float(geom.halfLength)
        return fcl.Cylinder(r, h), trimesh.creation.cylinder(radius=r, height=h, sections=24)
    if kind == "Sphere":
        r = float(geom.radius)
        return fcl.Sphere(r), trimesh.creation.icosphere(radius=r, subdivisions=2)
    if kind == "Capsule":
        r, h = float(geom.radius), 2 * float(geom.halfLength)
        return fcl.Capsule(r, h), trimesh.creation.capsule(radius=r, height=h)
    if go.meshPath:
        mesh = trimesh.load(go.meshPath, force="mesh")
        mesh.apply_scale(np.asarray(go.meshScale, dtype=np.float64))
        return bvh(mesh), mesh
    raise WorkbenchError(f"collision geometry {go.name} has unsupported type {kind}; use meshes or primitives")


def cylinders_collide(radius: float, lengths: np.ndarray, rotations: np.ndarray, centres: np.ndarray,
                      target: fcl.CollisionObject, skip: np.ndarray | None = None) -> np.ndarray:
    """(N,) whether each cylinder (radius, length along its z, rotation (N, 3, 3), centre (N, 3)) hits `target`;
    rows where `skip` is True are not tested (False)."""
    out = np.zeros(len(lengths), dtype=bool)
    for k in np.flatnonzero(~skip if skip is not None else np.ones(len(lengths), dtype=bool)):
        cyl = fcl.CollisionObject(fcl.Cylinder(radius, float(lengths[k])), fcl.Transform(rotations[k], centres[k]))
        out[k] = collide(cyl, target)
    return out
