"""Loading and validating object meshes (CONVENTIONS.md, Units): SI scaling, sanity checks, centre of mass."""

from __future__ import annotations

import hashlib
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from workbench.errors import MeshError
from workbench.geometry.repair import HOLE_EDGES, HOLE_SIZE, open_border, repair, volume_centre
from workbench.params import HAND_SIZED, PART_SIZE, SCALE, single_blas

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "inch": 0.0254}
NAMES = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "in": "inches"}
MIN_EXTENT, MAX_EXTENT = PART_SIZE.lo, PART_SIZE.hi  # declared in workbench.params, quoted by every size message
TYPICAL = (HAND_SIZED.lo, HAND_SIZED.hi)  # the sizes (m) of parts a hand-sized gripper usually meets, for the unit hints
MAX_TRIANGLES = 2**31 - 1  # the store keeps vertex indices as 32-bit integers (object.faces INTEGER[3][])


class MeshWarning(UserWarning):
    """A mesh was accepted after a repair or with a weaker assumption (degenerate faces, not watertight)."""


@dataclass(frozen=True)
class ObjectModel:
    """A rigid object in its own frame, in metres.

    `com_method` is "volume" for a watertight mesh and "area" otherwise; `digest` identifies the
    scaled geometry, so stored results can be reused for the same mesh and scale; `repairs` says what was repaired
    at load, one line each (geometry/repair.py).
    """

    name: str
    mesh: trimesh.Trimesh
    com: np.ndarray
    com_method: str
    scale: float
    source: str = ""
    digest: str = field(default="")
    repairs: tuple[str, ...] = ()

    @property
    def n_triangles(self) -> int:
        return int(len(self.mesh.faces))


def resolve_scale(scale: float | None, units: str | None) -> float:
    """The factor to metres from an explicit scale or a unit name (`m`, `cm`, `mm`, `in`)."""
    if scale is not None and units is not None:
        raise MeshError("give either scale or units, not both")
    if units is not None:
        if units not in UNITS:
            raise MeshError(f"unknown unit {units!r}: use one of {', '.join(UNITS)}")
        return UNITS[units]
    s = 1.0 if scale is None else float(scale)
    if SCALE.problem(s) is not None:
        raise MeshError(f"scale must be a positive finite number, {SCALE.describe()}, got {scale!r}")
    return s


def load_object(path: str | Path, scale: float | None = None, units: str | None = None,
                name: str | None = None, accept_size: bool = False) -> ObjectModel:
    """Load a mesh file (STL, OBJ, PLY, OFF, glTF/GLB, COLLADA) as an object in metres (CONVENTIONS.md: scaled once,
    at load). Read in metres because neither `scale` nor `units` is given, a part larger than a hand-sized one
    (TYPICAL) is refused with the units that would make it so, unless `accept_size`."""
    path = Path(path)
    if not path.exists():
        raise MeshError(f"object file {path} does not exist")
    if path.is_dir():
        raise MeshError(f"object file {path} is a folder; give a mesh file (STL, OBJ, PLY, OFF, GLB, DAE)")
    if path.stat().st_size == 0:
        raise MeshError(f"object file {path} is empty")
    check_declared_size(path)
    try:
        loaded = trimesh.load(path, force=None, process=False)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"object file {path} is not a readable mesh ({type(exc).__name__}: {exc})") from None
    pieces = None
    if isinstance(loaded, trimesh.Scene):
        # each node's mesh placed by the scene graph's transforms, and which node each face came from
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        if not geoms:
            raise MeshError(f"object file {path} holds no triangle mesh")
        pieces = np.repeat(np.arange(len(geoms)), [len(g.faces) for g in geoms])
        loaded = trimesh.util.concatenate(geoms)
    if isinstance(loaded, trimesh.PointCloud):
        raise MeshError(f"object file {path} has {_count(len(loaded.vertices), 'vertex', 'vertices')} but no "
                        f"triangle faces")
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError(f"object file {path} is not a triangle mesh (got {type(loaded).__name__})")
    if scale is None and units is None and not accept_size and len(loaded.faces):
        v = np.asarray(loaded.vertices)
        extent = float(np.ptp(v[np.bincount(np.asarray(loaded.faces).ravel(), minlength=len(v)) > 0], axis=0).max())
        if TYPICAL[1] < extent <= MAX_EXTENT:  # larger: refused as implausible below, whatever is accepted
            raise MeshError(f"object file {path} is {extent:.4g} m across read in metres (no --units or --scale), larger "
                            f"than a hand-sized part (at most {HAND_SIZED.hi:g} m); {_scale_hint(extent)}; or give "
                            f"--accept-size to plan it in metres")
    return from_arrays(loaded.vertices, loaded.faces, scale=resolve_scale(scale, units),
                       name=name or path.stem, source=str(path), pieces=pieces)


def check_triangle_count(triangles: int, label: str, vertices: int = 0, verb: str = "has") -> None:
    """Refuse a mesh of more triangles (or vertices) than the store's 32-bit indices hold, before any array is built."""
    for count, what in ((triangles, "triangles"), (vertices, "vertices")):
        if count > MAX_TRIANGLES:
            raise MeshError(f"{label} {verb} {count:,} {what}, more than the {MAX_TRIANGLES:,} a store holds (32-bit "
                            f"indices); decimate it (e.g. to a million triangles) first")


def check_declared_size(path: Path) -> None:
    """The triangle count a binary STL's or a PLY's header declares, checked before the mesh is read: above the
    store's limit, or more triangles than the file's bytes can hold (a damaged or truncated file), it is refused
    in one line instead of failing inside the reader."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(4096)
    suffix = path.suffix.lower()
    ascii_stl = head.lstrip().lower().startswith(b"solid") and b"facet" in head.lower()
    if suffix == ".stl" and len(head) >= 84 and not ascii_stl:  # a binary header may begin with "solid" too
        n = int.from_bytes(head[80:84], "little")
        check_triangle_count(n, f"object file {path}", verb="declares in its binary STL header")
        if size < 84 + 50 * n:
            raise MeshError(f"object file {path} is a binary STL whose header declares {n:,} triangles ({84 + 50 * n:,} "
                            f"bytes) but holds {size:,} bytes: it is truncated or damaged; export it again")
    elif suffix == ".ply" and head.startswith(b"ply"):
        m = re.search(rb"^element\s+face\s+(\d+)", head, re.MULTILINE)
        if m:
            n = int(m.group(1))
            check_triangle_count(n, f"object file {path}", verb="declares in its PLY header")
            if size < 3 * n:  # at least a count byte and two more per face, whatever the format
                raise MeshError(f"object file {path} declares {n:,} faces in its PLY header but holds {size:,} bytes: it is "
                                f"truncated or damaged; export it again")


def from_trimesh(mesh: trimesh.Trimesh, name: str, scale: float = 1.0) -> ObjectModel:
    """Wrap a mesh built in code (already in metres unless `scale` says otherwise)."""
    return from_arrays(mesh.vertices, mesh.faces, scale=scale, name=name, source="<memory>")


@single_blas
def from_arrays(vertices: np.ndarray, faces: np.ndarray, scale: float, name: str, source: str,
                pieces: np.ndarray | None = None) -> ObjectModel:
    """Validate vertex and face arrays, scale to metres, repair what is safe to repair (geometry/repair.py), compute
    the centre of mass. `pieces` (per face): the file's own meshes, joined as one part (geometry/repair.py)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    label = source if source != "<memory>" else f"mesh {name!r}"
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) == 0:
        raise MeshError(f"{label} has no vertices")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise MeshError(f"{label} has no triangle faces")
    check_triangle_count(len(faces), label, len(vertices))
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices)).any(axis=1).sum())
        raise MeshError(f"{label} has {_count(bad, 'vertex', 'vertices')} with NaN or infinite coordinates; repair "
                        f"the file")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"{label} has faces that index missing vertices; repair the file")
    # size first, on the referenced vertices: merging vertices of a sub-micron part would make every face degenerate
    extent = float(np.ptp(vertices[np.bincount(faces.ravel(), minlength=len(vertices)) > 0] * scale, axis=0).max())
    if extent > MAX_EXTENT or (MIN_EXTENT > extent > 0):
        raise MeshError(f"{label} is {extent:.4g} m across {_read_as(scale)}, implausible for a gripper "
                        f"(allowed: {PART_SIZE.describe()}); {_scale_hint(extent, scale)}")
    # built from copies (the scaled vertices, the faces) that the repairs may change in place: no second copy
    mesh = trimesh.Trimesh(vertices * scale, faces.copy(), process=False, validate=False)
    mesh, repairs = repair(mesh, label, pieces=pieces, copy=False)
    for note in repairs:
        warnings.warn(f"{label}: {note}", MeshWarning, stacklevel=3)
    extent = float(mesh.extents.max())
    if extent > MAX_EXTENT or extent < MIN_EXTENT:
        hint = _scale_hint(extent, scale)
        raise MeshError(f"{label} is {extent:.4g} m across {_read_as(scale)}, implausible for a gripper "
                        f"(allowed: {PART_SIZE.describe()}); {hint}")
    if extent > TYPICAL[1] and scale == 1.0:
        warnings.warn(f"{label} is {extent:.3g} m across read in metres, larger than a gripper-sized part; "
                      f"{_scale_hint(extent, scale)}", MeshWarning, stacklevel=3)
    volume, centre = volume_centre(mesh) if mesh.is_watertight and mesh.is_winding_consistent else (0.0, None)
    if volume > 0:
        com, method = centre, "volume"
    else:
        edges, span = open_border(mesh)
        why = (f"open: {edges} edges border its holes, the widest {span * 1e3:.3g} mm across; a hole is closed at "
               f"load when it is at most {HOLE_SIZE * 1e3:.3g} mm across and has at most {HOLE_EDGES} edges" if edges
               else "its faces do not close a volume")
        warnings.warn(f"{label} is not watertight ({why}): centre of mass weighted by area; a closed export gives "
                      f"the solid's", MeshWarning, stacklevel=3)
        com = (mesh.triangles_center * mesh.area_faces[:, None]).sum(0) / mesh.area
        method = "area"
    return ObjectModel(name=name, mesh=mesh, com=com, com_method=method, scale=scale, source=source,
                       digest=mesh_digest(mesh.vertices, mesh.faces), repairs=tuple(repairs))


def mesh_digest(vertices: np.ndarray, faces: np.ndarray) -> str:
    """The digest of a scaled, repaired mesh (float64 vertices, int64 faces): what stored results are keyed by."""
    return hashlib.sha256(np.ascontiguousarray(vertices, dtype=np.float64).tobytes()
                          + np.ascontiguousarray(faces, dtype=np.int64).tobytes()).hexdigest()[:16]


def _read_as(scale: float) -> str:
    """How the file was read, for the size messages."""
    return "read in metres (no --units or --scale)" if scale == 1.0 else f"after scale {scale:g}"


def _scale_hint(extent: float, scale: float = 1.0) -> str:
    """The units (or scale) that make a part `extent` m across at `scale` gripper-sized, for the error message:
    those giving a typical part size first, each with the size it gives."""
    raw = extent / scale  # in the file's own units
    fits = [(u, f) for u, f in UNITS.items() if u != "inch" and f != scale and MIN_EXTENT <= raw * f <= MAX_EXTENT]
    typical = [(u, f) for u, f in fits if TYPICAL[0] <= raw * f <= TYPICAL[1]]
    if typical or fits:
        return "; ".join(f"if the file is in {NAMES[u]}, pass --units {u} ({raw * f * 1000:.3g} mm across)"
                         for u, f in (typical or fits))
    small = extent < MIN_EXTENT
    limit = MIN_EXTENT if small else MAX_EXTENT
    need, side = limit / raw, "or more" if small else "or less"
    if SCALE.problem(need) is not None:  # beyond --scale's declared range: no value of it would do
        return (f"no unit or --scale ({SCALE.describe()}) makes it {'at least' if small else 'at most'} {limit * 1000:g} mm "
                f"across (it would take --scale {need:.3g} {side}); check the file, or the part cannot be gripped")
    if small:
        return (f"no unit makes it at least {limit * 1000:g} mm across: it would take --scale {need:.3g} or more "
                f"({SCALE.describe()}); check the file's units, or the part is too small to grip")
    return (f"it would take --scale {need:.3g} or less ({SCALE.describe()}); pass the scale that converts the file's "
            f"units to metres")


def _count(n: int, one: str, many: str) -> str:
    """`n` and the noun in the number it takes ("1 vertex", "3 vertices")."""
    return f"{n:,} {one if n == 1 else many}"
