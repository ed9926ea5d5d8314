"""brdffit.explore driven from Python, as its widget's front end drives it: a slider moved (the
state's loss, rel_rmse and images follow, checked against values computed here in NumPy), Fit
(the same result as brdffit.fit from the values shown), a change of model and of light, the
front end's messages, Export, and figure(). The browser test (test_explore_browser.py) drives the
same widget in JupyterLab."""

from __future__ import annotations

import io

import numpy as np
import pytest

import brdffit
from brdffit.errors import InputError, UsageError
from brdffit.grid import ubo_angles_deg

pytest.importorskip("anywidget", reason="anywidget (the test extra) is not installed")

from PIL import Image  # noqa: E402

from brdffit.explorer.lighting import sphere_directions  # noqa: E402
from brdffit.plot.explorer import TABLE_ZOOM  # noqa: E402

SAMPLE = "data/sample_ubo81.exr"


@pytest.fixture(scope="module")
def m():
    return brdffit.load(SAMPLE)


@pytest.fixture
def explorer(m):
    return brdffit.explore(m)


def rgb(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def by_hand(m, model: str, params: dict):
    """(log loss, rel_rmse, f (6561, C)) of ``model`` at ``params`` on the sample, in NumPy: the
    model's own JAX formula, the docs/fitting.md#fitting definitions written out (every sample weighs 1)."""
    f = np.asarray(brdffit.models.get(model).eval(params, np.asarray(m.wi), np.asarray(m.wo)))
    ref = np.asarray(m.values, np.float64)
    used = m.valid_mask()
    cos = np.asarray(m.wi)[:, 2:3]
    r = np.log1p(f * cos) - np.log1p(ref * cos)
    loss = np.mean(r[used] ** 2)
    rel = np.sqrt(np.sum((f - ref)[used] ** 2) / np.sum(ref[used] ** 2))
    return loss, rel, f


# -- a slider ---------------------------------------------------------------------------------------
def test_a_parameter_change_shows_the_loss_and_images_of_the_new_values(explorer, m):
    before = explorer.state
    explorer.set_params(alpha=0.05, ks=[0.9, 0.8, 0.7])
    after = explorer.state
    params = {**before["params"], "alpha": [0.05], "ks": [0.9, 0.8, 0.7]}
    assert after["params"] == params
    loss, rel, f = by_hand(m, "ggx", params)
    np.testing.assert_allclose(after["loss"], loss, rtol=1e-9)
    np.testing.assert_allclose(after["rel_rmse"], rel, rtol=1e-9)
    assert after["loss_name"] == "log" and after["status"] == "set by hand"
    for name in ("fitted", "log_ratio", "slices", "sphere_fit"):
        assert after["images"][name] != before["images"][name], name
    for name in ("measured", "sphere_measured"):
        assert after["images"][name] == before["images"][name], name
    # the fitted table's pixels: log(f) from the measured data's range to [0, 255] (1st percentile of
    # the positive used values to the largest), per channel, the samples a fit leaves out magenta
    used = m.valid_mask()
    ref = np.asarray(m.values)[used]
    lo, hi = np.percentile(ref[ref > 0], 1), ref.max()
    want = np.clip((np.log(np.clip(f, lo, hi)) - np.log(lo)) / (np.log(hi) - np.log(lo)), 0, 1) * 255
    want[~used] = (255, 0, 255)
    shown = rgb(after["images"]["fitted"])[1::TABLE_ZOOM, 1::TABLE_ZOOM].reshape(-1, 3)
    np.testing.assert_allclose(shown, want, atol=0.51)


def test_bad_values_are_refused_with_one_line(explorer):
    with pytest.raises(UsageError, match="no parameter 'roughness'; it has kd, ks, alpha, f0"):
        explorer.set_params(roughness=0.2)
    with pytest.raises(UsageError, match=r"f0 = \[1.5\] is outside its bounds \[0, 1\]"):
        explorer.set_params(f0=1.5)
    with pytest.raises(UsageError, match="light theta must be in degrees in"):
        explorer.light = (90, 0)
    with pytest.raises(UsageError, match="unknown model"):
        explorer.model = "gxx"
    assert explorer.state["params"]["f0"] == [0.04]


def test_the_sliders_span_the_bounds_and_move_logarithmically_for_roughness(explorer):
    sliders = {(s["param"], s["index"]): s for s in explorer._sliders}
    assert len(sliders) == 8  # kd and ks per channel, alpha, f0
    assert sliders["alpha", 0]["log"] and not sliders["f0", 0]["log"] and not sliders["kd", 1]["log"]
    assert (sliders["alpha", 0]["lo"], sliders["alpha", 0]["hi"]) == (1e-4, 1.0)  # bounds, the physical range for inf
    assert (sliders["f0", 0]["lo"], sliders["f0", 0]["hi"]) == (0.0, 1.0)
    explorer.set_params(ks=3.0)  # above the physical range on an open side: the slider grows to hold it
    assert {(s["param"], s["hi"]) for s in explorer._sliders if s["param"] == "ks"} == {("ks", 4.5)}


# -- Fit --------------------------------------------------------------------------------------------
def test_fit_is_brdffit_fit_from_the_values_shown(explorer, m):
    explorer.set_params(alpha=0.3, kd=0.2)
    start = explorer.params
    result = explorer.fit()
    same = brdffit.fit(m, "ggx", init=start)
    for name, value in same.params.items():
        np.testing.assert_array_equal(result.params[name], value)
        np.testing.assert_array_equal(explorer.params[name], value)  # the sliders moved to the result
    state = explorer.state
    np.testing.assert_allclose(state["loss"], same.loss_value, rtol=1e-9)
    np.testing.assert_allclose(state["rel_rmse"], same.metrics["rel_rmse"], rtol=1e-9)
    assert state["status"] == "lm fit: converged" and state["warnings"] == list(same.warnings)
    assert explorer.result is result
    explorer.set_params(alpha=0.1)
    assert explorer.state["status"] == "set by hand" and explorer.state["warnings"] == []


def test_multistart_is_brdffit_fit_from_its_start_grid(explorer, m):
    explorer.set_params(alpha=0.9)  # not a start of the grid's
    explorer._on_action(explorer, {"action": "multistart"}, [])
    same = brdffit.fit(m, "ggx", multistart=8)
    for name, value in same.params.items():
        np.testing.assert_array_equal(explorer.params[name], value)
    assert explorer.result.options == same.options


def test_an_explorer_can_start_from_a_fit_file(m, tmp_path):
    r = brdffit.fit(m, "lambert+ggx")
    r.to_json(tmp_path / "fit.json")
    e = brdffit.explore(SAMPLE, model="phong", fit=tmp_path / "fit.json")
    assert e.model == "lambert+ggx" and e.state["status"] == "lm fit: converged"
    np.testing.assert_allclose(e.state["loss"], r.loss_value, rtol=1e-9)
    with pytest.raises(UsageError, match="fit must be a FitResult or a fit.json path"):
        brdffit.explore(m, fit=42)
    with pytest.raises(InputError, match="no such file"):
        brdffit.explore(tmp_path / "missing.exr")


# -- model and light --------------------------------------------------------------------------------
def test_a_change_of_model_keeps_the_parameters_it_shares(explorer, m):
    explorer.set_params(kd=[0.3, 0.2, 0.1])
    explorer.model = "lambert+ggx"
    mdl = brdffit.models.get("lambert+ggx")
    assert explorer.model == "lambert+ggx" and explorer.state["model"] == "lambert+ggx"
    assert list(explorer.params) == list(mdl.param_names)
    assert explorer.state["params"]["kd"] == [0.3, 0.2, 0.1]
    defaults = mdl.defaults()
    for name in mdl.param_names[1:]:
        np.testing.assert_array_equal(explorer.params[name], np.asarray(defaults[name]))
    loss, _, _ = by_hand(m, "lambert+ggx", explorer.state["params"])
    np.testing.assert_allclose(explorer.state["loss"], loss, rtol=1e-9)
    assert len(explorer._sliders) == mdl.n_free


def test_the_light_moves_the_slices_the_spheres_and_the_table_marker(explorer):
    before = explorer.state
    explorer.light = (60, 90)
    after = explorer.state
    assert after["light"] == (60.0, 90.0)
    # by hand: the 60-degree ring starts at 1 + 6 + 12 + 18 = 37, phi steps 18: phi 90 is its 6th
    assert explorer._info["light_row"] == 37 + 5
    for name in ("slices", "sphere_measured", "sphere_fit"):
        assert after["images"][name] != before["images"][name], name
    for name in ("measured", "fitted", "log_ratio"):
        assert after["images"][name] == before["images"][name], name
    assert after["loss"] == before["loss"]  # the loss is over the whole table, whatever the light
    explorer.light = (30, 400)  # phi is taken modulo 360
    assert explorer.light == (30.0, 40.0)


def test_exposure_brightens_the_spheres_by_stops(explorer):
    dark = explorer.state
    explorer.exposure = 1.0
    bright = explorer.state
    for name in ("measured", "fitted", "log_ratio", "slices"):
        assert bright["images"][name] == dark["images"][name], name
    # one stop: twice the linear value before the sRGB curve (compared where neither clips)
    a, b = (rgb(x["images"]["sphere_measured"]).astype(float) / 255 for x in (dark, bright))

    def linear(v):
        return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)

    ok = (a > 0.2) & (b < 0.9)
    assert ok.sum() > 1000
    np.testing.assert_allclose(linear(b[ok]), 2 * linear(a[ok]), rtol=0.03, atol=0.004)


def test_the_sphere_preview_is_the_validation_sphere_at_the_pixel_centres(explorer):
    """Against the docs/validation.md#validation-rendering shading written out here (tests/test_render_sphere.py's closed form at the
    pixel centres): frame s = (z, 0, -x)/|.|, t = n x s, radiance f_r (n . l); an anisotropic
    model, so that a wrong tangent shows."""
    explorer.model = "ward"
    explorer.set_params(alpha_x=0.08, alpha_y=0.4)
    explorer.light = (40, 30)
    size = 128
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    x, y = np.meshgrid(c, -c)
    on = x * x + y * y < 1
    n = np.stack([x[on], y[on], np.sqrt(1 - x[on] ** 2 - y[on] ** 2)], -1)
    s = np.stack([n[:, 2], np.zeros(len(n)), -n[:, 0]], -1)
    s /= np.linalg.norm(s, axis=1, keepdims=True)
    t = np.cross(n, s)
    t_l, p_l = np.radians(40), np.radians(30)
    light = np.array([np.sin(t_l) * np.cos(p_l), np.sin(t_l) * np.sin(p_l), np.cos(t_l)])
    v = np.array([0.0, 0.0, 1.0])
    wi = np.stack([s @ light, t @ light, n @ light], -1)
    wo = np.stack([s @ v, t @ v, n @ v], -1)
    lit = n @ light > 0
    f = np.asarray(brdffit.models.get("ward").eval(explorer.params, wi[lit], wo[lit]))
    want = np.zeros((size, size, 3))
    rows, cols = np.nonzero(on)
    want[rows[lit], cols[lit]] = f * (n @ light)[lit, None]
    np.testing.assert_allclose(explorer._view.sphere_fit, want, rtol=1e-9, atol=1e-12)
    d = sphere_directions(light, size)
    assert d.pixels.size == np.count_nonzero(lit)


# -- the front end's messages ---------------------------------------------------------------------------
def test_the_front_end_s_changes_and_actions(explorer, tmp_path):
    frame = explorer._info["frame"]
    params = {k: list(v) for k, v in explorer.state["params"].items()}
    params["alpha"] = [2e-4]
    params["f0"] = [1.0000001]  # a slider's end a rounding step outside: put inside the bounds
    explorer._params = params  # as the widget's sync sets it
    assert explorer._info["frame"] == frame + 1
    assert explorer.state["params"]["alpha"] == [2e-4] and explorer.state["params"]["f0"] == [1.0]
    explorer._light = [15.0, 60.0]
    assert explorer.light == (15.0, 60.0) and explorer._info["light_row"] == 2
    explorer._on_action(explorer, {"action": "light_row", "row": 80}, [])
    assert explorer.light == tuple(ubo_angles_deg()[80])
    target = tmp_path / "paint.xml"
    explorer._on_action(explorer, {"action": "export", "path": str(target)}, [])
    assert explorer._info["error"] and "not a fit's result: Fit first" in explorer._info["message"]
    assert not target.exists()
    explorer._on_action(explorer, {"action": "fit"}, [])
    assert "fit: converged" in explorer._info["message"] and explorer.state["status"] == "lm fit: converged"
    explorer._on_action(explorer, {"action": "export", "path": str(target), "to": "mitsuba:roughplastic"}, [])
    assert not explorer._info["error"], explorer._info["message"]
    assert "converged" not in explorer._info["message"]  # the fit's message was shown once, then this one
    assert "converted ggx -> mitsuba:roughplastic: rel_rmse" in explorer._info["message"]
    assert 'type="roughplastic"' in target.read_text()
    explorer._on_action(explorer, {"action": "export", "path": str(target)}, [])
    assert explorer._info["error"] and "exists" in explorer._info["message"]
    explorer._on_action(explorer, {"action": "undo"}, [])
    assert explorer._info["error"] and explorer._info["message"] == "undo: unknown action 'undo'"


def test_compare_shows_error_against_run_time(explorer):
    report = explorer.compare(["lambert", "ggx"])
    assert [r["model"] for r in report.rows] == ["lambert", "ggx"]
    png = explorer.state["images"]["pareto"]
    assert png.startswith(b"\x89PNG") and rgb(png).shape[1] > 500
    assert "compare: best ggx / lm" in explorer._info["message"]


# -- figure() -------------------------------------------------------------------------------------
def test_figure_shows_the_same_view(explorer):
    explorer.set_params(alpha=0.1)
    explorer.light = (45, 0)
    fig = explorer.figure()
    titles = [ax.get_title() for ax in fig.axes]
    assert "measured: sample_two_lobe" in titles and "model: ggx" in titles
    assert {"R, in-plane", "G, in-plane", "B, in-plane", "R, cross-plane"} <= set(titles)
    model_table = [ax for ax in fig.axes if ax.get_title() == "model: ggx"][0]
    live = rgb(explorer.state["images"]["fitted"])[1::TABLE_ZOOM, 1::TABLE_ZOOM] / 255
    np.testing.assert_allclose(model_table.get_images()[0].get_array(), live, atol=0.51 / 255)
    # the in-plane curve of a GGX lobe peaks on the mirror side at the light's angle
    ax = [a for a in fig.axes if a.get_title() == "R, in-plane"][0]
    curve = [line for line in ax.get_lines() if line.get_label() == "fit"][0]
    s, f = np.degrees(curve.get_xdata()), curve.get_ydata()
    assert 43 < s[np.argmax(f)] < 47
    text = "\n".join(t.get_text() for a in fig.axes for t in a.texts)
    assert f"log loss {explorer.state['loss']:.4g}" in text
    assert explorer._repr_png_().startswith(b"\x89PNG")


@pytest.mark.mitsuba
def test_render_shows_mitsuba_spheres_which_the_preview_matches(explorer):
    """Render: both spheres rendered by Mitsuba (brdffit.render_sphere) under the light, shown until
    the next change; the preview they replace agrees with them inside the disc (the preview takes
    each pixel's centre, a render averages its footprint: they differ at the silhouette)."""
    explorer.fit()
    explorer.light = (40, 30)
    preview = explorer.state
    previews = explorer._view.sphere_measured.copy(), explorer._view.sphere_fit.copy()
    rendered = explorer.render()
    state = explorer.state
    assert state["spheres"] == "Mitsuba" and "Mitsuba" in explorer._info["spheres"]
    for name in ("sphere_measured", "sphere_fit"):
        assert state["images"][name] != preview["images"][name], name
    c = (np.arange(128) + 0.5) * (2.0 / 128) - 1.0
    x, y = np.meshgrid(c, -c)
    inner = x * x + y * y < 0.9**2
    for mine, theirs in zip(previews, rendered):
        d = (mine - theirs)[inner]
        assert np.sqrt(np.mean(d**2)) < 0.01 * np.sqrt(np.mean(theirs[inner] ** 2))
    explorer.exposure = 1.0  # the renders stay under another exposure...
    assert explorer.state["spheres"] == "Mitsuba"
    explorer.set_params(alpha=0.2)  # ...and give way to the preview on a change of the view
    assert explorer.state["spheres"] == "preview"
