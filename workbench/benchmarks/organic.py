"""A procedural set of organic objects, the kind users bring: smooth and noisy blobs, ellipsoids, tori
(one lying flat thinner than the fingers are long), a flat pebble,
cups (closed walls and a single open sheet), a brick with studs (manifold3d), a scan with holes and a flat-bottomed
noisy scan. 300 to 5,000 triangles, some not watertight; metres; seeded, so every run builds the same meshes.

`ORGANIC` maps a name to a builder; `organic_set()` builds them all. `min_width` is the narrowest extent of an object
over all directions (the convex hull's minimum width), which decides whether a parallel jaw can close around it.
"""

from __future__ import annotations

import numpy as np
import trimesh


def _sphere(rows: int, cols: int) -> trimesh.Trimesh:
    """A UV sphere of radius 1 with about 2 * rows * cols triangles."""
    return trimesh.creation.uv_sphere(radius=1.0, count=[rows, cols])


def _smooth_field(dirs: np.ndarray, rng: np.random.Generator, terms: int, freq: float) -> np.ndarray:
    """A smooth random scalar on unit directions: a sum of random plane waves."""
    k = rng.normal(size=(terms, 3)) * freq
    phase = rng.uniform(0, 2 * np.pi, terms)
    amp = rng.uniform(0.5, 1.0, terms) / terms
    return (np.sin(dirs @ k.T + phase) * amp).sum(axis=1)


def blob(seed: int = 0, radius: float = 0.03, bump: float = 0.25, noise: float = 0.0, rows: int = 24,
         cols: int = 48, stretch=(1.0, 1.0, 1.0)) -> trimesh.Trimesh:
    """A star-shaped blob: a sphere whose radius varies smoothly (`bump` relative), plus white noise (m)."""
    rng = np.random.default_rng(seed)
    m = _sphere(rows, cols)
    d = m.vertices / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    r = radius * (1 + bump * _smooth_field(d, rng, 6, 2.5))
    r = r + noise * rng.standard_normal(len(d))
    v = d * r[:, None] * np.asarray(stretch)
    return trimesh.Trimesh(v, m.faces, process=True)


def ellipsoid(axes=(0.03, 0.02, 0.045), rows: int = 20, cols: int = 40) -> trimesh.Trimesh:
    m = _sphere(rows, cols)
    return trimesh.Trimesh(m.vertices * np.asarray(axes), m.faces, process=True)


def torus(major: float = 0.035, minor: float = 0.012, sections: int = 48, minor_sections: int = 16) -> trimesh.Trimesh:
    return trimesh.creation.torus(major_radius=major, minor_radius=minor, major_sections=sections,
                                  minor_sections=minor_sections)


def _revolve(profile: np.ndarray, sections: int) -> trimesh.Trimesh:
    """A surface of revolution about z of a polyline (r, z), open where the profile is open."""
    return trimesh.creation.revolve(profile, sections=sections)


def cup(radius: float = 0.032, height: float = 0.09, wall: float = 0.004, sections: int = 48) -> trimesh.Trimesh:
    """A mug body: closed walls of thickness `wall`, open at the top (watertight solid)."""
    prof = np.array([[0.0, 0.0], [radius, 0.0], [radius, height], [radius - wall, height],
                     [radius - wall, wall], [0.0, wall]])
    return _revolve(prof, sections)


def washer(outer: float = 0.05, inner: float = 0.04, thickness: float = 0.006, sections: int = 64) -> trimesh.Trimesh:
    """A flat washer (watertight): its centre of mass lies in the hole, at least `inner` from any grasp on the rim."""
    prof = np.array([[inner, 0.0], [outer, 0.0], [outer, thickness], [inner, thickness], [inner, 0.0]])
    return _revolve(prof, sections)


def open_bowl(radius: float = 0.03, height: float = 0.05, sections: int = 40, rings: int = 10) -> trimesh.Trimesh:
    """A single curved sheet (no thickness, open rim): not watertight."""
    t = np.linspace(0.0, 1.0, rings)
    prof = np.column_stack([radius * np.sin(0.5 * np.pi * t) + 1e-4, height * (1 - np.cos(0.5 * np.pi * t))])
    return _revolve(prof[::-1], sections)


def stud_brick(nx: int = 2, ny: int = 4, pitch: float = 0.008 * 1.6, height: float = 0.0096 * 1.6,
               stud_d: float = 0.0048 * 1.6, stud_h: float = 0.0017 * 1.6) -> trimesh.Trimesh:
    """A toy brick with studs on top (manifold3d union), 1.6 times the usual size."""
    import manifold3d as mf

    body = mf.Manifold.cube([nx * pitch, ny * pitch, height])
    for i in range(nx):
        for j in range(ny):
            stud = mf.Manifold.cylinder(stud_h + 1e-4, stud_d / 2, stud_d / 2, 24)
            body = body + stud.translate([(i + 0.5) * pitch, (j + 0.5) * pitch, height - 1e-4])
    mesh = body.to_mesh()
    out = trimesh.Trimesh(np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts), process=True)
    out.apply_translation(-out.bounds.mean(axis=0))
    return out


def holed(mesh: trimesh.Trimesh, seed: int = 0, holes: int = 3, size: int = 6) -> trimesh.Trimesh:
    """`mesh` with a few small holes punched in it (faces removed around random seeds): not watertight."""
    rng = np.random.default_rng(seed)
    keep = np.ones(len(mesh.faces), dtype=bool)
    centres = mesh.triangles_center
    for f in rng.choice(len(mesh.faces), holes, replace=False):
        d = np.linalg.norm(centres - centres[f], axis=1)
        keep[np.argsort(d)[:size]] = False
    out = mesh.copy()
    out.update_faces(keep)
    out.remove_unreferenced_vertices()
    return out


def flat_bottom_scan(seed: int = 3, noise: float = 5e-5) -> trimesh.Trimesh:
    """A scanned blob pressed flat at the bottom (every vertex below the cut raised onto it), with 0.05 mm noise
    everywhere: its base is flat only to about 0.1 mm."""
    m = blob(seed=seed, radius=0.03, bump=0.15, rows=24, cols=48)
    v = m.vertices.copy()
    cut = v[:, 2].min() + 0.012
    v[:, 2] = np.maximum(v[:, 2], cut)
    rng = np.random.default_rng(seed)
    v += noise * rng.standard_normal(v.shape)
    return trimesh.Trimesh(v, m.faces, process=True)


ORGANIC = {
    "blob_smooth": lambda: blob(seed=1, rows=20, cols=40),
    "blob_noisy": lambda: blob(seed=2, noise=3e-4, rows=26, cols=50),
    "blob_coarse": lambda: blob(seed=4, rows=12, cols=14, radius=0.028),
    "blob_long": lambda: blob(seed=5, stretch=(0.7, 0.9, 1.8), rows=24, cols=50),
    "ellipsoid": lambda: ellipsoid(),
    "torus": lambda: torus(),
    "ring": lambda: torus(major=0.03, minor=0.008),
    "pebble": lambda: blob(seed=8, bump=0.1, noise=3e-4, stretch=(1.3, 1.0, 0.55), rows=22, cols=44),
    "washer": lambda: washer(),
    "cup": lambda: cup(),
    "open_bowl": lambda: open_bowl(),
    "stud_brick": lambda: stud_brick(),
    "scan_holes": lambda: holed(blob(seed=6, noise=2e-4, rows=26, cols=50), seed=6),
    "flat_scan": lambda: flat_bottom_scan(),
}


def organic_set() -> dict[str, trimesh.Trimesh]:
    return {name: make() for name, make in ORGANIC.items()}


def min_width(mesh: trimesh.Trimesh) -> float:
    """The narrowest extent over all directions: the minimum over hull face normals of the hull's extent along it."""
    hull = mesh.convex_hull
    proj = hull.vertices @ hull.face_normals.T
    return float((proj.max(axis=0) - proj.min(axis=0)).min())
