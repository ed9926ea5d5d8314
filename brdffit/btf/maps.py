"""``ParameterMaps``: the result of a per-texel fit (docs/btf.md#btfs-per-texel-fitting), and its files.

``params.exr`` is a multi-part OpenEXR (OpenEXR 3.5 Python API): one part per model parameter,
named after it, channels ``R,G,B`` (a parameter with one value per colour channel) or ``Y``,
32-bit float; then the parts ``loss`` (the fit's loss value per texel), ``converged`` (1 or 0)
and ``steps`` (solver iterations), channel ``Y``. Every part's header holds ``brdffit_model``,
``brdffit_loss`` and ``brdffit_solver``, so the file alone is enough to render the maps
(``brdffit validate-btf``). Previews: ``preview_<name>.png`` per map (colour parameters as an
RGB image scaled by their 99th percentile and sRGB-encoded, the others through viridis between
their 1st and 99th percentiles) and ``maps.png`` (all maps with colour bars). ``summary.json``:
model, loss, solver, texels, converged count, per-parameter and loss statistics (min, median, mean,
max), timing.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

from .._files import atomic_file
from ..errors import InputError

STAT_MAPS = ("loss", "converged", "steps")


@dataclasses.dataclass(frozen=True, eq=False)
class ParameterMaps:
    """Per-texel fitted parameters: ``params[name]`` is (H, W, size) float64 (size 1 or 3),
    ``loss`` (H, W) float64, ``converged`` (H, W) bool, ``steps`` (H, W) int."""

    model: str
    params: dict
    loss: np.ndarray
    converged: np.ndarray
    steps: np.ndarray
    loss_name: str = "log"
    solver: str = ""
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.loss.shape)

    def texel_params(self, row: int, col: int) -> dict[str, np.ndarray]:
        return {k: np.asarray(v[row, col]) for k, v in self.params.items()}

    def maps(self) -> dict[str, np.ndarray]:
        """Every map as (H, W, size), parameters first, then loss / converged / steps."""
        out = {k: np.asarray(v) for k, v in self.params.items()}
        out.update({"loss": self.loss[..., None], "converged": self.converged[..., None].astype(np.float64),
                    "steps": self.steps[..., None].astype(np.float64)})
        return out

    def summary(self) -> dict:
        def stats(a):
            a = np.asarray(a, np.float64)
            return {"min": float(a.min()), "median": float(np.median(a)), "mean": float(a.mean()), "max": float(a.max())}

        return {
            "model": self.model, "loss": self.loss_name, "solver": self.solver,
            "texels": int(self.loss.size), "height": self.shape[0], "width": self.shape[1],
            "converged": int(self.converged.sum()),
            "loss_value": stats(self.loss), "steps": stats(self.steps),
            "params": {k: stats(v) for k, v in self.params.items()},
            **self.info,
        }

    # files --------------------------------------------------------------------------------------
    def save_exr(self, path, force: bool = False) -> Path:
        import OpenEXR

        head = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage,
                "brdffit_model": self.model, "brdffit_loss": self.loss_name, "brdffit_solver": self.solver,
                # how the BTF was read (region, step, scale ...), so that validate-btf reads it alike
                "brdffit_btf_options": json.dumps(self.info.get("btf_options", {}), default=_plain)}
        parts = []
        for name, a in self.maps().items():
            a = np.ascontiguousarray(a, np.float32)
            chans = {"RGB": a} if a.shape[-1] == 3 else {"Y": np.ascontiguousarray(a[..., 0])}
            parts.append(OpenEXR.Part(dict(head), chans, name))
        with atomic_file(path, force=force, suffix=".exr") as tmp:
            OpenEXR.File(parts).write(str(tmp))
        return Path(path)

    @classmethod
    def load(cls, path) -> "ParameterMaps":
        """Read a ``params.exr`` written by :meth:`save_exr`."""
        import OpenEXR

        path = Path(path)
        if not path.is_file():
            raise InputError(path, "no such file")
        try:
            f = OpenEXR.File(str(path), separate_channels=True)
            parts = [(p.name(), p.header, p.channels) for p in f.parts]
        except Exception as exc:  # noqa: BLE001 - the library's message on one line
            raise InputError(path, f"unreadable OpenEXR: {' '.join(str(exc).split())[:200]}") from None
        head = parts[0][1]
        if "brdffit_model" not in head:
            raise InputError(path, "not a brdffit parameter map (no brdffit_model in the header)")
        arrays = {}
        for name, _, chans in parts:
            if {"R", "G", "B"} <= set(chans):
                arrays[name] = np.stack([np.asarray(chans[c].pixels, np.float64) for c in "RGB"], -1)
            elif "Y" in chans:
                arrays[name] = np.asarray(chans["Y"].pixels, np.float64)[..., None]
            else:
                raise InputError(path, f"part {name!r} has neither R,G,B nor Y channels")
        missing = [k for k in STAT_MAPS if k not in arrays]
        if missing:
            raise InputError(path, f"missing part(s) {', '.join(missing)}")
        model = str(head["brdffit_model"])
        from .. import models

        try:
            mdl = models.get(model)
        except KeyError:
            raise InputError(path, f"unknown model {model!r} in the header") from None
        params = {}
        for p in mdl.params:
            if p.name not in arrays:
                raise InputError(path, f"no part for parameter {p.name!r} of {model}")
            params[p.name] = arrays[p.name]
        return cls(model=model, params=params, loss=arrays["loss"][..., 0], converged=arrays["converged"][..., 0] > 0.5,
                   steps=arrays["steps"][..., 0].astype(int), loss_name=str(head.get("brdffit_loss", "")),
                   solver=str(head.get("brdffit_solver", "")),
                   info={"file": str(path), "btf_options": json.loads(str(head.get("brdffit_btf_options", "{}")) or "{}")})

    def save(self, folder, force: bool = False) -> list[Path]:
        """preview_<name>.png, maps.png, summary.json and params.exr in ``folder``, each atomic;
        params.exr last, so that its presence means a complete result."""
        from ..plot import map_preview_png

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        files = []
        for name, a in self.maps().items():
            target = folder / f"preview_{name}.png"
            with atomic_file(target, force=force, suffix=".png") as tmp:
                map_preview_png(a, tmp)
            files.append(target)
        with atomic_file(folder / "maps.png", force=force, suffix=".png") as tmp:
            tmp.write_bytes(self._repr_png_())
        files.append(folder / "maps.png")
        with atomic_file(folder / "summary.json", force=force, suffix=".json") as tmp:
            tmp.write_text(json.dumps(self.summary(), indent=2, default=_plain) + "\n")
        files.append(folder / "summary.json")
        files.append(self.save_exr(folder / "params.exr", force=force))
        return files

    def export(self, path, *, bsdf_id: str | None = None, force: bool = False, source=None) -> list[Path]:
        """The maps of a native model as the renderer's own material with every map a texture
        (docs/btf.md#btfs-per-texel-fitting and docs/materials.md#native-materials-and-exports), the extension picking the format: ``.xml`` Mitsuba 3 (textures in
        ``<stem>_textures/`` beside it), ``.glb``/``.gltf`` glTF 2.0, ``.blend`` Blender. Returns the
        paths written; see :mod:`brdffit.materials.textured`."""
        from ..materials.textured import export_maps

        return export_maps(self, path, bsdf_id=bsdf_id, force=force,
                           source=source if source is not None else self.info.get("file"))

    # display ------------------------------------------------------------------------------------
    def _repr_png_(self) -> bytes:
        from ..plot import parameter_maps, png_bytes

        return png_bytes(parameter_maps(self))

    def _repr_html_(self) -> str:
        import base64

        s = self.summary()
        rows = "".join(f"<tr><td>{k}</td><td>{v['min']:.4g}</td><td>{v['mean']:.4g}</td><td>{v['max']:.4g}</td></tr>"
                       for k, v in {**s["params"], "loss": s["loss_value"], "steps": s["steps"]}.items())
        img = base64.b64encode(self._repr_png_()).decode()
        return (f"<div><b>ParameterMaps</b> {self.model} ({self.loss_name} loss): {s['height']} x {s['width']} texels, "
                f"{s['converged']} converged<table><tr><th>map</th><th>min</th><th>mean</th><th>max</th></tr>{rows}"
                f"</table><img src='data:image/png;base64,{img}'/></div>")

    def __repr__(self) -> str:
        return (f"ParameterMaps({self.model}, {self.shape[0]} x {self.shape[1]} texels, "
                f"{int(self.converged.sum())}/{self.loss.size} converged, maps: {', '.join(self.params)})")


def _plain(o):
    if isinstance(o, (np.integer, np.floating)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)
