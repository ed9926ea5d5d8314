"""The renderers a sphere is rendered with, behind one registry (docs/validation.md#a-second-renderer-cycles).

A :class:`Renderer` says what it is (``name``, the ``label`` a fit's images get), whether it can
render a source (:meth:`Renderer.check`: one line when it cannot, before any work), what it renders a
source with (:meth:`Renderer.material`: Mitsuba's BSDF, Cycles' Principled settings), whether its
environment is there (:meth:`Renderer.ready`) and the sphere images themselves (:meth:`Renderer.render`),
in the one framing of docs/validation.md#validation-rendering. :data:`RENDERERS` holds Mitsuba (any
source) and Cycles (a ``blender:principled`` fit, through the Blender worker); ``render_sphere``,
``validate`` and the command line take their choices from it, and this is the one module that looks
at a renderer's name. A renderer is one entry here and the module that renders for it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from ..errors import UsageError
from .bsdf import Source, as_source
from .cycles import cycles_material, render_sphere_cycles
from .scene import DEFAULT_SPP, disc_mask, light_directions, render_sphere_mitsuba

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


def _nothing(*_args) -> None:
    return None


def _cycles_ready() -> None:
    from .. import cycles

    cycles.worker()  # no Blender environment: one line


@dataclasses.dataclass(frozen=True)
class Renderer:
    """One renderer of the validation sphere."""

    name: str
    #: appended to a fit's label in a validation's panels ("" for the default renderer)
    label: str
    #: what it renders ``src`` with (raises one UsageError / InputError line where it cannot)
    material: Callable[[Source], object]
    #: ``(src, dirs, size, irradiance, spp, seed, mask, progress)`` -> (L, size, size, 3) float32
    render: Callable[..., np.ndarray]
    #: its environment (a worker process, a library), one line where it is missing
    ready: Callable[[], None] = _nothing

    def check(self, src: Source) -> None:
        """One line (UsageError, InputError) when this renderer cannot render ``src``, before any work."""
        self.material(src)

    def can_render(self, src: Source) -> bool:
        try:
            self.check(src)
        except UsageError:
            return False
        return True


RENDERERS: dict[str, Renderer] = {
    "mitsuba": Renderer("mitsuba", "", material=lambda src: src.bsdf, render=render_sphere_mitsuba),
    "cycles": Renderer("cycles", " (Cycles)", material=cycles_material, render=render_sphere_cycles,
                       ready=_cycles_ready),
}


def names() -> tuple[str, ...]:
    """The renderers' names, the default (Mitsuba, which renders every source) first."""
    return tuple(RENDERERS)


def choices() -> str:
    """The renderers' names as the command line's help gives them: "mitsuba (default) | cycles"."""
    return " | ".join(f"{name} (default)" if k == 0 else name for k, name in enumerate(names()))


def get(renderer: str | Renderer) -> Renderer:
    """The renderer called ``renderer`` (any case), or one UsageError line naming the choices."""
    if isinstance(renderer, Renderer):
        return renderer
    found = RENDERERS.get(str(renderer).strip().lower())
    if found is None:
        raise UsageError(f"renderer {renderer!r}: use one of {', '.join(names())}")
    return found


def render_sphere(
    source,
    lights,
    size: int = 256,
    irradiance: float = 1.0,
    spp: int = DEFAULT_SPP,
    seed: int = 0,
    progress=None,
    renderer: str | Renderer = "mitsuba",
) -> Float[np.ndarray, "L size size 3"]:
    """Linear radiance of the unit sphere under each light, (L, size, size, 3) float32, zero outside
    the disc (docs/validation.md#validation-rendering).

    ``source``: a FitResult, a ``(model_name, params)`` pair, a UBO-81 Measurement, or a path to an
    RGL ``.bsdf`` (or another measurement file). ``lights``: unit world directions towards the
    lights (L, 3), or (theta, phi) pairs in radians (L, 2). ``irradiance``: on a surface facing the
    light. ``spp``: samples per pixel (stratified when a square). ``progress(k, L)`` is called
    after each image. ``renderer``: a name of :data:`RENDERERS`: "mitsuba" (any source) or "cycles"
    (a ``blender:principled`` fit, rendered by Blender's Cycles with its own Principled BSDF:
    :mod:`brdffit.render.cycles`).

    An isotropic BRDF renders f_r(l, v) (n.l) irradiance with n = (x, y, sqrt(1 - x^2 - y^2)),
    v = (0, 0, 1); anisotropic models see the tangent s = (z, 0, -x)/sqrt(x^2 + z^2) (horizontal,
    pointing right at the image centre; see :mod:`brdffit.render.scene`).
    """
    dirs = light_directions(lights)  # bad lights (degrees, below the horizon) fail before any work
    chosen = get(renderer)
    size = int(size)
    if size < 1 or spp < 1:
        raise ValueError("size and spp must be >= 1")
    return chosen.render(as_source(source), dirs, size, irradiance, int(spp), int(seed), disc_mask(size), progress)
