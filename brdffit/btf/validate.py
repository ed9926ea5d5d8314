"""``brdffit.validate_btf``: fitted parameter maps rendered in Mitsuba 3 beside the BTF's own
photographs (docs/btf.md#btfs-per-texel-fitting).

The scene holds only what this comparison needs: a square (Mitsuba's ``rectangle``, [-1, 1]^2 in
the plane z = 0, normal +z, texture coordinates u = (x + 1)/2, v = (y + 1)/2) carrying the maps, an
orthographic camera, one directional light, the ``direct`` integrator sampling emitters only, a
box filter and one sample per pixel at its centre (stratified, no jitter).

Geometry. A BTF photograph of the pair (light, view) is *rectified*: texel (r, c) of the texture
at pixel (r, c), whatever the view. So the camera looks along -view, but its film is sheared
onto the square: its to-world transform maps film x, y to world x, y (as a camera on +z would)
and its z axis to -view, so every ray leaves the point (x, y) + 3 view towards -view and hits the
square at (x, y). The image is then rectified exactly like the photograph, one pixel per texel,
and every pixel sees the view direction of the pair. The light is directional along the pair's
light direction with irradiance 1 / cos(theta_light) on a surface facing it, so a pixel's
radiance, f_r(l, v) cos(theta_light) / cos(theta_light), is f_r itself: the quantity the BTF
stores (``load_btf`` already divides out cos(theta_light) for ``includes_cos`` data).

The BSDF evaluates the model's own JAX formula (``model.eval``, the one definition) with each
lane's texel parameters: it reuses the callback BSDF of :mod:`brdffit.render.bsdf` (evaluated
Dr.Jit calls, the docs/conventions.md#conventions direction conventions at the boundary) and adds the texture lookup
(nearest texel of ``si.uv``; row 0 at the top, v = 1).

Metrics per pair (:mod:`brdffit.render.metrics`): RMSE and relative RMSE of f_r over the texels,
PSNR and FLIP of the tone-mapped images (exposure from the photograph). Files (``out``, atomic):
``photo_<pair>.exr``, ``render_<pair>.exr`` (linear f_r), ``panel_<pair>.png`` (photograph |
render | error), ``metrics.json``. ``<pair>`` is ``tlTTT_plPPP_tvTTT_pvPPP``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import UsageError
from ..grid import UBO_SIZE, ubo_directions, ubo_index
from ..io.images import direction_name
from .maps import ParameterMaps
from .reader import BTF

#: Default (light, view) pairs in degrees ((theta, phi), (theta, phi)): head-on, two mirror
#: configurations (the specular peak), an off-specular and a grazing one.
DEFAULT_PAIRS_DEG = (
    ((0, 0), (0, 0)),
    ((30, 0), (30, 180)),
    ((45, 60), (15, 240)),
    ((60, 90), (60, 270)),
    ((75, 0), (45, 100)),
)
#: Lanes per call of the jitted per-texel model (one compilation serves every render).
CHUNK = 1 << 14


def pair_indices(pairs) -> list[tuple[int, int]]:
    """(light, view) UBO indices from index pairs, or from ((tl, pl), (tv, pv)) degree pairs."""
    out = []
    for p in pairs:
        a, b = p
        if np.ndim(a) == 0 and np.ndim(b) == 0:
            light, view = int(a), int(b)
            if not (0 <= light < UBO_SIZE and 0 <= view < UBO_SIZE):
                raise UsageError(f"pair {p}: indices must be in 0..80")
        else:
            try:
                light, view = ubo_index(int(a[0]), int(a[1])), ubo_index(int(b[0]), int(b[1]))
            except KeyError:
                raise UsageError(f"pair {p}: not a direction pair of the UBO-81 grid (degrees)") from None
        out.append((light, view))
    if not out:
        raise UsageError("no (light, view) pairs to validate")
    return out


def textured_bsdf(maps: ParameterMaps):
    """A Mitsuba BSDF rendering ``maps``: brdffit's map BSDF (``brdffit.mitsuba_bsdf`` with
    parameter maps: the model's JAX formula at the nearest texel's parameters). Texel rows run
    top to bottom in the BTF's images, upwards in the square's v coordinate, hence the flip."""
    from ..render.export import mitsuba_bsdf

    return mitsuba_bsdf(maps.model, {name: np.asarray(v, np.float64)[::-1] for name, v in maps.params.items()})


def _camera_to_world(mi, view: np.ndarray):
    """Orthographic camera whose film covers [-1, 1]^2 of the square, rays along -view (sheared)."""
    base = np.asarray(mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0], up=[0, 1, 0]).matrix, np.float64)
    m = base.copy()
    m[:3, 2] = -view  # the camera's z axis: the direction its rays travel
    m[:3, 3] = 3.0 * view
    return mi.ScalarTransform4f(m.tolist())


def scene_dict(bsdf, height: int, width: int, light: np.ndarray, view: np.ndarray) -> dict:
    from .._mitsuba import mitsuba
    from ..render.scene import direct_scene

    sampler = {"type": "stratified", "sample_count": 1, "jitter": False}
    return direct_scene(_camera_to_world(mitsuba(), view), width, height, sampler,
                        {"square": {"type": "rectangle", "bsdf": bsdf}}, light, 1.0 / light[2])


def render_maps(maps: ParameterMaps, pairs) -> np.ndarray:
    """f_r images (P, H, W, 3) of the maps rendered for each (light, view) pair (indices or degrees)."""
    from .._mitsuba import mitsuba
    from ..render.bsdf import evaluated_calls
    mi = mitsuba()
    idx = pair_indices(pairs)
    dirs = ubo_directions()
    h, w = maps.shape
    bsdf = textured_bsdf(maps)
    out = np.zeros((len(idx), h, w, 3), np.float32)
    with evaluated_calls():
        for k, (light, view) in enumerate(idx):
            # A scene per pair (the camera's shear and the light change); the BSDF is made once.
            scene = mi.load_dict(scene_dict(bsdf, h, w, dirs[light], dirs[view]))
            out[k] = np.asarray(mi.render(scene, spp=1, seed=0))[..., :3]
    return out


@dataclasses.dataclass(frozen=True, eq=False)
class BTFValidation:
    pairs: list  # (light, view) indices
    photos: np.ndarray  # (P, H, W, 3) f_r of the BTF
    renders: np.ndarray  # (P, H, W, 3)
    metrics: dict  # "pairs": [...], "overall": {...}
    files: tuple
    seconds: dict

    def __repr__(self) -> str:
        o = self.metrics["overall"]
        return (f"BTFValidation({len(self.pairs)} pairs: rmse {o['rmse']:.4g}, psnr {o['psnr']:.2f} dB "
                f"(worst {o['psnr_min']:.2f}), flip {o['flip']:.4f})")

    def _repr_png_(self) -> bytes:
        from ..plot import btf_panel, png_bytes

        return png_bytes(btf_panel(self.photos, self.renders, [direction_name(*p) for p in self.pairs],
                                   self.metrics["pairs"]))


def validate_btf(btf: BTF, maps, pairs=DEFAULT_PAIRS_DEG, *, out=None, force: bool = False) -> BTFValidation:
    """Render ``maps`` (ParameterMaps or a params.exr path) for each (light, view) pair and compare
    with ``btf``'s photographs; see the module docstring."""
    from ..plot import btf_panel
    from ..render.metrics import image_metrics
    from ..render.outputs import ValidationRun

    run = ValidationRun(out, force)  # checks the output folder before the work
    if not isinstance(maps, ParameterMaps):
        maps = ParameterMaps.load(maps)
    if tuple(maps.shape) != tuple(btf.shape):
        raise UsageError(f"the maps have {maps.shape[0]} x {maps.shape[1]} texels, the BTF {btf.height} x {btf.width}")
    idx = pair_indices(pairs)
    photos = np.stack([btf.image(light, view) for light, view in idx]).astype(np.float64)
    if photos.shape[-1] == 1:
        photos = np.repeat(photos, 3, axis=-1)
    run.lap("read photographs")
    renders = render_maps(maps, idx)
    run.lap("render")
    mask = np.ones(btf.shape, bool)
    per = []
    for k, (light, view) in enumerate(idx):
        m = image_metrics(photos[k], renders[k], mask)
        per.append({"pair": direction_name(light, view), "light": light, "view": view,
                    **{key: v for key, v in m.items() if not key.startswith("_")}, "_mse": m["_mse_tonemapped"]})
    d = renders.astype(np.float64) - photos
    rms_ref = float(np.sqrt(np.mean(photos**2)))
    mse_t = float(np.mean([p["_mse"] for p in per]))
    overall = {"rmse": float(np.sqrt(np.mean(d * d))), "rel_rmse": float(np.sqrt(np.mean(d * d))) / rms_ref if rms_ref else float("nan"),
               "psnr": float(10 * np.log10(1 / mse_t)) if mse_t > 0 else float("inf"),
               "psnr_min": float(min(p["psnr"] for p in per)), "flip": float(np.mean([p["flip"] for p in per]))}
    for p in per:
        p.pop("_mse")
    metrics = {"pairs": per, "overall": overall, "model": maps.model, "btf": btf.name,
               "texels": [btf.height, btf.width]}
    with run.folder():
        for k, (light, view) in enumerate(idx if run.writing else ()):
            name = direction_name(light, view)
            run.exr(f"photo_{name}.exr", photos[k], "zip")
            run.exr(f"render_{name}.exr", renders[k], "zip")
            run.png(f"panel_{name}.png", btf_panel(photos[k : k + 1], renders[k : k + 1], [name], per[k : k + 1]))
        run.metrics_json({**metrics, "seconds": {**run.seconds, "total": run.total()}})
    seconds = {**run.seconds, "total": run.total()}
    return BTFValidation(pairs=idx, photos=photos, renders=renders, metrics=metrics, files=tuple(run.files),
                         seconds=seconds)
