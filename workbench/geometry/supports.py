"""Support faces of a convex hull, merged when coplanar within a tolerance (Wan & Harada, Section IV).

A scanned base is flat only to a tolerance: its convex hull is many small faces whose normals differ by a degree
or so, none of which holds the centre of mass's projection on its own. The hull's faces are first joined into
facets (faces in one plane to rounding, however the hull triangulated them), and facets are grouped greedily,
largest first: a facet joins a group when its normal is within `angle` of the group's seed and all its vertices lie
within `distance` of the seed's plane, or when its vertices lie within a quarter of `distance` whatever its tilt
(thin slivers along the rim of a noisy base), as long as it does not face away from the seed and is a sliver beside
it (at most `SLIVER_SHARE` of the seed's area): the equal strips of a thin faceted rod are its sides, each tilted
from the next, and joined in pairs they would make a support out of the edge between them. A group is one
candidate support resting on its area-weighted normal; its support polygon is the convex hull of the group's
vertices (all within `distance` of the table). Only the group's own vertices count: on a curved side (a cylinder's
flat strips) vertices of neighbouring strips also lie within half a millimetre of the table, but the object would
roll, not rest on them.
"""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.geometry._hullkernel import group_facets
from workbench.geometry.hull import merge_tolerance


def coplanar_groups(hull: trimesh.Trimesh, distance: float, angle: float) -> tuple[list[np.ndarray], np.ndarray]:
    """Groups of hull faces (arrays of face ids, largest seed first) and their area-weighted outward unit normals.

    The hull's faces are first joined into facets, the faces within `hull.merge_tolerance` of one plane: a flat side
    is one facet however it is triangulated, with the slivers that rounding puts along its edges (a subdivided part
    saved as STL). Facets are grouped greedily, largest first, as a whole: a tilted facet joins a group only when all
    of it lies within the tolerance, never the few of its triangles that happen to lie near the seed's edge. The walk
    (`_hullkernel.group_facets`) costs what each group's size costs, not the hull's."""
    faces = np.asarray(hull.faces, dtype=np.int64)
    verts = np.asarray(hull.vertices, dtype=np.float64)
    normals = np.asarray(hull.face_normals, dtype=np.float64)
    areas = np.asarray(hull.area_faces)
    if len(faces) == 0:
        return [], np.zeros((0, 3))
    graph = _hull_graph(hull)
    tol = merge_tolerance(verts)
    # faces into facets: each face its own facet, joined when within the tolerance of a larger one's plane
    single = np.arange(len(faces), dtype=np.int64)
    facet_of = group_facets(verts, faces, single, np.arange(len(faces) + 1, dtype=np.int64), single,
                            np.ascontiguousarray(normals), np.lexsort((single, -areas)), *graph, tol, tol, 2.0,
                            np.ascontiguousarray(areas, dtype=np.float64), np.inf, 2.0)
    label = _grouped(verts, faces, normals, areas, facet_of, graph, distance, 0.25 * distance, float(np.cos(angle)))
    k = np.argsort(label, kind="stable")
    groups = np.split(k, np.cumsum(np.bincount(label, minlength=int(label.max()) + 1))[:-1])
    wn = np.array([(normals[g] * areas[g, None]).sum(axis=0) for g in groups]).reshape(-1, 3)
    return groups, wn / np.linalg.norm(wn, axis=1, keepdims=True).clip(1e-300)


SLIVER_SHARE = 0.25  # a tilted facet joins a support as a sliver only with at most this share of its seed's area
SLIVER_TILT = float(np.radians(5.0))  # or when tilted less than this from it


def _grouped(verts, faces, normals, areas, facet_of, graph, distance, flat, cos_a) -> np.ndarray:
    """The group of every face: facets (`facet_of`, numbered 0..T-1) grouped by `group_facets`, seeds by area."""
    T = int(facet_of.max()) + 1
    members = np.argsort(facet_of, kind="stable")
    m_ptr = np.concatenate([[0], np.cumsum(np.bincount(facet_of, minlength=T))])
    area = np.bincount(facet_of, weights=areas, minlength=T)
    fn = np.column_stack([np.bincount(facet_of, weights=normals[:, a] * areas, minlength=T) for a in range(3)])
    length = np.linalg.norm(fn, axis=1, keepdims=True)
    first = normals[members[m_ptr[:-1]]]  # a facet of slivers only: its first face's normal
    fn = np.where(length > 1e-300, fn / np.where(length > 1e-300, length, 1.0), first)
    order = np.lexsort((np.arange(T), -area))
    label = group_facets(verts, faces, facet_of, m_ptr, members.astype(np.int64), np.ascontiguousarray(fn), order,
                         *graph, float(distance), float(flat), float(cos_a), area, SLIVER_SHARE,
                         float(np.cos(SLIVER_TILT)))
    return label[facet_of]


def _hull_graph(hull: trimesh.Trimesh) -> tuple[np.ndarray, ...]:
    """The hull's vertex neighbours and each vertex's faces, both in CSR form: (v_ptr, v_adj, f_ptr, f_idx)."""
    faces = np.asarray(hull.faces, dtype=np.int64)
    nv = len(hull.vertices)
    e = np.asarray(hull.edges_unique, dtype=np.int64)
    src, dst = np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]])
    k = np.argsort(src, kind="stable")
    v_ptr, v_adj = np.searchsorted(src[k], np.arange(nv + 1)), dst[k]
    fv = faces.ravel()
    k = np.argsort(fv, kind="stable")
    f_ptr, f_idx = np.searchsorted(fv[k], np.arange(nv + 1)), k // 3
    return v_ptr, v_adj, f_ptr, f_idx


def support_stability(points: np.ndarray, com: np.ndarray, normal: np.ndarray) -> float:
    """Stability of resting on the support `points` (vertices of one coplanar group) with outward `normal` down:
    the distance from the centre of mass's projection to the support polygon's boundary over the centre of mass's
    height (Section VI); negative when the projection falls outside, 0 when the support has no area."""
    from scipy.spatial import ConvexHull

    rel = points - com
    height = float((rel @ normal).max())
    if len(points) < 3 or height <= 0:
        return 0.0
    p2 = rel @ _plane_bases(normal[None])[0].T
    try:
        h = ConvexHull(p2)
    except Exception:  # collinear support: no area
        return 0.0
    return float(np.min(-h.equations[:, 2])) / height  # equations: unit n.x + d <= 0 inside; negative outside


def _plane_bases(normals: np.ndarray) -> np.ndarray:
    """Two unit vectors (G, 2, 3) spanning the plane normal to each unit normal (G, 3)."""
    a = np.zeros_like(normals)
    a[np.arange(len(normals)), np.argmin(np.abs(normals), axis=1)] = 1.0
    u = a - np.einsum("gj,gj->g", a, normals)[:, None] * normals
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return np.stack([u, np.cross(normals, u)], axis=1)


def stabilities(hull: trimesh.Trimesh, com: np.ndarray, groups: list[np.ndarray], normals: np.ndarray,
                floor: float = 0.0) -> np.ndarray:
    """`support_stability` of every group, its support the vertices of its faces. Groups whose farthest support point
    from the centre of mass's vertical cannot give a stability of `floor` score 0 (no hull is built). Supports of at
    most SMALL vertices (most of a curved part's hull) are scored together, by `_small_stabilities`."""
    faces = np.asarray(hull.faces)
    verts = np.asarray(hull.vertices)
    out = np.zeros(len(groups))
    support = [np.unique(faces[g]) for g in groups]
    size = np.array([len(v) for v in support])
    small = np.flatnonzero(size <= SMALL)
    if len(small):
        idx = np.array([np.resize(support[i], SMALL) for i in small])  # padded by repeating the group's vertices
        out[small] = _small_stabilities(verts[idx], com, normals[small], floor)
    for i in np.flatnonzero(size > SMALL):
        pts = verts[support[i]]
        rel = pts - com
        n = normals[i]
        h = rel @ n
        height = float(h.max())
        if height <= 0:
            continue
        reach = np.sqrt(max(float((np.einsum("vj,vj->v", rel, rel) - h**2).max()), 0.0))
        if reach / height < floor:
            continue
        out[i] = support_stability(pts, com, n)
    return out


SMALL = 8  # supports of at most this many vertices are scored together, without a hull each


def _small_stabilities(pts: np.ndarray, com: np.ndarray, normals: np.ndarray, floor: float) -> np.ndarray:
    """`support_stability` of G supports of SMALL points each (G, SMALL, 3; repeated points allowed) with outward
    `normals` (G, 3), all at once, and 0 where the farthest point cannot give `floor`. The support polygon's edges are
    the point pairs with every other point on one side; the stability is the least signed distance from the centre
    of mass's projection to their lines (negative outside) over its height."""
    rel = pts - com
    h = np.einsum("gvj,gj->gv", rel, normals)
    height = h.max(axis=1)
    reach = np.sqrt(np.clip((np.einsum("gvj,gvj->gv", rel, rel) - h**2).max(axis=1), 0.0, None))
    p2 = np.einsum("gvj,gcj->gvc", rel, _plane_bases(normals))  # (G, K, 2)
    i, j = np.triu_indices(pts.shape[1], 1)
    e = p2[:, j] - p2[:, i]  # (G, P, 2)
    length = np.linalg.norm(e, axis=2)
    tol = 1e-9 * np.maximum(np.abs(p2).max(axis=(1, 2)), 1e-300)
    m = np.stack([-e[..., 1], e[..., 0]], axis=2) / np.maximum(length, 1e-300)[..., None]
    side = np.einsum("gpkc,gpc->gpk", p2[:, None, :, :] - p2[:, i][:, :, None, :], m)  # (G, P, K)
    lo, hi = side.min(axis=2), side.max(axis=2)
    edge = (length > tol[:, None]) & ((lo >= -tol[:, None]) | (hi <= tol[:, None]))
    inward = np.where(lo >= -tol[:, None], 1.0, -1.0)
    dist = np.where(edge, -inward * np.einsum("gpc,gpc->gp", p2[:, i], m), np.inf).min(axis=1)
    area = np.abs(side).max(axis=(1, 2)) > tol
    ok = (height > 0) & area & (reach >= floor * height)
    return np.where(ok, dist / np.where(height > 0, height, 1.0), 0.0)


def rest_probabilities(hull: trimesh.Trimesh, com: np.ndarray, groups: list[np.ndarray], normals: np.ndarray,
                       stable: np.ndarray, rock_angle: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static stable-pose probabilities of the supports (groups of hull faces) and which of them rock:
    (probability (G,), rocking (G,)).

    A part dropped in a uniformly random orientation first lands, quasi-statically, on the hull face that the
    downward ray from its centre of mass meets, with probability that face's solid angle seen from the centre of
    mass over 4 pi; on a face of an unstable support it rolls over the edge beyond which the centre of mass
    projects, onto the neighbouring face, until it reaches a stable support (the drop statistics of Goldberg et al.'s
    part feeding and of Dex-Net's stable poses). A stable support is a rocking one when the tilt that tips it over its
    weakest edge (the edge nearest the centre of mass's projection) is below half `rock_angle` and the angle to the
    hull face beyond that edge below `rock_angle`: a small tilt rolls it onto the next facet, as on a faceted round
    side (a regular polygon's sides tip at half the angle between them). A broad support next to a rounded edge,
    which tips only at a large tilt, does not rock. The
    part rolls on from it, so that it gets no probability, unless rolling on never ends on a support that does not
    rock (a rounded part, all of whose supports rock): then the plain quasi-static flow decides.
    `stable` (G,) marks the supports holding the centre of mass's projection.
    """
    faces = np.asarray(hull.faces)
    tri = np.asarray(hull.triangles) - com
    fn = np.asarray(hull.face_normals)
    T = len(faces)
    group = np.full(T, -1, dtype=np.int64)
    for g, members in enumerate(groups):
        group[members] = g
    # the face across each edge (edge e of face f: vertices e and e + 1)
    across = np.full((T, 3), -1, dtype=np.int64)
    key = {}
    for f in range(T):
        for e in range(3):
            a, b = faces[f, e], faces[f, (e + 1) % 3]
            other = key.pop((b, a), None)
            if other is None:
                key[(a, b)] = (f, e)
            else:
                across[f, e], across[other[0], other[1]] = other[0], f
    # the centre of mass (origin) projected on each face's plane, in barycentric coordinates
    p = -np.einsum("fj,fj->f", tri[:, 0], fn)[:, None] * -fn
    v0, v1 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    w = p - tri[:, 0]
    d00, d01, d11 = (np.einsum("fj,fj->f", v0, v0), np.einsum("fj,fj->f", v0, v1), np.einsum("fj,fj->f", v1, v1))
    d20, d21 = np.einsum("fj,fj->f", w, v0), np.einsum("fj,fj->f", w, v1)
    den = np.where(np.abs(d00 * d11 - d01**2) > 0, d00 * d11 - d01**2, 1.0)
    lb = (d11 * d20 - d01 * d21) / den
    lc = (d00 * d21 - d01 * d20) / den
    bary = np.column_stack([1 - lb - lc, lb, lc])
    # rolling over the edge opposite the most negative coordinate: edge (i + 1, i + 2) is edge index (i + 1) % 3
    plain = across[np.arange(T), (np.argmin(bary, axis=1) + 1) % 3]
    nxt = plain.copy()
    rocking = np.zeros(len(groups), dtype=bool)
    if rock_angle > 0:
        for g in np.flatnonzero(stable):
            members = groups[g]
            out_edges = [(f, e) for f in members for e in range(3) if group[across[f, e]] != g]
            if not out_edges:
                continue
            # the boundary edge nearest the centre of mass's projection on the support's plane
            n = normals[g]
            height = abs(float(tri[members[0], 0] @ n))
            q = height * n
            dist = []
            for f, e in out_edges:
                a, b = tri[f, e], tri[f, (e + 1) % 3]
                t = np.clip(((q - a) @ (b - a)) / max((b - a) @ (b - a), 1e-300), 0.0, 1.0)
                dist.append(np.linalg.norm(a + t * (b - a) - q))
            f, e = out_edges[int(np.argmin(dist))]
            beyond = across[f, e]
            tip = np.arctan2(min(dist), height)
            if beyond >= 0 and tip < 0.5 * rock_angle and np.arccos(np.clip(fn[beyond] @ n, -1.0, 1.0)) < rock_angle:
                rocking[g] = True
                for m in members:  # the part rolls on across that edge
                    nxt[m] = beyond

    def flow(rest: np.ndarray, step: np.ndarray) -> np.ndarray:
        """The support each face's drop ends on (-1: none, rolling on in a cycle)."""
        terminal = rest[group] | (step < 0)
        target = np.where(terminal, np.arange(T), step)
        for _ in range(int(np.ceil(np.log2(max(T, 2)))) + 2):  # pointer jumping: each round doubles the steps
            target = np.where(terminal[target], target, target[target])
        return np.where(terminal[target] & rest[group[target]], group[target], -1)

    end = flow(stable & ~rocking, nxt)
    end = np.where(end >= 0, end, flow(stable, plain))
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    la, lb_, lc_ = (np.linalg.norm(x, axis=1) for x in (a, b, c))
    num = np.abs(np.einsum("fj,fj->f", a, np.cross(b, c)))
    den = la * lb_ * lc_ + np.einsum("fj,fj->f", a, b) * lc_ + np.einsum("fj,fj->f", a, c) * lb_ \
        + np.einsum("fj,fj->f", b, c) * la
    omega = 2 * np.arctan2(num, den)  # solid angle of each face seen from the centre of mass
    landed = end >= 0
    prob = np.bincount(end[landed], weights=omega[landed], minlength=len(groups))
    total = prob.sum()
    return (prob / total if total > 0 else prob), rocking


def support_image(turn: np.ndarray, normals: np.ndarray, heights: np.ndarray, angle: float = np.radians(0.5),
                  distance: float = 5e-4) -> np.ndarray | None:
    """Where a turn (3, 3) about the centre of mass maps supports with unit `normals` (G, 3) and planes at `heights`
    (G,) from it: image (G,), the support whose normal is within `angle` of the turned normal and whose height is
    within `distance`; None unless every support maps onto a distinct one."""
    cos = (normals @ np.asarray(turn, dtype=np.float64).T) @ normals.T  # (G, G): image of i against j
    image = np.argmax(cos, axis=1) if len(normals) else np.zeros(0, dtype=np.int64)
    ok = (cos[np.arange(len(image)), image] >= np.cos(angle)) & (np.abs(heights[image] - heights) <= distance)
    return image if ok.all() and len(np.unique(image)) == len(image) else None


def symmetric_average(values: np.ndarray, normals: np.ndarray, heights: np.ndarray, turns: np.ndarray) -> np.ndarray:
    """`values` (G,) of supports averaged over the orbits of a symmetry group `turns` (K, 3, 3) about the centre of
    mass (`support_image` of each turn; a turn that does not map the supports onto themselves is skipped): the mean
    of values over each support's images. Quantities that depend only on the hull and the centre of mass, such as
    the rest probabilities, are equal on supports a symmetry swaps, whatever the hull's triangulation makes of them."""
    values = np.asarray(values, dtype=np.float64)
    images = [im for im in (support_image(g, normals, heights) for g in np.asarray(turns).reshape(-1, 3, 3)) if im is not None]
    return np.mean([values[im] for im in images], axis=0) if images else values
