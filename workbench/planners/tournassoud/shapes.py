"""Parts of the paper's figures built in code: the L-shaped part of Fig. 1 (Tournassoud et al. 1987)."""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.geometry.objects import ObjectModel, from_trimesh


def prism(outline: list[tuple[float, float]], caps: list[tuple[int, int, int]], depth: float) -> trimesh.Trimesh:
    """A watertight prism: the x-z polygon `outline` (triangulated by `caps`) extruded along y, centred on y = 0."""
    n = len(outline)
    verts = [(x, -depth / 2, z) for x, z in outline] + [(x, depth / 2, z) for x, z in outline]
    faces = []
    for k in range(n):
        a, b = k, (k + 1) % n
        faces += [(a, b, n + b), (a, n + b, n + a)]
    for a, b, c in caps:
        faces += [(a, c, b), (n + a, n + b, n + c)]
    mesh = trimesh.Trimesh(np.array(verts, dtype=np.float64), np.array(faces), process=True)
    trimesh.repair.fix_normals(mesh)
    return mesh


def l_part(long: float = 0.06, thick: float = 0.02, depth: float = 0.03, name: str = "L") -> ObjectModel:
    """The L-shaped part of Fig. 1: two legs `long` x `thick` in the x-z plane sharing a corner, `depth` along y."""
    outline = [(0, 0), (long, 0), (long, thick), (thick, thick), (thick, long), (0, long)]
    return from_trimesh(prism(outline, [(0, 1, 2), (0, 2, 3), (0, 3, 4), (0, 4, 5)], depth), name)
