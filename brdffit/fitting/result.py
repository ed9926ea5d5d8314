"""`FitResult` (docs/fitting.md#fitting): what a fit found, how well, how fast, and whether it converged.

A FitResult is data: its fields, its JSON (``to_json`` / ``from_json``) and ``eval`` (the fitted
model's f_r). What other layers do with a fit are their functions: :func:`brdffit.materials.export`
and :func:`brdffit.materials.convert` (material files, native models), :func:`brdffit.mitsuba_bsdf`
(a Mitsuba BSDF), :mod:`brdffit.plot` (figures). The class keeps thin doors to them (``export``,
``convert``, ``to_mitsuba``, ``_repr_png_``), each importing what it calls where the import checks see
it, which is why this module's layer stands above the material files, the renderers and the figures
(``[tool.importlinter]`` in pyproject.toml). The fit driver, in the engine below them, makes
FitResults without importing this class: its callers name the type (``result_type``).
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._fit_defaults import STATUS_TEXT
from ..errors import InputError
from ..models.base import Model
from .fitfile import METRIC_ALIASES, check_fit_document, parse_fit_text

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


FORMAT = "brdffit.fit/1"


def _metrics(recorded: dict) -> dict[str, float]:
    """A fit file's metrics, an old name read as today's (``fitfile.METRIC_ALIASES``) unless both
    are present."""
    out = {k: _float(v) for k, v in recorded.items() if METRIC_ALIASES.get(k) not in recorded}
    return {METRIC_ALIASES.get(k, k): v for k, v in out.items()}


def _float(x) -> float:
    """A number of a fit file; null (what strict JSON writes for NaN and inf) is NaN."""
    return float("nan") if x is None else float(x)


def _at_bound(recorded: dict) -> dict[str, str]:
    """A fit file's ``at_bound`` (checked by ``fitfile``): text as it is; per-channel flags (a list of
    booleans) as the text they stand for, a side not being recorded ("on a bound in channel 2")."""
    out = {}
    for name, v in recorded.items():
        if isinstance(v, str):
            out[name] = v
        elif any(v):
            on = [str(i) for i, flag in enumerate(v) if flag]
            out[name] = "on a bound" if len(on) == len(v) else \
                f"on a bound in channel{'s' if len(on) > 1 else ''} {', '.join(on)}"
    return out


def _code_of(status: str, converged: bool) -> int:
    """The status code a status text stands for (0 for any converged text, 4 for one unknown)."""
    if converged:
        return 0
    return next((code for code, text in STATUS_TEXT.items() if code and text == status), 4)


def _floats(a) -> list[float]:
    return [float(x) for x in np.asarray(a, dtype=np.float64).reshape(-1)]


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult:
    """One fit. ``params`` maps the model's parameter names (docs/models.md#models) to numpy arrays of shape (size,)."""

    model: Model
    params: dict[str, np.ndarray]
    loss: str
    loss_value: float
    #: The fit's loss (under its name, evaluated afresh at the result), "rmse", "log_rmse",
    #: "rel_rmse", "mean_rel_error", "max_abs_error" (over the used samples, equally weighted).
    #: Other losses' values: ``brdffit.fitting.losses.evaluate`` (what ``compare`` reports). A
    #: converted fit's (``convert``) are against the source fit's BRDF, not against data.
    metrics: dict[str, float]
    steps: int
    converged: bool
    status: str
    #: "compile" (XLA compilation, 0 when a cached solver served this shape), "run" (work after
    #: compilation), "init" (the part of compile + run spent on the start grid).
    seconds: dict[str, float]
    solver: str
    data_name: str
    n_used: int
    n_excluded: int
    excluded: dict[str, int] = dataclasses.field(default_factory=dict)
    stderr: dict[str, np.ndarray | None] = dataclasses.field(default_factory=dict)
    start: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    options: dict[str, Any] = dataclasses.field(default_factory=dict)
    #: Parameters that ended on a bound of the fit's space: name -> "lower" / "upper", or per
    #: channel ("lower in channel 0"). Fixed parameters are not listed.
    at_bound: dict[str, str] = dataclasses.field(default_factory=dict)
    #: One sentence each: a parameter on a bound, a lobe narrower than the sample spacing, a
    #: parameter the data do not determine (``brdffit.fitting.space.fit_warnings``).
    warnings: tuple[str, ...] = ()
    #: The status as a code (``brdffit._fit_defaults.STATUS_TEXT``: 0 converged, 1 out of steps,
    #: 2 diverged, 3 non-finite, 4 solver failed), beside ``status``'s text. None given: read
    #: from ``status`` (fit files written before the code was recorded).
    status_code: int | None = None

    def __post_init__(self):
        if self.status_code is None:
            object.__setattr__(self, "status_code", _code_of(self.status, self.converged))

    @property
    def model_name(self) -> str:
        return self.model.name

    @property
    def channels(self) -> int:
        return self.model.channels

    @property
    def n_params(self) -> int:
        return self.model.n_free

    def eval(
        self, wi: Float[np.ndarray, "N 3"] | Float[np.ndarray, "3"], wo: Float[np.ndarray, "N 3"] | Float[np.ndarray, "3"]
    ) -> Float[np.ndarray, "N C"] | Float[np.ndarray, " C"]:
        """f_r of the fitted model as a NumPy array (docs/fitting.md#fitting): (N, 3) directions give (N, C), a single
        (3,) pair gives (C,), a (3,) direction against (N, 3) others is broadcast. Directions below
        the horizon (z <= 0 for either) give 0. ``self.model.eval`` is the differentiable JAX form
        ((N, 3) only, JAX arrays, no horizon test): use it inside ``jax.grad`` / ``jit``."""
        wi = np.asarray(wi, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        if wi.shape[-1:] != (3,) or wo.shape[-1:] != (3,) or wi.ndim > 2 or wo.ndim > 2:
            from ..errors import UsageError

            raise UsageError(f"FitResult.eval needs directions of shape (3,) or (N, 3); got {wi.shape} and {wo.shape}")
        single = wi.ndim == 1 and wo.ndim == 1
        wi2, wo2 = np.broadcast_arrays(np.atleast_2d(wi), np.atleast_2d(wo))
        from .model_eval import eval_model  # JAX's compilation: not needed to read a fit file

        f = eval_model(self.model, self.params, wi2, wo2)
        f[(wi2[:, 2] <= 0) | (wo2[:, 2] <= 0)] = 0.0
        return f[0] if single else f

    # -- Jupyter --------------------------------------------------------------------------------------
    def _repr_png_(self) -> bytes:
        """The fitted model on the UBO-81 grid (:func:`brdffit.plot.table`)."""
        from ..plot import png_bytes, table

        return png_bytes(table(self))

    def _repr_html_(self) -> str:
        import base64
        import html

        rows = "".join(
            f"<tr><td>{html.escape(k)}</td><td>{html.escape(np.array2string(np.asarray(v), precision=4))}</td>"
            f"<td>{'' if self.stderr.get(k) is None else html.escape(np.array2string(np.asarray(self.stderr[k]), precision=2))}</td></tr>"
            for k, v in self.params.items()
        )
        metrics = ", ".join(f"{k} {v:.4g}" for k, v in self.metrics.items() if k in ("rmse", "log_rmse", "rel_rmse"))
        metrics += self._against()
        colour = "green" if self.converged else "red"
        img = base64.b64encode(self._repr_png_()).decode()
        return (
            f"<p><b>{html.escape(self.model.name)}</b> fit of <b>{html.escape(self.data_name)}</b> "
            f"({html.escape(self.solver)}, {html.escape(self.loss)} loss): "
            f"<span style='color:{colour}'>{html.escape(self.status)}</span>, {self.steps} steps, "
            f"{self.seconds.get('run', 0.0):.3g} s run + {self.seconds.get('compile', 0.0):.3g} s compile<br>"
            f"{html.escape(metrics)}</p>"
            f"<table><tr><th>parameter</th><th>value</th><th>std. error</th></tr>{rows}</table>"
            f"<img src='data:image/png;base64,{img}'/>"
        )

    def to_mitsuba(self) -> dict:
        """A BSDF dict for ``mi.load_dict`` that renders this fit in any Mitsuba 3 scene (docs/materials.md#a-fit-in-any-mitsuba-scene):
        :func:`brdffit.mitsuba_bsdf` of this fit (for a ``mitsuba:*`` fit Mitsuba's own plugin,
        otherwise the ``brdffit`` plugin with the same JAX formula)."""
        from ..render.export import mitsuba_bsdf

        return mitsuba_bsdf(self)

    def convert(self, model: str | Model, **options) -> "FitResult":
        """This fit as ``model`` (a native model: ``mitsuba:roughplastic``, ``gltf:metallic_roughness``,
        ...): ``model`` fitted to this fit's BRDF on the UBO-81 grid, the conversion error in
        ``options["converted_from"]`` (docs/materials.md#native-materials-and-exports; :func:`brdffit.materials.convert`)."""
        from ..materials import convert

        return convert(self, getattr(model, "name", model), **options)

    def export(self, path: str | os.PathLike, to: str | Model | None = None, *, bsdf_id: str | None = None,
               force: bool = False) -> "FitResult":
        """Write this fit as a material file, the extension picking the format: ``.xml`` Mitsuba 3,
        ``.glb``/``.gltf`` glTF 2.0, ``.blend`` Blender, ``.mtlx`` MaterialX (docs/materials.md#native-materials-and-exports;
        :func:`brdffit.materials.export`). With ``to``, the fit is converted first; returns the fit
        written. ``bsdf_id`` is held to the CLI's ``--id`` rule (letters, digits, '_', not starting with
        a digit; else UsageError); default: the file's name made so."""
        from ..materials import export

        return export(self, path, to=None if to is None else getattr(to, "name", to), bsdf_id=bsdf_id, force=force)

    # -- JSON -------------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "model": self.model.name,
            "channels": self.model.channels,
            "params": {k: _floats(v) for k, v in self.params.items()},
            "loss": self.loss,
            "loss_value": float(self.loss_value),
            "metrics": {k: float(v) for k, v in self.metrics.items()},
            "steps": int(self.steps),
            "converged": bool(self.converged),
            "status": self.status,
            "status_code": int(self.status_code),
            "seconds": {k: float(v) for k, v in self.seconds.items()},
            "solver": self.solver,
            "data_name": self.data_name,
            "n_used": int(self.n_used),
            "n_excluded": int(self.n_excluded),
            "excluded": {k: int(v) for k, v in self.excluded.items()},
            "stderr": {k: (None if v is None else _floats(v)) for k, v in self.stderr.items()},
            "start": {k: _floats(v) for k, v in self.start.items()},
            "options": self.options,
            "at_bound": dict(self.at_bound),
            "warnings": list(self.warnings),
            "citation": self.model.citation,
        }

    def to_json(self, path: str | os.PathLike | None = None, indent: int = 2) -> str:
        """Strict JSON text (floats written with full precision: the round trip is exact; a number
        that is not finite, a diverged fit's loss or metric, is written null and read back as NaN)."""
        from .._files import json_text

        text = json_text(self.to_dict(), indent=indent)
        if path is not None:
            Path(path).write_text(text + "\n")
        return text

    @classmethod
    def from_json(cls, source: str | os.PathLike) -> "FitResult":
        """From JSON text or a path to a fit.json file."""
        path = None
        text = source
        if isinstance(source, os.PathLike) or (isinstance(source, str) and not source.lstrip().startswith("{")):
            from .._files import read_input

            path = Path(source)
            text = read_input(path, "a fit file (JSON)")
        d = parse_fit_text(text, path)
        return cls.from_dict(d, path=path)

    @classmethod
    def from_dict(cls, d: dict[str, Any], path=None) -> "FitResult":
        model = check_fit_document(d, path)  # every field checked: bad files are one line, not a crash later
        params = d["params"]
        try:
            checked = model.check_params({k: np.asarray(v, dtype=np.float64) for k, v in params.items()})
        except ValueError as exc:
            raise InputError(path, str(exc)) from None
        return cls(
            model=model,
            params={k: np.asarray(v, dtype=np.float64) for k, v in checked.items()},
            loss=d.get("loss", ""),
            loss_value=_float(d.get("loss_value")),
            metrics=_metrics(d.get("metrics", {})),
            steps=int(d.get("steps", 0)),
            converged=bool(d.get("converged", False)),
            status=str(d.get("status", "")),
            status_code=None if d.get("status_code") is None else int(d["status_code"]),
            seconds={k: _float(v) for k, v in d.get("seconds", {}).items()},
            solver=str(d.get("solver", "")),
            data_name=str(d.get("data_name", "")),
            n_used=int(d.get("n_used", 0)),
            n_excluded=int(d.get("n_excluded", 0)),
            excluded={k: int(v) for k, v in d.get("excluded", {}).items()},
            stderr={k: (None if v is None else np.asarray(v, dtype=np.float64)) for k, v in d.get("stderr", {}).items()},
            start={k: np.asarray(v, dtype=np.float64) for k, v in d.get("start", {}).items()},
            options=dict(d.get("options", {})),
            # Absent from fit.json files written before they existed: none recorded.
            at_bound=_at_bound(d.get("at_bound") or {}),
            warnings=tuple(str(w) for w in (d.get("warnings") or ())),
        )

    def _against(self) -> str:
        """" against the SOURCE fit" for a converted fit (its loss and metrics measure the conversion,
        not the data: ``brdffit.materials.convert``), else ""."""
        c = self.options.get("converted_from") if isinstance(self.options, dict) else None
        return f" against the {c.get('model')} fit" if isinstance(c, dict) else ""

    def __repr__(self) -> str:
        ps = ", ".join(f"{k}={np.array2string(np.asarray(v), precision=4)}" for k, v in self.params.items())
        return (
            f"FitResult({self.model.name} on {self.data_name!r}: {ps}; {self.loss}={self.loss_value:.4g}"
            f"{self._against()}, {self.status}, {self.steps} steps, {self.solver})"
        )
