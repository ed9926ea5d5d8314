"""``brdffit.validate``: a fit against its reference, rendered under a sweep of lights (docs/validation.md#validation-rendering).

Written files (in ``out``, atomically: the folder appears complete or not at all):

- ``reference_tTT_pPPP.exr``, ``fit_tTT_pPPP.exr``: linear radiance per light (theta, phi of the
  light in integer degrees), 32-bit float RGB OpenEXR.
- ``panel_tTT_pPPP.png``: reference | fit | signed error per channel (R, G, B) with a colour bar,
  per light (:func:`brdffit.plot.sphere_panel`).
- ``table.png``: the 81x81 UBO tables, measured | fitted | log residual per channel
  (:func:`brdffit.plot.compare_table`); ``table_reference.exr`` and
  ``table_fit.exr``: the two tables (rows light, columns view, f_r in 1/sr; entries a measured
  table marks invalid are NaN in the reference table and left out of the table metrics).
- ``metrics.json``: rmse, rel_rmse, psnr, flip per light and overall (see
  :mod:`brdffit.render.metrics`), the table metrics, the settings and where the time went.
"""

from __future__ import annotations

import contextlib
import dataclasses
from pathlib import Path

import numpy as np

from .outputs import ValidationRun
from ..grid import ubo_pairs
from .bsdf import Source, as_source, import_native
from .renderers import get as get_renderer, render_sphere
from .scene import DEFAULT_SPP, disc_mask, light_directions

#: Default light sweep: (theta, phi) in degrees, from the camera direction to grazing.
DEFAULT_LIGHTS_DEG = ((0, 0), (20, 45), (40, 135), (60, 225), (75, 315))


def default_lights(n: int = 5) -> np.ndarray:
    """``n`` light (theta, phi) pairs in radians: theta evenly 0..75 degrees, phi turning by 90."""
    if n < 1:
        raise ValueError("the number of lights must be >= 1")
    if n == 5:
        deg = np.asarray(DEFAULT_LIGHTS_DEG, np.float64)
    else:
        theta = np.round(np.linspace(0, 75, n)) if n > 1 else np.array([45.0])
        phi = np.where(theta > 0, (45 + 90 * np.arange(n) - 90) % 360, 0)
        deg = np.stack([theta, phi], -1)
    return np.deg2rad(deg)


@dataclasses.dataclass(frozen=True, eq=False)
class Validation:
    """The result of :func:`validate`."""

    lights: np.ndarray  # (L, 3) world directions towards the lights
    reference: np.ndarray  # (L, size, size, 3) linear radiance
    fit: np.ndarray  # (L, size, size, 3)
    table_reference: np.ndarray  # (81, 81, 3) f_r, 1/sr
    table_fit: np.ndarray  # (81, 81, 3)
    metrics: dict  # "lights": [per light], "overall": {...}, "table": {...}
    files: tuple[Path, ...]
    seconds: dict[str, float]

    def __repr__(self) -> str:
        o = self.metrics["overall"]
        return (
            f"Validation({len(self.lights)} lights, {self.reference.shape[1]} px: rmse {o['rmse']:.4g}, "
            f"psnr {o['psnr']:.1f} dB, flip {o['flip']:.3f}; {len(self.files)} files)"
        )

    def _repr_png_(self) -> bytes:
        """Reference and fit spheres under every light (:func:`brdffit.plot.spheres`)."""
        from ..plot import png_bytes, spheres

        return png_bytes(spheres(self))

    def _repr_html_(self) -> str:
        import base64
        import html

        o, t = self.metrics["overall"], self.metrics.get("table", {})
        img = base64.b64encode(self._repr_png_()).decode()
        table = (f"; 81x81 table: RMSE {t['rmse']:.4g} 1/sr, log-RMSE {t['log_rmse']:.4g}" if t else "")
        return (
            f"<p><b>Validation</b> of {html.escape(str(self.metrics.get('fit', 'fit')))} against "
            f"{html.escape(str(self.metrics.get('reference', 'reference')))}: {len(self.lights)} lights, "
            f"{self.reference.shape[1]} px; RMSE {o['rmse']:.4g}, PSNR {o['psnr']:.1f} dB, FLIP {o['flip']:.3f}"
            f"{html.escape(table)}</p><img src='data:image/png;base64,{img}'/>"
        )


def as_fit(fit) -> Source:
    """The fit to validate: a FitResult, a path to a fit.json, a (model_name, params) pair."""
    if isinstance(fit, (str, Path)) and str(fit).lower().endswith(".json"):
        from ..fitting.result import FitResult

        fit = FitResult.from_json(Path(fit))
    return as_source(fit)


def _table(src: Source) -> tuple[np.ndarray, np.ndarray]:
    """(81, 81, 3) f_r of a source on the UBO-81 pairs, and the valid mask (81, 81): finite, and
    for a measured table its valid samples only (the interpolator fills the others)."""
    wi, wo = ubo_pairs()
    values = np.array(src.brdf(wi, wo)).reshape(81, 81, 3)
    valid = np.all(np.isfinite(values), axis=-1)
    if src.valid is not None:
        valid &= src.valid
        values[~valid] = np.nan  # shown as missing, not as interpolated data
    return values, valid


def _tag(d: np.ndarray) -> str:
    theta = int(round(np.degrees(np.arccos(np.clip(d[2], -1, 1)))))
    phi = int(round(np.degrees(np.arctan2(d[1], d[0])) % 360)) % 360 if theta > 0 else 0
    return f"t{theta:02d}_p{phi:03d}"


def validate(
    source,
    fit,
    lights=None,
    size: int = 256,
    out: str | Path | None = None,
    force: bool = False,
    spp: int = DEFAULT_SPP,
    irradiance: float = 1.0,
    progress=None,
    renderer: str = "mitsuba",
) -> Validation:
    """Render ``fit`` and its reference ``source`` under each light, compare, and write the results.

    ``source``: the reference: a path to an RGL ``.bsdf`` (Mitsuba's ``measured`` plugin) or to any
    measurement file ``brdffit.load`` reads, or a UBO-81 ``Measurement`` (tabulated BSDF).
    ``fit``: a FitResult, a path to a fit.json, or a ``(model_name, params)`` pair.
    ``lights``: (L, 3) directions or (L, 2) (theta, phi) radians; default :data:`DEFAULT_LIGHTS_DEG`.
    ``out``: folder to write (see the module docstring); nothing is written when None.
    ``progress(stage, k, n)`` is called as the work goes on.
    ``renderer``: what renders the fit, "mitsuba" or "cycles" (a ``blender:principled`` fit in
    Blender's Cycles, docs/materials.md#native-materials-and-exports); the reference is always rendered by Mitsuba.
    """
    chosen = get_renderer(renderer)
    run = ValidationRun(out, force)  # checks the output folder before the work

    def tell(stage, k=0, n=0):
        if progress is not None:
            progress(stage, k, n)

    import_native()  # in this thread, before any background thread exists
    from .bsdf import COMPILE_SECONDS

    n_compiled = len(COMPILE_SECONDS)
    ref_src = as_source(source)
    fit_src = as_fit(fit)
    dirs = light_directions(default_lights() if lights is None else lights)
    chosen.check(fit_src)  # a fit the renderer cannot render: one line, before any work
    chosen.ready()  # its environment missing (Blender's, for Cycles): one line, before any work
    run.lap("load")

    ref_imgs = render_sphere(ref_src, dirs, size=size, irradiance=irradiance, spp=spp,
                             progress=lambda k, n: tell("render reference", k, n))
    run.lap("render reference")
    fit_imgs = render_sphere(fit_src, dirs, size=size, irradiance=irradiance, spp=spp,
                             progress=lambda k, n: tell("render fit", k, n), renderer=chosen)
    run.lap("render fit")
    compiled = COMPILE_SECONDS[n_compiled:]

    from concurrent.futures import ThreadPoolExecutor

    from .metrics import exposure, image_metrics, summarise, table_metrics

    # FLIP and NumPy release the GIL: the per-light metrics run in two threads while this thread
    # evaluates the tables, writes the EXRs and draws the panels (which wait for their metrics).
    mask = disc_mask(int(size))
    fit_label = fit_src.label + chosen.label
    scales = [exposure(ref_imgs[k], mask) for k in range(len(dirs))]
    with contextlib.ExitStack() as stack:
        pool = stack.enter_context(ThreadPoolExecutor(2))
        futures = [pool.submit(image_metrics, ref_imgs[k], fit_imgs[k], mask, scales[k]) for k in range(len(dirs))]
        tab_ref, valid_ref = _table(ref_src)
        tab_fit, _ = _table(fit_src)
        valid3 = np.broadcast_to(valid_ref[..., None], tab_ref.shape)
        table = table_metrics(tab_ref, tab_fit, valid3)
        run.lap("tables")
        stack.enter_context(run.folder())  # the folder appears complete or not at all
        if run.writing:
            for k, d in enumerate(dirs):
                run.exr(f"reference_{_tag(d)}.exr", ref_imgs[k])
                run.exr(f"fit_{_tag(d)}.exr", fit_imgs[k])
            run.exr("table_reference.exr", tab_ref)
            run.exr("table_fit.exr", tab_fit)
            run.lap("write exr")
            from .. import plot
        per_light = []
        for k, d in enumerate(dirs):
            m = futures[k].result()
            theta = np.degrees(np.arccos(np.clip(d[2], -1, 1)))
            phi = np.degrees(np.arctan2(d[1], d[0])) % 360
            per_light.append({"light": [float(x) for x in d], "theta_deg": float(theta), "phi_deg": float(phi), **m})
            tell("metrics", k + 1, len(dirs))
            if run.writing:
                fig = plot.sphere_panel(ref_imgs[k], fit_imgs[k], d, metrics=per_light[k], scale=scales[k],
                                        ref_label=ref_src.label, fit_label=fit_label, irradiance=irradiance)
                run.png(f"panel_{_tag(d)}.png", fig, dpi=90)
                tell("panels", k + 1, len(dirs) + 1)
        overall = summarise(per_light, ref_imgs, fit_imgs, mask)
        public = [{k: v for k, v in p.items() if not k.startswith("_")} for p in per_light]
        metrics = {
            "reference": ref_src.label,
            "fit": fit_src.label,
            "renderer": chosen.name,
            "size": int(size),
            "spp": int(spp),
            "irradiance": float(irradiance),
            "lights": public,
            "overall": overall,
            "table": table,
        }
        if run.writing:
            fig = plot.compare_table(tab_ref, tab_fit, title=(
                f"UBO-81 table, {fit_src.label} against {ref_src.label}: RMSE {table['rmse']:.3g} 1/sr   "
                f"rel. RMSE {table['rel_rmse']:.3g}   log-RMSE {table['log_rmse']:.3g} (RMS of the residual shown)"))
            run.png("table.png", fig, dpi=90)
            tell("panels", len(dirs) + 1, len(dirs) + 1)
            run.lap("metrics and panels")
            metrics["seconds"] = run.rounded_seconds()
            run.metrics_json(metrics)
    run.lap("metrics and panels" if out is not None else "metrics")
    seconds = run.seconds
    if compiled:
        # not a stage of its own: it ran in a background thread during the reference render
        seconds["jit compile (overlapped)"] = sum(compiled)
    metrics["seconds"] = {k: round(v, 4) for k, v in seconds.items()}
    return Validation(
        lights=dirs,
        reference=ref_imgs,
        fit=fit_imgs,
        table_reference=tab_ref,
        table_fit=tab_fit,
        metrics=metrics,
        files=tuple(run.files),
        seconds=dict(seconds),
    )
