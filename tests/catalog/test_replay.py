"""The driver at scale: recorded units replayed into the real driver and a real store as 256 workers would produce
them (`workbench bench catalog --simulate-workers`); every copy is stored whole, each
part's grips with their IK rows and graph, while the units arrive at that rate."""

from __future__ import annotations

import json

import duckdb

from workbench.catalog.driver import CatalogParams, build_catalog, collect_parts
from workbench.catalog.replay import REPLICA, ReplayClient, copies_for, record_units
from workbench.catalog.robots import parse_robots
from workbench.planners.tournassoud.shapes import l_part
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.robots.ik import IKOptions

PARAMS = CatalogParams(tabletop=TabletopParams(x_min=0.4, x_max=0.6, nx=2, y_min=0.0, y_max=0.0, ny=1, angles=2,
                                               max_grasps=10),
                       ik=IKOptions(library=2048, seeds=2, self_collide=True), ik_chunk=32)


def test_replay_at_256_workers_stores_every_copy_and_the_driver_keeps_up(tmp_path):
    mesh = tmp_path / "L.stl"
    l_part().mesh.export(mesh)
    robots = parse_robots("panda")
    rec = record_units(collect_parts([mesh]), robots, PARAMS, tmp_path / "recorded", progress=False)
    (folder, table, seconds), = rec.parts.values()
    assert seconds > 0 and len(rec.ik) >= 2 and len(rec.graphs) == 1
    copies = copies_for(rec, 256, units_per_worker=2)
    client = ReplayClient(rec, 256, copies, tmp_path / "staging")
    db = tmp_path / "replay.duckdb"
    res = build_catalog(client.parts(), robots, db, client, PARAMS, progress=False)
    client.stop()
    assert res.failures == [] and client.units == copies * rec.units_per_copy()
    con = duckdb.connect(str(db), read_only=True)
    names = {r[0] for r in con.execute("SELECT name FROM object").fetchall()}
    grips = con.execute("SELECT count(*) FROM tabletopgrips").fetchone()[0]
    ik = con.execute("SELECT count(*), count(DISTINCT idtabletopgrips) FROM ik").fetchone()
    graphs = con.execute("SELECT count(*) FROM catalog_unit WHERE kind = 'graph' AND status = 'done'").fetchone()[0]
    con.close()
    per_copy = json.loads(table.column("record")[0].as_py())["grips"]
    assert names == {f"L{REPLICA}{k}" for k in range(copies)}
    assert grips == copies * per_copy and ik == (grips, grips) and graphs == copies
    # how busy the driver was is a measurement (`workbench bench catalog --simulate-workers`), not asserted here
