"""docs/models.md#how-models-are-tested 'done when': every model equals an independent implementation.

* ``ggx`` (kd = 0, ks = 1, f0 = 1) equals Mitsuba 3's ``roughconductor`` (ggx, material none)
  eval / cos(theta) to 1e-5 relative on the UBO-81 pairs, for several alpha; ``lambert`` equals
  Mitsuba's ``diffuse``.
* Every other model equals its paper's formula written here in NumPy, with angles where the
  paper uses angles (acos, atan2, tan), i.e. not the rearranged angle-free JAX expressions.
"""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.models import get

WI, WO = brdffit.ubo_pairs()


def _random_pairs(n=400, max_deg=88.0, seed=1):
    rng = np.random.default_rng(seed)
    th = np.arccos(rng.uniform(np.cos(np.deg2rad(max_deg)), 1.0, (2, n)))
    ph = rng.uniform(0, 2 * np.pi, (2, n))
    v = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    return v[0], v[1]


RI, RO = _random_pairs()
PAIRS_WI = np.concatenate([WI, RI])
PAIRS_WO = np.concatenate([WO, RO])


# -- NumPy references from the papers -------------------------------------------------------------
def angles(w):
    return np.arccos(np.clip(w[:, 2], -1, 1)), np.arctan2(w[:, 1], w[:, 0])


def half(wi, wo):
    h = wi + wo
    return h / np.linalg.norm(h, axis=1, keepdims=True)


def schlick(f0, c):
    return f0 + (1 - f0) * (1 - c) ** 5


def v_groove(wi, wo, h):
    nh, nl, nv, vh = h[:, 2], wi[:, 2], wo[:, 2], np.sum(wo * h, 1)
    return np.minimum(1, np.minimum(2 * nh * nv / vh, 2 * nh * nl / vh))


def ref_phong(p, wi, wo):  # Lewis 1994: kd/pi + ks (n+2)/(2pi) cos^n(alpha), alpha = angle(R, V)
    R = 2 * wi[:, 2:3] * np.array([0, 0, 1.0]) - wi
    cos_a = np.clip(np.sum(R * wo, 1), 0, None)
    return p["kd"] / np.pi + p["ks"] * (p["n"] + 2) / (2 * np.pi) * (cos_a**p["n"])[:, None]


def ref_phong_classic(p, wi, wo):  # I_s / (I_L cos th_i) with I_s = I_L r_s cos^h(alpha)
    R = 2 * wi[:, 2:3] * np.array([0, 0, 1.0]) - wi
    cos_a = np.clip(np.sum(R * wo, 1), 0, None)
    return p["kd"] / np.pi + p["ks"] * (cos_a**p["n"] / wi[:, 2])[:, None]


def ref_blinn_phong(p, wi, wo):
    th_h, _ = angles(half(wi, wo))
    return p["kd"] / np.pi + p["ks"] * (p["n"] + 8) / (8 * np.pi) * (np.cos(th_h) ** p["n"])[:, None]


def ref_ward(p, wi, wo):  # Ward 1992 eq. 5a
    ax, ay = p["alpha_x"], p["alpha_y"]
    d, ph = angles(half(wi, wo))
    e = np.exp(-np.tan(d) ** 2 * (np.cos(ph) ** 2 / ax**2 + np.sin(ph) ** 2 / ay**2))
    return p["kd"] / np.pi + p["ks"] * (e / (4 * np.pi * ax * ay * np.sqrt(wi[:, 2] * wo[:, 2])))[:, None]


def ref_torrance_sparrow(p, wi, wo):
    h = half(wi, wo)
    alpha, _ = angles(h)  # the paper's facet angle
    D = np.exp(-((alpha / p["m"]) ** 2))
    F = schlick(p["f0"], np.sum(wi * h, 1))
    spec = F * v_groove(wi, wo, h) * D / (4 * wi[:, 2] * wo[:, 2])
    return p["kd"] / np.pi + p["ks"] * spec[:, None]


def ref_cook_torrance(p, wi, wo):  # 1982: D = exp(-(tan a/m)^2)/(m^2 cos^4 a), R = F D G/(pi nl nv)
    h = half(wi, wo)
    a, _ = angles(h)
    m = p["alpha"]
    D1982 = np.exp(-((np.tan(a) / m) ** 2)) / (m**2 * np.cos(a) ** 4)
    F = schlick(p["f0"], np.sum(wi * h, 1))
    R1982 = F * D1982 * v_groove(wi, wo, h) / (np.pi * wi[:, 2] * wo[:, 2])
    return p["kd"] / np.pi + p["ks"] * (R1982 / 4)[:, None]  # modern normalisation: ks_1982 = ks/4


def ref_oren_nayar(p, wi, wo):  # 1994 eq. 30, qualitative model
    ti, pi_ = angles(wi)
    to, po = angles(wo)
    s2 = p["sigma"] ** 2
    A = 1 - 0.5 * s2 / (s2 + 0.33)
    B = 0.45 * s2 / (s2 + 0.09)
    a, b = np.maximum(ti, to), np.minimum(ti, to)
    val = A + B * np.maximum(0, np.cos(pi_ - po)) * np.sin(a) * np.tan(b)
    return p["kd"] / np.pi * val[:, None]


def ref_lafortune(p, wi, wo, lobes=("",)):
    f = p["kd"] / np.pi + 0 * wi[:, :1]
    for s in lobes:
        C = np.array([p["cx" + s], p["cx" + s], p["cz" + s]]).ravel()
        dot = np.sum(C * wi * wo, 1)
        # the documented overflow cap: a lobe value never exceeds e^100 (float64)
        lobe = np.where(dot > 0, np.exp(np.minimum(p["n" + s] * np.log(np.where(dot > 0, dot, 1.0)), 100.0)), 0.0)
        f = f + p["rho" + s] * lobe[:, None]
    return f


def ref_ashikhmin_shirley(p, wi, wo):  # 2000, eqs. 4 and 5
    nu, nv, rs, rd = p["nu"], p["nv"], p["rs"], p["rd"]
    h = half(wi, wo)
    th_h, ph_h = angles(h)
    kh = np.sum(wi * h, 1)
    expo = nu * np.cos(ph_h) ** 2 + nv * np.sin(ph_h) ** 2
    spec = np.sqrt((nu + 1) * (nv + 1)) / (8 * np.pi) * np.cos(th_h) ** expo / (kh * np.maximum(wi[:, 2], wo[:, 2]))
    spec = spec[:, None] * schlick(rs, kh[:, None])
    diff = 28 * rd / (23 * np.pi) * (1 - rs) * ((1 - (1 - wi[:, 2:3] / 2) ** 5) * (1 - (1 - wo[:, 2:3] / 2) ** 5))
    return spec + diff


def ref_ggx(p, wi, wo):  # Walter et al. 2007 eqs. 33, 34 with separable Smith G
    h = half(wi, wo)
    th_h, _ = angles(h)
    a2 = p["alpha"] ** 2
    D = a2 / (np.pi * np.cos(th_h) ** 4 * (a2 + np.tan(th_h) ** 2) ** 2)

    def G1(w):
        return 2 / (1 + np.sqrt(1 + a2 * np.tan(np.arccos(w[:, 2])) ** 2))

    F = schlick(p["f0"], np.sum(wi * h, 1))
    return p["kd"] / np.pi + p["ks"] * (F * G1(wi) * G1(wo) * D / (4 * wi[:, 2] * wo[:, 2]))[:, None]


REFERENCES = {
    "phong": ref_phong,
    "phong_classic": ref_phong_classic,
    "blinn_phong": ref_blinn_phong,
    "ward": ref_ward,
    "torrance_sparrow": ref_torrance_sparrow,
    "cook_torrance": ref_cook_torrance,
    "oren_nayar": ref_oren_nayar,
    "lafortune": ref_lafortune,
    "ashikhmin_shirley": ref_ashikhmin_shirley,
    "ggx": ref_ggx,
    "lafortune3": lambda p, wi, wo: ref_lafortune(p, wi, wo, lobes=("1", "2", "3")),
}


def param_draws(model, n=3, seed=0):
    """Defaults plus random draws (log-uniform on log axes), as NumPy (C,) / scalars."""
    import jax

    draws = [model.defaults()] + [model.sample(k, margin=0.05) for k in jax.random.split(jax.random.key(seed), n)]
    # Keep exponents/roughness in the range where values are not all underflowed, so the
    # comparison is informative; the extremes are the stability tests' job.
    out = []
    for d in draws:
        q = {k: np.asarray(v, dtype=np.float64) for k, v in d.items()}
        for prm in model.params:
            if prm.role == "exponent":
                q[prm.name] = np.minimum(q[prm.name], 2000.0)
            if prm.role == "roughness" and prm.scale == "log":
                q[prm.name] = np.maximum(q[prm.name], 0.02)
        out.append({k: (v if v.size > 1 else v.reshape(())) for k, v in q.items()})
    return out


@pytest.mark.parametrize("name", sorted(REFERENCES))
def test_model_equals_paper_formula_in_numpy(name):
    model = get(name)
    ref = REFERENCES[name]
    with np.errstate(divide="ignore", invalid="ignore"):
        for p in param_draws(model):
            got = np.asarray(model.eval(p, PAIRS_WI, PAIRS_WO))
            want = np.broadcast_to(ref(p, PAIRS_WI, PAIRS_WO), got.shape)
            ok = np.isfinite(want)
            # the angle form is undefined only where h == n exactly for AS (0^0-like exponent)
            assert ok.mean() > 0.99, f"{name}: reference undefined on {1 - ok.mean():.2%} of pairs"
            scale = np.max(np.abs(want[ok]))
            np.testing.assert_allclose(got[ok], want[ok], rtol=1e-7, atol=1e-10 * scale, err_msg=f"{name} {p}")


def test_composite_is_sum_of_components_with_shared_kd():
    model = get("lambert+ggx+ggx")
    p = {k: np.asarray(v) for k, v in model.sample(__import__("jax").random.key(3), margin=0.1).items()}
    got = np.asarray(model.eval(p, PAIRS_WI, PAIRS_WO))
    want = p["kd"] / np.pi
    for k in ("1", "2"):
        q = {"kd": 0.0, "ks": p[f"ggx{k}.ks"], "alpha": p[f"ggx{k}.alpha"][0], "f0": p[f"ggx{k}.f0"][0]}
        want = want + ref_ggx(q, PAIRS_WI, PAIRS_WO)
    np.testing.assert_allclose(got, want, rtol=1e-7)


# -- Mitsuba ---------------------------------------------------------------------------------------
def _mitsuba_eval_over_cos(bsdf_dict, wi, wo):
    """Mitsuba f_r: eval(si.wi = wo, wo_arg = wi) / cos(theta of the eval direction)."""
    from brdffit._mitsuba import mitsuba

    mi = mitsuba()
    bsdf = mi.load_dict(bsdf_dict)
    if mi.variant().startswith("scalar"):  # no usable libLLVM: one pair at a time
        out = []
        for a, b in zip(wi, wo):
            si = mi.SurfaceInteraction3f()
            si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
            si.wi = mi.Vector3f(*map(float, b.astype(np.float32)))
            out.append(np.asarray(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, a.astype(np.float32))))))
        return np.asarray(out, dtype=np.float64).reshape(len(wi), 3) / wi[:, 2:3].astype(np.float32).astype(np.float64)
    si = mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    si.wi = mi.Vector3f(np.ascontiguousarray(wo.T, dtype=np.float32))
    v = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(np.ascontiguousarray(wi.T, dtype=np.float32)))
    v = np.asarray(v, dtype=np.float64)
    v = v.T if v.shape[0] == 3 else v
    return v / wi[:, 2:3].astype(np.float32).astype(np.float64)


@pytest.mark.mitsuba
@pytest.mark.parametrize("alpha", [0.05, 0.2, 0.5, 1.0])
def test_ggx_equals_mitsuba_roughconductor(alpha):
    # Mitsuba computes in float32: compare with our model on the same float32-rounded directions.
    wi = WI.astype(np.float32).astype(np.float64)
    wo = WO.astype(np.float32).astype(np.float64)
    want = _mitsuba_eval_over_cos(
        {"type": "roughconductor", "distribution": "ggx", "alpha": alpha, "material": "none"}, wi, wo
    )
    model = get("ggx")
    got = np.asarray(model.eval({"kd": 0.0, "ks": 1.0, "alpha": alpha, "f0": 1.0}, wi, wo))
    assert np.all(want > 0)
    np.testing.assert_allclose(got, want, rtol=1e-5)


@pytest.mark.mitsuba
def test_lambert_equals_mitsuba_diffuse():
    kd = [0.2, 0.5, 0.9]
    want = _mitsuba_eval_over_cos(
        {"type": "diffuse", "reflectance": {"type": "rgb", "value": kd}}, WI, WO
    )
    got = np.asarray(get("lambert").eval({"kd": np.asarray(kd)}, WI, WO))
    np.testing.assert_allclose(got, want, rtol=1e-5)
