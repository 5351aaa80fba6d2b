"""Safe mesh repair at load (issue 10): what is repaired is reported; what cannot be is refused in one line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
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
    obj = _load(trimesh.Trimesh(good.vertices, faces, process=False), "flipped")
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
    # overlapping pieces of one part (a bear made of convex pieces) stay together
    pieces = trimesh.util.concatenate([big, trimesh.creation.icosphere(radius=0.015).apply_translation([0.03, 0, 0])])
    obj = _load(pieces, "pieces")
    assert len(obj.mesh.faces) == len(pieces.faces)


def test_clean_mesh_reports_no_repair(tmp_path):
    path = tmp_path / "clean.stl"
    trimesh.creation.box((0.05, 0.04, 0.03)).export(path)
    assert load_object(path).repairs == ()
