"""Image and table metrics of a validation (docs/validation.md#validation-rendering): RMSE, relative RMSE, PSNR, FLIP.

- ``rmse``: root mean square difference of the linear radiance over the pixels on the disc (all
  channels), in the units of the render (radiance per unit irradiance times ``irradiance``).
- ``rel_rmse``: ``rmse`` divided by the RMS of the reference over the same pixels.
- ``psnr``: of the tone-mapped images (:func:`tonemap`), in dB, peak 1, over the disc.
- ``flip``: mean LDR-FLIP (NVIDIA's ``flip-evaluator`` package) of the tone-mapped images over
  the disc, in [0, 1], lower is better.

Tone mapping: both images are scaled by one exposure, 1 / (99.5th percentile of the reference's
largest channel on the disc), clipped to [0, 1] and sRGB-encoded. The exposure depends on the
reference only, so a fit that is too bright or too dark is shown (and scored) as such.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..io.images import linear_to_srgb

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


def exposure(reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Scale that maps the 99.5th percentile of the reference (largest channel) to 1."""
    ref = np.asarray(reference, np.float64)
    peak = ref.max(axis=-1)
    if mask is not None:
        peak = peak[np.broadcast_to(mask, peak.shape)]
    peak = peak[np.isfinite(peak)]
    level = float(np.percentile(peak, 99.5)) if peak.size else 0.0
    return 1.0 / level if level > 0 else 1.0


def tonemap(img: np.ndarray, scale: float) -> np.ndarray:
    """Linear radiance -> display sRGB in [0, 1] with a fixed exposure ``scale``."""
    return linear_to_srgb(np.nan_to_num(np.asarray(img, np.float64) * scale, nan=0.0, posinf=1.0, neginf=0.0))


def luminance(img: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of linear RGB (..., 3)."""
    return np.asarray(img, np.float64) @ np.array([0.2126, 0.7152, 0.0722])


def image_metrics(
    reference: Float[np.ndarray, "H W 3"], test: Float[np.ndarray, "H W 3"], mask: np.ndarray, scale: float | None = None
) -> dict[str, float]:
    """rmse, rel_rmse, psnr, flip of one image pair over the ``mask`` pixels."""
    import flip_evaluator

    ref = np.asarray(reference, np.float64)
    tst = np.asarray(test, np.float64)
    m = np.asarray(mask, bool)
    d = (tst - ref)[m]
    rmse = float(np.sqrt(np.mean(d * d)))
    ref_rms = float(np.sqrt(np.mean(ref[m] ** 2)))
    scale = exposure(ref, m) if scale is None else scale
    a, b = tonemap(ref, scale), tonemap(tst, scale)
    mse_t = float(np.mean((a[m] - b[m]) ** 2))
    psnr = float(10 * np.log10(1.0 / mse_t)) if mse_t > 0 else float("inf")
    fmap, _, _ = flip_evaluator.evaluate(
        a.astype(np.float32), b.astype(np.float32), "LDR", inputsRGB=True, applyMagma=False, computeMeanError=False
    )
    fmap = np.asarray(fmap).reshape(ref.shape[:2])
    out = {
        "rmse": rmse,
        "rel_rmse": rmse / ref_rms if ref_rms > 0 else float("nan"),
        "psnr": psnr,
        "flip": float(np.mean(fmap[m])),
        "_flip_map": fmap,
        "_mse_tonemapped": mse_t,
    }
    if not (np.all(np.isfinite(ref[m])) and np.all(np.isfinite(tst[m]))):
        # The tone mapper clips inf and NaN to displayable values, so PSNR and FLIP would read as a
        # perfect match of images that hold no numbers (docs/fitting.md#hostile-but-valid-data): none of them can be computed.
        out.update(rmse=float("nan"), rel_rmse=float("nan"), psnr=float("nan"), flip=float("nan"),
                   _mse_tonemapped=float("nan"))
    return out


def summarise(per_light: list[dict], reference: np.ndarray, test: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """Overall metrics across all lights: pooled rmse / relative rmse / psnr, mean FLIP."""
    m = np.broadcast_to(np.asarray(mask, bool), reference.shape[:3])
    d = (np.asarray(test, np.float64) - np.asarray(reference, np.float64))[m]
    rmse = float(np.sqrt(np.mean(d * d)))
    ref_rms = float(np.sqrt(np.mean(np.asarray(reference, np.float64)[m] ** 2)))
    mse_t = float(np.mean([p["_mse_tonemapped"] for p in per_light]))
    if not np.all(np.isfinite(d)):  # as image_metrics: no number, no metric
        rmse = float("nan")
    return {
        "rmse": rmse,
        "rel_rmse": rmse / ref_rms if ref_rms > 0 else float("nan"),
        # NaN (a light whose images hold no numbers) stays NaN: never a perfect-looking inf
        "psnr": float(10 * np.log10(1.0 / mse_t)) if mse_t > 0 else (float("inf") if mse_t == 0 else float("nan")),
        "flip": float(np.mean([p["flip"] for p in per_light])),
    }


def format_metric(value: float, spec: str) -> str:
    """A metric for people: ``n/a`` where it could not be computed (NaN), else ``format(value, spec)``."""
    return "n/a" if value != value else format(value, spec)


def table_metrics(reference: np.ndarray, fitted: np.ndarray, valid: np.ndarray) -> dict[str, float]:
    """Errors of the fitted 81x81 table against the reference on the valid entries (f_r, 1/sr);
    ``log_rmse`` is the one definition of docs/fitting.md#fitting (:func:`brdffit.fitting.losses.log_rmse`, with the
    UBO-81 light's cos theta), the figure a fit reports."""
    from ..fitting.losses import log_rmse
    from ..grid import ubo_directions

    ref_t = np.asarray(reference, np.float64)
    fit_t = np.asarray(fitted, np.float64)
    valid = np.asarray(valid, bool)
    if valid.ndim == ref_t.ndim - 1:  # one flag per (light, view) pair: the same for every channel
        valid = valid[..., None]
    valid = np.broadcast_to(valid, ref_t.shape)
    ref = ref_t[valid]
    fit = fit_t[valid]
    d = fit - ref
    rmse = float(np.sqrt(np.mean(d * d)))
    ref_rms = float(np.sqrt(np.mean(ref * ref)))
    cos_l = np.clip(ubo_directions()[:, 2], 1e-7, 1.0)[:, None, None]
    used = valid.astype(np.float64)
    lrmse = log_rmse(np.where(valid, fit_t, 0.0), np.where(valid, ref_t, 0.0), cos_l, used)
    return {
        "rmse": rmse,
        "rel_rmse": rmse / ref_rms if ref_rms > 0 else float("nan"),
        "log_rmse": float(lrmse),
        "valid_pairs": int(np.count_nonzero(np.all(valid, axis=-1) if valid.ndim == 3 else valid)),
    }
