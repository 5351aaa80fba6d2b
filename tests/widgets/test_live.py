"""Widgets answer a slider at once: a view-only change reaches the viewer as visibility and transforms, never as
geometry (counted from the messages a browser would receive), a value already computed is answered from the cache,
and a notebook kernel's meshcat server ends with the kernel."""

from __future__ import annotations

import asyncio
import os
import threading
import time
from urllib.parse import urlparse

import numpy as np
import pytest

from workbench.grasping.grasps import plan_grasps
from workbench.planners.wan_harada.tabletop import TabletopParams
from workbench.viewer.scenes import geometry_sent, new_scene
from workbench.widgets.grasping import GraspExplorer
from workbench.widgets.wan_harada import PlacementExplorer


class Browser:
    """A websocket client of a meshcat server, as the viewer page is: it records the type of every message."""

    def __init__(self, vis):
        import tornado.websocket
        import umsgpack

        port = urlparse(vis.url()).port
        self.types: list[str] = []
        self.messages: list[dict] = []
        self.loop = asyncio.new_event_loop()
        ready = threading.Event()

        async def listen() -> None:
            conn = await tornado.websocket.websocket_connect(f"ws://127.0.0.1:{port}/")
            ready.set()
            while (msg := await conn.read_message()) is not None:
                self.messages.append(umsgpack.unpackb(msg))
                self.types.append(self.messages[-1]["type"])

        self.thread = threading.Thread(target=lambda: self.loop.run_until_complete(listen()), daemon=True)
        self.thread.start()
        assert ready.wait(10), "no websocket connection to the meshcat server"

    def settle(self, quiet: float = 0.3, limit: float = 20.0) -> list[str]:
        """The messages received until none arrived for `quiet` seconds."""
        deadline, seen, last = time.monotonic() + limit, -1, time.monotonic()
        while time.monotonic() < deadline:
            if len(self.types) != seen:
                seen, last = len(self.types), time.monotonic()
            elif time.monotonic() - last > quiet:
                break
            time.sleep(0.05)
        return list(self.types)


@pytest.fixture
def explorer(box, hand):
    ex = GraspExplorer(box, hand, vis=new_scene())
    yield ex
    ex.vis.window.close()


def test_view_only_changes_send_no_geometry(explorer):
    browser = Browser(explorer.vis)
    explorer.run()
    before = len(browser.settle())
    assert before > 0 and "set_object" in browser.types[:before]
    explorer.facet.value = min(2, explorer.facet.max)
    explorer.hands.value = 10
    explorer.selected.value = explorer.selected.max // 2
    explorer.layers["all samples"].value = True
    explorer.layers["facets"].value = False
    got = browser.settle()[before:]
    assert got, "the view-only changes reached the viewer"
    assert set(got) <= {"set_property", "set_transform"}, got
    # a threshold is a recomputation: its geometry is sent, in a few objects however many facets and hands
    explorer.tau.value = explorer.tau.value + 5
    replan = browser.settle()[before + len(got):]
    assert 0 < replan.count("set_object") <= 24 < len(explorer.plan.facets) + 2 * explorer.max_hands


def _array(ext) -> np.ndarray:
    return np.frombuffer(ext.data, dtype=np.float32)


def test_the_highlighted_facet_is_the_only_geometry_in_reach_and_in_place(explorer):
    """What the viewer draws within its far plane (100 m) after choosing a facet is that facet's triangles, lifted
    off the part along its normal: the others, sent in the same object, are far out of reach."""
    browser = Browser(explorer.vis)
    explorer.run()
    plan, mesh = explorer.plan, explorer.obj.mesh
    facet = next(m for m in browser.settle() and browser.messages
                 if m["type"] == "set_object" and m["path"].endswith("grasps/facet"))
    corners = _array(facet["object"]["geometries"][0]["data"]["attributes"]["position"]["array"]).reshape(-1, 3)
    for f in (1, len(plan.facets) - 1):
        explorer.facet.value = f
        browser.settle()
        move = next(m for m in reversed(browser.messages)
                    if m["type"] == "set_transform" and m["path"].endswith("grasps/facet"))
        matrix = np.asarray(move["matrix"], dtype=np.float64).reshape(4, 4).T  # three.js is column-major
        placed = corners.astype(np.float64) + matrix[:3, 3]
        near = np.linalg.norm(placed.reshape(-1, 3, 3), axis=2).max(axis=1) < 100
        lift = 0.004 * float(mesh.scale) * plan.facets.normals[f]
        want = mesh.vertices[mesh.faces[plan.facets.triangles_of(f)]] + lift
        got = placed.reshape(-1, 3, 3)[near]
        assert len(got) == len(want) > 0
        np.testing.assert_allclose(np.sort(got.reshape(-1, 9), axis=0), np.sort(want.reshape(-1, 9), axis=0), atol=1e-4)


def test_a_threshold_already_computed_comes_from_the_cache(explorer):
    first = explorer.run()
    tau = explorer.tau.value
    explorer.tau.value = tau + 6
    other = explorer.plan
    assert other is not first and explorer.cache.misses == 2
    explorer.tau.value = tau
    assert explorer.plan is first and explorer.cache.hits == 1
    assert other.params.tau == pytest.approx(np.radians(tau + 6))
    fresh = plan_grasps(explorer.obj, explorer.gripper, explorer.params())  # the cached plan is the library's
    assert fresh.counts == first.counts and np.array_equal(fresh.grasps.poses, first.grasps.poses)


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False


def _meshcat_servers() -> set[int]:
    out = set()
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/cmdline", "rb") as f:
                    if b"meshcat.servers.zmqserver" in f.read():
                        out.add(int(d))
            except OSError:
                pass
    return out


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="counts processes in /proc")
def test_shutting_a_kernel_down_ends_its_meshcat_server():
    from jupyter_client.manager import start_new_kernel

    km, kc = start_new_kernel(kernel_name="python3")
    out: list = []
    try:
        before = _meshcat_servers()
        reply = kc.execute_interactive("from workbench.viewer.scenes import new_scene\nvis = new_scene()\n"
                                       "print(vis.window.server_proc.pid)", timeout=60,
                                       output_hook=lambda msg: out.append(msg))
        assert reply["content"]["status"] == "ok"
        pid = int(next(m["content"]["text"] for m in out if m["msg_type"] == "stream"))
        assert pid in _meshcat_servers() - before and _alive(pid)
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)  # a kill, as a stuck kernel gets: no atexit handler runs
    deadline = time.monotonic() + 10
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not _alive(pid), "the meshcat server outlived its kernel"



def test_placement_view_settings_send_no_geometry_and_the_grid_reruns_only_the_roadmap(box, hand):
    plan = plan_grasps(box, hand)
    ex = PlacementExplorer(box, hand, plan.grasps.poses, plan.grasps.jawwidth, vis=new_scene(),
                           tabletop=TabletopParams(nx=2, ny=2, angles=2))
    try:
        browser = Browser(ex.vis)
        ex.run()
        before = len(browser.settle())
        sent = geometry_sent(ex.vis)
        ex.which.value = ex.which.options[-1][1]
        ex.hands.value = 3
        ex.roadmap.value = True
        got = browser.settle()[before:]
        assert got and set(got) <= {"set_property", "set_transform"}, got
        assert geometry_sent(ex.vis) == sent  # the window's own count agrees with what the viewer received
        placements = ex.placements
        ex.nx.value = 3  # the grid: the roadmap is recomputed, the placements are not
        assert ex.placements is placements and ex.stage_cache.misses == 1 and ex.tabletop_cache.misses == 2
        assert len(ex.tt.poses) == len(placements) * 3 * 2 * 2
    finally:
        ex.vis.window.close()
