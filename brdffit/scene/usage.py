"""``brdffit.scene_usage``: where a scene looks at a material, and how much each look matters (docs/scene.md#scene-aware-fitting).

How the pairs and their contributions are recorded
--------------------------------------------------
A BSDF plugin sees the directions it is evaluated at, but neither the throughput of the path
that reached it nor the radiance that will arrive along a sampled direction, so a recording
*BSDF* can only guess a pair's share of the image. The integrator knows both. So brdffit renders
the scene once with its own small path tracer (:func:`_trace`, written with Mitsuba's Python
API on the scene's own sensor, shapes, emitters and BSDFs; the same estimator as Mitsuba's
``path`` integrator: next-event estimation plus BSDF sampling, combined with the power
heuristic, no Russian roulette) and records, at every vertex whose BSDF is the material:

- the emitter sample: the pair (towards the sampled emitter, towards where the path came from),
  weight = luminance of ``throughput * f cos / pdf-of-light * MIS``, exactly the term that
  sample adds to its pixel;
- the BSDF sample: the pair (sampled direction, towards where the path came from), weight =
  luminance of everything the path adds to its pixel *after* that vertex (its emitter hit and
  all deeper terms, each already carrying the throughput through this vertex). The tracer keeps
  each path's running sum and subtracts the sum at the vertex from the final one.

Each weight is divided by the samples per pixel, so the weights sum (over one vertex per path)
to the image's luminance sum: "contribution to the image". Pairs that add nothing (a sampled
direction escaping into a black background, a light behind the surface) are not recorded. The
material is the scene's own BSDF (or ``source``, when given), so the recorded directions are
those of the real render. Depth follows the scene's integrator: ``path`` uses its ``max_depth``
(-1 is capped at :data:`MAX_DEPTH_CAP`), ``direct`` is depth 2, other integrators depth 3.

Frames (docs/conventions.md#conventions): Mitsuba's ``si.wi`` points towards where the path came from, i.e. to the
viewer side: it becomes ``wo``; the direction towards the light (emitter sample, or the
sampled continuation) becomes ``wi``. A back-face hit of a two-sided material is mirrored to
the front (both z negated, as Mitsuba's ``twosided`` does).

Weights for a measurement: :meth:`Usage.weights`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import re
import time

import numpy as np

from .._mitsuba import mitsuba
from ..errors import UsageError
from ..grid import half_diff
from ._drjit import python_bsdf_render
from .load import load_scene, replaced, scene_name

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


#: Weight of the pairs the scene does not use, relative to its most used ones: chosen with
#: benchmarks/bench_scene.py, where the scene gains more than the sphere validation loses on every
#: material (results in benchmarks/README.md).
DEFAULT_FLOOR = 0.3
#: Distance (degrees, see Usage.coverage) within which a measured sample covers a scene's pair.
COVERAGE_RADIUS_DEG = 20.0
#: How far beyond the data's largest polar angle a scene's direction still counts as covered.
COVERAGE_MARGIN_DEG = 5.0
#: Path length used for integrators with unbounded depth (``max_depth = -1``).
MAX_DEPTH_CAP = 8
#: Rec. 709 luminance of linear RGB: the scalar a contribution is measured in.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


# --------------------------------------------------------------------------------------------
# Rusinkiewicz coordinates and the density over them


def rusinkiewicz(wi: Float[np.ndarray, "N 3"], wo: Float[np.ndarray, "N 3"]) -> Float[np.ndarray, "N 3"]:
    """(theta_h, theta_d, phi_d) in radians (Rusinkiewicz 1998), phi_d folded into [0, pi/2].

    For an isotropic BRDF phi_d and phi_d + pi describe the same value (reciprocity: swapping wi
    and wo), and phi_d and -phi_d too (mirror symmetry about the plane of incidence), so
    phi_d -> |phi_d| mod pi -> min(phi_d, pi - phi_d) loses nothing.
    """
    theta_h, theta_d, phi_d = half_diff(wi, wo)
    phi_d = np.mod(phi_d, np.pi)
    phi_d = np.minimum(phi_d, np.pi - phi_d)
    return np.stack([theta_h, theta_d, phi_d], -1)


#: Grid of the density: 1 degree cells over theta_h, theta_d in [0, 90] and phi_d in [0, 90].
_CELLS = 91


def _pair_coordinates(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """(smaller theta, larger theta, |dphi| sqrt(sin theta_i sin theta_o)) in degrees: the
    coordinates :meth:`Usage.coverage` measures distances in."""
    ti = np.arccos(np.clip(wi[:, 2], -1.0, 1.0))
    to = np.arccos(np.clip(wo[:, 2], -1.0, 1.0))
    dphi = np.abs(np.mod(np.arctan2(wi[:, 1], wi[:, 0]) - np.arctan2(wo[:, 1], wo[:, 0]) + np.pi, 2 * np.pi) - np.pi)
    arc = dphi * np.sqrt(np.abs(np.sin(ti) * np.sin(to)))
    return np.degrees(np.stack([np.minimum(ti, to), np.maximum(ti, to), arc], -1))


def _histogram(coords: np.ndarray, weight: np.ndarray) -> np.ndarray:
    idx = np.clip(np.rint(np.degrees(coords)).astype(np.int64), 0, _CELLS - 1)
    flat = np.ravel_multi_index(idx.T, (_CELLS,) * 3)
    return np.bincount(flat, weights=weight, minlength=_CELLS**3).reshape((_CELLS,) * 3)


# --------------------------------------------------------------------------------------------
# Usage


@dataclasses.dataclass(frozen=True, eq=False)
class Usage:
    """The (light, view) pairs at which a scene evaluates a material, with their contributions.

    ``wi`` (K, 3) towards the light, ``wo`` (K, 3) towards the viewer, local frame of the
    material (docs/conventions.md#conventions); ``weight`` (K,) the luminance each pair adds to the image (see the
    module docstring); ``emitter_sampled`` (K,) True for emitter samples, False for sampled
    directions. ``pixels``, ``spp``, ``max_depth``, ``seconds``: how it was rendered.
    """

    wi: np.ndarray
    wo: np.ndarray
    weight: np.ndarray
    emitter_sampled: np.ndarray
    scene: str
    material: str
    pixels: tuple[int, int]
    spp: int
    max_depth: int
    seconds: float

    def __len__(self) -> int:
        return int(self.weight.shape[0])

    def __repr__(self) -> str:
        return (
            f"Usage({self.material!r} in {self.scene}: {len(self)} pairs from {self.pixels[0]}x{self.pixels[1]} px "
            f"at {self.spp} spp, depth {self.max_depth}; {self.seconds:.2f} s)"
        )

    def coordinates(self) -> Float[np.ndarray, "K 3"]:
        """The pairs as (theta_h, theta_d, phi_d) radians, phi_d folded (:func:`rusinkiewicz`)."""
        return rusinkiewicz(self.wi, self.wo)

    def sample(self, n: int = 2048, *, seed: int = 0) -> tuple[Float[np.ndarray, "n 3"], Float[np.ndarray, "n 3"]]:
        """``n`` of the recorded pairs (wi, wo), drawn without replacement in proportion to their
        contribution: directions at which to sample a source that can be evaluated anywhere (RGL,
        MERL, UTIA: ``brdffit.load(path, wi=..., wo=...)``), so a fit sees data where the scene
        looks, e.g. beyond the 75 degrees the UBO-81 grid reaches."""
        k = len(self)
        if k == 0:
            raise UsageError(f"{self.scene}: the scene never shows {self.material!r} lit: no pairs to sample")
        rng = np.random.default_rng(seed)
        take = rng.choice(k, size=min(int(n), k), replace=False, p=self.weight / self.weight.sum())
        return self.wi[take].copy(), self.wo[take].copy()

    def density(self, wi, wo, *, bandwidth_deg: float = 5.0) -> Float[np.ndarray, " N"]:
        """Usage density at the pairs (wi, wo), relative to its maximum (in [0, 1]).

        A kernel density estimate over (theta_h, theta_d, phi_d): the weighted pairs are binned
        into 1-degree cells, smoothed with a Gaussian of ``bandwidth_deg`` along each axis
        (reflecting at 0 and 90 degrees, which is what the folds of phi_d and the symmetry of the
        half-vector frame about theta = 0 call for), and read at the asked pairs by trilinear
        interpolation.
        """
        from scipy.ndimage import gaussian_filter, map_coordinates

        if not bandwidth_deg > 0:
            raise UsageError(f"bandwidth_deg must be > 0, got {bandwidth_deg}")
        grid = gaussian_filter(_histogram(self.coordinates(), self.weight), sigma=float(bandwidth_deg), mode="reflect",
                               truncate=3.0)
        peak = grid.max()
        if not peak > 0:
            return np.zeros(np.asarray(wi).reshape(-1, 3).shape[0])
        at = np.degrees(rusinkiewicz(wi, wo)).T
        return np.clip(map_coordinates(grid / peak, at, order=1, mode="nearest"), 0.0, 1.0)

    def weights(self, measurement, *, bandwidth_deg: float = 5.0, floor: float = DEFAULT_FLOOR) -> Float[np.ndarray, " N"]:
        """Sample weights (N,) for ``measurement``'s directions: where this scene looks, floored.

        Parameterisation: Rusinkiewicz's half/difference angles (theta_h, theta_d, phi_d). For the
        isotropic BRDFs brdffit fits they are the natural axes: a specular lobe is narrow along
        theta_h only, Fresnel and shadowing change along theta_d, and reciprocity and mirror
        symmetry fold phi_d into [0, 90] degrees, so a pair and its swapped twin count as one
        (with (theta_i, theta_o, |dphi|) a lobe is a diagonal band and a kernel blurs across it).

        The weight is :meth:`density` (maximum 1) raised to ``floor`` (default
        :data:`DEFAULT_FLOOR`): no sample is dropped (a fit still sees the whole table) unless
        ``floor=0`` is asked. Samples below the
        horizon get the floor too; the fit leaves them out anyway.
        """
        if not 0.0 <= floor <= 1.0:
            raise UsageError(f"floor must be in [0, 1], got {floor}")
        wi = np.asarray(measurement.wi, np.float64)
        wo = np.asarray(measurement.wo, np.float64)
        return np.maximum(self.density(wi, wo, bandwidth_deg=bandwidth_deg), floor)

    def coverage(self, measurement, *, radius_deg: float = COVERAGE_RADIUS_DEG) -> float:
        """The fraction of this usage's weight at pairs the measurement's valid samples cover.

        A pair (theta_i, theta_o, dphi) counts as covered when (1) neither direction lies more than
        ``COVERAGE_MARGIN_DEG`` beyond the data's largest polar angle (UBO-81 stops at 75 degrees:
        a scene that looks at 86 degrees is not covered, however near the 75-degree ring is), and
        (2) a valid sample lies within ``radius_deg`` of it in (theta_i, theta_o, dphi sqrt(sin
        theta_i sin theta_o)) degrees, light and view sorted (reciprocity): the azimuth difference
        weighs as the arc it spans, nothing at the pole, where an isotropic BRDF does not depend on
        it. Within the UBO-81 grid's 75 degrees, a pair lies at most 16 degrees from a sample in these
        units (median 6.5, 99th percentile 11; measured over 200,000 random pairs).
        1 where the data see everything the scene looks at; below 1 where the scene looks beyond
        them: there a scene-weighted fit falls back to the floor weight, i.e. to the plain fit."""
        from scipy.spatial import cKDTree

        total = float(np.sum(self.weight))
        if len(self) == 0 or not total > 0:
            return 1.0
        valid = measurement.valid_mask()
        if not valid.any():
            return 0.0
        data = _pair_coordinates(np.asarray(measurement.wi, np.float64)[valid], np.asarray(measurement.wo, np.float64)[valid])
        pairs = _pair_coordinates(self.wi, self.wo)
        inside = pairs[:, 1] <= data[:, 1].max() + COVERAGE_MARGIN_DEG  # column 1: the larger polar angle
        dist, _ = cKDTree(data).query(pairs, k=1, distance_upper_bound=float(radius_deg))
        return float(np.sum(self.weight[inside & np.isfinite(dist)]) / total)

def fit_data(source, usage: Usage, *, n: int = 2048, seed: int = 0):
    """The measurement to fit for a scene: ``source`` (a path or a Measurement) read as usual, and,
    when it can be evaluated anywhere (RGL, MERL, UTIA ``.bin``: ``brdffit.load`` takes ``wi, wo``),
    sampled at the UBO-81 pairs *plus* ``n`` pairs drawn from ``usage`` (:meth:`Usage.sample`),
    so the fit has data where the scene looks even beyond the grid's 75 degrees."""
    from pathlib import Path

    from ..grid import ubo_pairs
    from ..io import detect_format, load
    from ..measurement import Measurement

    if isinstance(source, Measurement):
        return source
    path = Path(source)
    if detect_format(path) not in ("rgl", "merl", "utia"):
        return load(path)
    uwi, uwo = ubo_pairs()
    swi, swo = usage.sample(n, seed=seed)
    return load(path, wi=np.concatenate([uwi, swi]), wo=np.concatenate([uwo, swo]))


# --------------------------------------------------------------------------------------------
# Rendering the scene and recording


def integrator_depth(integrator) -> int:
    """Path length the scene's integrator renders (see the module docstring)."""
    text = str(integrator)
    m = re.search(r"max_depth\s*=\s*(-?\d+)", text)
    if m:
        depth = int(m.group(1))
        return MAX_DEPTH_CAP if depth < 0 else min(depth, MAX_DEPTH_CAP)
    if text.startswith("DirectIntegrator"):
        return 2
    return 3


def _np(x) -> np.ndarray:
    return np.asarray(x)


def _vec(v) -> np.ndarray:
    return np.stack([np.asarray(v.x, np.float64), np.asarray(v.y, np.float64), np.asarray(v.z, np.float64)], -1)


def _lum(spectrum) -> np.ndarray:
    return np.stack([np.asarray(spectrum[c], np.float64) for c in range(3)], -1) @ LUMINANCE


def _trace(scene, target, spp: int, seed: int, max_depth: int):
    """Render ``scene`` with the path tracer of the module docstring; return the records (NumPy)."""
    mi = mitsuba()
    import drjit as dr

    sensor = scene.sensors()[0]
    film = sensor.film()
    size = film.crop_size()
    offset = film.crop_offset()
    width, height = int(size[0]), int(size[1])
    n = width * height * spp
    sampler = mi.load_dict({"type": "independent", "sample_count": spp})
    sampler.seed(seed, n)

    idx = dr.arange(mi.UInt32, n) // spp
    pos = mi.Vector2f(mi.Float(idx % width), mi.Float(idx // width)) + sampler.next_2d()
    pos = (pos + mi.Vector2f(offset)) / mi.Vector2f(film.size())
    aperture = sampler.next_2d()
    t = sensor.shutter_open() + sampler.next_1d() * sensor.shutter_open_time()
    ray, ray_weight = sensor.sample_ray(t, sampler.next_1d(), pos, aperture)

    ctx = mi.BSDFContext()
    target_ptr = mi.BSDFPtr(target)
    beta = mi.Spectrum(ray_weight)
    L = mi.Spectrum(0.0)
    active = mi.Bool(True)
    prev_si = None
    prev_pdf = mi.Float(1.0)
    prev_delta = mi.Bool(True)

    def mis(a, b):
        a2, b2 = a * a, b * b
        return dr.select(a2 + b2 > 0, a2 / (a2 + b2), 0.0)

    emitter_records = []  # (wi, wo, weight)
    pending = []  # (lanes, wi, wo, L at the vertex): BSDF samples waiting for the final sums
    for depth in range(max_depth):
        si = scene.ray_intersect(ray, active)
        # emission arriving along the path (the previous vertex's BSDF sample), MIS-weighted
        if depth == 0:
            L += dr.select(active, beta * si.emitter(scene).eval(si, active), 0.0)
        else:
            ds = mi.DirectionSample3f(scene, si, prev_si)
            em_pdf = dr.select(prev_delta, 0.0, scene.pdf_emitter_direction(prev_si, ds, active & ~prev_delta))
            L += dr.select(active, beta * mis(prev_pdf, em_pdf) * ds.emitter.eval(si, active & (prev_pdf > 0)), 0.0)
        active_next = active & si.is_valid() & (depth + 1 < max_depth)
        if depth + 1 >= max_depth:
            break
        bsdf = si.bsdf(ray)
        on_target = active_next & (bsdf == target_ptr)

        # next-event estimation
        active_em = active_next & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        ds, em_weight = scene.sample_emitter_direction(si, sampler.next_2d(), True, active_em)
        active_em &= ds.pdf != 0.0
        wo_local = si.to_local(ds.d)
        bsdf_val, bsdf_pdf = bsdf.eval_pdf(ctx, si, wo_local, active_em)
        mis_em = dr.select(ds.delta, 1.0, mis(ds.pdf, bsdf_pdf))
        direct = dr.select(active_em, beta * bsdf_val * em_weight * mis_em, 0.0)
        L += direct
        rec = _np(on_target & active_em)
        if rec.any():
            emitter_records.append((_vec(wo_local)[rec], _vec(si.wi)[rec], _lum(direct)[rec]))

        # BSDF sampling: the continuation
        bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), active_next)
        dr.eval(L, bs.wo, bs.pdf, bsdf_weight)
        rec = _np(on_target & (bs.pdf > 0))
        if rec.any():
            lanes = np.flatnonzero(rec)
            pending.append((lanes, _vec(bs.wo)[rec], _vec(si.wi)[rec], _lum(L)[lanes]))
        ray = si.spawn_ray(si.to_world(bs.wo))
        beta *= bsdf_weight
        prev_si = mi.Interaction3f(si)
        prev_pdf = bs.pdf
        prev_delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        active = active_next & (bs.pdf > 0) & (dr.max(beta) > 0)
        dr.eval(ray, beta, prev_si, prev_pdf, prev_delta, active)

    final = _lum(L)
    wi_all, wo_all, w_all, em_all = [], [], [], []
    for wi, wo, w in emitter_records:
        wi_all.append(wi), wo_all.append(wo), w_all.append(w), em_all.append(np.ones(len(w), bool))
    for lanes, wi, wo, before in pending:
        wi_all.append(wi), wo_all.append(wo), w_all.append(final[lanes] - before), em_all.append(np.zeros(len(lanes), bool))
    if not w_all:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, bool), (width, height)
    return (np.concatenate(wi_all), np.concatenate(wo_all), np.concatenate(w_all) / spp, np.concatenate(em_all),
            (width, height))


def scene_usage(scene, material: str, *, spp: int = 16, seed: int = 0, source=None, max_depth: int | None = None) -> Usage:
    """Render ``scene`` once and record where it looks at the BSDF with id ``material`` (docs/scene.md#scene-aware-fitting).

    ``scene``: a Mitsuba 3 XML path, a scene dict or an ``mi.Scene``. ``spp``: paths per pixel.
    ``source``: render the material as this BRDF instead of the scene's own (a FitResult, a
    ``(model, params)`` pair, a UBO-81 Measurement or an RGL ``.bsdf`` path), e.g. the measured
    reference, so that the weights follow the real material's highlights. ``max_depth``: path
    length, default the scene integrator's. See the module docstring for what is recorded.
    """
    if int(spp) < 1:
        raise UsageError(f"spp must be >= 1, got {spp}")
    t0 = time.perf_counter()
    loaded = load_scene(scene, material)
    depth = integrator_depth(loaded.scene.integrator()) if max_depth is None else int(max_depth)
    if depth < 2:
        raise UsageError(f"max_depth must be >= 2 (a path needs a vertex on the material and a light), got {depth}")
    with python_bsdf_render():
        if source is None:
            records = _trace(loaded.scene, loaded.original, int(spp), int(seed), depth)
        else:
            from .render import source_bsdf

            bsdf = source_bsdf(source)
            with replaced(loaded, bsdf) as sc:
                records = _trace(sc, loaded.shapes[0].bsdf(), int(spp), int(seed), depth)
            del bsdf
    del loaded
    wi, wo, w, em, pixels = records
    # two-sided materials: a back-face vertex mirrored to the front; then reflection only
    back = wo[:, 2] < 0
    wi[back, 2] *= -1
    wo[back, 2] *= -1
    keep = (wi[:, 2] > 0) & (wo[:, 2] > 0) & (w > 0) & np.isfinite(w)
    wi = wi[keep] / np.linalg.norm(wi[keep], axis=1, keepdims=True)
    wo = wo[keep] / np.linalg.norm(wo[keep], axis=1, keepdims=True)
    return Usage(wi=wi, wo=wo, weight=w[keep], emitter_sampled=em[keep], scene=scene_name(scene), material=material,
                 pixels=pixels, spp=int(spp), max_depth=depth, seconds=time.perf_counter() - t0)


def cli_usage(source: str, scene: str | None, material: str | None):
    """``brdffit fit SOURCE --scene S --material ID``: (measurement to fit, usage), or UsageError."""
    if scene is None or material is None:
        raise UsageError("--scene and --material go together: the scene file and the id of the BSDF to fit for")
    usage = scene_usage(scene, material, source=source)
    if len(usage) == 0:
        from ..errors import InputError

        raise InputError(scene, f"the scene never shows {material!r} lit (no light reaches the camera through it)")
    return fit_data(source, usage), usage
