"""Tests of workbench.objects.load_object: bundled objects, scale and units, bad input, repairs (CONVENTIONS.md, Units)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

from workbench.errors import MeshError, WorkbenchError
from workbench.geometry.objects import UNITS, MeshWarning, from_arrays, load_object
from workbench.resources import bundled_objects, paper_objects

# triangle budgets of the bundled objects (assets/objects/README.md)
TRIANGLES = {"tube": (1500, 2000), "wheel": (900, 1500), "planebody": (2000, 5000),
             "bracket": (10000, 14000), "tail": (15000, 20000), "drill": (33000, 37000)}
FRANKA_JAW = 0.08
BOX = (0.04, 0.06, 0.10)  # metres
BOX_CENTRE = np.array([0.01, -0.02, 0.05])


def box(extents=BOX, centre=BOX_CENTRE) -> trimesh.Trimesh:
    """An axis-aligned box with outward faces."""
    mesh = trimesh.creation.box(extents=extents)
    mesh.apply_translation(centre)
    return mesh


def write_obj(path: Path, vertices, faces) -> Path:
    """Write an OBJ by hand, so that NaNs, degenerate and flipped faces reach the loader untouched."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in np.asarray(vertices, dtype=float).tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in np.asarray(faces, dtype=int).tolist()]
    path.write_text("\n".join(lines) + "\n")
    return path


def load_quietly(path: Path, **kwargs):
    """load_object, failing the test on any MeshWarning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshWarning)
        return load_object(path, **kwargs)


# ---------------------------------------------------------------- bundled objects


def test_all_bundled_objects_are_present():
    assert set(bundled_objects()) == set(TRIANGLES)


@pytest.mark.parametrize("name", sorted(TRIANGLES))
def test_bundled_object_is_a_clean_solid(name):
    path = bundled_objects()[name]
    obj = load_quietly(path)
    mesh = obj.mesh
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume > 0 and obj.com_method == "volume"
    lo, hi = mesh.bounds
    assert np.all(obj.com > lo) and np.all(obj.com < hi)
    assert TRIANGLES[name][0] <= obj.n_triangles <= TRIANGLES[name][1]
    assert 0.02 < mesh.extents.max() < 0.3  # metres, gripper-sized
    assert path.stat().st_size < 3_000_000


@pytest.mark.parametrize("name", sorted(TRIANGLES))
def test_bundled_object_has_opposing_faces_within_the_franka_jaw(name):
    """Some surface points see an opposite, anti-parallel surface closer than the jaw opening."""
    mesh = load_quietly(bundled_objects()[name]).mesh
    points, face = trimesh.sample.sample_surface(mesh, 200, seed=0)
    normals = mesh.face_normals[face]
    hits, ray, tri = mesh.ray.intersects_location(points - 1e-6 * normals, -normals, multiple_hits=False)
    width = np.linalg.norm(hits - points[ray], axis=1)
    antiparallel = -(mesh.face_normals[tri] * normals[ray]).sum(axis=1) > np.cos(np.radians(10))
    assert np.count_nonzero((width > 0.002) & (width < FRANKA_JAW) & antiparallel) >= 10


# ---------------------------------------------------------------- scale and units


def test_units_mm_equals_scale_0001(tmp_path):
    path = tmp_path / "part_mm.stl"
    box(np.array(BOX) * 1000, BOX_CENTRE * 1000).export(path)
    by_unit = load_quietly(path, units="mm")
    by_scale = load_quietly(path, scale=0.001)
    np.testing.assert_array_equal(by_unit.mesh.vertices, by_scale.mesh.vertices)
    np.testing.assert_array_equal(by_unit.mesh.faces, by_scale.mesh.faces)
    assert by_unit.digest == by_scale.digest
    assert by_unit.scale == by_scale.scale == 0.001
    np.testing.assert_allclose(by_unit.mesh.extents, BOX, rtol=1e-6)
    np.testing.assert_allclose(by_unit.com, BOX_CENTRE, atol=1e-7)


@pytest.mark.parametrize("unit", sorted(UNITS))
def test_each_unit_scales_to_metres(tmp_path, unit):
    factor = UNITS[unit]
    path = tmp_path / f"part_{unit}.stl"
    box(np.array(BOX) / factor, BOX_CENTRE / factor).export(path)
    obj = load_quietly(path, units=unit)
    np.testing.assert_allclose(obj.mesh.extents, BOX, rtol=1e-6)
    np.testing.assert_allclose(obj.mesh.volume, np.prod(BOX), rtol=1e-5)


def _paper_readme_extents() -> dict[str, tuple[float, float, float]]:
    """Extents in mm per file, from the table in the paper objects' README.md."""
    objects = paper_objects()
    if not objects:
        return {}
    readme = next(iter(objects.values())).parent / "README.md"
    rows = re.findall(r"^\| (\S+\.stl) \|.*\| ([\d.]+) x ([\d.]+) x ([\d.]+) \|\s*$", readme.read_text(), re.M)
    return {name: (float(x), float(y), float(z)) for name, x, y, z in rows}


@pytest.mark.parametrize("row", ["TU", "PB", "PW", "PS", "PT"])
def test_paper_object_in_mm_gets_readme_extents(row):
    objects = paper_objects()
    if row not in objects:
        pytest.skip("the paper's objects (../shared/objects/wan-harada) are not present")
    path = objects[row]
    expected_mm = _paper_readme_extents()[path.name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MeshWarning)  # PB is not watertight
        obj = load_object(path, units="mm")
    np.testing.assert_allclose(obj.mesh.extents, np.array(expected_mm) / 1000, atol=0.06e-3)


# ---------------------------------------------------------------- bad input


def test_mesh_error_is_a_workbench_error():
    assert issubclass(MeshError, WorkbenchError)


def _text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _export(mesh: trimesh.Trimesh, path: Path) -> Path:
    mesh.export(path)
    return path


TETRA = [[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0, 0, 0.05]]
TETRA_FACES = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]

BAD_FILES = {
    "missing file": (lambda d: d / "nope.stl", {}, r"does not exist"),
    "empty file": (lambda d: _text(d / "empty.stl", ""), {}, r"is empty"),
    "folder": (lambda d: d, {}, r"is a folder"),
    "text as stl": (lambda d: _text(d / "notes.stl", "shopping list\neggs\nmilk\n"), {}, r"no triangle mesh"),
    "text as txt": (lambda d: _text(d / "notes.txt", "shopping list\n"), {}, r"not a readable mesh"),
    "text as ply": (lambda d: _text(d / "notes.ply", "shopping list\n"), {}, r"not a readable mesh"),
    "nan vertex": (lambda d: write_obj(d / "nan.obj", [[0, 0, 0], [np.nan, 0, 0]] + TETRA[2:], TETRA_FACES), {},
                   r"1 vertex with NaN or infinite"),
    "inf vertex": (lambda d: write_obj(d / "inf.obj", [[0, 0, 0], [np.inf, 0, 0]] + TETRA[2:], TETRA_FACES), {},
                   r"1 vertex with NaN or infinite"),
    "no faces": (lambda d: write_obj(d / "points.obj", TETRA, np.zeros((0, 3))), {}, r"no triangle faces"),
    "metres loaded as mm": (lambda d: _export(box(), d / "metres.stl"), {"units": "mm"},
                            r"0\.0001 m across.*implausible"),
    "mm loaded without scale": (lambda d: _export(box(np.array(BOX) * 1000), d / "mm.stl"), {},
                                r"100 m across.*implausible.*--units mm \(100 mm across\)"),
    "unknown unit": (lambda d: _export(box(), d / "a.stl"), {"units": "furlong"}, r"unknown unit 'furlong'"),
    "zero scale": (lambda d: _export(box(), d / "a.stl"), {"scale": 0.0}, r"scale must be a positive"),
    "negative scale": (lambda d: _export(box(), d / "a.stl"), {"scale": -0.001}, r"scale must be a positive"),
    "nan scale": (lambda d: _export(box(), d / "a.stl"), {"scale": float("nan")}, r"scale must be a positive"),
    "scale and units": (lambda d: _export(box(), d / "a.stl"), {"scale": 1.0, "units": "m"},
                        r"either scale or units"),
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_bad_input_raises_mesh_error_naming_the_problem(tmp_path, case):
    make, kwargs, message = BAD_FILES[case]
    path = make(tmp_path)
    with pytest.raises(MeshError, match=message) as info:
        load_object(path, **kwargs)
    assert isinstance(info.value, WorkbenchError)
    if "scale" not in kwargs and "units" not in kwargs:
        assert str(path) in str(info.value)  # names the input


def test_face_indexing_a_missing_vertex_is_refused():
    with pytest.raises(MeshError, match="index missing vertices"):
        from_arrays(np.array(TETRA, float), np.array(TETRA_FACES[:3] + [[1, 2, 7]]), 1.0, "t", "<memory>")


def test_only_degenerate_faces_is_refused():
    with pytest.raises(MeshError, match="only degenerate"):
        from_arrays(np.array([[0, 0, 0], [0.05, 0, 0], [0.1, 0, 0]], float), np.array([[0, 1, 2]]), 1.0, "t", "<memory>")


# ---------------------------------------------------------------- repairs and weaker assumptions


def test_degenerate_faces_are_removed_with_a_warning(tmp_path):
    good = box()
    midpoint = good.vertices[good.edges_unique[0]].mean(axis=0)
    a, b = good.edges_unique[0]
    vertices = np.vstack([good.vertices, midpoint])
    faces = np.vstack([good.faces, [[a, a, b], [a, len(good.vertices), b]]])  # repeated index; collinear
    path = write_obj(tmp_path / "degenerate.obj", vertices, faces)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        obj = load_object(path)
    messages = [str(w.message) for w in caught if issubclass(w.category, MeshWarning)]
    assert len(messages) == 1 and "removed 2 degenerate faces" in messages[0]
    assert obj.n_triangles == 12 and len(obj.mesh.vertices) == 8
    assert obj.mesh.is_watertight and obj.com_method == "volume"
    assert obj.mesh.volume == pytest.approx(np.prod(BOX), rel=1e-9)
    np.testing.assert_allclose(obj.com, BOX_CENTRE, atol=1e-12)


def test_open_mesh_is_accepted_with_area_weighted_centre_of_mass(tmp_path):
    closed = box()
    top = closed.face_normals[:, 2] > 0.5
    faces = closed.faces[~top]  # no lid
    path = write_obj(tmp_path / "open.obj", closed.vertices, faces)
    with pytest.warns(MeshWarning, match="not watertight"):
        obj = load_object(path)
    assert obj.com_method == "area" and not obj.mesh.is_watertight
    tri = closed.vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    expected = (tri.mean(axis=1) * area[:, None]).sum(axis=0) / area.sum()
    np.testing.assert_allclose(obj.com, expected, atol=1e-12)
    assert expected[2] < BOX_CENTRE[2] - 0.005  # the missing lid moves it down: the check can tell


def test_inside_out_mesh_is_turned_outward(tmp_path):
    closed = box()
    path = write_obj(tmp_path / "inverted.obj", closed.vertices, closed.faces[:, ::-1])
    with pytest.warns(MeshWarning, match="normals outward"):
        obj = load_object(path)
    assert obj.repairs == ("turned the normals outward (the mesh was inside out)",)
    assert obj.mesh.volume == pytest.approx(np.prod(BOX), rel=1e-9) and obj.com_method == "volume"
    np.testing.assert_allclose(obj.com, BOX_CENTRE, atol=1e-12)


def test_inconsistently_oriented_faces_are_reoriented(tmp_path):
    closed = box()
    faces = closed.faces.copy()
    faces[0] = faces[0][::-1]  # one face flipped: closed, but the signed volume is wrong
    path = write_obj(tmp_path / "flipped.obj", closed.vertices, faces)
    with pytest.warns(MeshWarning, match="not consistently oriented"):
        obj = load_object(path)
    assert obj.mesh.is_winding_consistent and obj.com_method == "volume"
    assert obj.mesh.volume == pytest.approx(np.prod(BOX), rel=1e-9)
    np.testing.assert_allclose(obj.com, BOX_CENTRE, atol=1e-12)


@pytest.mark.parametrize("ext", ["stl", "obj", "ply"])
def test_stl_obj_and_ply_load(tmp_path, ext):
    path = tmp_path / f"box.{ext}"
    box().export(path)
    obj = load_quietly(path)
    assert obj.name == "box" and obj.source == str(path)
    assert obj.n_triangles == 12 and obj.mesh.is_watertight
    np.testing.assert_allclose(obj.mesh.extents, BOX, rtol=1e-6)
    np.testing.assert_allclose(obj.com, BOX_CENTRE, atol=1e-7)


def test_unit_hints_name_every_unit_giving_a_gripper_sized_part(tmp_path):
    """A 5-unit can is 50 mm in centimetres and 127 mm in inches: the error names both, with the sizes; a 2 m part
    read in metres is refused naming the units that would make it hand-sized, and accepted with a warning when its size
    is accepted (--accept-size)."""
    can = tmp_path / "can.stl"
    trimesh.creation.cylinder(radius=2.0, height=5.0, sections=24).export(can)
    with pytest.raises(WorkbenchError) as err:
        load_object(can)
    msg = str(err.value)
    assert "--units cm (50 mm across)" in msg and "--units in (127 mm across)" in msg and "--units mm" not in msg
    bar = tmp_path / "bar.stl"
    trimesh.creation.box((2.0, 1.0, 1.0)).export(bar)
    with pytest.raises(WorkbenchError, match=r"2 m across read in metres.*--units in \(50.8 mm across\).*--accept-size"):
        load_object(bar)
    with pytest.warns(MeshWarning, match=r"2 m across read in metres.*--units in \(50.8 mm across\)"):
        obj = load_object(bar, accept_size=True)
    assert obj.mesh.extents.max() == pytest.approx(2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error", MeshWarning)
        assert load_object(bar, units="in").mesh.extents.max() == pytest.approx(0.0508)


# ---------------------------------------------------------------- size hints quote the declared ranges


def test_size_hints_quote_the_declared_ranges_and_a_scale_that_works(tmp_path, capsys):
    """The size refusals quote PART_SIZE, HAND_SIZED and --scale's range as workbench.params declares them; a
    suggested --scale within that range makes the part load, and where none within it would, the hint says so
    (the largest allowed scale is still refused)."""
    from workbench.cli.main import build_parser
    from workbench.params import HAND_SIZED, PART_SIZE, SCALE

    speck = _export(box(np.array(BOX) * 0.002), tmp_path / "speck.stl")  # 0.16 mm across in metres
    with pytest.raises(MeshError) as info:
        load_object(speck)
    text = str(info.value)
    assert f"allowed: {PART_SIZE.describe()}" in text and SCALE.describe() in text
    scale = float(re.search(r"--scale ([0-9.e+]+) or more", text).group(1))
    assert SCALE.problem(scale) is None
    loaded = load_quietly(speck, scale=scale * 1.01)  # the hint's scale, rounded to three digits
    assert loaded.mesh.extents.max() >= PART_SIZE.lo
    dust = _export(box(np.array(BOX) * 2e-6), tmp_path / "dust.stl")  # 0.16 um: no scale in range reaches 5 mm
    with pytest.raises(MeshError, match=re.escape(f"no unit or --scale ({SCALE.describe()}) makes it at least 5 mm")):
        load_object(dust)
    with pytest.raises(MeshError, match="implausible"):
        load_object(dust, scale=SCALE.hi)
    big = _export(box(np.array(BOX) * 12), tmp_path / "big.stl")  # 0.96 m across, read in metres
    with pytest.raises(MeshError, match=re.escape(f"larger than a hand-sized part (at most {HAND_SIZED.hi:g} m)")):
        load_object(big)
    with pytest.raises(MeshError, match=re.escape(SCALE.describe())):
        load_object(big, scale=0.0)
    with pytest.raises(SystemExit):
        build_parser(["grasps"]).parse_args(["grasps", "--help"])
    helptext = " ".join(capsys.readouterr().out.split())
    assert f"over {HAND_SIZED.hi:g} m across is refused" in helptext and f"(up to {PART_SIZE.hi:g} m)" in helptext
