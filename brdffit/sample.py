"""The bundled sample measurement, ``data/sample_ubo81.exr``, and the code that makes it.

A synthetic two-lobe material on the UBO-81 grid, "measured" the way a camera-based BTF device
would see it:

1. ground truth f_r = Lambert (kd) + a sharp GGX lobe + a broad GGX lobe, evaluated with the
   project's own models (``brdffit.models.get("lambert")`` and ``get("ggx")`` with kd = 0);
2. measurement noise: multiplicative log-normal (sigma 3 %) times the truth, plus additive
   Gaussian noise (sigma 0.002 1/sr), fixed seed;
3. 8-bit quantisation: the value divided by an exposure of 4 1/sr is sRGB-encoded to 8-bit codes
   (as an image of a BTF would be), then decoded back to linear with the exact sRGB EOTF and
   multiplied by the exposure again. Codes clipped at 255 (over-exposed highlights) get weight 0.

Values are stored as float32 (the EXR pixels), so the file holds no float64 side copy and stays
small. Regenerate with ``python -m brdffit.sample`` (writes ``data/sample_ubo81.exr``); a test
checks that the committed file equals a fresh generation.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .grid import ubo_pairs
from .measurement import Measurement

SEED = 20261121
#: ground-truth parameters (for tests and the demo's comparison)
TRUTH = {
    "kd": (0.30, 0.16, 0.07),  # warm, orange-brown diffuse albedo
    "sharp": {"ks": (0.50, 0.50, 0.50), "alpha": 0.08, "f0": 0.04},
    "broad": {"ks": (0.60, 0.45, 0.30), "alpha": 0.35, "f0": 0.04},
}
NOISE_REL, NOISE_ABS = 0.03, 0.002
EXPOSURE = 4.0
DEFAULT_PATH = Path(__file__).resolve().parents[1] / "data" / "sample_ubo81.exr"


def ground_truth(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The noiseless two-lobe f_r at light ``wi`` / view ``wo``, (N, 3)."""
    from . import models

    lambert, ggx = models.get("lambert"), models.get("ggx")
    f = np.asarray(lambert.eval({"kd": np.array(TRUTH["kd"])}, wi, wo), dtype=np.float64)
    for lobe in ("sharp", "broad"):
        p = TRUTH[lobe]
        params = {"kd": np.zeros(3), "ks": np.array(p["ks"]), "alpha": np.array([p["alpha"]]), "f0": np.array([p["f0"]])}
        f = f + np.asarray(ggx.eval(params, wi, wo), dtype=np.float64)
    return f


def generate(seed: int = SEED) -> Measurement:
    """The sample measurement (deterministic for a given seed)."""
    from .io.images import linear_to_srgb, srgb_to_linear

    wi, wo = ubo_pairs()
    truth = ground_truth(wi, wo)
    rng = np.random.default_rng(seed)
    noisy = truth * rng.lognormal(0.0, NOISE_REL, truth.shape) + rng.normal(0.0, NOISE_ABS, truth.shape)
    scaled = noisy / EXPOSURE
    codes = np.round(linear_to_srgb(scaled) * 255.0)  # linear_to_srgb clips to [0, 1]
    clipped = np.any(scaled >= 1.0, axis=1)
    values = (srgb_to_linear(codes / 255.0) * EXPOSURE).astype(np.float32).astype(np.float64)
    weights = np.where(clipped, 0.0, 1.0)
    return Measurement(
        wi=wi,
        wo=wo,
        values=values,
        weights=weights,
        name="sample_two_lobe",
        source=f"brdffit.sample.generate(seed={seed})",
        grid="ubo81",
        extra={
            "format": "sample",
            "generator": "Lambert + GGX(alpha 0.08) + GGX(alpha 0.35); noise 3% log-normal + 0.002 Gaussian; "
            "8-bit sRGB quantisation at exposure 4 1/sr; clipped codes weight 0",
            "seed": seed,
            "truth_kd": TRUTH["kd"],
            "truth_sharp": (TRUTH["sharp"]["ks"], TRUTH["sharp"]["alpha"], TRUTH["sharp"]["f0"]),
            "truth_broad": (TRUTH["broad"]["ks"], TRUTH["broad"]["alpha"], TRUTH["broad"]["f0"]),
            "exposure": EXPOSURE,
            "clipped": int(clipped.sum()),
        },
    )


def write(path: str | Path = DEFAULT_PATH, *, force: bool = True) -> Path:
    """Generate and save the sample (EXR or NPZ by extension)."""
    from .io import save

    return save(generate(), path, force=force)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else DEFAULT_PATH
    out = write(path)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
