"""The explorer as a user meets it: JupyterLab started on localhost by this test, a notebook holding
``brdffit.explore`` opened in headless Chromium (Debian's ``chromium``, driven by Playwright), its
cell run (Shift+Enter), a parameter slider clicked, the light picked on the table, Fit
clicked; the shown loss and images must change each time, and a screenshot of the widget is kept
(``out/explore-browser/explorer.png``; with BRDFFIT_SCREENSHOT=docs/explorer.png also a 256-colour
copy there, the README's).

``make test`` installs what this needs: Chromium by scripts/setup.sh (apt-get, as root), JupyterLab
and Playwright by the test extra. The test is skipped, with one line, only where Chromium is
missing and cannot be installed (not root, or no apt-get); Playwright's own browser download is
not used.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import socket
import statistics
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync"]
TOKEN = "brdffit-browser-test"
SHOTS = REPO / "out" / "explore-browser"

sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright (the test extra) is not installed")
pytest.importorskip("jupyterlab", reason="JupyterLab (the test extra) is not installed")
pytest.importorskip("anywidget", reason="anywidget (the test extra) is not installed")


def _chromium() -> Path:
    if CHROMIUM.is_file():
        return CHROMIUM
    if os.geteuid() == 0 and shutil.which("apt-get"):
        pytest.fail(f"{CHROMIUM} is missing, and this machine can install it: run scripts/setup.sh (make test does)")
    pytest.skip(f"Chromium is not at {CHROMIUM} and cannot be installed here (needs root and apt-get)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _notebook(path: Path) -> None:
    source = (f"import brdffit\n"
              f"explorer = brdffit.explore({str(REPO / 'data' / 'sample_ubo81.exr')!r})\n"
              f"explorer")
    cell = {"cell_type": "code", "execution_count": None, "id": "explorer", "metadata": {}, "outputs": [],
            "source": source}
    nb = {"cells": [cell], "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python",
                                                       "name": "python3"}}, "nbformat": 4, "nbformat_minor": 5}
    path.write_text(json.dumps(nb))


@dataclasses.dataclass(frozen=True)
class Lab:
    url: str
    log: Path


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    """JupyterLab of this interpreter on a free localhost port, serving a folder with the notebook;
    its kernel is this interpreter too (ipykernel's own python3 spec)."""
    root = tmp_path_factory.mktemp("lab")
    _notebook(root / "explore.ipynb")
    # no "official Jupyter news?" prompt over the widget (JupyterLab's announcements plugin)
    (root / ".config" / "labconfig").mkdir(parents=True)
    (root / ".config" / "labconfig" / "page_config.json").write_text(
        json.dumps({"disabledExtensions": {"@jupyterlab/apputils-extension:announcements": True}}))
    # the user's own Jupyter folders left out (a kernel spec of theirs named python3 would win)
    env = {**os.environ, "JUPYTER_CONFIG_DIR": str(root / ".config"), "JUPYTER_DATA_DIR": str(root / ".data"),
           "JUPYTER_RUNTIME_DIR": str(root / ".runtime"), "JUPYTER_PLATFORM_DIRS": "1"}
    port = _free_port()
    log = open(root / "lab.log", "w")
    server = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--ip=127.0.0.1", f"--port={port}",
         f"--IdentityProvider.token={TOKEN}", f"--ServerApp.root_dir={root}", "--LabApp.news_url=None",
         "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate", "--LabApp.extension_manager=readonly",
         *(["--allow-root"] if os.geteuid() == 0 else [])],
        cwd=root, env=env, stdout=log, stderr=subprocess.STDOUT)
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 90
        while True:
            try:
                with urllib.request.urlopen(f"{url}/api/status?token={TOKEN}", timeout=2) as reply:
                    if reply.status == 200:
                        break
            except OSError:
                pass
            if server.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"JupyterLab did not start: {(root / 'lab.log').read_text()[-3000:]}")
            time.sleep(0.5)
        yield Lab(url, root / "lab.log")
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    executable = _chromium()
    profile = tmp_path_factory.mktemp("chromium-profile")
    with sync_api.sync_playwright() as p:
        # a fresh profile (--user-data-dir), which Playwright takes as this argument
        context = p.chromium.launch_persistent_context(profile, executable_path=str(executable), headless=True,
                                                       args=FLAGS, viewport={"width": 1500, "height": 1100})
        yield context
        context.close()


def _shown(page) -> dict:
    """The loss line and the images' sources as the page shows them."""
    return page.evaluate("""() => {
        const root = document.querySelector('.bf-explorer');
        const src = {};
        for (const img of root.querySelectorAll('img.bf-img')) src[img.dataset.name] = img.getAttribute('src') || '';
        return {loss: root.querySelector('.bf-loss').textContent, frame: root.dataset.frame,
                status: root.querySelector('.bf-status').textContent, src};
    }""")


def _after(page, before: dict, timeout: float = 30_000) -> dict:
    """What the page shows once a view newer than ``before`` has arrived."""
    page.wait_for_function("f => document.querySelector('.bf-explorer').dataset.frame !== f", arg=before["frame"],
                           timeout=timeout)
    return _shown(page)


def _click_at(page, locator, fraction: float) -> None:
    box = locator.bounding_box()
    page.mouse.click(box["x"] + fraction * box["width"], box["y"] + box["height"] / 2)


@pytest.fixture
def page(browser):
    page = browser.new_page()
    yield page
    page.close()


@contextlib.contextmanager
def evidence(page, lab: Lab):
    """Where the test fails inside, a screenshot of the page and the end of the server's log."""
    try:
        yield
    except BaseException:
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "failure.png"))
        print(f"\nbrowser test failed: screenshot {SHOTS / 'failure.png'}; JupyterLab's log ends:\n"
              + lab.log.read_text()[-4000:])
        raise


@pytest.mark.slow
def test_explorer_in_jupyterlab(lab, page):
    with evidence(page, lab):
        page.goto(f"{lab.url}/lab/tree/explore.ipynb?token={TOKEN}")
        cell = page.locator(".jp-Notebook .jp-Cell").first
        cell.wait_for(timeout=60_000)
        page.get_by_text("Python 3 (ipykernel) | Idle").wait_for(timeout=60_000)
        cell.locator(".jp-InputPrompt").click()  # the notebook focused, the cell selected
        page.keyboard.press("Shift+Enter")
        root = page.locator(".bf-explorer")
        root.wait_for(timeout=120_000)
        page.wait_for_function("() => document.querySelector('.bf-explorer .bf-loss').textContent.includes('loss')",
                               timeout=60_000)
        start = _shown(page)
        assert "set by hand" in start["status"]

        # a slider moved as a user does, with the mouse: the loss and the model's images change, the
        # measurement's do not
        alpha = page.locator(".bf-slider[data-param='alpha'] input.bf-range")
        latencies = []
        shown = start
        for fraction in (0.85, 0.6, 0.75, 0.55, 0.8):
            t = time.perf_counter()
            _click_at(page, alpha, fraction)
            shown = _after(page, shown)
            latencies.append(time.perf_counter() - t)
        moved = shown
        assert moved["loss"] != start["loss"]
        for name in ("fitted", "sphere_fit", "log_ratio", "slices"):
            assert moved["src"][name] != start["src"][name], name
        for name in ("measured", "sphere_measured"):
            assert moved["src"][name] == start["src"][name], name
        print(f"\nbrowser: slider click to new view, median {1e3 * statistics.median(latencies):.0f} ms "
              f"of {len(latencies)} (kernel and page on this machine)")

        # the light picked on the table: a row near the bottom is a light at theta = 75 degrees
        theta = page.locator(".bf-light .bf-slider").first.locator("input.bf-number")
        table = page.locator("img.bf-measured")
        box = table.bounding_box()
        page.mouse.click(box["x"] + box["width"] / 2, box["y"] + box["height"] * 0.95)
        lit = _after(page, moved)
        assert float(theta.input_value()) == 75.0
        assert lit["src"]["sphere_measured"] != moved["src"]["sphere_measured"]

        # Fit: the sliders move to the result, the loss drops, the status says converged
        value_before = alpha.input_value()
        page.locator("button.bf-fit").click()
        fitted = _after(page, lit, timeout=120_000)
        assert "fit: converged" in fitted["status"], fitted["status"]
        assert float(fitted["loss"].split()[2]) < float(lit["loss"].split()[2])
        assert alpha.input_value() != value_before
        SHOTS.mkdir(parents=True, exist_ok=True)
        shot = SHOTS / "explorer.png"
        root.screenshot(path=str(shot))
        assert shot.stat().st_size > 10_000
        print(f"browser: screenshot {shot.relative_to(REPO)}")
        readme_copy = os.environ.get("BRDFFIT_SCREENSHOT")
        if readme_copy:
            from PIL import Image

            # 256 colours (fast octree: it keeps the channels' red, green and blue, median cut did not)
            Image.open(shot).convert("RGB").quantize(256, method=Image.Quantize.FASTOCTREE).save(REPO / readme_copy,
                                                                                                  optimize=True)
