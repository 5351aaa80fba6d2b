"""The notebooks as a person sees them: JupyterLab in headless Chromium, Run All, look, move a widget.

Starts JupyterLab on 127.0.0.1 (a free port, a random token) over a copy of `notebooks/` (the repository's files are
never saved into), opens every notebook, runs all its cells and waits for the kernel. Then, per notebook:
no cell shows an error (error outputs, tracebacks, "Error displaying widget") and the browser console logs no
error; every meshcat view draws a canvas that is not blank, and the part covers at least a stated share of its first
view (the camera frames the work); notebook 04's caption and footer name the same step; moving one widget changes
its view or its numbers, and where that move is view-only the views receive no geometry (counted from the meshcat
messages reaching the page). The time from the move to the update, the part's share and the messages are recorded
in `build/screenshots/latencies.json` and printed, not asserted (the `workbench bench widgets` tables hold the
targets). Nothing waits on a fixed wall-clock limit: Run All is followed while cells keep finishing, with a ceiling
only against a hang. Finally a `plan.html` written by `workbench demo` must animate (two screenshots a moment apart
differ) with its caption and footer naming the same step. Screenshots go to `build/screenshots/` for a person.

A view's animation is paused once it plays (`hold_animations`): headless Chromium draws WebGL in software, and a
looping plan animation would keep a core busy redrawing, slowing the kernel, every screenshot and every click several
times over; it also means a view that changes after a move changed because of the move, not the animation's clock.
Whether an animation plays is `plan.html`'s check.

Needs Chromium (`apt-get install chromium`; playwright's own browser download is not used) and the test extras
(playwright). Without them the module skips with one line saying what is missing.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SHOTS = ROOT / "build" / "screenshots"
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]
MIN_DRAWN = 0.005  # a view is blank below this drawn share (an empty meshcat scene scores about 0.003)
HANG = 1800.0  # seconds without any cell finishing before a Run All counts as hung (a ceiling, not a time limit)
# Console messages that are not the workbench's: JupyterLab asking the network for news/updates (blocked in CI).
BENIGN_CONSOLE = re.compile(r"lab/api/news|update check|favicon|GPU stall due to ReadPixels")


def find_chromium() -> str | None:
    for name in (os.environ.get("WORKBENCH_CHROMIUM"), "chromium", "chromium-browser", "google-chrome"):
        if name and (path := shutil.which(name)):
            return path
    return None


CHROMIUM = find_chromium()
try:
    from playwright.sync_api import sync_playwright
except ImportError:  # pragma: no cover - depends on the install
    sync_playwright = None

pytestmark = [
    pytest.mark.skipif(CHROMIUM is None, reason="no Chromium found (apt-get install chromium): browser test skipped"),
    pytest.mark.skipif(sync_playwright is None, reason="playwright is not installed (pip install -e '.[test]'): "
                                                      "browser test skipped"),
]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass
class Lab:
    url: str
    token: str
    root: Path
    proc: subprocess.Popen

    def api(self, path: str, method: str = "GET") -> object:
        req = urllib.request.Request(f"{self.url}api/{path}", method=method,
                                     headers={"Authorization": f"token {self.token}"})
        with urllib.request.urlopen(req, timeout=10) as r:
            body = r.read()
        return json.loads(body) if body else None


    def shutdown_kernels(self) -> None:
        """Stop every kernel (each notebook's kernel holds a meshcat server and its scenes)."""
        try:
            for k in self.api("sessions"):
                self.api(f"sessions/{k['id']}", method="DELETE")
        except OSError:
            pass


def write_lab_settings(settings: Path) -> None:
    """Every cell kept in the page (no virtual scrolling), no autosave into the copies, no news pop-ups."""
    (settings / "@jupyterlab/notebook-extension").mkdir(parents=True, exist_ok=True)
    (settings / "@jupyterlab/notebook-extension/tracker.jupyterlab-settings").write_text(
        json.dumps({"windowingMode": "none", "autoStartDefaultKernel": True}))
    (settings / "@jupyterlab/docmanager-extension").mkdir(parents=True, exist_ok=True)
    (settings / "@jupyterlab/docmanager-extension/plugin.jupyterlab-settings").write_text(json.dumps({"autosave": False}))
    (settings / "@jupyterlab/apputils-extension").mkdir(parents=True, exist_ok=True)
    (settings / "@jupyterlab/apputils-extension/notification.jupyterlab-settings").write_text(
        json.dumps({"fetchNews": "false", "checkForUpdates": False}))


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """`workbench demo` started in the background (it runs while the notebooks are driven; plan_html waits)."""
    out = tmp_path_factory.mktemp("demo")
    exe = Path(sys.executable).parent / "workbench"
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "workbench.cli"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    with open(out / "demo.log", "w") as log:  # a file, not a pipe: a full pipe would stall the demo
        proc = subprocess.Popen(cmd + ["demo", "--out", str(out), "--workers", "1"], env=env, stdout=log,
                                stderr=subprocess.STDOUT)
        yield proc, out
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.fixture(scope="module")
def lab(tmp_path_factory, demo) -> Lab:
    root = tmp_path_factory.mktemp("lab")
    shutil.copytree(ROOT / "notebooks", root / "notebooks", ignore=shutil.ignore_patterns(".ipynb_checkpoints"))
    write_lab_settings(root / "settings")
    port, token = free_port(), secrets.token_hex(16)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])),
               JUPYTERLAB_SETTINGS_DIR=str(root / "settings"), JUPYTERLAB_WORKSPACES_DIR=str(root / "workspaces"))
    cmd = [sys.executable, "-m", "jupyter", "lab", "--no-browser", "--ip=127.0.0.1", f"--port={port}",
           "--ServerApp.port_retries=0", f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={root}",
           "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
           "--ContentsManager.pre_save_hook=workbench.widgets.saving.strip_widget_views"]  # as `make lab` does
    if os.geteuid() == 0:
        cmd.append("--allow-root")
    log = open(root / "jupyter.log", "w")
    proc = subprocess.Popen(cmd, cwd=root, env=env, stdout=log, stderr=subprocess.STDOUT)
    server = Lab(f"http://127.0.0.1:{port}/", token, root, proc)
    deadline = time.monotonic() + 90
    while True:
        if proc.poll() is not None:
            pytest.fail(f"JupyterLab exited with status {proc.returncode}: {(root / 'jupyter.log').read_text()[-2000:]}")
        try:
            server.api("status")
            break
        except OSError:
            if time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"JupyterLab did not answer on port {port}: {(root / 'jupyter.log').read_text()[-2000:]}")
            time.sleep(0.5)
    yield server
    server.shutdown_kernels()
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGINT)  # JupyterLab asks to confirm a single ^C
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    log.close()


@pytest.fixture(scope="module")
def browser():
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield b
        b.close()


class Console:
    """Errors the page (any frame) reports: console.error and uncaught exceptions."""

    def __init__(self, page):
        self.errors: list[str] = []
        page.on("console", self._console)
        page.on("pageerror", lambda exc: self.errors.append(f"uncaught: {exc}"))

    def _console(self, msg) -> None:
        if msg.type == "error" and not BENIGN_CONSOLE.search(msg.text):
            self.errors.append(f"console.error: {msg.text}")


# --- images -------------------------------------------------------------------------------------------------------

def image(png: bytes) -> np.ndarray:
    from io import BytesIO

    from PIL import Image

    return np.asarray(Image.open(BytesIO(png)).convert("RGB"), dtype=np.int16)


def drawn_share(img: np.ndarray) -> float:
    """Share of the view covered by drawn things: pixels away from their row's background colour (meshcat's
    background is a vertical gradient), after an erosion that removes thin lines (the grid, the axes); the
    "Open Controls" bar at the top is left out. An empty meshcat scene scores about 0.003."""
    from scipy import ndimage

    img = img[24:]
    off = np.abs(img - np.median(img, axis=1, keepdims=True)).max(axis=2) > 30
    return float(ndimage.binary_erosion(off, np.ones((7, 7))).mean())


def colour_share(img: np.ndarray, color: int) -> float:
    """Share of the view in the hue of `color` (0xRRGGBB), shaded or lit: saturated pixels within 12 degrees of
    its hue (the sky gradient and the grey robot are far from every part colour used)."""
    import colorsys

    rgb = img[24:].reshape(-1, 3) / 255.0
    mx, mn = rgb.max(1), rgb.min(1)
    sat = np.where(mx > 0, (mx - mn) / np.maximum(mx, 1e-9), 0)
    r, g, b = rgb.T
    d = np.maximum(mx - mn, 1e-9)
    hue = np.where(mx == r, ((g - b) / d) % 6, np.where(mx == g, (b - r) / d + 2, (r - g) / d + 4)) * 60
    target = colorsys.rgb_to_hsv(((color >> 16) & 255) / 255, ((color >> 8) & 255) / 255, (color & 255) / 255)
    off = np.abs((hue - target[0] * 360 + 180) % 360 - 180)
    return float(((off < 12) & (sat > 0.35) & (mx > 0.15)).mean())


class Frames:
    """meshcat messages the page's views receive (through the Jupyter server's proxy), by type."""

    def __init__(self, page):
        self.types: list[str] = []
        page.on("websocket", self._socket)

    def _socket(self, ws) -> None:
        if "/proxy/" in ws.url:
            ws.on("framereceived", self._frame)

    def _frame(self, payload) -> None:
        import umsgpack

        if isinstance(payload, (bytes, bytearray)):
            try:
                self.types.append(umsgpack.unpackb(bytes(payload)).get("type", "?"))
            except Exception:  # not a meshcat command
                self.types.append("?")

    def settle(self, page, quiet: float = 1.0, limit: float = 120.0) -> int:
        """Wait until no message arrived for `quiet` seconds; the number received so far."""
        deadline, seen, last = time.monotonic() + limit, -1, time.monotonic()
        while time.monotonic() < deadline:
            if len(self.types) != seen:
                seen, last = len(self.types), time.monotonic()
            elif time.monotonic() - last > quiet:
                break
            page.wait_for_timeout(100)
        return len(self.types)


HOLD = """() => { const a = window.viewer && window.viewer.animator;
  if (a && a.playing) { a.pause(); return true; } return false; }"""


def hold_animations(page) -> int:
    """Pause the animation of every meshcat view in the page that plays one; how many were playing."""
    from playwright.sync_api import Error

    held = 0
    for frame in page.frames:
        try:
            held += bool(frame.evaluate(HOLD))
        except Error:  # a frame still loading or gone
            pass
    return held


BOTH = "() => ['wb-caption', 'wb-footer'].map(i => (document.getElementById(i) || {}).textContent || '')"
"""The caption and the footer read at one moment (the page updates both in the same animation frame)."""


def step_named(text: str) -> str:
    """ "step k of n" (or "start") from a caption or footer."""
    m = re.match(r"\s*(start|step \d+ of \d+)", text)
    return m.group(1) if m else ""


def record(stem: str, values: dict) -> None:
    """Latencies and shares measured in Chromium, kept for a person (the benchmark holds the targets)."""
    data = json.loads(LATENCIES.read_text()) if LATENCIES.exists() else {}
    data[stem] = values
    LATENCIES.write_text(json.dumps(data, indent=1))
    print(f"{stem}: {values}")


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    if a.shape != b.shape:
        return a.size
    return int((np.abs(a - b).max(axis=2) > 24).sum())


# --- JupyterLab driving ---------------------------------------------------------------------------------------------

def prompts(page) -> list[str]:
    return page.eval_on_selector_all(".jp-CodeCell .jp-InputArea-prompt", "els => els.map(e => e.textContent.trim())")


def kernel_status(page) -> str:
    return page.evaluate("() => document.querySelector('.jp-Notebook-ExecutionIndicator')?.dataset.status || ''")


def wait_idle(page, timeout: float = 60.0) -> None:
    """Wait until the kernel is idle and no cell is queued or running."""
    deadline = time.monotonic() + timeout
    page.wait_for_timeout(300)
    while time.monotonic() < deadline:
        if kernel_status(page) == "idle" and not any("*" in p for p in prompts(page)):
            return
        page.wait_for_timeout(250)
    raise AssertionError(f"kernel still busy after {timeout:.0f} s (status {kernel_status(page)!r})")


def shown_errors(page) -> list[str]:
    """Errors a person would see in the outputs: tracebacks and widgets that failed to display."""
    texts = page.eval_on_selector_all(".jp-OutputArea-output", "els => els.map(e => e.innerText)")
    bad = re.compile(r"Traceback \(most recent call last\)|Error displaying widget|model not found|\w+(Error|Warning): ")
    return [t.strip()[:400] for t in texts if bad.search(t)]


def run_all(page, console: Console, name: str) -> None:
    page.locator(".jp-Notebook").first.wait_for(timeout=60_000)
    wait_idle(page, HANG)
    # the widget manager registers with the kernel shortly after it reports idle; widgets displayed before then
    # show "model not found"
    page.locator(".jp-StatusBar-TextItem", has_text=re.compile(r"\| Idle")).first.wait_for(timeout=60_000)
    page.wait_for_timeout(3000)
    if page.locator("#jp-left-stack").is_visible():  # the file browser takes width the notebook can use
        page.locator("li.lm-TabBar-tab.lm-mod-current[data-id='filebrowser']").click()
    dialog = page.locator(".jp-Dialog", has_text="Select Kernel")

    def click_run_all() -> None:
        if dialog.is_visible():  # JupyterLab sometimes asks, on a fresh workspace, though the kernelspec is known
            dialog.locator(".jp-mod-accept").click()
            wait_idle(page, 60.0)
        page.locator(".lm-MenuBar-itemLabel", has_text=re.compile(r"^Run$")).click()
        page.get_by_role("menuitem", name="Run All Cells", exact=True).click()

    click_run_all()
    clicks, settled = 1, 0
    progress, last = None, time.monotonic()
    while time.monotonic() - last < HANG:  # waits as long as cells keep finishing: a loaded machine is only slower
        page.wait_for_timeout(1000)
        hold_animations(page)
        errors = shown_errors(page)
        assert not errors, f"{name}: a cell shows an error:\n" + "\n---\n".join(errors)
        ps = prompts(page)
        if ps != progress:
            progress, last = ps, time.monotonic()
        idle = kernel_status(page) == "idle" and not any("*" in p for p in ps)
        if ps and all(re.fullmatch(r"\[\d+\]:", p) for p in ps) and idle:
            return
        settled = settled + 1 if idle else 0
        # A Run All sent while the kernel was still connecting can run only the first cells: send it again
        # (every notebook runs top to bottom again without harm).
        if settled >= 5 and clicks < 4:
            click_run_all()
            clicks, settled = clicks + 1, 0
    raise AssertionError(f"{name}: no cell finished for {HANG:.0f} s (hung?): prompts {prompts(page)}")


def views(page):
    """meshcat views in the outputs (iframes holding a meshcat viewer)."""
    return page.locator(".jp-OutputArea-output iframe")


def view_image(frame_el, timeout: float = 30.0) -> np.ndarray:
    """A screenshot of one view once its canvas has drawn something coloured (or the last one at the timeout)."""
    frame_el.scroll_into_view_if_needed()
    frame_el.content_frame.locator("canvas").first.wait_for(timeout=timeout * 1000)
    deadline = time.monotonic() + timeout
    while True:
        img = image(frame_el.screenshot())
        if drawn_share(img) > MIN_DRAWN or time.monotonic() > deadline:
            return img
        frame_el.page.wait_for_timeout(500)


def numbers(page) -> list[str]:
    """What the widgets report: every HTML/label widget's and printed output's text, without slider readouts and
    busy indicators."""
    return page.eval_on_selector_all(".jp-OutputArea-output .widget-html:not(.workbench-busy), "
                                     ".jp-OutputArea-output .widget-label-basic",
                                     "els => els.map(e => e.innerText)")


def slider(page, label: str):
    """The ipywidgets slider whose description starts with `label`."""
    box = page.locator(".widget-slider", has=page.locator(".widget-label", has_text=re.compile("^" + re.escape(label))))
    return box.first


def move_slider(page, label: str, steps: int = 1) -> None:
    handle = slider(page, label).locator(".noUi-handle").first
    handle.scroll_into_view_if_needed()
    handle.focus()
    for _ in range(steps):
        handle.press("ArrowRight")


def click(page, text: str) -> None:
    page.locator(".jp-OutputArea-output button", has_text=re.compile("^" + re.escape(text) + "$")).first.click()


def select(page, label: str, index: int = 1) -> None:
    """Pick entry `index` of the dropdown whose description starts with `label`."""
    box = page.locator(".widget-dropdown", has=page.locator(".widget-label", has_text=re.compile("^" + re.escape(label))))
    box.first.locator("select").select_option(index=index)


# One move per notebook: something a person would try first. Notebooks not listed get the first slider moved.
MOVES = {
    "01": lambda page: move_slider(page, "highlighted facet", 3),
    "02": lambda page: select(page, "selected placement"),
    "03": lambda page: move_slider(page, "feasible grip"),
    "04": lambda page: (move_slider(page, "start x (m)", 4), click(page, "search")),  # the view animates: numbers
    "05": lambda page: move_slider(page, "switch"),
    "06": lambda page: move_slider(page, "theta (deg)", 5),
    "07": lambda page: (move_slider(page, "start x (m)", 4), click(page, "search")),  # the explorer of the picked part
}
VIEW_ONLY = {"01", "02", "03", "05", "06"}  # their move only shows, hides or moves what the view holds: no geometry is sent
# The part's colour in the notebook's first view (None: the part is drawn in many colours, so everything drawn
# counts) and the least share of the frame it covers: the camera frames the work, not the room.
PART = {"01": (None, 0.08), "02": (0xE0C040, 0.001), "03": (None, 0.04), "04": (0xE0A030, 0.0003),
        "05": (None, 0.06)}  # 03's blue part is the sky's hue: there everything drawn (robot, table, part) counts;
# 04's part is small beside the whole arm, and the hand hides some of it while it is held
LATENCIES = ROOT / "build" / "screenshots" / "latencies.json"


def default_move(page) -> bool:
    """Notebooks without a listed move: nudge the first slider, else pick another entry of the first dropdown
    with a choice. False when the notebook has neither."""
    handle = page.locator(".jp-OutputArea-output .noUi-handle")
    if handle.count():
        handle.first.scroll_into_view_if_needed()
        handle.first.focus()
        handle.first.press("ArrowRight")
        return True
    for select in page.locator(".jp-OutputArea-output .widget-dropdown select").all():
        if select.locator("option").count() > 1:
            select.select_option(index=1)
            return True
    return False


def check_notebook(browser, lab: Lab, path: Path) -> None:
    name, stem = path.name, path.stem
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = context.new_page()
    console = Console(page)
    sockets: list[str] = []
    page.on("websocket", lambda ws: sockets.append(ws.url))
    meshcat = Frames(page)
    try:
        # a workspace of its own: only this notebook open (JupyterLab would reopen the previous tabs)
        page.goto(f"{lab.url}lab/workspaces/{stem}/tree/notebooks/{name}?reset&token={lab.token}")
        run_all(page, console, name)
        page.wait_for_timeout(1000)
        hold_animations(page)
        assert not shown_errors(page), f"{name}: a cell shows an error: {shown_errors(page)}"

        outputs = " ".join(page.eval_on_selector_all(".jp-OutputArea-output", "els => els.map(e => e.innerText)"))
        assert "You can open the visualizer" not in outputs, f"{name}: meshcat's server banner is printed"

        frames = views(page)
        before = []
        for i in range(frames.count()):
            img = view_image(frames.nth(i))
            before.append(img)
            frames.nth(i).screenshot(path=SHOTS / f"{stem}_view{i}.png")
            assert drawn_share(img) > MIN_DRAWN, f"{name}: meshcat view {i} is blank"
        if frames.count():  # the views reach meshcat through the Jupyter server, as from another machine
            proxied = [u for u in sockets if "/proxy/" in u]
            assert proxied, f"{name}: no view connected through the Jupyter server's proxy (sockets: {sockets})"
        for i, out in enumerate(page.locator(".jp-OutputArea-output:has(.jupyter-widgets)").all()):
            out.scroll_into_view_if_needed()
            out.screenshot(path=SHOTS / f"{stem}_widgets{i}.png")

        measured: dict = {}
        if frames.count() and stem[:2] in PART:
            color, least = PART[stem[:2]]
            share = drawn_share(before[0]) if color is None else colour_share(before[0], color)
            measured["part share"] = round(share, 4)
            assert share >= least, f"{name}: the part covers {share:.2%} of its view, less than {least:.2%}"
        if stem.startswith("04") and frames.count():  # the view's caption and footer name the same step
            inner = frames.first.element_handle().content_frame()
            texts = []
            for _ in range(20):
                texts = inner.evaluate(BOTH)
                if all(texts):
                    break
                page.wait_for_timeout(500)
            assert step_named(texts[0]) and step_named(texts[0]) == step_named(texts[1]), texts

        text_before = numbers(page)
        move = MOVES.get(stem[:2])
        sent_before = meshcat.settle(page)
        t0 = time.monotonic()
        if move is not None:
            move(page)
        if move is None and not default_move(page):
            print(f"{name}: no slider or dropdown to move")
        else:
            changed, animated = False, stem[:2] in ("04", "07")  # a search starts a new animation: read the numbers
            while not changed and time.monotonic() - t0 < HANG / 6:
                page.wait_for_timeout(100)
                if not animated:
                    after = [image(frames.nth(i).screenshot()) for i in range(frames.count())]
                    changed = any(changed_pixels(a, b) > 200 for a, b in zip(before, after))
                changed = changed or numbers(page) != text_before
            measured["move to update (s)"] = round(time.monotonic() - t0, 3)
            wait_idle(page, HANG)
            hold_animations(page)  # a search plays its new plan
            if stem.startswith("04"):  # the overlay follows the new plan: its footer is one of the plan's steps listed
                texts = frames.first.element_handle().content_frame().evaluate(BOTH)
                assert step_named(texts[0]) and step_named(texts[0]) == step_named(texts[1]), texts
                assert texts[1] == "start" or texts[1] in " ".join(numbers(page)), (texts, numbers(page))
            for i in range(frames.count()):
                frames.nth(i).screenshot(path=SHOTS / f"{stem}_view{i}_moved.png")
            assert changed, f"{name}: moving a widget changed neither a view nor a number"
            got = meshcat.types[sent_before:meshcat.settle(page)]
            measured["meshcat messages"] = {t: got.count(t) for t in sorted(set(got))}
            if stem[:2] in VIEW_ONLY:
                assert "set_object" not in got, f"{name}: a view-only change sent geometry: {measured['meshcat messages']}"
        record(stem, measured)
        assert not shown_errors(page), f"{name}: a cell shows an error after the move: {shown_errors(page)}"
        assert not console.errors, f"{name}: browser console errors:\n" + "\n".join(console.errors[:10])
    finally:
        hold_animations(page)
        page.screenshot(path=SHOTS / f"{stem}_page.png")
        context.close()
        lab.shutdown_kernels()


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_in_browser(browser, lab, path):
    SHOTS.mkdir(parents=True, exist_ok=True)
    check_notebook(browser, lab, path)


@pytest.fixture(scope="module")
def plan_html(demo) -> Path:
    proc, out = demo
    proc.wait(timeout=600)
    assert proc.returncode == 0, f"workbench demo failed: {(out / 'demo.log').read_text()[-2000:]}"
    assert (out / "plan.html").is_file(), f"workbench demo wrote no plan.html in {out}"
    return out / "plan.html"


def test_plan_html_animates(browser, plan_html):
    SHOTS.mkdir(parents=True, exist_ok=True)
    context = browser.new_context(viewport={"width": 1000, "height": 700})
    page = context.new_page()
    console = Console(page)
    try:
        page.goto(plan_html.as_uri())
        page.wait_for_selector("canvas", timeout=60_000)
        first = image(page.screenshot(path=SHOTS / "plan_html_0.png"))
        deadline = time.monotonic() + 30
        while drawn_share(first) < MIN_DRAWN and time.monotonic() < deadline:
            page.wait_for_timeout(500)
            first = image(page.screenshot(path=SHOTS / "plan_html_0.png"))
        assert drawn_share(first) > MIN_DRAWN, "plan.html shows a blank scene"
        caption = page.locator("#wb-caption")
        assert re.match(r"(start|step \d+ of \d+): ", caption.inner_text()), "plan.html has no caption for the step playing"
        for _ in range(5):  # at a few moments of the animation
            texts = page.evaluate(BOTH)
            assert step_named(texts[0]) == step_named(texts[1]), f"plan.html's caption and footer disagree: {texts}"
            page.wait_for_timeout(300)
        page.wait_for_timeout(1500)
        second = image(page.screenshot(path=SHOTS / "plan_html_1.png"))
        assert changed_pixels(first, second) > 200, "plan.html does not animate: two screenshots 1.5 s apart match"
        assert not console.errors, "plan.html console errors:\n" + "\n".join(console.errors[:10])
    finally:
        context.close()
