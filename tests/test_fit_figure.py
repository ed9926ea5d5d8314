"""The figure ``brdffit fit`` writes (fit.png) and what reading and plotting a fit compile in a new
process (docs/fitting.md#solvers: a second ``brdffit fit`` process within 2.5 s).

Pinned values come from the test's own inputs (the parameters it builds the fit from, the figure
size in inches), never from the code under test.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg

import brdffit.plot as bp
from brdffit import Measurement, models
from brdffit.fitting.result import FitResult
from brdffit.grid import ubo_pairs

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "sample_ubo81.exr"
GGX = {"kd": [0.3, 0.25, 0.2], "ks": [0.7, 0.65, 0.6], "alpha": [0.125], "f0": [0.04]}


def ggx_fit(params=GGX) -> FitResult:
    m = models.get("ggx")
    return FitResult(model=m, params={k: np.asarray(v, np.float64) for k, v in m.check_params(params).items()},
                     loss="log", loss_value=1.5e-5, metrics={"log_rmse": 0.004}, steps=7, converged=True,
                     status="converged", seconds={"run": 0.1}, solver="lm", data_name="table", n_used=6561,
                     n_excluded=0)


def table(channels: int = 3) -> Measurement:
    wi, wo = ubo_pairs()
    f = np.asarray(models.get("ggx").with_channels(channels).eval(
        models.get("ggx").with_channels(channels).check_params({"kd": 0.3, "ks": 0.6, "alpha": 0.2, "f0": 0.05}),
        wi, wo))
    return Measurement(wi, wo, f, name="table", grid="ubo81")


def test_fit_figure_panels_do_not_overlap_and_stay_inside():
    """Without a layout engine the geometry is fixed: every axes (5 panels, 2 colour bars) inside
    the figure, no two overlapping, each 81x81 panel square (equal aspect fills its box)."""
    grey = table(1)
    figures = ((bp.fit_figure(table(3), ggx_fit()), 5),
               (bp.compare_table(grey, np.asarray(grey.values).reshape(81, 81, 1) * 1.01), 3))
    for fig, panels in figures:
        canvas = FigureCanvasAgg(fig)
        canvas.draw()  # apply_aspect: positions as drawn
        w, h = fig.get_size_inches()
        boxes = [ax.get_position() for ax in fig.axes]
        assert sum(1 for ax in fig.axes if ax.get_images()) == panels
        for b in boxes:
            assert 0 <= b.x0 < b.x1 <= 1 and 0 <= b.y0 < b.y1 <= 1
        for i, a in enumerate(boxes):
            for b in boxes[i + 1:]:
                overlap_w = min(a.x1, b.x1) - max(a.x0, b.x0)
                overlap_h = min(a.y1, b.y1) - max(a.y0, b.y0)
                assert overlap_w <= 1e-9 or overlap_h <= 1e-9, (a, b)
        for ax in fig.axes:
            if ax.get_images():
                b = ax.get_position()
                np.testing.assert_allclose(b.width * w, b.height * h, rtol=1e-6)
        # every text drawn lies inside the figure (titles, tick labels, colour-bar labels, summary)
        renderer = canvas.get_renderer()
        W, H = fig.bbox.width, fig.bbox.height
        texts = [t for ax in fig.axes for t in (ax.title, ax.xaxis.label, ax.yaxis.label)]
        for axis in (a for ax in fig.axes for a in (ax.xaxis, ax.yaxis)):
            lo, hi = sorted(axis.get_view_interval())
            span = 1e-9 * (hi - lo)
            texts += [t for loc, t in zip(axis.get_ticklocs(), axis.get_ticklabels()) if lo - span <= loc <= hi + span]
        texts += [t for t in fig.texts] + ([fig._suptitle] if fig._suptitle else [])
        for t in texts:
            if t.get_text() and t.get_visible():
                e = t.get_window_extent(renderer)
                assert e.x0 >= -1 and e.y0 >= -1 and e.x1 <= W + 1 and e.y1 <= H + 1, (t.get_text(), e)


def test_fit_figure_states_the_fitted_parameters():
    fig = bp.fit_figure(table(), ggx_fit())
    summary = "\n".join(t.get_text() for t in fig.texts if t is not fig._suptitle)
    assert "ggx fit, 7 steps, log loss 1.5e-05" in summary
    lines = {line.split()[0]: line.split()[1:] for line in summary.splitlines()[1:]}
    # the values the fit was built from, as written by hand here
    assert lines == {"kd": ["0.3", "0.25", "0.2"], "ks": ["0.7", "0.65", "0.6"], "alpha": ["0.125"], "f0": ["0.04"]}


def test_reading_and_plotting_a_fit_compile_few_programs(tmp_path):
    """In a new process: reading the sample EXR and preparing it compile nothing; the fit figure
    compiles at most two programs (the model on the table's directions, the log residual), not
    one per JAX operation as evaluating op by op did (~75 programs, each lowered in every new
    process even when JAX's disk cache holds it)."""
    code = f"""
import json, sys
import jax, numpy as np
lowered = []
def on_event(event, duration, **kwargs):
    if event == "/jax/core/compile/jaxpr_to_mlir_module_duration":
        lowered.append(kwargs.get("fun_name", "?"))
jax.monitoring.register_event_duration_secs_listener(on_event)
sys.path.insert(0, {str(REPO / 'tests')!r})
import brdffit, brdffit.plot as bp
from brdffit.fitting.problem import prepare
from test_fit_figure import ggx_fit
m = brdffit.load({str(SAMPLE)!r})
prepare(m)
read = list(lowered)
r = ggx_fit()  # (building it by hand from lists compiles a few conversions: not the figure's)
before = len(lowered)
bp.fit_figure(m, r).savefig({str(tmp_path / 'fit.png')!r}, dpi=50)
print(json.dumps({{"read": read, "figure": lowered[before:]}}))
"""
    env = dict(os.environ, BRDFFIT_CACHE=str(tmp_path / "cache"))
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stderr[-3000:]
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got["read"] == []
    assert 1 <= len(got["figure"]) <= 2, got["figure"]


def test_the_brdffit_process_exits_normally_with_its_collector_tuned(tmp_path):
    """``entry()`` (the executable): main's exit status, atexit handlers run (the interpreter's
    exit is not skipped), the collector's thresholds raised and the objects frozen before exit."""
    code = """
import atexit, gc, sys
def at_exit():
    print("atexit", gc.get_threshold(), gc.get_freeze_count() > 0)
atexit.register(at_exit)
sys.argv = ["brdffit", "fit", "/nonexistent/table.exr", "--model", "ggx"]
from brdffit.cli import entry
entry()
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                         env=dict(os.environ, BRDFFIT_CACHE="off"))
    assert run.returncode == 2, run.stderr
    assert "/nonexistent/table.exr" in run.stderr and "Traceback" not in run.stderr
    assert run.stdout.strip() == "atexit (100000, 50, 1000) True"


def test_importing_brdffit_leaves_the_collector_as_it_found_it():
    """``import brdffit`` pauses the cyclic collector while JAX loads, and restores the caller's
    setting: off stays off, on stays on."""
    code = """
import gc
for enabled in (False, True):
    (gc.enable if enabled else gc.disable)()
    for name in [m for m in list(__import__("sys").modules) if m == "brdffit" or m.startswith("brdffit.")]:
        del __import__("sys").modules[name]
    import brdffit
    print(enabled, gc.isenabled())
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split() == ["False", "False", "True", "True"]
