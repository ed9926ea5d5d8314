"""Parameter recovery for every model through the public ``brdffit.fit`` (default settings:
variable-projection grid start, LM, log loss).

Data: for each model, N_SETS parameter sets drawn with the model's *own* PRNG key (derived from its
name, so no two models share draws) from the identifiable ranges declared below in RANGES, evaluated
on the UBO-81 pairs, with 1 % multiplicative Gaussian noise (its own seed per model and set).

Asserted for every set, every model, no parameter waived:
- the fit converged (status "converged": a fit that stopped at max_steps fails);
- its BRDF reproduces the *noise-free* truth within 1 % relative RMSE over the UBO-81 table
  (REL_RMSE_TOL; the noise is 1 % per sample, a good fit averages it down to ~0.1 %);
- every parameter is within 2 % of the truth (PARAM_RTOL; relative, per channel).
  Lafortune's (rho, C, n) have an exact scaling degeneracy, (s C . x)^n rho = (C . x)^n (s^n rho),
  so for it the identified combinations are checked at 2 % instead of cx, cz, rho themselves:
  cx / cz (the lobe direction) and rho cz^n (its height); kd and n directly.

Why these ranges (the UBO grid is 15 degrees apart; a lobe narrower than that is seen only at its
mirror samples, so only its peak height ks F / alpha^2 is measured, not ks and alpha separately):
roughness alpha, m, alpha_x/y in [0.08, 0.5] (lobe half-width about 5..30 degrees; the sample
spacing resolves this) and Phong-type exponents up to ~100 (width ~ 1/sqrt(n) rad); albedos away
from 0 so that 2 % relative is meaningful against 1 % noise; f0 up to 0.6 (above that the Fresnel
curve (1 - f0)(1 - h.l)^5 is too flat over the grid to separate f0 from ks).
"""

from __future__ import annotations

import math
import zlib

import jax
import numpy as np
import pytest

import brdffit
from brdffit import models
from brdffit.grid import ubo_pairs

WI, WO = ubo_pairs()
N_SETS = 4
NOISE = 0.01
REL_RMSE_TOL = 0.01
PARAM_RTOL = 0.02

LOG = "log"
ALB = (0.05, 0.5)
ROUGH = (0.08, 0.5, LOG)
#: model -> parameter -> (low, high[, "log"]): the identifiable ranges the truths are drawn from
RANGES: dict[str, dict[str, tuple]] = {
    "lambert": {"kd": (0.05, 0.9)},
    "oren_nayar": {"kd": (0.1, 0.9), "sigma": (0.2, 1.2)},
    "phong": {"kd": ALB, "ks": (0.3, 1.0), "n": (5.0, 60.0, LOG)},
    "phong_classic": {"kd": ALB, "ks": (0.3, 2.0), "n": (5.0, 60.0, LOG)},
    "blinn_phong": {"kd": ALB, "ks": (0.3, 1.0), "n": (10.0, 150.0, LOG)},
    "ward": {"kd": ALB, "ks": (0.2, 0.9), "alpha_x": ROUGH, "alpha_y": ROUGH},
    "torrance_sparrow": {"kd": ALB, "ks": (0.5, 5.0), "m": ROUGH, "f0": (0.05, 0.6)},
    "cook_torrance": {"kd": ALB, "ks": (0.3, 1.0), "alpha": ROUGH, "f0": (0.05, 0.6)},
    "ggx": {"kd": ALB, "ks": (0.3, 1.0), "alpha": ROUGH, "f0": (0.05, 0.6)},
    "lafortune": {"kd": ALB, "rho": (0.5, 5.0), "cx": (-1.0, -0.6), "cz": (0.6, 1.0), "n": (5.0, 60.0, LOG)},
    "ashikhmin_shirley": {"rd": ALB, "rs": (0.05, 0.5), "nu": (5.0, 100.0, LOG), "nv": (5.0, 100.0, LOG)},
    # native models (docs/materials.md#native-materials-and-exports): the renderer's parameters
    "mitsuba:roughconductor": {"alpha": ROUGH, "eta": (0.2, 2.0), "k": (1.0, 5.0)},
    "mitsuba:roughplastic": {"diffuse_reflectance": ALB, "alpha": ROUGH, "int_ior": (1.3, 2.0),
                             "specular_reflectance": (0.5, 1.0)},
    "mitsuba:principled": {"base_color": (0.2, 0.9), "roughness": (0.3, 0.7), "metallic": (0.05, 0.4),
                           "specular": (0.3, 1.0), "anisotropic": (0.2, 0.8), "sheen": (0.3, 0.9),
                           "clearcoat": (0.3, 0.9), "clearcoat_gloss": (0.0, 0.3)},
    "gltf:metallic_roughness": {"base_color": (0.2, 0.9), "metallic": (0.1, 0.9), "roughness": (0.3, 0.7)},
    "blender:principled": {"base_color": (0.2, 0.9), "metallic": (0.1, 0.9), "roughness": (0.3, 0.7),
                           "ior": (1.3, 2.0), "specular_tint": (0.5, 1.0)},
}

#: (model, set) -> why the current solver fails it; strict, so a listed case that passes fails the run.
#: (The bounded LM of docs/fitting.md#solvers recovers phong_classic-1 and torrance_sparrow-1/-3, which the old
#: active-set solver lost to local minima.)
KNOWN_FAILURES: dict[tuple[str, int], str] = {
    # Not a solver failure since the structured solver: the fit reaches the minimum of this noise
    # draw (a fit started at the truth ends at the same loss, 3.69707e-7, and n = 35.92), but there
    # n is 1.9 % and blue rho cz^n 2.2 % from the truth.
    ("lafortune", 2): "the noise draw's minimum lies 2.2 % from the truth in blue rho cz^n (a fit from the truth ends there too)",
    # As lafortune 2: a fit started at the truth ends at the default fit's loss (1.5554808e-6), with
    # clearcoat 0.547 for 0.502, so the glossy peak there is 2.7 % above the truth's.
    ("mitsuba:principled", 1): "the noise draw's minimum lies 2.7 % from the truth in the glossy peak (a fit from the truth ends there too)",
    # A solver-start gap, left open (docs/materials.md#native-materials-and-exports's closing note): the default start's grid gives eta and
    # k three shared values each, and these fits converge in another (eta, k) valley of a channel
    # (k = 0 there) whose Fresnel curve matches at the grid's angles only: rel_rmse 0.099 and 0.043.
    ("mitsuba:roughconductor", 0): "default start: converged in another (eta, k) valley (rel_rmse 0.099)",
    ("mitsuba:roughconductor", 1): "default start: converged in another (eta, k) valley (rel_rmse 0.043)",
}


def model_key(name: str) -> jax.Array:
    return jax.random.PRNGKey(zlib.crc32(name.encode()))


def truth(name: str, k: int) -> dict[str, np.ndarray]:
    model = models.get(name)
    keys = jax.random.split(jax.random.fold_in(model_key(name), k), len(model.params))
    out = {}
    for key, p in zip(keys, model.params):
        lo, hi, *log = RANGES[name][p.name]
        u = np.asarray(jax.random.uniform(key, (model.size(p),), dtype=np.float64))
        out[p.name] = np.exp(np.log(lo) + u * np.log(hi / lo)) if log else lo + u * (hi - lo)
    return out


def _compared(name: str, params: dict) -> dict[str, np.ndarray]:
    """The quantities the data identify: the parameters themselves, except Lafortune's degeneracy
    and the conductor's complex IOR, which the data see only through its Fresnel curve (compared at
    0, 30 and 60 degrees, Fresnel's formula by Moeller written again here)."""
    if name == "mitsuba:roughconductor":
        eta, k = (np.asarray(params[x], np.float64) for x in ("eta", "k"))
        out = {"alpha": np.asarray(params["alpha"], np.float64)}
        for deg in (0, 30, 60):
            c = math.cos(math.radians(deg))
            n2 = (eta + 1j * k) ** 2
            root = np.sqrt(n2 - (1 - c * c))
            rs = np.abs((c - root) / (c + root)) ** 2
            rp = np.abs((n2 * c - root) / (n2 * c + root)) ** 2
            out[f"F({deg})"] = 0.5 * (rs + rp)
        return out
    if name == "mitsuba:principled":
        # specular, clearcoat and clearcoat_gloss shape the same glossy peak (the dielectric GGX lobe
        # and the weak GTR1 lobe beside it): at 1 % noise the fit started at the truth ends 2-18 %
        # away in them (at the loss of the default fit), so what is compared is the peak they make:
        # f_r with base_color and sheen 0 at the mirror pairs of the UBO-81 grid (2 %)
        model = models.get(name)
        out = {k: np.asarray(params[k], np.float64) for k in ("base_color", "roughness", "metallic",
                                                                 "anisotropic", "sheen")}
        glossy = {**params, "base_color": np.zeros(3), "sheen": np.zeros(1)}
        mirror = np.abs(WI[:, :2] + WO[:, :2]).sum(axis=1) < 1e-9
        out["glossy peak"] = np.asarray(model.eval(model.check_params(glossy), WI[mirror], WO[mirror]))
        return out
    if name != "lafortune":
        return {k: np.asarray(v, np.float64) for k, v in params.items()}
    cx, cz, n, rho = (np.asarray(params[k], np.float64) for k in ("cx", "cz", "n", "rho"))
    return {"kd": np.asarray(params["kd"]), "n": n, "cx/cz": cx / cz, "rho cz^n": rho * cz**n}


def test_ranges_cover_every_model_inside_its_bounds():
    assert sorted(RANGES) == models.names()
    for name, ranges in RANGES.items():
        model = models.get(name)
        assert sorted(ranges) == sorted(p.name for p in model.params), name
        for p in model.params:
            lo, hi = ranges[p.name][:2]
            assert p.lower <= lo < hi <= p.upper, (name, p.name, (lo, hi), (p.lower, p.upper))


def test_draws_are_independent_between_models():
    # the same uniform draws must not be reused across models (the old test gave three microfacet
    # models the same near-zero roughness quantile in three of four sets)
    u = {}
    for name in models.names():
        m = models.get(name)
        keys = jax.random.split(jax.random.fold_in(model_key(name), 0), len(m.params))
        u[name] = float(jax.random.uniform(keys[-1], ()))
    assert len(set(np.round(list(u.values()), 12))) == len(u)


def _cases():
    for name in models.names():
        for k in range(N_SETS):
            reason = KNOWN_FAILURES.get((name, k))
            marks = [pytest.mark.xfail(reason=reason, strict=True)] if reason else []
            yield pytest.param(name, k, id=f"{name}-{k}", marks=marks)


@pytest.mark.slow  # 44 fits of 6561 samples: ~5 min on 2 busy cores
@pytest.mark.parametrize("name, k", list(_cases()))
def test_recovery(name, k):
    model = models.get(name)
    true = truth(name, k)
    clean = np.asarray(model.eval(model.check_params(true), WI, WO))
    rng = np.random.default_rng([zlib.crc32(name.encode()), k])
    noisy = clean * (1 + NOISE * rng.standard_normal(clean.shape))
    r = brdffit.fit(brdffit.Measurement(WI, WO, noisy, grid="ubo81", name=f"{name}-{k}"), name)
    assert r.converged, (r.status, true, r)
    fitted = np.asarray(r.eval(WI, WO))
    rel = math.sqrt(np.mean((fitted - clean) ** 2) / np.mean(clean**2))
    assert rel < REL_RMSE_TOL, (rel, true, r)
    got, want = _compared(name, r.params), _compared(name, true)
    for key in want:
        np.testing.assert_allclose(got[key], want[key], rtol=PARAM_RTOL, err_msg=f"{name} set {k}: {key}")
