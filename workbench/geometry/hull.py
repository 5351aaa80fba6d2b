"""The convex hull of a part, with the facets that rounding splits merged back (qhull's pre-merge).

A finely triangulated part saved in single precision (an STL of a subdivided or tessellated part) has vertices along
its hull's edges and on its flat sides rounded up to 6e-8 of their coordinates out of plane. A plain hull keeps
each of them as a vertex and splits every flat side into slivers whose normals point anywhere. Merging facets that
lie in one plane to within `merge_tolerance` (well above that rounding, far below anything a gripper or a table
feels) gives back the part's own hull: its flat sides as coplanar triangles and its corners as vertices.
"""

from __future__ import annotations

import numpy as np
import trimesh

MERGE = 1e-7  # of the part's size: facets this close to one plane are one
ROUNDING = 5e-7  # of the largest coordinate: several times single precision's rounding (6e-8)


def merge_tolerance(points: np.ndarray) -> float:
    """The distance (m) within which hull facets of `points` (N, 3) are merged into one plane."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return 0.0
    return max(MERGE * float(np.ptp(points, axis=0).max()), ROUNDING * float(np.abs(points).max()))


def convex_hull(points: np.ndarray) -> trimesh.Trimesh:
    """The convex hull of `points` (N, 3) with facets within `merge_tolerance` of one plane merged (qhull C-n,
    measured in the unit box that QbB scales the points to), triangulated (Qt), outward-facing."""
    points = np.asarray(points, dtype=np.float64)
    extent = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    premerge = 2.0 * merge_tolerance(points) / extent if extent > 0 else 0.0
    return trimesh.convex.convex_hull(points, qhull_options=f"QbB Pp Qt C-{premerge:.3g}")


def part_hull(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """`convex_hull` of a part's vertices, built once per mesh (kept in its cache, dropped when the mesh changes)."""
    hull = mesh._cache["workbench_hull"]
    if hull is None:
        hull = mesh._cache["workbench_hull"] = convex_hull(mesh.vertices.view(np.ndarray))
    return hull
