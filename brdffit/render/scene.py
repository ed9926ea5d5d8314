"""The validation scene and its Mitsuba render (docs/validation.md#validation-rendering: framing is normative).

``brdffit.render_sphere`` (:mod:`brdffit.render.renderers`) renders with Mitsuba through
:func:`render_sphere_mitsuba`, with Cycles through :mod:`brdffit.render.cycles`, in this framing.

The scene holds only what a comparison needs: the unit sphere with the BSDF, an orthographic
camera on +z looking down -z with +y up whose film covers exactly [-1, 1]^2 (the sphere fills the
frame), one directional light, the ``direct`` integrator sampling emitters only (no BSDF samples:
a directional light cannot be hit by them), a box pixel filter. All light directions render with
one scene: only the emitter's transform changes between images (``mi.traverse``).

Framing: pixel (row i, column j) has its centre at x = 2(j + 0.5)/size - 1, y = 1 - 2(i + 0.5)/size;
each pixel is the box-filtered average over its footprint; pixels whose centre lies outside the
disc x^2 + y^2 < 1 are set to 0.

Tangent frame (anisotropic models). The sphere is Mitsuba's ``sphere`` shape turned so that its
parameterisation pole points to world +y (``to_world`` = rotation by -90 degrees about x). Mitsuba's
shading frame is then: normal n = (x, y, z) the surface point, tangent s = (z, 0, -x)/sqrt(x^2 + z^2)
(the direction of increasing longitude about +y; at the image centre s = +x, pointing right),
bitangent t = n x s (at the centre t = +y, up). Local phi = 0 is along s. Seen from the camera the
tangents are horizontal along the equator and curve around the poles at the top and bottom of the
disc, like lines of latitude on a globe seen from the side; the degenerate poles lie on the
silhouette, not in the middle of the image.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .._mitsuba import mitsuba
from .bsdf import Source, evaluated_calls

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


#: Samples per pixel (stratified over the pixel footprint) for ``render_sphere``.
DEFAULT_SPP = 4


def light_directions(lights) -> Float[np.ndarray, "L 3"]:
    """Unit world directions (L, 3) towards the lights, from directions (L, 3) or (theta, phi) (L, 2).

    Angles are radians, theta from +z, phi from +x counter-clockwise seen from +z (docs/conventions.md#conventions).
    """
    from ..errors import UsageError

    a = np.asarray(lights, np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2 or a.shape[1] not in (2, 3) or a.shape[0] == 0:
        raise UsageError(f"lights must be (L, 3) directions or (L, 2) (theta, phi) pairs, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise UsageError("light directions must be finite")
    if a.shape[1] == 2:
        t, p = a[:, 0], a[:, 1]
        if np.any(np.abs(a) > 2 * np.pi):
            k = int(np.argmax(np.any(np.abs(a) > 2 * np.pi, axis=1)))
            raise UsageError(f"light (theta, phi) = ({a[k, 0]:g}, {a[k, 1]:g}) is not in radians: degrees? "
                             "use np.radians(...)")
        if np.any((t < 0) | (t > np.pi / 2)):
            k = int(np.argmax((t < 0) | (t > np.pi / 2)))
            raise UsageError(f"light theta = {t[k]:g} rad ({np.degrees(t[k]):.0f} deg) is below the horizon (degrees? use np.radians): "
                             "theta must be in [0, pi/2] (radians, from +z towards the camera)")
        a = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
    norm = np.linalg.norm(a, axis=1, keepdims=True)
    if np.any(norm == 0):
        raise UsageError("light directions must be non-zero")
    a = a / norm
    if np.any(a[:, 2] < -1e-12):
        k = int(np.argmax(a[:, 2] < -1e-12))
        raise UsageError(f"light direction {tuple(float(x) for x in a[k])} is below the horizon (z < 0): the camera "
                         "looks from +z, so lights need z >= 0")
    return a


def pixel_centres(size: int) -> tuple[np.ndarray, np.ndarray]:
    """World (x, y) of the pixel centres, each (size, size), in the framing of docs/validation.md#validation-rendering."""
    c = (np.arange(size) + 0.5) * (2.0 / size) - 1.0
    return np.meshgrid(c, -c)


def disc_mask(size: int) -> np.ndarray:
    """Pixels whose centre lies on the sphere's disc, (size, size) bool."""
    x, y = pixel_centres(size)
    return x * x + y * y < 1.0


def _look_at(mi, origin, target, up):
    return mi.ScalarTransform4f().look_at(origin=list(map(float, origin)), target=list(map(float, target)), up=list(map(float, up)))


def _light_to_world(mi, d: np.ndarray):
    """Transform of a directional emitter whose light travels along -d (d points to the light)."""
    up = [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0]
    return _look_at(mi, (0.0, 0.0, 0.0), -d, up)


def _sampler(spp: int) -> dict:
    """Stratified (jittered) samples over the pixel footprint when spp is a square (1, 4, 16, ...),
    which Mitsuba's stratified sampler needs, else independent ones."""
    root = int(round(spp**0.5))
    if root * root == spp:
        return {"type": "stratified", "sample_count": spp, "jitter": True}
    return {"type": "independent", "sample_count": spp}


def direct_scene(camera_to_world, width: int, height: int, sampler: dict, shapes: dict, light: np.ndarray,
                 irradiance: float) -> dict:
    """A scene of brdffit's renders: an orthographic camera, the given shapes, one directional light,
    direct illumination only (one emitter sample, no BSDF sample). The validation sphere below and a
    BTF's square (``brdffit.btf.validate``) are the two."""
    mi = mitsuba()
    return {
        "type": "scene",
        "integrator": {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0},
        "sensor": {
            "type": "orthographic",
            "to_world": camera_to_world,
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "pixel_format": "rgb",
                     "rfilter": {"type": "box"}},
            "sampler": sampler,
        },
        **shapes,
        "light": {"type": "directional", "to_world": _light_to_world(mi, light),
                  "irradiance": {"type": "rgb", "value": float(irradiance)}},
    }


def scene_dict(bsdf, size: int, spp: int, irradiance: float, light: np.ndarray) -> dict:
    """The Mitsuba scene description (see the module docstring)."""
    mi = mitsuba()
    # The orthographic camera images [-1, 1]^2 of its local x, y: the unit sphere fills it.
    camera = _look_at(mi, (0, 0, 3), (0, 0, 0), (0, 1, 0))
    # Parameterisation pole to +y: see "Tangent frame" in the module docstring.
    sphere = {"type": "sphere", "to_world": mi.ScalarTransform4f().rotate(axis=[1, 0, 0], angle=-90.0), "bsdf": bsdf}
    return direct_scene(camera, size, size, _sampler(spp), {"sphere": sphere}, light, irradiance)


def render_sphere_mitsuba(src: Source, dirs: np.ndarray, size: int, irradiance: float, spp: int, seed: int,
                          mask: np.ndarray, progress=None) -> np.ndarray:
    """(L, size, size, 3) float32 linear radiance of ``src`` on the validation sphere, zero outside the
    disc: one scene, the light's transform changed between images (``brdffit.render_sphere``, the
    Mitsuba renderer of :mod:`brdffit.render.renderers`)."""
    mi = mitsuba()
    scene = mi.load_dict(scene_dict(src.bsdf, size, int(spp), irradiance, dirs[0]))
    params = mi.traverse(scene)
    out = np.zeros((len(dirs), size, size, 3), np.float32)
    with evaluated_calls():
        for k, d in enumerate(dirs):
            if k > 0:
                params["light.to_world"] = _light_to_world(mi, d)
                params.update()
            img = np.asarray(mi.render(scene, spp=int(spp), seed=int(seed)))
            out[k] = np.where(mask[..., None], img[..., :3], 0.0)
            if progress is not None:
                progress(k + 1, len(dirs))
    return out
