"""brdffit.plot (docs/validation.md#figures) and the figure defects of docs/DESIGN.md#where-users-meet-brdffit (item 9), without rendering.

Values pinned here are computed by hand in the test (NumPy on the arrays given), never read back
from the code under test.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib
import numpy as np
import pytest

import brdffit.plot as bp
from brdffit import Measurement, models
from brdffit.fitting.result import FitResult
from brdffit.grid import ubo_pairs

GGX = {"kd": [0.3, 0.25, 0.2], "ks": [0.3, 0.3, 0.3], "alpha": [0.3], "f0": [0.05]}
REPO = Path(__file__).resolve().parents[1]


def ggx_values(params=GGX):
    wi, wo = ubo_pairs()
    model = models.get("ggx")
    return wi, wo, np.asarray(model.eval(model.check_params(params), wi, wo))


def measurement(values=None, weights=None) -> Measurement:
    wi, wo, f = ggx_values()
    return Measurement(wi, wo, f if values is None else values, weights=weights, name="ggx_table", grid="ubo81")


def fit_result(params=GGX, model="ggx") -> FitResult:
    m = models.get(model)
    return FitResult(model=m, params={k: np.asarray(v, np.float64) for k, v in m.check_params(params).items()},
                     loss="log", loss_value=0.0, metrics={"log_rmse": 0.0}, steps=1, converged=True, status="ok",
                     seconds={"run": 0.1}, solver="lm", data_name="ggx_table", n_used=6561, n_excluded=0)


def colourbars(fig):
    return [ax._colorbar for ax in fig.axes if getattr(ax, "_colorbar", None) is not None]


def images(fig):
    return [im for ax in fig.axes for im in ax.get_images()]


# -- defect 9: log colour range from the data --------------------------------------------------------
def test_log_range_comes_from_the_measured_data_not_the_fit():
    m = measurement()
    too_bright = fit_result({**GGX, "ks": [30.0, 30.0, 30.0]})  # a fit 100x brighter at its peak
    fig = bp.compare_table(m, too_bright)
    values = np.asarray(m.values)
    hi, lo = values.max(), np.percentile(values[values > 0], 1)
    log_bars = [cb for cb in colourbars(fig) if isinstance(cb.norm, matplotlib.colors.LogNorm)]
    assert len(log_bars) == 1
    np.testing.assert_allclose([log_bars[0].norm.vmin, log_bars[0].norm.vmax], [lo, hi], rtol=1e-12)


# -- defect 9: excluded samples have their own colour and a legend -----------------------------------
def test_excluded_samples_are_magenta_with_a_legend():
    weights = np.ones(6561)
    weights[81 * 10: 81 * 10 + 7] = 0  # light 10, views 0..6
    m = measurement(weights=weights)
    for fig in (bp.table(m), bp.compare_table(m, fit_result())):
        rgb = images(fig)[0].get_array()
        np.testing.assert_array_equal(rgb[10, :7], np.tile([1.0, 0.0, 1.0], (7, 1)))
        # the top of the map (brightest valid samples) is not that colour
        assert not np.any(np.all(rgb[np.ones((81, 81), bool) & (weights.reshape(81, 81) > 0)] == [1, 0, 1], axis=-1))
        legends = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
        assert "excluded samples (7)" in legends


# -- defect 9: the error panel's range comes from the data -------------------------------------------
def test_error_range_follows_the_data():
    m = measurement()
    close = fit_result({**GGX, "kd": [0.301, 0.25, 0.2]})  # a good fit: tiny residuals
    fig = bp.compare_table(m, close)
    wi, wo, f_ref = ggx_values()
    _, _, f_fit = ggx_values({**GGX, "kd": [0.301, 0.25, 0.2]})
    cos = wi[:, 2:3]
    residual = np.log1p(f_fit * cos) - np.log1p(f_ref * cos)
    expected = np.abs(residual).max()  # the whole range of the errors (docs/materials.md#native-materials-and-exports: not a percentile)
    errors = [im for im in images(fig) if im.get_array().ndim == 2]
    assert len(errors) == 3
    for im in errors:
        lo, hi = im.get_clim()
        assert lo == -hi
        np.testing.assert_allclose(hi, expected, rtol=1e-9)  # not the fixed +-1 of before


def test_error_scale_reaches_the_largest_error():
    """A few errors far above the rest (a fit that misses a peak by x20) stay on the scale: the
    colour bar runs to the largest error, logarithmic beyond the 99.5th percentile (docs/materials.md#native-materials-and-exports: it
    stopped at +-0.25 while errors reached 20)."""
    import matplotlib.colors

    n = 32
    ref = np.full((n, n, 3), 0.1)
    fit = ref + 0.01 * np.sin(np.arange(n * n * 3)).reshape(n, n, 3)
    fit[3, 4] += 20.0  # one pixel far off
    fig = bp.sphere_panel(ref, fit, np.array([0.0, 0.0, 1.0]))
    ims = [ax.get_images()[0] for ax in fig.axes if ax.get_title().endswith("fit − reference")]
    for im in ims:
        lo, hi = im.get_clim()
        assert hi == pytest.approx(np.abs(fit - ref).max()) and lo == -hi
        assert isinstance(im.norm, matplotlib.colors.SymLogNorm)
        assert im.norm.linthresh == pytest.approx(np.percentile(np.abs(fit - ref), 99.5))


# -- defect 9: colour (per-channel) error maps, R/G/B labels -----------------------------------------
def test_sphere_panel_shows_a_chroma_error_that_luminance_hides():
    n = 16
    yellow = np.zeros((n, n, 3))
    yellow[...] = (0.6, 0.6, 0.0)
    lum = 0.2126 * 0.6 + 0.7152 * 0.6
    whitish = np.full((n, n, 3), lum)  # same luminance, no colour: invisible in a luminance map
    fig = bp.sphere_panel(yellow, whitish, np.array([0.0, 0.0, 1.0]), metrics=None)
    titles = [ax.get_title() for ax in fig.axes]
    assert [t for t in titles if t.endswith("fit − reference")] == ["R: fit − reference", "G: fit − reference",
                                                                      "B: fit − reference"]
    blue = [ax for ax in fig.axes if ax.get_title().startswith("B:")][0].get_images()[0].get_array()
    np.testing.assert_allclose(blue, lum - 0.0)
    assert colourbars(fig), "the error maps have a colour bar"


def test_scatter_labels_channels_r_g_b():
    from brdffit.sample import ground_truth

    rng = np.random.default_rng(0)
    wi = rng.normal(size=(200, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo = wi[::-1].copy()
    m = Measurement(wi, wo, ground_truth(wi, wo), name="scattered")
    fig = bp.scatter(m, fit_result())
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert labels[:3] == ["R", "G", "B"]


# -- defect 9: one tick convention on every 81x81 display; units ------------------------------------
def test_every_81x81_display_has_the_same_ring_ticks_and_units():
    m = measurement()
    # ring centres by hand: ring sizes 1, 6, 12, 18, 20, 24
    centres = (0.0, 3.5, 12.5, 27.5, 46.5, 68.5)
    labels = ("0°", "15°", "30°", "45°", "60°", "75°")
    ticks = set()
    grey = Measurement(m.wi, m.wo, np.asarray(m.values)[:, :1], name="grey", grid="ubo81")
    grey_fit = np.asarray(grey.values).reshape(81, 81, 1) * 1.01  # one residual panel: none under "fitted"
    for fig in (bp.table(m), bp.table(fit_result()), bp.compare_table(m, fit_result()), bp.fit_figure(m, fit_result()),
                bp.compare_table(grey, grey_fit)):
        panels = [ax for ax in fig.axes if ax.get_images()]
        for ax in panels:
            view = tuple(ax.get_xticks()) + tuple(t.get_text() for t in ax.get_xticklabels())
            if view:
                ticks.add(view)
                assert ax.get_xlabel().startswith("view θ ring")
            else:  # only above a panel of the same column that labels the view rings
                column = [a for a in panels if np.isclose(a.get_position().x0, ax.get_position().x0)]
                last = min(column, key=lambda a: a.get_position().y0)
                assert last is not ax and tuple(last.get_xticks()) == centres and ax.get_xlabel() == ""
            light = tuple(ax.get_yticks()) + tuple(t.get_text() for t in ax.get_yticklabels())
            if light:
                ticks.add(light)
                assert ax.get_ylabel() == "light θ ring"
            else:  # only right of a panel of the same row that labels the light rings
                row = [a for a in panels if np.isclose(a.get_position().y0, ax.get_position().y0)]
                first = min(row, key=lambda a: a.get_position().x0)
                assert first is not ax and tuple(first.get_yticks()) == centres and ax.get_ylabel() == ""
    assert ticks == {centres + labels}
    fig = bp.compare_table(m, fit_result())
    assert "1/sr" in fig._suptitle.get_text() and "log-RMSE" in fig._suptitle.get_text()
    labels = [cb.ax.get_ylabel() for cb in colourbars(fig)]
    assert any("(1/sr)" in x for x in labels) and any("ln(1 + f_fit cos" in x for x in labels)


# -- the one log_rmse (defect 4) ------------------------------------------------------------------------
def test_table_log_rmse_is_the_fit_definition():
    from brdffit.render.metrics import table_metrics

    wi, wo, f_ref = ggx_values()
    _, _, f_fit = ggx_values({**GGX, "alpha": [0.35]})
    valid = np.ones((81, 81, 3), bool)
    valid[3] = False
    cos = wi[:, 2:3].reshape(81, 81, 1)
    d = (np.log(1 + f_fit.reshape(81, 81, 3) * cos) - np.log(1 + f_ref.reshape(81, 81, 3) * cos))[valid]
    by_hand = np.sqrt(np.mean(d**2))
    got = table_metrics(f_ref.reshape(81, 81, 3), f_fit.reshape(81, 81, 3), valid)["log_rmse"]
    np.testing.assert_allclose(got, by_hand, rtol=1e-12)
    # and the figure's title states the same number
    ref = f_ref.reshape(81, 81, 3).copy()
    ref[3] = np.nan
    title = bp.compare_table(ref, f_fit.reshape(81, 81, 3))._suptitle.get_text()
    assert f"log-RMSE {by_hand:.3g}" in title


def test_fit_and_compare_report_the_same_log_rmse():
    from brdffit import compare, fit

    m = measurement()
    noisy = m.replace(values=np.asarray(m.values) * np.random.default_rng(1).lognormal(0, 0.05, (6561, 3)))
    r = fit(noisy, "lambert")
    wi = np.asarray(noisy.wi)
    d = np.log(1 + r.eval(wi, np.asarray(noisy.wo)) * wi[:, 2:3]) - np.log(1 + np.asarray(noisy.values) * wi[:, 2:3])
    np.testing.assert_allclose(r.metrics["log_rmse"], np.sqrt(np.mean(d**2)), rtol=1e-9)
    row = compare(noisy, ["lambert"], ["lm"], ["log"]).rows[0]
    np.testing.assert_allclose(row["log_rmse"], r.metrics["log_rmse"], rtol=1e-9)


# -- slices ----------------------------------------------------------------------------------------
def test_slices_dots_are_the_measured_in_plane_samples():
    sharp = {"kd": [0.1, 0.1, 0.1], "ks": [0.5, 0.5, 0.5], "alpha": [0.1], "f0": [0.5]}
    m = measurement(values=ggx_values(sharp)[2])
    fig = bp.slices(m, fit_result(sharp), theta_light=np.radians(45))
    ax = [a for a in fig.axes if a.get_title() == "R, in-plane"][0]
    dots = [line for line in ax.get_lines() if line.get_marker() == "o"][0]
    # by hand: light (45, 0) is UBO index 19 + 0 = 19; in-plane views have phi 0 or 180
    from brdffit.grid import ubo_angles_deg

    ang = ubo_angles_deg()
    light = int(np.flatnonzero((ang[:, 0] == 45) & (ang[:, 1] == 0))[0])
    views = np.flatnonzero((ang[:, 1] % 180 == 0))
    signed = np.radians(np.where(ang[views, 1] == 180, 1, -1) * ang[views, 0])
    table = np.asarray(m.values).reshape(81, 81, 3)
    got = sorted(zip(np.round(dots.get_xdata(), 9), dots.get_ydata()))
    want = sorted(zip(np.round(signed, 9), table[light, views, 0]))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    curve = [line for line in ax.get_lines() if line.get_label() == "fit"][0]
    assert len(curve.get_xdata()) > 100
    # within the measured range the fitted curve peaks on the mirror side, at about +45 degrees
    s, f = np.degrees(curve.get_xdata()), curve.get_ydata()
    inside = np.abs(s) <= 75
    assert 40 < s[inside][np.argmax(f[inside])] < 50


def test_slices_reject_degrees():
    from brdffit.errors import UsageError

    with pytest.raises(UsageError, match="radians"):
        bp.slices(measurement(), theta_light=45)


# -- defect 2: no backend changes, no pyplot ------------------------------------------------------------
def test_no_matplotlib_use_in_the_package():
    offenders = [str(p.relative_to(REPO)) for p in (REPO / "brdffit").rglob("*.py")
                 if "matplotlib.use(" in p.read_text() or "import matplotlib.pyplot" in p.read_text()]
    assert offenders == []


def test_figures_keep_the_callers_backend(tmp_path):
    """Every public figure path (plot functions, Report.plot, the CLI's fit figure) in a process
    whose backend is 'svg': afterwards it is still 'svg'."""
    code = f"""
import matplotlib
matplotlib.use("svg")
import numpy as np, sys
sys.path.insert(0, {str(REPO / 'tests')!r})
from test_plot import measurement, fit_result
import brdffit.plot as bp
from brdffit.fitting.compare import Report
m, r = measurement(), fit_result()
rows = tuple(dict(model="ggx", solver=s, loss="log", loss_log=1e-3 * (1 + k), run_s=0.1 + k, converged=True)
             for k, s in enumerate(("lm", "scipy")))
for fig in (bp.table(m), bp.compare_table(m, r), bp.slices(m, r), bp.fit_figure(m, r), Report(rows, "x").plot(),
            bp.spheres(np.zeros((2, 8, 8, 3)), np.radians([(0, 0), (30, 0)]))):
    fig.savefig({str(tmp_path)!r} + "/f.png")
assert matplotlib.get_backend() == "svg", matplotlib.get_backend()
assert "matplotlib.pyplot" not in sys.modules
print("ok")
"""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0 and "ok" in run.stdout, run.stderr[-3000:]


def test_figures_show_themselves_in_jupyter():
    fig = bp.table(measurement())
    assert fig._repr_png_().startswith(b"\x89PNG")


def _zlib_level_class(png: bytes) -> int:
    """FLEVEL of the first IDAT chunk's zlib header (RFC 1950): 0 fastest, 1 fast (levels 2-5),
    2 default (6), 3 maximum (7-9)."""
    import struct

    pos = 8  # after the signature
    while pos < len(png):
        length, kind = struct.unpack(">I4s", png[pos:pos + 8])
        if kind == b"IDAT":
            return png[pos + 9] >> 6  # second byte of the zlib stream: FLG
        pos += 12 + length
    raise AssertionError("no IDAT chunk")


def test_figures_write_pngs_at_the_documented_compression_and_other_formats_unchanged(tmp_path):
    import io

    fig = bp.table(measurement())
    fig.savefig(tmp_path / "t.png", dpi=30)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=30)
    assert bp.PNG_COMPRESS_LEVEL == 3
    assert _zlib_level_class((tmp_path / "t.png").read_bytes()) == _zlib_level_class(buf.getvalue()) == 1
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=30, pil_kwargs={"compress_level": 9})  # the caller's choice wins
    assert _zlib_level_class(buf.getvalue()) == 3
    fig.savefig(tmp_path / "t.pdf")  # no PNG options passed to another backend
    assert (tmp_path / "t.pdf").read_bytes().startswith(b"%PDF")


def test_btf_figures_come_from_brdffit_plot():
    """The BTF displays are brdffit figures (Jupyter PNG, the figures' PNG settings): the maps,
    RGB as previews with their scale in the title and scalar maps with a colour bar; the
    validation panel, one row per pair with its metrics."""
    import types

    rgb = np.full((4, 5, 3), 0.5)
    maps = types.SimpleNamespace(maps=lambda: {"kd": rgb, "alpha": np.linspace(0.1, 0.3, 20).reshape(4, 5, 1)},
                                 model="ggx", shape=(4, 5), converged=np.ones((4, 5), bool))
    fig = bp.parameter_maps(maps)
    assert isinstance(fig, bp.Figure) and fig._suptitle.get_text() == "ggx: 4 x 5 texels, 20 converged"
    assert [ax.get_title() for ax in fig.axes if ax.get_images()] == ["kd (RGB, /0.5)", "alpha"]
    assert len(fig.axes) == 3  # alpha's colour bar
    photos = np.full((2, 6, 6, 3), 0.2)
    fig = bp.btf_panel(photos, photos * 1.1, ["pair a", "pair b"], [{"psnr": 30.04, "flip": 0.0123}] * 2)
    assert isinstance(fig, bp.Figure) and fig._repr_png_().startswith(b"\x89PNG")
    titles = [ax.get_title() for ax in fig.axes if ax.get_images()]
    assert titles[:3] == ["BTF photograph\npair a", "render of the maps\npair a",
                          "|error| / exposure level\npsnr 30.0 dB, flip 0.012"] and len(titles) == 6
