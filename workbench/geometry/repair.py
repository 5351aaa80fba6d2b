"""Safe mesh repair for the meshes users bring: scans, exports with flipped faces, open meshes.

Only repairs that cannot change the intended shape are made, and each is reported in one line:
merge duplicate vertices (reported for indexed meshes; an STL's per-face corners are merged silently), drop degenerate and duplicate faces, make the winding consistent and the normals point
outward, fill small holes (loops of at most `hole_edges` edges and `hole_size` across, fanned from their centroid;
trimesh.repair.fill_holes fills any three- or four-sided hole whatever its size, so a missing lid would be closed).
A file holding several bodies is one part when they touch, interpenetrate or nest within 1e-4 of the part's largest
extent (CAD exports of one part as several shells, convex-piece models): the part is their union (manifold3d), so
that sampling, the pads and placements see only its outer surface, or, when a piece is not closed, the pieces less
their faces inside another piece. Small separate bodies (together under `debris` of the part's area) are dropped;
bodies really apart are refused, naming their gap, since which one is meant cannot be guessed.

The repaired mesh is put in a canonical order (`canonical`), so that a repaired file and the clean file it repairs
are the same part to every later stage.
"""

from __future__ import annotations

import manifold3d
import numpy as np
import trimesh
from scipy.spatial import cKDTree

from workbench.errors import MeshError
from workbench.geometry._repairkernel import (centre_terms, face_areas, rotated_faces, triple_codes, unit_normals,
                                              volume_terms, winding_flags)
from workbench.geometry._segkernel import connected, edge_groups, neighbour_table
from workbench.geometry.collision import mesh_distance
from workbench.geometry.facets import EDGES_KEY


HOLE_EDGES, HOLE_SIZE = 32, 0.01  # the holes closed at load: loops of at most this many edges and metres across


def repair(mesh: trimesh.Trimesh, label: str, hole_edges: int = HOLE_EDGES, hole_size: float = HOLE_SIZE,
           debris: float = 0.1, pieces: np.ndarray | None = None,
           copy: bool = True) -> tuple[trimesh.Trimesh, list[str]]:
    """The repaired mesh and one line per repair made (empty when nothing was needed). `pieces` (per face, optional):
    which of the file's meshes each face came from (a glTF scene's nodes). `copy=False` lets the repairs change
    `mesh` itself, for a caller that built it only to repair it."""
    notes: list[str] = []
    built = False
    if pieces is not None and len(np.unique(pieces)) > 1:
        # the file's own pieces first: merged together, coincident faces of pieces meeting face to face would be taken
        # for duplicates and their shared corners would glue them into one body that is not closed
        mesh, body_note, built = _one_body(mesh, label, debris, np.asarray(pieces))
        if body_note:
            notes.append(body_note)
    # the repairs of a mesh the pieces were joined into are the join's, not the file's
    whose = " where the pieces were joined" if built else ""
    nv = len(mesh.vertices)
    # an STL stores every face's own corners: merging them is loading, not repairing; an indexed mesh (OBJ, PLY)
    # that repeats vertices has seams, and merging those is a repair worth reporting
    uses = np.bincount(np.asarray(mesh.faces).ravel(), minlength=nv)
    indexed = bool(uses.max(initial=0) > 1)
    if copy:
        mesh = mesh.copy()
    if not (uses.all() and _distinct_positions(mesh.vertices)):  # else merging would change nothing
        mesh.merge_vertices()
    if indexed and len(mesh.vertices) < nv:
        notes.append(f"merged {nv - len(mesh.vertices)} duplicate vertices{whose}")
    faces = mesh.faces
    areas = face_areas(np.ascontiguousarray(mesh.vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    degenerate = repeated | (areas <= 1e-14 * max(1.0, float(areas.max(initial=0.0))))
    if degenerate.all():
        raise MeshError(f"{label} has only degenerate (zero-area) faces")
    if degenerate.any():
        mesh.update_faces(~degenerate)
        notes.append(f"removed {int(degenerate.sum())} degenerate faces{whose}")
    if _repeated_triples(mesh.faces, len(mesh.vertices)):  # else no face covers another: nothing to drop
        walls = _inner_walls(mesh.faces)
        if walls.any():
            mesh.update_faces(~walls)
            notes.append(f"removed {int(walls.sum()) // 2} pairs of coincident, opposite faces (the wall where two "
                         f"pieces meet face to face)")
        nf = len(mesh.faces)
        mesh.update_faces(mesh.unique_faces())
        if len(mesh.faces) < nf:
            notes.append(f"dropped {nf - len(mesh.faces)} duplicate faces")
    mesh.remove_unreferenced_vertices()
    # in its final labelling from here, unless a repair below changes the faces: the edge tables built next are then
    # the loaded part's, and its segmentation reuses them
    mesh = canonical(mesh)
    edited = False
    groups = edge_groups(mesh.faces, len(mesh.vertices))
    if (np.diff(groups[1]) > 2).any():  # an edge of more than two faces: pieces may meet face to face there
        walls = _coplanar_walls(mesh)
        if walls.any() and not walls.all():
            mesh.update_faces(~walls)
            mesh.remove_unreferenced_vertices()
            notes.append(f"removed {int(walls.sum())} faces of the walls where pieces meet face to face (coplanar "
                         f"faces of opposite normals covering each other)")
            groups, edited = edge_groups(mesh.faces, len(mesh.vertices)), True
    whole = mesh
    table = neighbour_table(*groups, len(mesh.faces))
    mesh, body_note, _ = _one_body(mesh, label, debris, table=table)
    if body_note:
        notes.append(body_note)
    edited |= mesh is not whole
    watertight, winding = edge_flags(mesh.faces, len(mesh.vertices), None if edited else groups)
    if not watertight:
        before = len(mesh.faces)
        filled = _fill_loops(mesh, hole_edges, hole_size)
        if filled:
            notes.append(f"filled {filled} small holes (at most {hole_size * 1e3:.3g} mm across) with "
                         f"{len(mesh.faces) - before} faces")
            watertight, winding = edge_flags(mesh.faces, len(mesh.vertices))
            edited = True
    if not winding:
        trimesh.repair.fix_normals(mesh)  # consistent winding, and outward when closed
        notes.append("faces were not consistently oriented; re-oriented them")
        watertight, winding = edge_flags(mesh.faces, len(mesh.vertices))
        edited = True
    if watertight and _inside_out(mesh):
        mesh.invert()
        notes.append("turned the normals outward (the mesh was inside out)")
        edited = True
    out = canonical(mesh) if edited else mesh
    if not edited:
        out._cache[EDGES_KEY] = (*groups, table)
    # a relabelling: the same edges, used the same ways (trimesh would find them again at a second's cost at 1M faces)
    out._cache["is_watertight"], out._cache["is_winding_consistent"] = watertight, winding
    # trimesh's normals, to the bit, without its (n, 3, 3) corner array: a tenth of its time on a full-resolution scan
    out._cache["face_normals"] = unit_normals(np.ascontiguousarray(out.vertices, dtype=np.float64),
                                              np.ascontiguousarray(out.faces, dtype=np.int64))
    return out, notes


def face_pairs(mesh: trimesh.Trimesh, table: np.ndarray | None = None) -> np.ndarray:
    """(P, 2) the faces joined across an edge that exactly two faces share (trimesh's face adjacency, as a set), from
    one sort of the edges (or from `table`, the mesh's `neighbour_table`)."""
    n = len(mesh.faces)
    if table is None:
        table = neighbour_table(*edge_groups(mesh.faces, len(mesh.vertices)), n)
    t = np.repeat(np.arange(n), 3)
    other = table.ravel()
    keep = other < n
    return np.column_stack([t[keep], other[keep]])


def edge_flags(faces: np.ndarray, n_vertices: int,
               groups: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[bool, bool]:
    """(watertight, winding consistent) as trimesh defines them: every edge is shared by exactly two faces; each
    edge shared by two faces is used by them in opposite directions. One sort of the edges (or `groups`, the faces'
    `edge_groups`)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if len(faces) == 0:
        return False, True
    watertight, winding = winding_flags(*(edge_groups(faces, n_vertices) if groups is None else groups), faces)
    return bool(watertight), bool(winding)


def volume_centre(mesh: trimesh.Trimesh) -> tuple[float, np.ndarray]:
    """The signed volume of a closed mesh and its centre of mass (uniform density): trimesh's integration
    (`trimesh.triangles.mass_properties`, the same operations and sums, so the same bits) without the inertia's
    terms, which cost two thirds of it; the per-face terms compiled (`_repairkernel.centre_terms`), and the edge
    cross products kept in the mesh's cache, where trimesh's areas and normals find them."""
    cross, integral = centre_terms(np.ascontiguousarray(mesh.vertices, dtype=np.float64),
                                   np.ascontiguousarray(mesh.faces, dtype=np.int64))
    if mesh._cache["triangles_cross"] is None:
        mesh._cache["triangles_cross"] = cross
    integrated = integral.sum(axis=1) / np.array([6, 24, 24, 24], dtype=np.float64)
    return float(integrated[0]), integrated[1:4] / integrated[0]


def _inside_out(mesh: trimesh.Trimesh) -> bool:
    """Whether a closed mesh's signed volume is negative (its normals point inward): the sign of the compiled sum of
    `volume_centre`'s volume terms where it exceeds the bound on any summation order's error, else `volume_centre`'s."""
    s, bound = volume_terms(np.ascontiguousarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64))
    return bool(s < 0) if abs(s) > bound else volume_centre(mesh)[0] < 0


def canonical(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The same oriented surface with its vertices in coordinate order and its faces in index order, each face
    starting at its lowest vertex (its winding kept): a file's vertex and face order, and which corner each face
    lists first, then change nothing downstream (sample order, caches, the object's digest)."""
    v = np.asarray(mesh.vertices)
    order = _coordinate_order(v)
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order))
    n = len(v)
    f, key = rotated_faces(rank, np.ascontiguousarray(mesh.faces, dtype=np.int64), n)
    if 0 < n < 2**21:  # the three indices as one int64 key: its stable sort is the lexicographic one, 3x faster
        f = f[np.argsort(key, kind="stable")]
    else:
        f = f[np.lexsort((f[:, 2], f[:, 1], f[:, 0]))]
    return trimesh.Trimesh(v[order], f, process=False, validate=False)


def _coordinate_order(v: np.ndarray) -> np.ndarray:
    """`np.lexsort((z, y, x))` of the points `v` (N, 3): a stable sort by x, then the runs of equal x (few, on a
    scan; a CAD part's flat sides share coordinates) sorted by y and z, several times faster than sorting all three
    keys."""
    order = np.argsort(v[:, 0], kind="stable")
    xs = v[order, 0]
    same = xs[1:] == xs[:-1]
    if same.any():
        tied = np.flatnonzero(np.r_[same, False] | np.r_[False, same])  # the positions in a run of equal x
        run = np.cumsum(np.r_[True, ~same])[tied]
        sub = order[tied]
        order[tied] = sub[np.lexsort((v[sub, 2], v[sub, 1], run))]
    return order


def _one_body(mesh: trimesh.Trimesh, label: str, debris: float, pieces: np.ndarray | None = None,
              touch: float = 1e-4, table: np.ndarray | None = None) -> tuple[trimesh.Trimesh, str, bool]:
    """One part from the file's bodies: bodies that touch, interpenetrate or lie inside one another (within `touch`
    of the part's largest extent, well above export precision) are pieces of one part and become their union;
    small separate bodies are debris and are dropped; bodies really apart are refused, naming the gap. `pieces`
    (per face) names the file's own pieces (a scene's meshes): each is split into bodies on its own, so that pieces
    meeting face to face are not glued at their shared corners into one body that is not closed. `table`: the
    mesh's `neighbour_table`, when known. Returns the part, the note on what was done (empty when nothing was) and
    whether the part is a mesh built from several bodies (their union, or the pieces kept together)."""
    bodies = []
    for p in np.unique(pieces) if pieces is not None else [None]:
        part = mesh if p is None else _submesh(mesh, pieces == p)
        if p is not None:
            part.merge_vertices()
        if p is not None or table is None:
            table = neighbour_table(*edge_groups(part.faces, len(part.vertices)), len(part.faces))
        if connected(table):  # one body: no labels to build
            bodies.append(part)
            continue
        labels = trimesh.graph.connected_component_labels(face_pairs(part, table), node_count=len(part.faces))
        bodies += [part] if labels.max(initial=0) == 0 else [_submesh(part, labels == i) for i in range(labels.max() + 1)]
    n = len(bodies)
    if n <= 1:
        return mesh, "", False
    area = np.array([b.area for b in bodies])
    tol = touch * float(mesh.extents.max())
    gap = _gaps(bodies, tol)
    cluster = trimesh.graph.connected_component_labels(np.argwhere(np.triu(gap <= tol, 1)), node_count=n)
    carea = np.bincount(cluster, weights=area)
    big = int(np.argmax(carea))
    rest = float(carea.sum() - carea[big])
    if rest > debris * carea[big]:
        # the nearest body to the largest piece's cluster, for the message
        other = cluster != big
        inner = cluster == big
        nearest = float(gap[np.ix_(inner, other)].min())
        sizes = ", ".join(f"{a * 1e4:.3g}" for a in sorted(carea, reverse=True)[:4])
        raise MeshError(f"{label} holds {int(cluster.max()) + 1} separate bodies of comparable size (areas {sizes} "
                        f"cm^2), the nearest {nearest * 1e3:.3g} mm apart (pieces within {tol * 1e3:.2g} mm are "
                        f"joined as one part); export the one body to grasp as its own file")
    notes = []
    keep = np.flatnonzero(cluster == big)
    if rest > 0:
        dropped = n - len(keep)
        notes.append(f"kept the largest body ({carea[big] * 1e4:.3g} cm^2) and dropped {dropped} small separate "
                     f"{'body' if dropped == 1 else 'bodies'} ({rest * 1e4:.3g} cm^2 in all)")
    if len(keep) == 1:
        return bodies[int(keep[0])], "; ".join(notes), False
    pieces = [bodies[i] for i in keep]
    total = float(sum(p.area for p in pieces))
    joined = _union(pieces, tol)
    if joined is not None:
        notes.append(f"joined {len(keep)} touching bodies into one part (their union: {joined.area * 1e4:.3g} of "
                     f"{total * 1e4:.3g} cm^2 of surface is outside)")
        return joined, "; ".join(notes), True
    # no union (a piece is not closed): the pieces stay together, less the faces inside another piece
    outer = _outer_faces(pieces)
    kept = trimesh.util.concatenate(pieces)
    kept.update_faces(outer)
    kept.remove_unreferenced_vertices()
    why = ("not every piece is closed" if not all(p.is_watertight for p in pieces)
           else "manifold3d did not join the closed pieces into one solid")
    notes.append(f"kept {len(keep)} touching bodies together as one part (no union: {why}; "
                 f"{int((~outer).sum())} faces inside another piece dropped)")
    return kept, "; ".join(notes), True


def _distinct_positions(vertices: np.ndarray) -> bool:
    """Whether no two vertices share a position at trimesh's merge precision (`tol.merge`), as its `merge_vertices`
    rounds them: then, every vertex being used, merging keeps the mesh as it is. One sort of one int64 hash per vertex;
    a hash shared by two positions answers False, and trimesh then merges as usual."""
    q = (np.asarray(vertices) * (10 ** trimesh.util.decimal_to_digits(trimesh.tol.merge))).round().astype(np.int64)
    h = np.sort(q[:, 0] * np.int64(0x9E3779B97F4A7C1) + q[:, 1] * np.int64(0x632BE59BD9B4E01) + q[:, 2])  # wraps
    return bool((h[1:] != h[:-1]).all())


def _repeated_triples(faces: np.ndarray, n_vertices: int) -> bool:
    """Whether two faces use the same three vertices (in any order): one sort of one int64 key per face."""
    if n_vertices >= 2**21:
        return True  # the key would overflow: let the full checks decide
    code = np.sort(triple_codes(np.ascontiguousarray(faces, dtype=np.int64), n_vertices))
    return bool((code[1:] == code[:-1]).any())


def _inner_walls(faces: np.ndarray) -> np.ndarray:
    """Mask of faces that another face covers with the opposite winding (the same three vertices): both are the
    inside wall of two pieces meeting face to face, not surface."""
    key = np.sort(faces, axis=1)
    # the winding's parity: an even rotation of the sorted triple, or an odd one
    even = ((faces == np.roll(key, 0, axis=1)).all(axis=1) | (faces == np.roll(key, 1, axis=1)).all(axis=1)
            | (faces == np.roll(key, 2, axis=1)).all(axis=1))
    # which faces share a vertex triple: the triples sorted (lexicographically), then numbered
    order = np.lexsort((key[:, 2], key[:, 1], key[:, 0]))
    ks = key[order]
    new = np.r_[True, (ks[1:] != ks[:-1]).any(axis=1)] if len(ks) else np.zeros(0, dtype=bool)
    inv = np.empty(len(key), dtype=np.int64)
    inv[order] = np.cumsum(new) - 1
    n = int(inv.max()) + 1 if len(inv) else 0
    pos = np.bincount(inv, weights=even, minlength=n)
    neg = np.bincount(inv, weights=~even, minlength=n)
    return ((pos > 0) & (neg > 0))[inv]


def _coplanar_walls(mesh: trimesh.Trimesh, rel: float = 1e-9) -> np.ndarray:
    """Mask of the faces of walls where two closed pieces meet face to face, triangulated differently on either side
    (`_inner_walls` finds the same triangles twice): in one plane (within about 1e3 `rel` of the part's size), the
    faces of either normal whose centres lie on faces of the other, when the corners of each side's such faces lie
    on the other side's too (the same region, not a small block standing on a larger one, which the union joins)."""
    n = np.asarray(mesh.face_normals)
    tri = np.asarray(mesh.triangles)
    size = max(float(mesh.extents.max()), 1e-12)
    # a plane's key: its normal made to point into the upper half space, and its offset along it
    flip = np.where((n[:, 2] < 0) | ((n[:, 2] == 0) & ((n[:, 1] < 0) | ((n[:, 1] == 0) & (n[:, 0] < 0)))), -1.0, 1.0)
    un = n * flip[:, None]
    off = np.einsum("ij,ij->i", un, tri[:, 0])
    key = np.column_stack([np.round(un * 1e6), np.round(off / (1e3 * rel * size))]).astype(np.int64)
    with np.errstate(over="ignore"):  # one hash per plane (wrapping)
        h = key @ np.array([0x9E3779B97F4A7C1, 0x632BE59BD9B4E01, 0x2545F4914F6CDD1D, 1], dtype=np.int64)
    order = np.argsort(h, kind="stable")
    hs = h[order]
    starts = np.flatnonzero(np.r_[True, hs[1:] != hs[:-1], True])
    plane = np.empty(len(h), dtype=np.int64)
    plane[order] = np.repeat(np.arange(len(starts) - 1), np.diff(starts))
    both = np.flatnonzero((np.bincount(plane[flip > 0], minlength=len(starts) - 1) > 0)
                          & (np.bincount(plane[flip < 0], minlength=len(starts) - 1) > 0))
    out = np.zeros(len(tri), dtype=bool)
    for p in both:
        faces = order[starts[p]:starts[p + 1]]
        centres = tri[faces].mean(axis=1)
        side = flip[faces] > 0
        up, down = faces[side], faces[~side]
        up, down = up[_on_triangles(centres[side], tri[down])], down[_on_triangles(centres[~side], tri[up])]
        if (len(up) and len(down) and _on_triangles(tri[up].reshape(-1, 3), tri[down]).all()
                and _on_triangles(tri[down].reshape(-1, 3), tri[up]).all()):
            out[up] = out[down] = True
    return out


def _on_triangles(points: np.ndarray, tri: np.ndarray, chunk: int = 1 << 20) -> np.ndarray:
    """(P,) whether each point, in the plane of the coplanar triangles `tri` (T, 3, 3), lies on one of them."""
    hit = np.zeros(len(points), dtype=bool)
    if len(tri) == 0:
        return hit
    step = max(1, chunk // len(tri))
    for s in range(0, len(points), step):
        q = points[s:s + step]
        bary = trimesh.triangles.points_to_barycentric(np.tile(tri, (len(q), 1, 1)), np.repeat(q, len(tri), axis=0))
        hit[s:s + step] = (bary >= -1e-9).all(axis=1).reshape(len(q), len(tri)).any(axis=1)
    return hit


def _submesh(mesh: trimesh.Trimesh, faces: np.ndarray) -> trimesh.Trimesh:
    out = trimesh.Trimesh(mesh.vertices, mesh.faces[faces], process=False, validate=False)
    out.remove_unreferenced_vertices()
    return out


def _gaps(bodies: list[trimesh.Trimesh], tol: float) -> np.ndarray:
    """Distances between bodies (n, n): 0 where they touch, cross or one lies inside the other; the bounding boxes'
    gap where those are more than `tol` apart (a lower bound), else the surfaces' distance (python-fcl)."""
    n = len(bodies)
    lo = np.array([b.bounds[0] for b in bodies])
    hi = np.array([b.bounds[1] for b in bodies])
    box = np.linalg.norm(np.maximum(0.0, np.maximum(lo[:, None] - hi[None], lo[None] - hi[:, None])), axis=2)
    gap = box.copy()
    for i in range(n):
        for j in range(i + 1, n):
            if box[i, j] > tol:
                continue
            d = mesh_distance(bodies[i], bodies[j])
            if d > 0 and any(_inside(bodies[a], bodies[b].vertices[:1]) for a, b in ((i, j), (j, i))):
                d = 0.0
            gap[i, j] = gap[j, i] = d
    return gap


def _inside(body: trimesh.Trimesh, points: np.ndarray) -> bool:
    return bool(body.is_watertight and body.contains(points).all())


def _union(pieces: list[trimesh.Trimesh], tol: float) -> trimesh.Trimesh | None:
    """The pieces' boolean union (manifold3d, in double precision) as one closed body, or None when a piece is not a
    closed manifold. Pieces whose touching faces rounding has moved apart (a scene's transforms, an export's
    precision) give separate solids, or one with the touching walls kept as a crack of zero width; the union is then
    taken of the vertices snapped to a grid of 1e-9 of the pieces' size, which puts faces within rounding of one
    plane in that plane, and failing that of the pieces grown about their centres by the least of 1e-3, 1e-2, 0.1
    and 1 times `tol` that joins them."""
    closed = []
    for p in pieces:
        if not p.is_watertight:
            return None
        q = p.copy()
        if q.volume < 0:
            q.invert()
        closed.append(q)

    size = float(np.ptp(np.vstack([q.vertices for q in closed]), axis=0).max())
    grid = 2.0 ** np.round(np.log2(max(1e-9 * size, 1e-300)))  # a power of two: the snapped values are exact

    def union(grow: float, snap: bool = False):
        solids = []
        for q in closed:
            # ungrown, the vertices as they are (or snapped): the rounding of c + (v - c) would move faces that
            # meet in exactly one plane apart
            if snap:
                v = np.round(q.vertices / grid) * grid
            elif grow == 0:
                v = q.vertices
            else:
                c = q.vertices.mean(axis=0)
                r = float(np.linalg.norm(q.vertices - c, axis=1).max())
                v = c + (q.vertices - c) * (1 + grow / max(r, 1e-12))
            m = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=np.ascontiguousarray(v, dtype=np.float64),
                                                      tri_verts=np.ascontiguousarray(q.faces, dtype=np.uint64)))
            if m.status() != manifold3d.Error.NoError or m.is_empty():
                return None
            solids.append(m)
        u = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add)
        if u.status() != manifold3d.Error.NoError or u.is_empty() or len(u.decompose()) > 1:
            return None
        out = u.to_mesh64()
        verts = np.asarray(out.vert_properties)[:, :3]
        if len(cKDTree(verts).query_pairs(1e-12 * max(float(np.ptp(verts, axis=0).max()), 1e-12))):
            return None  # two vertices at one point, to rounding: the rim of a crack between touching walls
        # as manifold3d gives it: merging its vertices (trimesh's processing) would pinch apart vertices closer than
        # the merge tolerance into edges of four faces
        joined = trimesh.Trimesh(verts, np.asarray(out.tri_verts, dtype=np.int64), process=False)
        return joined if joined.is_watertight and joined.body_count == 1 else None

    for grow, snap in ((0.0, False), (0.0, True), (1e-3 * tol, False), (1e-2 * tol, False), (0.1 * tol, False),
                       (tol, False)):
        joined = union(grow, snap)
        if joined is not None:
            return joined
    return None


def _outer_faces(pieces: list[trimesh.Trimesh]) -> np.ndarray:
    """Mask of the pieces' faces (concatenated) whose centres lie inside no other closed piece."""
    masks = []
    for i, p in enumerate(pieces):
        inside = np.zeros(len(p.faces), dtype=bool)
        for j, q in enumerate(pieces):
            if j != i and q.is_watertight:
                inside |= q.contains(p.triangles_center)
        masks.append(~inside)
    return np.concatenate(masks)


def open_border(mesh: trimesh.Trimesh) -> tuple[int, float]:
    """The edges used by one face only (the border of the mesh's holes) and the largest extent (m) of one connected
    run of them: (0, 0.0) for a mesh without holes."""
    e = np.asarray(mesh.faces)[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)
    order, starts = edge_groups(mesh.faces, len(mesh.vertices))
    single = order[starts[:-1][np.diff(starts) == 1]]
    if len(single) == 0:
        return 0, 0.0
    border = e[single]
    labels = trimesh.graph.connected_component_labels(border, node_count=len(mesh.vertices))
    # each run's box, from its vertices grouped by run (a scan may have thousands of holes)
    verts = np.unique(border)
    order = np.argsort(labels[verts], kind="stable")
    run, pts = labels[verts][order], np.asarray(mesh.vertices)[verts[order]]
    starts = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    span = float((np.maximum.reduceat(pts, starts, axis=0) - np.minimum.reduceat(pts, starts, axis=0)).max())
    return int(len(border)), span


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
