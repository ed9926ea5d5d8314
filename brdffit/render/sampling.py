"""Importance sampling for brdffit's Mitsuba BSDFs: a mixture of per-lobe proposals (Dr.Jit).

The *formula* of a model stays its JAX ``model.eval`` (what ``eval`` returns and what a sample's
weight is divided from). What this module adds is a sampling *density*: a valid pdf over outgoing
directions that follows the model's lobes, with ``sample`` drawing exactly from the density
``pdf`` returns. A mismatch between density and BRDF only costs noise, never bias.

Lobes (what each model's terms are sampled with, declared in the model's own file as
``Model.sampling``; directions in Mitsuba's local frame, ``wi`` the given direction -- towards the
camera -- and ``wo`` the sampled one -- towards the light):

=================  ==========================================================================
lobe               proposal
=================  ==========================================================================
cosine             cosine-weighted hemisphere (Lambert, Oren-Nayar and every kd term)
ggx                visible normals of GGX (Heitz, "Sampling the GGX Distribution of Visible
                   Normals", JCGT 7(4), 2018), through Mitsuba's ``MicrofacetDistribution``
beckmann           visible normals of Beckmann (same class): Cook-Torrance (alpha), Ward
                   (alpha_x, alpha_y: Ward's exponent is the anisotropic Beckmann one), and as
                   a proposal for Torrance-Sparrow's Gaussian in the half angle (alpha = m, the
                   same lobe for small angles, tan th ~ th)
power              cos^n about an axis: Phong (mirror direction, n), Lafortune (the axis
                   (cx v_x, cx v_y, cz v_z)/|.|, n), phong_classic
half_power         Ashikhmin-Shirley's half-vector density (their eq. 9, exact),
                   sqrt((nu+1)(nv+1))/(2 pi) (n.h)^(nu cos^2 ph + nv sin^2 ph); Blinn-Phong is
                   nu = nv = n
=================  ==========================================================================

Mixture weights: each lobe's directional albedo, estimated once per BSDF by the quadrature of
:mod:`brdffit.models.albedo` over the JAX formula with the other lobes' scale parameters set to 0, at a few view angles and averaged over channels; ``sample`` picks a lobe with probability
proportional to it (linear in cos theta between the nodes), and ``pdf`` is the weighted sum of the
lobes' densities. A floor of :data:`COSINE_FLOOR` on the cosine lobe keeps every direction the
BRDF may reach (the approximate proposals) sampled.
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math

import numpy as np

#: View directions (cos theta) at which lobe albedos are estimated; weights are linear between.
COS_NODES = np.array([0.05, 0.25, 0.5, 0.75, 1.0])
#: Smallest share of the cosine lobe in the mixture.
COSINE_FLOOR = 0.02
_NODES = tuple(float(c) for c in COS_NODES)


@dataclasses.dataclass(frozen=True)
class Lobe:
    """One term of a model, as far as sampling is concerned."""

    kind: str  # cosine | ggx | beckmann | power | half_power
    shape: tuple[float, ...] = ()  # ggx/beckmann: (alpha_u, alpha_v); power: (n, cx, cz); half_power: (nu, nv)
    #: composite parameter names that scale this lobe (the others are zeroed to isolate it)
    scales: tuple[str, ...] = ()
    #: index of a lobe whose albedo is included in this one's isolated albedo (subtract it)
    minus: int | None = None


def _scalar(params, name) -> float:
    return float(np.asarray(params[name], np.float64).reshape(-1)[0])


def _base_lobes(name: str, p, q) -> list[Lobe]:
    """Lobes of one base model, as its own file declares them (``Model.sampling``, a tuple of
    ``models.base.Proposal``). ``p(own_name)`` gives a parameter value; ``q(own_name)`` the
    composite name of a scale parameter (None when the composite holds it at 0)."""
    from ..models import get

    try:
        model = get(name)
    except KeyError:
        model = None
    s = lambda names: tuple(n for n in (q(x) for x in names) if n is not None)  # noqa: E731
    if model is None or model.sampling is None:
        return [Lobe("cosine", scales=s(("kd",)))]  # no declaration: cosine sampling (valid, not fast)
    return [Lobe(x.kind, tuple(float(v) for v in x.shape), s(x.scales), x.minus) for x in model.sampling(p)]


def _components(model):
    """[(component name, {own parameter name: composite name or None})] of a (composite) model."""
    parts = getattr(getattr(model, "formula", None), "args", None)
    if model.components and parts and all(hasattr(x, "names") for x in parts[0]):
        return [(c.name, dict(part.names)) for c, part in zip(model.components, parts[0])]
    return [(model.name, {n: n for n in model.param_names})]


def model_lobes(model, params) -> list[Lobe]:
    """The lobes of ``model`` at ``params`` (composite models: every component's lobes)."""
    lobes: list[Lobe] = []
    for name, names in _components(model):
        offset = len(lobes)
        own = _base_lobes(name, lambda x, names=names: _scalar(params, names[x]), lambda x, names=names: names.get(x))
        for lobe in own:
            if lobe.minus is not None:
                lobe = dataclasses.replace(lobe, minus=lobe.minus + offset)
            lobes.append(lobe)
    return lobes


def lobe_weights(model, params, lobes: list[Lobe]) -> np.ndarray:
    """(K, len(COS_NODES)) mixture weights: each lobe's albedo share per view angle (columns sum to 1)."""
    from ..fitting.model_eval import eval_model

    all_scales = {n for lobe in lobes for n in lobe.scales} | {
        p.name for p in model.params if p.linear and p.role == "albedo"
    }
    wi, wo, weight = _albedo_nodes()
    raw = []
    for lobe in lobes:
        if lobe.kind == "cosine" and not lobe.scales:
            raw.append(np.zeros(len(COS_NODES)))
            continue
        isolated = dict(model.check_params(params))
        for n in all_scales - set(lobe.scales):
            if n in isolated:
                isolated[n] = isolated[n] * 0.0
        f = eval_model(model, isolated, wi, wo).mean(axis=1)
        a = np.nansum((f * weight).reshape(2, len(COS_NODES), -1), axis=2)  # (azimuth, node)
        raw.append(a.mean(axis=0))
    raw = np.asarray(raw)
    for k, lobe in enumerate(lobes):
        if lobe.minus is not None:
            raw[k] = raw[k] - raw[lobe.minus]
    raw = np.where(np.isfinite(raw), np.maximum(raw, 0.0), 0.0)
    cos = [k for k, lobe in enumerate(lobes) if lobe.kind == "cosine"]
    total = raw.sum(axis=0)
    w = np.where(total > 0, raw / np.where(total > 0, total, 1.0), 0.0)
    if not cos:
        lobes.append(Lobe("cosine"))
        w = np.vstack([w, np.zeros(len(COS_NODES))])
        cos = [len(lobes) - 1]
    # the cosine lobe(s) get at least COSINE_FLOOR (all of it for a black material)
    share = w[cos].sum(axis=0)
    lift = np.maximum(COSINE_FLOOR - share, 0.0) * (total > 0) + (total <= 0)
    w = w * (1.0 - lift)
    w[cos[0]] += lift
    return w / w.sum(axis=0)


@functools.cache
def _albedo_nodes(n_u: int = 96, n_psi: int = 64):
    """Quadrature of the directional albedo at the COS_NODES views, two azimuths (x and y: an
    anisotropic lobe sees both axes): light directions (M, 3), views (M, 3), weights (M,) holding
    solid angle times cos theta of the light (0 below the horizon). The nodes of
    :mod:`brdffit.models.albedo`, dense around the mirror direction where the lobes peak; evaluated
    here through the compiled model (no compilation of its own)."""
    from ..models.albedo import _nodes

    u, psi, w = _nodes(n_u, n_psi)
    sin = np.sqrt(1.0 - COS_NODES**2)
    views = np.concatenate([np.stack([sin, 0 * sin, COS_NODES], -1), np.stack([0 * sin, sin, COS_NODES], -1)])
    wis, wos, ws = [], [], []
    for v in views:
        r = v * np.array([-1.0, -1.0, 1.0])
        t1 = np.array([-r[1], r[0], 0.0])
        t1 = t1 / np.linalg.norm(t1) if np.linalg.norm(t1) > 1e-12 else np.array([1.0, 0.0, 0.0])
        t2 = np.cross(r, t1)
        d = np.cos(u)[:, None] * r + np.sin(u)[:, None] * (np.cos(psi)[:, None] * t1 + np.sin(psi)[:, None] * t2)
        up = d[:, 2] > 0
        wis.append(np.where(up[:, None], d, [0.0, 0.0, 1.0]))
        wos.append(np.broadcast_to(v, d.shape))
        ws.append(np.where(up, w * d[:, 2], 0.0))
    return np.concatenate(wis), np.concatenate(wos), np.concatenate(ws)


@functools.cache
def _pdf_tools(variant: str):
    """Dr.Jit sample/pdf functions for one Mitsuba variant."""
    import drjit as dr

    from .._mitsuba import user_mitsuba

    mi = user_mitsuba()
    assert mi.variant() == variant

    @functools.lru_cache(maxsize=None)
    def microfacet(lobe):
        kind = mi.MicrofacetType.GGX if lobe.kind == "ggx" else mi.MicrofacetType.Beckmann
        return mi.MicrofacetDistribution(kind, float(lobe.shape[0]), float(lobe.shape[1]), True)

    def power_axis(lobe, wi):
        n, cx, cz = lobe.shape
        u = mi.Vector3f(cx * wi.x, cx * wi.y, cz * wi.z)
        norm = dr.norm(u)
        ok = norm > 1e-7
        return dr.select(ok, u / dr.select(ok, norm, 1.0), mi.Vector3f(0, 0, 1))

    def one_minus_pow(s, e):
        """1 - s^e for s in (0, 1], e small or large, without cancellation."""
        t = dr.log(dr.maximum(s, 1e-30)) * e
        return dr.select(t > -1e-3, -t * (1.0 + t * (0.5 + t / 6.0)), 1.0 - dr.exp(t))

    def sample_lobe(lobe, wi, s2):
        if lobe.kind == "cosine":
            return mi.warp.square_to_cosine_hemisphere(s2)
        if lobe.kind in ("ggx", "beckmann"):
            m, _ = microfacet(lobe).sample(wi, s2)
            return mi.reflect(wi, m)
        if lobe.kind == "power":
            n = lobe.shape[0]
            om = one_minus_pow(1.0 - s2.x, 1.0 / (n + 1.0))  # 1 - cos(angle to the axis)
            cos = 1.0 - om
            sin = dr.safe_sqrt(om * (2.0 - om))
            sp, cp = dr.sincos(2.0 * dr.pi * s2.y)
            local = mi.Vector3f(sin * cp, sin * sp, cos)
            return mi.Frame3f(power_axis(lobe, wi)).to_world(local)
        if lobe.kind == "half_power":
            nu, nv = lobe.shape
            q = dr.minimum(dr.floor(s2.x * 4.0), 3.0)
            u = s2.x * 4.0 - q
            phi0 = dr.atan(math.sqrt((nu + 1.0) / (nv + 1.0)) * dr.tan(0.5 * dr.pi * dr.minimum(u, 0.999999)))
            phi = dr.select(q == 0, phi0, dr.select(q == 1, dr.pi - phi0, dr.select(q == 2, dr.pi + phi0, 2 * dr.pi - phi0)))
            sp, cp = dr.sincos(phi)
            e = nu * cp * cp + nv * sp * sp
            om = one_minus_pow(1.0 - s2.y, 1.0 / (e + 1.0))
            cos = 1.0 - om
            sin = dr.safe_sqrt(om * (2.0 - om))
            h = mi.Vector3f(sin * cp, sin * sp, cos)
            return mi.reflect(wi, h)
        raise ValueError(lobe.kind)

    def pdf_lobe(lobe, wi, wo):
        if lobe.kind == "cosine":
            return mi.warp.square_to_cosine_hemisphere_pdf(wo)
        if lobe.kind in ("ggx", "beckmann"):
            m = dr.normalize(wi + wo)
            dwm = dr.dot(wo, m)
            return dr.select(dwm > 0, microfacet(lobe).pdf(wi, m) / (4.0 * dr.maximum(dwm, 1e-12)), 0.0)
        if lobe.kind == "power":
            n = lobe.shape[0]
            c = dr.dot(power_axis(lobe, wi), wo)
            return dr.select(c > 0, (n + 1.0) / (2.0 * dr.pi) * dr.power(dr.maximum(c, 1e-30), n), 0.0)
        if lobe.kind == "half_power":
            nu, nv = lobe.shape
            h = dr.normalize(wi + wo)
            sxy = h.x * h.x + h.y * h.y
            e = dr.select(sxy > 1e-20, (nu * h.x * h.x + nv * h.y * h.y) / dr.maximum(sxy, 1e-20), 0.5 * (nu + nv))
            ph = math.sqrt((nu + 1.0) * (nv + 1.0)) / (2.0 * dr.pi) * dr.power(dr.maximum(h.z, 1e-30), e)
            dih = dr.dot(wi, h)
            return dr.select((dih > 0) & (h.z > 0), ph / (4.0 * dr.maximum(dih, 1e-12)), 0.0)
        raise ValueError(lobe.kind)

    return mi, dr, sample_lobe, pdf_lobe


class Mixture:
    """Sampling density of one BSDF: lobes and their weights over the view angle (see module doc)."""

    def __init__(self, lobes: list[Lobe], weights: np.ndarray):
        self.lobes = list(lobes)
        self.weights = np.asarray(weights, np.float64)  # (K, len(COS_NODES))
        self._rows = [tuple(float(x) for x in row) for row in self.weights]

    @classmethod
    def cosine(cls) -> "Mixture":
        return cls([Lobe("cosine")], np.ones((1, len(COS_NODES))))

    @classmethod
    def for_model(cls, model, params) -> "Mixture":
        lobes = model_lobes(model, params)
        w = lobe_weights(model, params, lobes)  # may append a cosine lobe
        keep = [k for k in range(len(lobes)) if w[k].max() > 0]
        return cls([lobes[k] for k in keep], w[keep])

    def __repr__(self) -> str:
        parts = [f"{lobe.kind}{tuple(round(x, 4) for x in lobe.shape)}: {w.mean():.3f}" for lobe, w in zip(self.lobes, self.weights)]
        return "Mixture(" + ", ".join(parts) + ")"

    def _weights(self, mi, dr, cos_wi):
        """Per-lane lobe probabilities, piecewise linear in cos theta of wi between COS_NODES."""
        if isinstance(cos_wi, float):  # a scalar variant: one ray, plain numbers (the same function)
            c = min(max(cos_wi, _NODES[0]), 1.0)
            j = bisect.bisect_left(_NODES, c) - 1  # the last node below c (-1: c is the first node)
            if j < 0:
                return [row[0] for row in self._rows]
            t = (c - _NODES[j]) / (_NODES[j + 1] - _NODES[j])
            return [row[j] + t * (row[j + 1] - row[j]) for row in self._rows]
        c = dr.clip(cos_wi, COS_NODES[0], 1.0)
        out = []
        for row in self.weights:
            w = mi.Float(float(row[0]))
            for j in range(len(COS_NODES) - 1):
                c0, c1 = float(COS_NODES[j]), float(COS_NODES[j + 1])
                t = (c - c0) / (c1 - c0)
                w = dr.select((c > c0), float(row[j]) + t * float(row[j + 1] - row[j]), w)
            out.append(w)
        return out

    def pdf(self, variant: str, wi, wo):
        mi, dr, _, pdf_lobe = _pdf_tools(variant)
        ws = self._weights(mi, dr, wi.z)
        total = 0.0 if isinstance(wi.z, float) else mi.Float(0.0)
        for lobe, w in zip(self.lobes, ws):
            total = total + w * pdf_lobe(lobe, wi, wo)
        return dr.select((wi.z > 0) & (wo.z > 0), total, 0.0)

    def sample(self, variant: str, wi, s1, s2):
        """A direction wo: lobe chosen by s1 (cumulative weights), direction by s2."""
        mi, dr, sample_lobe, _ = _pdf_tools(variant)
        ws = self._weights(mi, dr, wi.z)
        if isinstance(s1, float):  # one ray: draw from the chosen lobe only
            k, acc = 0, ws[0]
            while k + 1 < len(ws) and s1 >= acc:
                k += 1
                acc += ws[k]
            return sample_lobe(self.lobes[k], wi, s2)
        wo = sample_lobe(self.lobes[0], wi, s2)
        acc = ws[0]
        for lobe, w in zip(self.lobes[1:], ws[1:]):
            wo = dr.select(s1 >= acc, sample_lobe(lobe, wi, s2), wo)
            acc = acc + w
        return wo


@functools.cache
def mixture_sampling(variant: str):
    """``pdf``, ``eval_pdf`` and ``sample`` of brdffit's Python BSDFs (as a class whose methods they
    take over: nanobind classes take one base only): directions drawn from the lobe mixture
    ``self.mixture``, values from ``self._eval_cos(si, wo, active)`` (f_r cos theta_light, a spectrum
    of the variant); a sample's weight is eval / pdf."""
    mi, dr, sample_lobe, pdf_lobe = _pdf_tools(variant)
    scalar = variant.startswith("scalar")
    glossy = mi.UInt32(+mi.BSDFFlags.GlossyReflection)

    class MixtureSampling:
        def pdf(self, ctx, si, wo, active=True):
            return dr.select(active, self.mixture.pdf(variant, si.wi, wo), 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_cos(si, wo, active), self.pdf(ctx, si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            wo = self.mixture.sample(variant, si.wi, sample1, sample2)
            bs = dr.zeros(mi.BSDFSample3f) if scalar else dr.zeros(mi.BSDFSample3f, dr.width(wo))
            bs.wo = wo
            bs.pdf = self.mixture.pdf(variant, si.wi, wo)
            bs.eta = 1.0
            bs.sampled_type = glossy
            bs.sampled_component = mi.UInt32(0)
            ok = active & (bs.pdf > 0) & (mi.Frame3f.cos_theta(si.wi) > 0) & (mi.Frame3f.cos_theta(wo) > 0)
            value = self._eval_cos(si, wo, ok)
            return bs, dr.select(ok, value / dr.maximum(bs.pdf, 1e-20), 0.0)

    return MixtureSampling


def bsdf_class_setup(variant: str):
    """(mi, dr, scalar, sampling) for a Python BSDF class of ``variant``, which must be the active
    one: the Mitsuba and Dr.Jit modules, whether it is a scalar variant, :func:`mixture_sampling`."""
    from .._mitsuba import user_mitsuba

    mi = user_mitsuba()
    if mi.variant() != variant:
        raise RuntimeError(f"brdffit: Mitsuba variant is {mi.variant()!r}, not {variant!r}")
    import drjit as dr

    return mi, dr, variant.startswith("scalar"), mixture_sampling(variant)
