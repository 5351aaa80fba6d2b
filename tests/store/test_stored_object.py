"""A stored object read back: the very mesh that was stored (not repaired again) while its bytes give its stored
digest; a row changed outside the workbench is caught by that digest and repaired again."""

from __future__ import annotations

import numpy as np
import trimesh

from workbench.geometry.objects import from_trimesh
from workbench.planners.wan_harada.stages import get_object
from workbench.store import Store
from workbench.store.objects import put_object


def test_stored_mesh_round_trips_and_a_changed_row_is_repaired_again(tmp_path):
    obj = from_trimesh(trimesh.creation.box(extents=[0.03, 0.04, 0.05]).subdivide(), "box")
    db = tmp_path / "o.duckdb"
    with Store(db) as store:
        put_object(store, obj)
        _, back = get_object(store, "box")
        assert back.digest == obj.digest and back.repairs == ()
        assert back.mesh.is_watertight and back.mesh.is_winding_consistent  # known from the stored centre of mass
        fresh = trimesh.Trimesh(back.mesh.vertices, back.mesh.faces, process=False)
        assert fresh.is_watertight and fresh.is_winding_consistent
        assert np.array_equal(back.mesh.vertices, obj.mesh.vertices) and np.array_equal(back.mesh.faces, obj.mesh.faces)
        assert np.allclose(back.com, obj.com) and back.com_method == obj.com_method == "volume"
        # a third of the faces turned inside out behind the workbench's back: the digest no longer matches
        faces = obj.mesh.faces.copy()
        faces[::3] = faces[::3, ::-1]
        store.run("UPDATE object SET faces = ? WHERE name = ?", [faces.tolist(), "box"])
        _, again = get_object(store, "box")
    # repaired again into the canonical mesh that was stored, not used with its faces inside out
    assert not np.array_equal(faces, obj.mesh.faces)
    assert np.array_equal(again.mesh.faces, obj.mesh.faces) and again.digest == obj.digest
    assert again.mesh.is_winding_consistent and np.isclose(again.mesh.volume, obj.mesh.volume)
