"""Safe mesh repair for the meshes users bring: scans, exports with flipped faces, open meshes.

Only repairs that cannot change the intended shape are made, and each is reported in one line:
merge duplicate vertices (reported for indexed meshes; an STL's per-face corners are merged silently), drop degenerate and duplicate faces, make the winding consistent and the normals point
outward, fill small holes (loops of at most `hole_edges` edges and `hole_size` across, fanned from their centroid;
trimesh.repair.fill_holes fills any three- or four-sided hole whatever its size, so a missing lid would be closed).
A file holding several separate bodies is reduced to its largest body when the others are small debris (together
under `debris` of its area); bodies that touch or overlap one another (a part built from pieces) stay together;
otherwise the mesh is refused, naming the bodies, since which one is meant cannot be guessed.
"""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.errors import MeshError


def repair(mesh: trimesh.Trimesh, label: str, hole_edges: int = 32, hole_size: float = 0.01,
           debris: float = 0.1) -> tuple[trimesh.Trimesh, list[str]]:
    """The repaired mesh and one line per repair made (empty when nothing was needed)."""
    notes: list[str] = []
    nv = len(mesh.vertices)
    # an STL stores every face's own corners: merging them is loading, not repairing; an indexed mesh (OBJ, PLY)
    # that repeats vertices has seams, and merging those is a repair worth reporting
    indexed = len(np.unique(mesh.faces)) < 3 * len(mesh.faces)
    mesh = mesh.copy()
    mesh.merge_vertices()
    if indexed and len(mesh.vertices) < nv:
        notes.append(f"merged {nv - len(mesh.vertices)} duplicate vertices")
    faces = mesh.faces
    areas = mesh.area_faces
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    degenerate = repeated | (areas <= 1e-14 * max(1.0, float(areas.max(initial=0.0))))
    if degenerate.all():
        raise MeshError(f"{label} has only degenerate (zero-area) faces")
    if degenerate.any():
        mesh.update_faces(~degenerate)
        notes.append(f"removed {int(degenerate.sum())} degenerate faces")
    nf = len(mesh.faces)
    mesh.update_faces(mesh.unique_faces())
    if len(mesh.faces) < nf:
        notes.append(f"dropped {nf - len(mesh.faces)} duplicate faces")
    mesh.remove_unreferenced_vertices()
    mesh, body_note = _one_body(mesh, label, debris)
    if body_note:
        notes.append(body_note)
    if not mesh.is_watertight:
        before = len(mesh.faces)
        filled = _fill_loops(mesh, hole_edges, hole_size)
        if filled:
            notes.append(f"filled {filled} small holes (at most {hole_size * 1e3:.3g} mm across) with "
                         f"{len(mesh.faces) - before} faces")
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_normals(mesh)  # consistent winding, and outward when closed
        notes.append("faces were not consistently oriented; re-oriented them")
    if mesh.is_watertight and mesh.volume < 0:
        mesh.invert()
        notes.append("turned the normals outward (the mesh was inside out)")
    return mesh, notes


def _one_body(mesh: trimesh.Trimesh, label: str, debris: float) -> tuple[trimesh.Trimesh, str]:
    """Keep every body when they form one cluster of touching bodies; else the largest when the rest is debris."""
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    n = int(labels.max()) + 1 if len(labels) else 0
    if n <= 1:
        return mesh, ""
    area = np.bincount(labels, weights=mesh.area_faces, minlength=n)
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    tri = mesh.triangles
    np.minimum.at(lo, labels, tri.min(axis=1))
    np.maximum.at(hi, labels, tri.max(axis=1))
    # clusters of bodies whose bounding boxes overlap (pieces of one part)
    touch = ((lo[:, None, :] <= hi[None, :, :] + 1e-9) & (hi[:, None, :] >= lo[None, :, :] - 1e-9)).all(axis=2)
    cluster = trimesh.graph.connected_component_labels(np.argwhere(np.triu(touch, 1)), node_count=n)
    carea = np.bincount(cluster, weights=area)
    big = int(np.argmax(carea))
    rest = float(carea.sum() - carea[big])
    if rest == 0:
        return mesh, f"kept {n} overlapping bodies together as one part"
    if rest <= debris * carea[big]:
        keep = cluster[labels] == big
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()
        dropped = int((cluster != big).sum())
        return mesh, (f"kept the largest body ({carea[big] * 1e4:.3g} cm^2) and dropped {dropped} small separate "
                      f"bodies ({rest * 1e4:.3g} cm^2 in all)")
    sizes = ", ".join(f"{a * 1e4:.3g}" for a in sorted(carea, reverse=True)[:4])
    raise MeshError(f"{label} holds {int(cluster.max()) + 1} separate bodies of comparable size (areas {sizes} cm^2); "
                    f"export the one body to grasp as its own file")


def _fill_loops(mesh: trimesh.Trimesh, max_edges: int, max_size: float) -> int:
    """Fan-fill boundary loops of at most `max_edges` edges and `max_size` across; returns the loops filled."""
    faces = mesh.faces
    e = faces[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    border = e[cnt[inv.ravel()] == 1]
    if len(border) == 0:
        return 0
    nxt: dict[int, int] = {}
    for a, b in border:
        if a in nxt:  # a vertex on two loops (non-manifold): leave it
            return 0
        nxt[int(a)] = int(b)
    seen: set[int] = set()
    new_v, new_f = [], []
    base = len(mesh.vertices)
    filled = 0
    for start in list(nxt):
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        cur = nxt[start]
        while cur != start and cur in nxt and cur not in seen and len(loop) <= max_edges:
            loop.append(cur)
            seen.add(cur)
            cur = nxt[cur]
        if cur != start or len(loop) > max_edges or len(loop) < 3:
            continue
        pts = mesh.vertices[loop]
        if np.ptp(pts, axis=0).max() > max_size:
            continue
        c = base + len(new_v)
        new_v.append(pts.mean(axis=0))
        # the border runs along the faces' own direction; the cap runs against it
        for a, b in zip(loop, loop[1:] + loop[:1]):
            new_f.append([b, a, c])
        filled += 1
    if filled:
        v = np.vstack([mesh.vertices, np.array(new_v)])
        f = np.vstack([mesh.faces, np.array(new_f)])
        mesh.vertices, mesh.faces = v, f  # noqa: PLW2901 (in-place on the caller's copy)
    return filled
