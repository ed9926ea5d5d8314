"""What the explorer computes once per light: the slices' geometry, the table row of the light and
the sphere preview's directions, with the measured sphere.

The sphere preview is the validation render (``brdffit.render_sphere``, docs/validation.md#validation-rendering) evaluated at the
pixel centres instead of rendered: the same framing (orthographic camera on +z, the unit sphere
filling [-1, 1]^2, pixel centres and disc from ``brdffit.render.scene``), the same shading frame
(normal n = the surface point, tangent s = (z, 0, -x) / sqrt(x^2 + z^2), bitangent n x s: see
``brdffit.render.scene``), radiance f_r(l, v) (n . l) per unit irradiance. The fit's sphere takes
f_r from the model, the measured one from the table through the interpolator the Mitsuba
reference uses (``brdffit.render.tabulated``). Only the box filter over each pixel's footprint is
left out, so the preview differs from a render at the silhouette and at sharp highlights.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import UsageError
from ..grid import ubo_directions
from ..plot.polar import SliceGeometry, slice_geometry
from ..render.scene import disc_mask, pixel_centres

#: Pixels across the sphere preview.
SPHERE_SIZE = 128


def light_direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def checked_light(light) -> tuple[float, float]:
    """(theta, phi) in degrees, theta in [0, 90), phi taken into [0, 360); else one ``UsageError``."""
    try:
        theta, phi = (float(x) for x in light)
    except (TypeError, ValueError):
        raise UsageError(f"light must be (theta, phi) in degrees, got {light!r}") from None
    if not (np.isfinite(theta) and np.isfinite(phi)) or not 0.0 <= theta < 90.0:
        raise UsageError(f"light theta must be in degrees in [0, 90), got {theta!r} (a light at or below the "
                         "horizon lights nothing)")
    return theta, phi % 360.0


@dataclasses.dataclass(frozen=True, eq=False)
class SphereDirections:
    """The lit pixels of the preview sphere: flat pixel indices and local directions."""

    size: int
    pixels: np.ndarray  # (n,) flat indices into (size, size)
    wi: np.ndarray  # (n, 3) towards the light, local frame
    wo: np.ndarray  # (n, 3) towards the camera, local frame
    cos_light: np.ndarray  # (n,) n . l

    def image(self, f: np.ndarray) -> np.ndarray:
        """(size, size, 3) radiance from f_r at the lit pixels, (n, C): f_r (n . l), grey for one channel."""
        f = np.asarray(f, np.float64)
        if f.shape[1] == 1:
            f = np.repeat(f, 3, axis=1)
        out = np.zeros((self.size * self.size, 3))
        out[self.pixels] = f[:, :3] * self.cos_light[:, None]
        return out.reshape(self.size, self.size, 3)


def sphere_directions(light: np.ndarray, size: int = SPHERE_SIZE) -> SphereDirections:
    """The preview sphere under the world direction ``light`` (see the module docstring)."""
    x, y = pixel_centres(size)
    inside = disc_mask(size)
    x, y = x[inside], y[inside]
    z = np.sqrt(np.maximum(1.0 - x * x - y * y, 0.0))
    n = np.stack([x, y, z], -1)
    s = np.stack([z, np.zeros_like(z), -x], -1)
    s /= np.maximum(np.linalg.norm(s, axis=1, keepdims=True), 1e-12)
    t = np.cross(n, s)
    cos_light = n @ light
    lit = cos_light > 0
    frame = np.stack([s, t, n], 1)[lit]  # (n, 3, 3): rows s, t, n
    view = np.array([0.0, 0.0, 1.0])
    return SphereDirections(size, np.flatnonzero(inside.reshape(-1))[lit], frame @ light, frame @ view, cos_light[lit])


@dataclasses.dataclass(frozen=True, eq=False)
class Lighting:
    """Everything of the view that depends on the light only."""

    light: tuple[float, float]  # (theta, phi) in degrees, as asked for
    row: int  # the table row (UBO light index) of the light the slices use
    geometry: SliceGeometry
    sphere: SphereDirections
    sphere_measured: np.ndarray  # (size, size, 3) radiance of the measured table's sphere


def lighting(measurement, interpolator, light: tuple[float, float], size: int = SPHERE_SIZE) -> Lighting:
    """The :class:`Lighting` of ``light`` ((theta, phi) degrees) over a UBO-81 measurement, whose
    table ``interpolator`` (``brdffit.render.tabulated.UboInterpolator``) evaluates."""
    theta, phi = light
    geometry = slice_geometry(measurement, np.radians(theta), np.radians(phi))
    row = int(np.argmax(ubo_directions() @ geometry.light))
    sphere = sphere_directions(light_direction(theta, phi), size)
    return Lighting((theta, phi), row, geometry, sphere, sphere.image(interpolator(sphere.wi, sphere.wo)))
