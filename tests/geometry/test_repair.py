"""Safe mesh repair at load (issue 10): what is repaired is reported; what cannot be is refused in one line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import manifold3d
import trimesh

from workbench.benchmarks.organic import blob, holed
from workbench.errors import MeshError
from workbench.geometry.objects import from_arrays, load_object


def _load(mesh: trimesh.Trimesh, name: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return from_arrays(mesh.vertices, mesh.faces, scale=1.0, name=name, source="<memory>")


def test_flipped_faces_and_inside_out_mesh_are_reoriented():
    good = blob(seed=1)
    faces = good.faces.copy()
    faces[::5] = faces[::5, ::-1]
    given = trimesh.Trimesh(good.vertices, faces, process=False)
    obj = _load(given, "flipped")
    assert np.array_equal(given.faces, faces) and np.array_equal(given.vertices, good.vertices)  # the caller's mesh kept
    assert obj.mesh.is_winding_consistent and obj.mesh.volume > 0
    assert obj.com_method == "volume" and np.allclose(obj.com, good.center_mass, atol=1e-9)
    assert any("re-oriented" in r for r in obj.repairs)
    inside_out = _load(trimesh.Trimesh(good.vertices, good.faces[:, ::-1], process=False), "inside_out")
    assert inside_out.mesh.volume > 0 and any("outward" in r for r in inside_out.repairs)


def test_duplicate_vertices_degenerate_faces_and_small_holes_are_fixed():
    m = holed(blob(seed=6, noise=2e-4, rows=26, cols=50), seed=6)
    assert not m.is_watertight
    # split every vertex of the first faces into duplicates and add a zero-area face
    v = np.vstack([m.vertices, m.vertices[m.faces[:10]].reshape(-1, 3)])
    f = m.faces.copy()
    f[:10] = len(m.vertices) + np.arange(30).reshape(10, 3)
    f = np.vstack([f, [[f[20, 0], f[20, 0], f[20, 1]]]])
    obj = _load(trimesh.Trimesh(v, f, process=False), "scan")
    text = "; ".join(obj.repairs)
    assert "duplicate vertices" in text and "degenerate" in text and "holes" in text, text
    assert obj.mesh.is_watertight and obj.com_method == "volume"


def test_several_bodies_largest_kept_or_refused():
    big = blob(seed=1)
    crumb = trimesh.creation.icosphere(radius=0.002).apply_translation([0.1, 0, 0])
    obj = _load(trimesh.util.concatenate([big, crumb]), "with_crumb")
    assert len(obj.mesh.faces) == len(big.faces) and any("largest body" in r for r in obj.repairs)
    twins = trimesh.util.concatenate([big, big.copy().apply_translation([0.2, 0, 0])])
    with pytest.raises(MeshError, match="2 separate bodies"):
        _load(twins, "twins")
    # overlapping pieces of one part (a bear made of convex pieces) become one body, their union
    pieces = trimesh.util.concatenate([big, trimesh.creation.icosphere(radius=0.015).apply_translation([0.03, 0, 0])])
    obj = _load(pieces, "pieces")
    assert obj.mesh.body_count == 1 and obj.mesh.area < pieces.area


def test_clean_mesh_reports_no_repair(tmp_path):
    path = tmp_path / "clean.stl"
    trimesh.creation.box((0.05, 0.04, 0.03)).export(path)
    assert load_object(path).repairs == ()


def test_repaired_boxes_give_the_clean_box_grasp_rows(tmp_path, hand):
    """A box re-wound in part, inside out, or with its vertices and faces shuffled and duplicated is the clean box:
    the same mesh, digest and grasp rows through the store."""
    from workbench.geometry.repair import canonical
    from workbench.grasping.grasps import GraspParams
    from workbench.planners.wan_harada.stages import ensure_grasps
    from workbench.store import Store
    from workbench.store.grasps import load_grasps

    clean = trimesh.creation.box((0.05, 0.04, 0.03))
    rng = np.random.default_rng(3)
    rewound = clean.faces.copy()
    rewound[::3] = rewound[::3, ::-1]
    perm = rng.permutation(len(clean.vertices))
    shuffled_v = clean.vertices[perm]
    shuffled_f = np.argsort(perm)[clean.faces][rng.permutation(len(clean.faces))]
    shuffled_f = np.roll(shuffled_f, 1, axis=1)  # each face listed from another corner, same winding
    dup_v = np.vstack([shuffled_v, shuffled_v])
    dup_f = np.vstack([shuffled_f, shuffled_f[:4], shuffled_f[5:9] + len(shuffled_v)])
    variants = {"clean": (clean.vertices, clean.faces), "rewound": (clean.vertices, rewound),
                "inside_out": (clean.vertices, clean.faces[:, ::-1]), "shuffled": (dup_v, dup_f)}
    rows = {}
    for label, (v, f) in variants.items():
        obj = _load(trimesh.Trimesh(v, f, process=False), "box")
        db = tmp_path / f"{label}.duckdb"
        result = ensure_grasps(db, obj, hand, GraspParams())
        with Store(db) as store:
            g = load_grasps(store, result.idobject, result.idparamset)
        rows[label] = (obj.digest, obj.mesh.vertices, obj.mesh.faces, g)
    assert len({r[0] for r in rows.values()}) == 1
    ref = rows["clean"]
    assert len(ref[3]["jawwidth"]) > 50
    for label, (_, v, f, g) in rows.items():
        assert np.array_equal(v, ref[1]) and np.array_equal(f, ref[2]), label
        for key in ("contactpoint0", "contactpoint1", "contactnormal0", "contactnormal1", "rotmat", "jawwidth"):
            assert np.array_equal(g[key], ref[3][key]), (label, key)
    once = canonical(clean)
    assert np.array_equal(canonical(once).faces, once.faces) and np.isclose(once.volume, clean.volume)
    f = np.asarray(once.faces)  # faces in lexicographic order, each from its lowest vertex
    assert np.array_equal(np.lexsort((f[:, 2], f[:, 1], f[:, 0])), np.arange(len(f))) and (f[:, 0] == f.min(axis=1)).all()


def _pieces() -> list[trimesh.Trimesh]:
    """A part from convex pieces as a convex decomposition exports it: a block, a second block meeting it face to
    face 4 um deep, and a peg sunk 10 mm into the first."""
    a = trimesh.creation.box((0.04, 0.03, 0.02))
    b = trimesh.creation.box((0.02, 0.03, 0.02)).apply_translation([0.03 - 4e-6, 0, 0])
    c = trimesh.creation.cylinder(radius=0.006, height=0.03, sections=24).apply_translation([-0.01, 0, 0.015])
    return [a, b, c]


def test_touching_pieces_are_one_part_with_the_union_surface(hand):
    from workbench.grasping.grasps import GraspParams, plan_grasps

    pieces = _pieces()
    joined = trimesh.util.concatenate(pieces)
    obj = _load(joined, "pieces")
    assert any("joined 3 touching bodies" in r for r in obj.repairs), obj.repairs
    assert obj.mesh.is_watertight and obj.mesh.body_count == 1
    assert obj.mesh.area < sum(p.area for p in pieces) - 1e-4  # the peg's sunk wall and the shared faces are gone
    assert np.isclose(obj.mesh.volume, 0.04 * 0.03 * 0.02 + 0.02 * 0.03 * 0.02 - 4e-6 * 0.03 * 0.02
                      + np.pi * 0.006**2 * 0.02, rtol=2e-2)
    plan = plan_grasps(obj, hand, GraspParams())
    assert len(plan.grasps) > 20
    # no sample lies inside a piece (signed distance is positive inside), so none on a face the union removed
    for p in pieces:
        assert trimesh.proximity.signed_distance(p, plan.samples.points).max() < 1e-6


def test_pieces_a_few_microns_apart_are_joined_and_bodies_5mm_apart_are_refused():
    a = trimesh.creation.box((0.03, 0.03, 0.03))
    near = trimesh.creation.box((0.03, 0.03, 0.03)).apply_translation([0.03 + 2e-6, 0, 0])
    obj = _load(trimesh.util.concatenate([a, near]), "gap")
    assert any("joined 2 touching bodies" in r for r in obj.repairs), obj.repairs
    far = trimesh.creation.box((0.03, 0.03, 0.03)).apply_translation([0.035, 0, 0])
    with pytest.raises(MeshError, match=r"nearest 5 mm apart"):
        _load(trimesh.util.concatenate([a, far]), "apart")


def test_boxes_sharing_a_face_exactly_are_one_closed_part_with_its_volume_centre(tmp_path):
    """Two closed boxes exported as one STL, sharing the plane x = 0 corner for corner but triangulated with other
    diagonals there: merged corners make the wall's edges shared by four faces, so splitting by edges gave four open
    pieces. The wall goes; the part is the closed 60 x 30 x 20 mm union, its centre of mass the volume's."""
    a = trimesh.creation.box((0.04, 0.03, 0.02)).apply_translation([0.02, 0, 0])
    b = trimesh.creation.box((0.02, 0.03, 0.02)).apply_translation([-0.01, 0, 0])
    walls = [np.sort(m.faces[np.isclose(m.triangles_center[:, 0], 0.0)], axis=1) for m in (a, b)]
    wall_a = {tuple(np.round(a.vertices[f].mean(axis=0), 9)) for f in walls[0]}
    wall_b = {tuple(np.round(b.vertices[f].mean(axis=0), 9)) for f in walls[1]}
    assert wall_a != wall_b  # other diagonals: no face of one wall repeats a face of the other
    path = tmp_path / "two_boxes.stl"
    trimesh.util.concatenate([a, b]).export(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        obj = load_object(path)
    assert any("walls where pieces meet face to face" in r for r in obj.repairs), obj.repairs
    assert obj.mesh.is_watertight and obj.mesh.body_count == 1 and obj.com_method == "volume"
    union = manifold3d.Manifold.cube([0.06, 0.03, 0.02]).translate([-0.02, -0.015, -0.01])
    assert np.isclose(obj.mesh.volume, union.volume(), rtol=1e-9)
    assert np.allclose(obj.com, [0.01, 0, 0], atol=1e-9)  # (40 x 20 mm + 20 x -10 mm) / 60 mm along x
    assert np.isclose(obj.mesh.area, union.surface_area(), rtol=1e-9)
    # a smaller block standing on part of a face is not a wall: the union joins it, keeping the uncovered rest
    c = trimesh.creation.box((0.02, 0.03, 0.04)).apply_translation([-0.01, 0, 0.01])
    obj = _load(trimesh.util.concatenate([a, c]), "step")
    assert obj.mesh.is_watertight and np.isclose(obj.mesh.volume, 0.04 * 0.03 * 0.02 + 0.02 * 0.03 * 0.04)


def test_an_l_bracket_of_boxes_touching_exactly_is_their_union_without_a_crack():
    """A base, an upright standing on part of it and a gusset touching both, exported as one mesh: the part is
    their union, 156 cm^2 (the boxes' 172 less both sides of the 4, 2 and 2 cm^2 where they touch) and 60 cm^3,
    with no wall left between upright and base (a crack of zero width there would add 8 cm^2). Built from their
    corners the boxes touch exactly; built from sizes and centres the upright stands an ulp off the base
    (0.04 - 0.03 != 0.01)."""
    bounds = [((0, 0, 0), (0.08, 0.04, 0.01)), ((0, 0, 0.01), (0.01, 0.04, 0.07)), ((0.01, 0.015, 0.01), (0.03, 0.025, 0.03))]
    exact = [trimesh.creation.box(bounds=np.array(b, dtype=float)) for b in bounds]
    centred = [trimesh.creation.box(np.subtract(hi, lo)).apply_translation(np.add(lo, hi) / 2) for lo, hi in bounds]
    assert centred[1].bounds[0, 2] != 0.01  # an ulp off the base
    for pieces in (exact, centred):
        obj = _load(trimesh.util.concatenate(pieces), "bracket")
        assert any("joined 3 touching bodies" in r for r in obj.repairs), obj.repairs
        assert obj.mesh.is_watertight and obj.mesh.body_count == 1
        assert np.isclose(obj.mesh.area, 0.0156, rtol=1e-9) and np.isclose(obj.mesh.volume, 6e-5, rtol=1e-9)
    # each box's corners moved by the rounding of c + (v - c) about its centre: the union as manifold3d gives it has
    # the crack, its rim's vertices doubled; the one returned is of the corners snapped back to one grid, without it
    from workbench.geometry.repair import _union

    rounded = []
    for p in exact:
        c = p.vertices.mean(axis=0)
        rounded.append(trimesh.Trimesh(c + (p.vertices - c) * 1.0, p.faces, process=False))
    plain = manifold3d.Manifold.batch_boolean([manifold3d.Manifold(manifold3d.Mesh64(
        vert_properties=p.vertices, tri_verts=p.faces.astype(np.uint64))) for p in rounded], manifold3d.OpType.Add)
    assert np.isclose(plain.surface_area(), 0.0164)
    joined = _union(rounded, 1e-4 * 0.08)
    assert joined.is_watertight and np.isclose(joined.area, 0.0156, rtol=1e-9)


def test_pieces_whose_union_has_vertices_closer_than_the_merge_tolerance_are_joined():
    """Two cubes 2 um apart and 1-5 nm askew (convex pieces as a decomposition exports them): their union, grown to
    touch, has vertices nanometres apart; merged, they would pinch its edges into edges of four faces. The union is
    kept as manifold3d gives it: one closed body with both cubes' volume."""
    for skew in (1e-9, 3e-9, 5e-9):
        a = trimesh.creation.box((0.03, 0.03, 0.03))
        b = trimesh.creation.box((0.03, 0.03, 0.03)).apply_translation([0.03 + 2e-6, skew, skew])
        obj = _load(trimesh.util.concatenate([a, b]), "askew")
        assert any("joined 2 touching bodies" in r for r in obj.repairs), obj.repairs
        assert obj.mesh.is_watertight and obj.mesh.body_count == 1 and obj.com_method == "volume"
        assert np.isclose(obj.mesh.volume, 2 * 0.03**3, rtol=1e-3)
        assert np.isclose(obj.mesh.area, 10 * 0.03**2, rtol=1e-3)  # the touching faces are inside


def test_exported_files_glb_scene_obj_materials_ply_colours(tmp_path):
    """A GLB scene of two pieces placed by the scene graph, an OBJ with materials and a PLY with vertex colours load
    as the one part they hold (metres)."""
    a = trimesh.creation.box((0.03, 0.02, 0.02))
    b = trimesh.creation.box((0.02, 0.02, 0.02))
    scene = trimesh.Scene()
    scene.add_geometry(a, node_name="base", transform=trimesh.transformations.translation_matrix([0.1, 0, 0]))
    scene.add_geometry(b, node_name="lid", transform=trimesh.transformations.translation_matrix([0.125, 0, 0]))
    glb = tmp_path / "part.glb"
    glb.write_bytes(scene.export(file_type="glb"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        obj = load_object(glb)
    assert obj.mesh.body_count == 1 and np.allclose(obj.mesh.bounds, [[0.085, -0.01, -0.01], [0.135, 0.01, 0.01]])
    assert np.isclose(obj.mesh.volume, 0.05 * 0.02 * 0.02)
    coloured = a.copy()
    coloured.visual.vertex_colors = np.tile([200, 30, 30, 255], (len(a.vertices), 1))
    ply = tmp_path / "part.ply"
    ply.write_bytes(coloured.export(file_type="ply"))
    objdir = tmp_path / "obj"
    objdir.mkdir()
    textured = a.copy()
    textured.visual = trimesh.visual.TextureVisuals(uv=np.random.default_rng(0).random((len(a.vertices), 2)),
                                                    material=trimesh.visual.material.SimpleMaterial(diffuse=[0, 200, 0, 255]))
    textured.export(objdir / "part.obj")
    assert (objdir / "material.mtl").exists() or any(p.suffix == ".mtl" for p in objdir.iterdir())
    for path in (ply, objdir / "part.obj"):
        got = load_object(path)
        assert np.isclose(got.mesh.volume, a.volume) and got.mesh.is_watertight, path


def test_a_scene_of_rotated_touching_nodes_is_one_part_and_the_cleanup_of_their_join_is_named_as_such(tmp_path):
    """A GLB of three nodes rotated and placed by the scene graph (a box, a cylinder standing on it, a box against
    its side face to face) loads as their union, whose volume is manifold3d's union of the placed pieces; the
    cleanup the union's mesh needs is reported as the join's, not as the file's faults."""
    from trimesh.transformations import rotation_matrix, translation_matrix

    a, b, c = (trimesh.creation.box((0.08, 0.04, 0.02)), trimesh.creation.cylinder(radius=0.012, height=0.04),
               trimesh.creation.box((0.02, 0.02, 0.05)))
    ta = rotation_matrix(np.radians(30), [0, 0, 1])
    placed = {"base": ta, "post": ta @ translation_matrix([0.02, 0.0, 0.03]),
              "arm": ta @ translation_matrix([-0.02, 0.045, 0.0]) @ rotation_matrix(np.pi / 2, [1, 0, 0])}
    scene = trimesh.Scene()
    for (name, t), m in zip(placed.items(), (a, b, c)):
        scene.add_geometry(m, node_name=name, geom_name=name, transform=t)
    glb = tmp_path / "scene.glb"
    glb.write_bytes(scene.export(file_type="glb"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        obj = load_object(glb)
    text = [str(w.message) for w in caught]
    union = None
    for (name, t), m in zip(placed.items(), (a, b, c)):
        m = m.copy().apply_transform(t)
        piece = manifold3d.Manifold(manifold3d.Mesh(vert_properties=np.asarray(m.vertices, np.float32),
                                                    tri_verts=np.asarray(m.faces, np.uint32)))
        union = piece if union is None else union + piece
    assert obj.mesh.is_watertight and obj.mesh.body_count == 1
    assert obj.mesh.volume == pytest.approx(union.volume(), rel=1e-4)
    assert any("joined 3 touching bodies" in t for t in text), text
    cleanup = [t for t in text if "duplicate vertices" in t or "degenerate faces" in t]
    assert all(t.endswith("where the pieces were joined") for t in cleanup), cleanup
    # a scene of one node is that node's mesh, with nothing joined
    single = trimesh.Scene()
    single.add_geometry(a, node_name="base", geom_name="base", transform=ta)
    glb.write_bytes(single.export(file_type="glb"))
    alone = load_object(glb)
    assert alone.repairs == () and alone.mesh.volume == pytest.approx(a.volume, rel=1e-6)  # float32 in the file


def test_edge_groups_match_a_stable_sort_of_the_vertex_pairs():
    """The linear edge sort that repair and segmentation share gives numpy's stable argsort of the edges' vertex pairs,
    on a fan's apex (a long run of one vertex), repeated and degenerate faces, and no faces."""
    from workbench.geometry._segkernel import edge_groups

    rng = np.random.default_rng(3)
    meshes = [trimesh.creation.cone(radius=0.02, height=0.03, sections=300),
              trimesh.Trimesh(rng.random((40, 3)), rng.integers(0, 40, (900, 3)), process=False), blob(seed=2)]
    for m in meshes:
        faces = np.asarray(m.faces, dtype=np.int64)
        u, v = faces, np.roll(faces, -1, axis=1)
        keys = (np.minimum(u, v) * len(m.vertices) + np.maximum(u, v)).ravel()
        order, starts = edge_groups(faces, len(m.vertices))
        assert np.array_equal(order, np.argsort(keys, kind="stable"))
        assert np.array_equal(starts, np.flatnonzero(np.r_[True, np.diff(keys[order]) != 0, True]))
    order, starts = edge_groups(np.zeros((0, 3), dtype=np.int64), 0)
    assert len(order) == 0 and starts.tolist() == [0]


def test_compiled_relabelling_edge_flags_and_face_codes_match_numpy_and_trimesh():
    """The compiled pieces of loading against an independent computation: each face relabelled and rotated to start
    at its lowest label as numpy's argmin rotation gives it (ties to the first), its sort key ordering the rows
    lexicographically; the watertight and winding flags as trimesh finds them; and two faces share a code exactly
    when they use the same three vertices. On a closed blob, the blob with flipped faces, an open one (a cap cut off)
    and random faces with repeated corners."""
    from workbench.geometry._repairkernel import rotated_faces, triple_codes
    from workbench.geometry.repair import edge_flags

    rng = np.random.default_rng(5)
    good = blob(seed=2)
    flipped = good.faces.copy()
    flipped[::7] = flipped[::7, ::-1]
    meshes = [good, trimesh.Trimesh(good.vertices, flipped, process=False),
              trimesh.Trimesh(good.vertices, good.faces[good.triangles_center[:, 2] < 0.01], process=False),
              trimesh.Trimesh(rng.random((30, 3)), rng.integers(0, 30, (500, 3)), process=False)]
    for m in meshes:
        faces = np.asarray(m.faces, dtype=np.int64)
        n = len(m.vertices)
        rank = rng.permutation(n).astype(np.int64)
        got, key = rotated_faces(rank, faces, n)
        labelled = rank[faces]
        first = np.argmin(labelled, axis=1)
        want = labelled[np.arange(len(faces))[:, None], (first[:, None] + np.arange(3)) % 3]
        assert np.array_equal(got, want)
        assert np.array_equal(np.argsort(key, kind="stable"), np.lexsort((got[:, 2], got[:, 1], got[:, 0])))
        plain = trimesh.Trimesh(m.vertices, faces, process=False)
        assert edge_flags(faces, n) == (plain.is_watertight, plain.is_winding_consistent)
        # the faces grouped by code are those grouped by their sorted corners
        codes = np.unique(triple_codes(faces, n), return_inverse=True)[1].ravel()
        rows = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True)[1].ravel()
        assert len(np.unique(np.c_[codes, rows], axis=0)) == codes.max() + 1 == rows.max() + 1
    assert rows.max() + 1 < len(meshes[3].faces)  # the random faces repeat some triples
    assert edge_flags(meshes[0].faces, len(meshes[0].vertices)) == (True, True)
    assert edge_flags(meshes[1].faces, len(meshes[1].vertices)) == (True, False)
    assert edge_flags(meshes[2].faces, len(meshes[2].vertices))[0] is False


def test_compiled_face_areas_and_volume_sign_are_trimeshs():
    """The repair's compiled face areas are trimesh's to the bit, and its volume sum has trimesh's volume's sign, with
    an error bound far below it, on a closed scan and the same scan inside out."""
    from workbench.geometry._repairkernel import face_areas, volume_terms

    m = blob(seed=2, noise=1e-4)
    for faces in (m.faces, m.faces[:, ::-1]):
        mesh = trimesh.Trimesh(m.vertices, faces, process=False)
        v, f = np.ascontiguousarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)
        assert np.array_equal(face_areas(v, f), mesh.area_faces)
        s, bound = volume_terms(v, f)
        assert np.sign(s) == np.sign(mesh.volume) and abs(s) > 1e6 * bound and np.isclose(s / 6, mesh.volume, rtol=1e-9)


def test_compiled_face_normals_are_trimeshs_and_a_loaded_part_carries_them():
    """The compiled face normals are trimesh's to the bit, zero where trimesh's are (a face too thin for its
    tolerance), and a loaded part's mesh holds them: its normals equal those trimesh computes afresh."""
    from workbench.geometry._repairkernel import unit_normals

    m = blob(seed=5, noise=1e-4)
    v = np.vstack([m.vertices, [[0.0, 0.0, 0.0], [1e-7, 0.0, 0.0], [0.0, 1e-7, 0.0], [0.0, 1e-6, 0.0]]])
    n = len(m.vertices)
    f = np.vstack([m.faces, [[n, n + 1, n + 2], [n, n + 1, n + 3]]])  # cross products 1e-14 and 1e-13
    mesh = trimesh.Trimesh(v, f, process=False)
    got = unit_normals(np.ascontiguousarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
    assert np.array_equal(got, mesh.face_normals)
    assert not got[-2:].any() and np.linalg.norm(got[:-2], axis=1).min() > 1 - 1e-12
    loaded = _load(blob(seed=5, noise=1e-4), "blob").mesh
    assert np.array_equal(loaded.face_normals, trimesh.Trimesh(loaded.vertices, loaded.faces, process=False).face_normals)



def test_a_loaded_part_carries_its_own_edge_tables_and_segments_as_without_them(tmp_path):
    """Loading keeps the edge tables it builds for the part's checks (`EDGES_KEY`), and they are those of the part as
    loaded: on a clean part, a part from a file, a part whose faces a repair changed after they were built (holes
    filled, winding fixed, pieces joined) and one turned outward, every kept table equals the tables built afresh from
    the loaded faces, and each part's segmentation equals that of a copy without them."""
    from workbench.geometry._segkernel import edge_groups, neighbour_table
    from workbench.geometry.facets import EDGES_KEY, segment

    good = blob(seed=1)
    flipped = good.faces.copy()
    flipped[::5] = flipped[::5, ::-1]
    a, b = trimesh.creation.box((0.03, 0.02, 0.02)), trimesh.creation.box((0.02, 0.02, 0.02))
    b.apply_translation([0.015, 0.0, 0.019])
    path = tmp_path / "part.stl"
    blob(seed=3, noise=1e-4).export(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        parts = {"clean": _load(good, "clean"), "file": load_object(path),
                 "holed": _load(holed(blob(seed=6, noise=2e-4, rows=26, cols=50), seed=6), "holed"),
                 "flipped": _load(trimesh.Trimesh(good.vertices, flipped, process=False), "flipped"),
                 "inside out": _load(trimesh.Trimesh(good.vertices, good.faces[:, ::-1], process=False), "inside out"),
                 "joined": _load(trimesh.util.concatenate([a, b]), "joined")}
    assert parts["holed"].repairs and parts["joined"].repairs and parts["flipped"].repairs
    kept = 0
    for name, obj in parts.items():
        mesh = obj.mesh
        tables = mesh._cache[EDGES_KEY]
        if tables is not None:
            kept += 1
            order, starts = edge_groups(np.asarray(mesh.faces), len(mesh.vertices))
            fresh = (order, starts, neighbour_table(order, starts, len(mesh.faces)))
            assert all(np.array_equal(x, y) for x, y in zip(tables, fresh)), name
        plain = trimesh.Trimesh(mesh.vertices.copy(), mesh.faces.copy(), process=False)
        assert plain._cache[EDGES_KEY] is None
        mine, theirs = segment(mesh), segment(plain)
        for field in ("tri_ptr", "tri_index", "normals", "centers", "areas", "seeds", "edge_ptr", "edges"):
            assert np.array_equal(getattr(mine, field), getattr(theirs, field)), (name, field)
    assert parts["clean"].mesh._cache[EDGES_KEY] is not None and parts["file"].mesh._cache[EDGES_KEY] is not None
    assert kept >= 2

def test_vertex_merging_is_skipped_only_where_trimesh_would_merge_none():
    """Distinct positions at trimesh's merge precision: a clean scan's vertices are, and a vertex repeated 1e-12 m
    away is not, as trimesh's own merge says."""
    from workbench.geometry.repair import _distinct_positions

    m = blob(seed=2)
    v = np.vstack([m.vertices, m.vertices[:1] + 1e-12])
    f = np.vstack([m.faces, [[len(m.vertices), 1, 2]]])
    for vertices, faces, distinct in ((m.vertices, m.faces, True), (v, f, False)):
        merged = trimesh.Trimesh(vertices, faces, process=False)
        merged.merge_vertices()
        assert _distinct_positions(vertices) is distinct and (len(merged.vertices) == len(vertices)) is distinct


def test_an_open_mesh_is_named_open_with_its_widest_hole():
    """A box without its 40 x 30 mm lid keeps its hole (far beyond the small holes closed at load); the warning says
    the mesh is open, how many edges border the hole and how wide it is."""
    from workbench.geometry.objects import MeshWarning

    box = trimesh.creation.box((0.04, 0.03, 0.02))
    lid = box.face_normals[:, 2] > 0.5
    box.update_faces(~lid)
    with pytest.warns(MeshWarning, match=r"not watertight \(open: 4 edges border its holes, the widest 40 mm across"):
        obj = from_arrays(box.vertices, box.faces, scale=1.0, name="open", source="<memory>")
    assert obj.com_method == "area" and not obj.mesh.is_watertight
