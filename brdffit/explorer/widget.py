"""The :class:`Explorer` widget: the Python side of ``brdffit.explore`` and the state its front end
(``explorer.js``, an anywidget module: JupyterLab, Notebook 7, VS Code) shows and changes.

The front end changes four synced traits (the model, the parameters, the light, the exposure) and
sends actions (fit, multistart, compare, export, render, a light picked on the table); the Python
methods of the same names do the same from code. After each change the view is computed again
(:mod:`.compute`), its images made (:class:`brdffit.plot.explorer.LiveImages`) and sent with the
numbers in one message; the front end sends its next change when that message has arrived, so a
dragged slider shows its latest position, not a queue of old ones.
"""

from __future__ import annotations

import base64
import contextlib
import time
from pathlib import Path

import anywidget
import numpy as np
import traitlets

from ..errors import InputError, UsageError
from ..grid import ubo_angles_deg
from ..measurement import Measurement
from . import controls
from .compute import Table, view
from .lighting import checked_light, lighting

HERE = Path(__file__).resolve().parent
#: The light the explorer starts with: (theta, phi) in degrees.
START_LIGHT = (45.0, 0.0)
#: Starts of the Multistart button (``brdffit.fit(..., multistart=)``: further grid starts).
MULTISTART = 8
#: Models the Compare button fits besides the one shown.
COMPARE_MODELS = ("lambert", "ggx", "lambert+ggx")


def _json_number(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def _model_names() -> list[str]:
    from .. import models

    return models.names()


class Explorer(anywidget.AnyWidget):
    """One measurement and its fits, interactively (docs/explorer.md#the-explorer). Made by :func:`brdffit.explore`.

    Python side: :attr:`params` / :meth:`set_params`, :attr:`model` (settable), :attr:`light`
    ((theta, phi) degrees, settable), :attr:`exposure` (stops, settable), :meth:`fit`,
    :meth:`multistart`, :meth:`compare`, :meth:`export`, :meth:`render` (Mitsuba), :attr:`state`,
    :meth:`figure`; :attr:`result` is the last fit. Bad values raise ``brdffit.UsageError``."""

    _esm = HERE / "explorer.js"
    _css = HERE / "explorer.css"

    # synced with the front end: it sets the first four, Python all of them
    _model = traitlets.Unicode("").tag(sync=True)
    _params = traitlets.Dict().tag(sync=True)  # name -> [values]
    _light = traitlets.List([*START_LIGHT]).tag(sync=True)  # (theta, phi) degrees
    _exposure = traitlets.Float(0.0).tag(sync=True)  # stops over the measured sphere's own exposure
    _models = traitlets.List().tag(sync=True)
    _sliders = traitlets.List().tag(sync=True)  # controls.Slider as dicts
    _images = traitlets.Dict().tag(sync=True)  # name -> base64 PNG
    _info = traitlets.Dict().tag(sync=True)  # the numbers and texts shown, and "frame": views sent so far

    def __init__(self, measurement: Measurement, model="ggx", fit=None):
        super().__init__()
        from ..fitting.problem import resolve_model

        self._table = Table.of(measurement)
        self._updating = False
        self._frame = 0
        self._message = ("", False)
        self._spheres = None  # Mitsuba renders (measured, model) of the view they were made for
        self._lit = None
        self.result = fit
        self.report = None
        self.timings: dict[str, float] = {}
        self._pngs: dict[str, bytes] = {}
        self._extra: dict[str, bytes] = {}  # images of actions: "pareto"
        from ..plot.explorer import LiveImages

        self._live = LiveImages(self._table.measured, self._table.valid)
        mdl = resolve_model(fit.model if fit is not None else model, measurement.n_channels)
        params = controls.checked(mdl, fit.params) if fit is not None else controls.carried(mdl, {})
        names = _model_names()
        with self._update():
            self._models = names if mdl.name in names else [*names, mdl.name]
            self._set_model(mdl, params)
        self.on_msg(self._on_action)
        self._refresh()

    # -- the Python side ---------------------------------------------------------------------------
    @property
    def model(self) -> str:
        return self._mdl.name

    @model.setter
    def model(self, name) -> None:
        from ..fitting.problem import resolve_model

        mdl = resolve_model(name, self._table.measurement.n_channels)  # UsageError naming the known ones
        with self._update():
            if mdl.name not in self._models:
                self._models = [*self._models, mdl.name]
            self._set_model(mdl, controls.carried(mdl, self.params))
        self._refresh()

    @property
    def params(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(v, np.float64) for k, v in self._params.items()}

    def set_params(self, **values) -> None:
        """Set parameters by name (a number, or one per channel); the others keep their values."""
        self._show_params(controls.with_values(self._mdl, self.params, values))

    @property
    def light(self) -> tuple[float, float]:
        """(theta, phi) of the light in degrees (the sphere's light; the slices and the table's
        marker use the measured light nearest to it)."""
        return tuple(float(x) for x in self._light)

    @light.setter
    def light(self, value) -> None:
        theta, phi = checked_light(value)
        with self._update():
            self._light = [theta, phi]
        self._refresh(light=True)

    @property
    def exposure(self) -> float:
        """Stops over the exposure of the measured sphere (99.5th percentile to 1, as validations)."""
        return float(self._exposure)

    @exposure.setter
    def exposure(self, stops: float) -> None:
        stops = float(stops)
        if not np.isfinite(stops):
            raise UsageError(f"exposure must be a finite number of stops, got {stops!r}")
        with self._update():
            self._exposure = stops
        self._refresh(keep_spheres=True)

    def fit(self, **options):
        """``brdffit.fit`` from the parameters shown (``init=``), with ``options``; the parameters
        move to the result, which is returned and kept in :attr:`result`."""
        from ..fitting.api import fit

        return self._fitted(fit(self._table.measurement, self._mdl, init=self.params, **options))

    def multistart(self, starts: int = MULTISTART, **options):
        """``brdffit.fit`` from its start grid with ``starts`` further starts (not from the values shown)."""
        from ..fitting.api import fit

        return self._fitted(fit(self._table.measurement, self._mdl, multistart=int(starts), **options))

    def compare(self, models=None, solvers=("lm",), **options):
        """``brdffit.compare`` of ``models`` (default: a few library models and the one shown):
        error against run time, shown as ``brdffit.plot.pareto``; the Report is returned and kept."""
        from ..fitting.compare import compare
        from ..plot import pareto, png_bytes

        models = list(models) if models else list(dict.fromkeys([*COMPARE_MODELS, self.model]))
        self.report = compare(self._table.measurement, models, list(solvers), **options)
        self._extra["pareto"] = png_bytes(pareto(self.report))
        best = self.report.best()
        self._message = (f"compare: best {best['model']} / {best['solver']} (log loss {best['loss_log']:.4g})", False)
        self._refresh()
        return self.report

    def export(self, path, to=None, *, force: bool = False):
        """Write the fit shown as a material file (:func:`brdffit.materials.export`: the extension picks the
        format; ``to`` converts to a native model first, the conversion error is shown). Needs the
        parameters shown to be a fit's: after moving a slider, fit first."""
        if self.result is None or not controls.same(controls.checked(self._mdl, self.result.params), self.params):
            raise UsageError("the parameters shown are not a fit's result: Fit first, then Export")
        from ..materials import conversion_line, export

        written = export(self.result, path, to=to, force=force)

        line = conversion_line(written)
        self._message = (f"exported {written.model.name} to {path}" + (f"; {line}" if line else ""), False)
        self._refresh()
        return written

    def render(self, size: int = 128, spp: int = 16):
        """Mitsuba renders (``brdffit.render_sphere``) of the measured table and of the model under
        the light, shown instead of the preview until the next change; returns (measured, model)."""
        from ..render.renderers import render_sphere

        light = [np.radians(self.light)]
        measured = render_sphere(self._table.measurement, light, size=size, spp=spp)[0]
        model = render_sphere((self._mdl.name, self.params), light, size=size, spp=spp)[0]
        self._spheres = (measured, model)
        self._refresh(keep_spheres=True)
        return measured, model

    @property
    def state(self) -> dict:
        """What is shown: model, params, loss (the fit's loss function, named by ``loss_name``),
        rel_rmse, log_rmse, light, exposure, warnings, and images (name -> the PNG bytes shown)."""
        v = self._view
        return {"model": self.model, "params": controls.as_lists(self.params), "loss": v.metrics[v.loss_name],
                "loss_name": v.loss_name, "rel_rmse": v.metrics["rel_rmse"], "log_rmse": v.metrics["log_rmse"],
                "light": self.light, "exposure": self.exposure, "status": v.status, "warnings": list(v.warnings),
                "spheres": v.sphere_kind, "images": {**self._pngs, **self._extra}}

    def figure(self):
        """The view as a matplotlib Figure (``brdffit.plot.explorer``)."""
        from ..plot.explorer import explorer

        return explorer(self._view)

    def _repr_png_(self) -> bytes:
        # the static picture where no widget front end runs (nbconvert, GitHub); a front end shows the widget
        from ..plot import png_bytes

        return png_bytes(self.figure())

    def __repr__(self) -> str:
        return f"Explorer({self.model} on {self._table.measurement.name!r}, light {self.light})"

    # -- internals ---------------------------------------------------------------------------------
    @contextlib.contextmanager
    def _update(self):
        """Traits set inside are not taken as the front end's changes (no view is computed for them)."""
        self._updating = True
        try:
            yield
        finally:
            self._updating = False

    def _set_model(self, mdl, params) -> None:
        self._mdl = mdl
        self._model = mdl.name
        self._sliders = [s.to_dict() for s in controls.sliders(mdl, params)]
        self._params = controls.as_lists(params)

    def _show_params(self, params) -> None:
        with self._update():
            self._sliders = [s.to_dict() for s in controls.sliders(self._mdl, params)]
            self._params = controls.as_lists(params)
        self._refresh()

    def _fitted(self, result):
        self.result = result
        self._message = (f"fit: {result.status}, {result.steps} steps, "
                         f"{result.seconds.get('run', 0) + result.seconds.get('compile', 0):.2f} s", not result.converged)
        self._show_params(controls.checked(self._mdl, result.params))
        return result

    def _status(self) -> tuple[str, tuple[str, ...]]:
        r = self.result
        if r is not None and r.model.name == self.model and controls.same(controls.checked(self._mdl, r.params),
                                                                          self.params):
            return f"{r.solver} fit: {r.status}", tuple(r.warnings)
        return "set by hand", ()

    def _refresh(self, light: bool = False, keep_spheres: bool = False) -> None:
        """Compute the view, make its images, send them with the numbers (one message)."""
        from ..render.metrics import exposure

        t0 = time.perf_counter()
        if light or self._lit is None:
            self._lit = lighting(self._table.measurement, self._table.interpolator, self.light)
        if not keep_spheres:
            self._spheres = None
        status, warnings = self._status()
        timings = {"lighting": time.perf_counter() - t0}
        scale = exposure(self._lit.sphere_measured) * 2.0 ** self.exposure
        loss = self.result.loss if self.result is not None else "log"
        self._view = view(self._table, self._mdl, self.params, self._lit, loss=loss, status=status,
                          warnings=warnings, spheres=self._spheres, scale=scale, timings=timings)
        t1 = time.perf_counter()
        self._pngs = self._live.images(self._view)
        t2 = time.perf_counter()
        self._frame += 1
        v = self._view
        message, error = self._message
        self._message = ("", False)
        with self.hold_sync():
            self._images = {k: base64.b64encode(b).decode("ascii") for k, b in {**self._pngs, **self._extra}.items()}
            self._info = {
                "frame": self._frame, "model": v.model_name, "data_name": v.data_name, "loss_name": v.loss_name,
                # JSON has no NaN or infinity: a non-finite number is shown as such from null
                **{k: _json_number(v.metrics[name]) for k, name in (("loss", v.loss_name), ("rel_rmse", "rel_rmse"),
                                                                    ("log_rmse", "log_rmse"))},
                "status": v.status, "warnings": list(v.warnings), "message": message, "error": error,
                "light_row": v.light_row, "slice_light": round(v.geometry.theta_light_deg, 1),
                "spheres": v.sphere_kind, "ms": round(1e3 * (time.perf_counter() - t0), 1),
                "native": [n for n in self._models if ":" in n]}
        self.timings = {**timings, "images": t2 - t1, "total": time.perf_counter() - t0}

    @traitlets.observe("_model", "_params", "_light", "_exposure")
    def _front_end_changed(self, change) -> None:
        if self._updating:
            return
        # the front end's values are trusted to be of the right kind, and put in range
        if change.name == "_model":
            from ..fitting.problem import resolve_model

            mdl = resolve_model(change.new, self._table.measurement.n_channels)
            with self._update():
                self._set_model(mdl, controls.carried(mdl, self.params))
        elif change.name == "_params":
            params = controls.clipped(self._mdl, change.new)
            with self._update():
                self._params = controls.as_lists(params)
        elif change.name == "_light":
            with self._update():
                self._light = list(checked_light(change.new))
        self._refresh(light=change.name == "_light", keep_spheres=change.name == "_exposure")

    def _on_action(self, _widget, content, _buffers) -> None:
        """A button of the front end: {"action": name, ...}."""
        action = content.get("action")
        try:
            if action == "fit":
                self.fit()
            elif action == "multistart":
                self.multistart()
            elif action == "compare":
                self.compare([m.strip() for m in str(content.get("models", "")).split(",") if m.strip()] or None)
            elif action == "export":
                self.export(content["path"], to=content.get("to") or None, force=bool(content.get("force")))
            elif action == "render":
                self.render()
            elif action == "light_row":
                theta, phi = ubo_angles_deg()[int(content["row"])]
                self.light = (theta, phi)
            else:  # a front end of another version
                raise UsageError(f"unknown action {action!r}")
        except (UsageError, InputError) as exc:
            self._message = (f"{action}: {exc}", True)
            self._refresh(keep_spheres=True)
        except Exception as exc:
            self._message = (f"{action}: internal error: {type(exc).__name__}: {exc}", True)
            self._refresh(keep_spheres=True)
            raise
