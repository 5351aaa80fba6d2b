"""Discrete contact points of a triangle mesh (Phoka & Sudsang, Section III).

Every facet's centroid is a candidate contact point and its inward unit normal the direction a fingertip
pushes. The paper's objects have about 500 triangles; larger meshes are decimated first by quadric edge
collapse (fast-simplification, through trimesh), a parameter of the stage.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from .errors import MeshError
from .objects import ObjectModel


@dataclass(frozen=True)
class ContactParams:
    """Parameters of the contact stage: `faces` is the triangle budget (None or 0 keeps the mesh as it is)."""

    faces: int | None = 500

    def validate(self) -> "ContactParams":
        if self.faces is not None and self.faces != 0 and self.faces < 4:
            raise MeshError(f"faces={self.faces} is too few triangles for contact points; use at least 4 (or 0 to keep the mesh)")
        return self


@dataclass(frozen=True)
class ContactSet:
    """Contact points T_O of an object: facet centroids, inward unit normals, the facet each comes from.

    `mesh` is the (decimated) mesh whose faces the contacts are the centroids of; `com` the object's centre
    of mass (the reference point of torques in force-closure tests); `radius` the largest distance of a contact
    from `com`, the length that makes torques comparable to forces.
    """

    points: np.ndarray      # (N, 3) metres
    normals: np.ndarray     # (N, 3) inward unit normals
    face: np.ndarray        # (N,) face index in `mesh`
    mesh: trimesh.Trimesh
    com: np.ndarray
    radius: float

    def __len__(self) -> int:
        return int(len(self.points))


def decimate(mesh: trimesh.Trimesh, faces: int | None) -> trimesh.Trimesh:
    """The mesh reduced to about `faces` triangles by quadric decimation (unchanged when already small enough)."""
    if len(mesh.faces) == 0:
        raise MeshError("mesh has no faces: give a triangle mesh with at least 4 faces")
    if not faces or len(mesh.faces) <= faces:
        out = mesh.copy()
    else:
        out = mesh.simplify_quadric_decimation(face_count=int(faces))
    area = out.area_faces
    keep = area > 1e-12 * max(float(area.max(initial=0.0)), 1e-300)
    if not keep.all():
        out.update_faces(keep)
        out.remove_unreferenced_vertices()
    if len(out.faces) < 4:
        raise MeshError(f"mesh decimated to {len(out.faces)} faces, too few for a 4-contact grasp; raise faces")
    if out.is_watertight and out.volume < 0:
        out.invert()
    return out


def contact_points(obj: ObjectModel | trimesh.Trimesh, params: ContactParams = ContactParams()) -> ContactSet:
    """Contact points T_O: centroids of the (decimated) faces with inward unit normals (Section III)."""
    params.validate()
    mesh = obj.mesh if isinstance(obj, ObjectModel) else obj
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError("mesh is empty: give a triangle mesh with faces")
    reduced = decimate(mesh, params.faces)
    points = np.asarray(reduced.triangles_center, dtype=np.float64)
    normals = -np.asarray(reduced.face_normals, dtype=np.float64)
    norm = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(norm > 0, norm, 1.0)
    if isinstance(obj, ObjectModel):
        com = np.asarray(obj.com, dtype=np.float64)
    else:
        com = np.asarray(reduced.center_mass if reduced.is_watertight else points.mean(0), dtype=np.float64)
    radius = float(np.linalg.norm(points - com, axis=1).max())
    return ContactSet(points=points, normals=normals, face=np.arange(len(points), dtype=np.int64), mesh=reduced,
                      com=com, radius=radius)
