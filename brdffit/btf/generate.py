"""Test and sample BTFs, generated (nothing large is committed).

- :func:`write_model_btf`: a UBO BTF image folder (or zip) from parameter maps of any model: every
  texel's 81x81 table is the model's own formula (``model.eval``, the one definition) at that
  texel's parameters, optionally with multiplicative Gaussian noise. The truth is known.
- :func:`write_mosaic_btf`: a BTF whose texels carry measured tables: the texture is split into
  regions (vertical stripes, or a grid of blocks), region k showing the k-th source's UBO-81
  table (any source ``brdffit.load`` reads, e.g. the RGL files evaluated through Mitsuba).
- :func:`smooth_maps`: parameter maps that vary smoothly over the texture (for tests and the
  benchmark), inside each parameter's bounds.

Images are written as OpenEXR (linear float32, default), Radiance ``.hdr``, or 8-bit sRGB
PNG / JPEG (values times ``exposure``, clipped to [0, 1]; read them back with
``load_btf(..., scale=1/exposure)``); names with ``_`` or, as in the Bonn archives, with spaces.
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .._files import remove_scratch, scratch_dir
from ..errors import UsageError
from ..grid import UBO_SIZE, ubo_pairs
from ..io.images import direction_name, linear_to_srgb

FORMATS = ("exr", "hdr", "png", "jpg")


def smooth_maps(model, height: int, width: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Per-parameter maps (H, W, size) that vary smoothly (a few low-frequency waves) between 20%
    and 80% of each parameter's axis (log axes for roughness and exponents); f0 is held at its
    default (the data of one UBO table do not determine it next to ks)."""
    from ..fitting.problem import resolve_model

    model = resolve_model(model, 3)
    rng = np.random.default_rng(seed)
    y, x = np.meshgrid(np.linspace(0, 1, height), np.linspace(0, 1, width), indexing="ij")
    out = {}
    for p in model.params:
        n = model.size(p)
        chans = []
        for _ in range(n):
            a, b, ph = rng.uniform(0.5, 2.0, 3)
            t = 0.5 + 0.3 * np.sin(2 * np.pi * (a * x + b * y) + 6 * ph) * np.cos(np.pi * (b * x - a * y))
            lo, hi = p._axis_bounds()
            if p.role == "albedo":
                lo, hi = 0.02, 0.6
            elif p.scale == "log" and p.role == "roughness":
                lo, hi = np.log(0.05), np.log(0.6)
            v = lo + t * (hi - lo)
            chans.append(np.exp(v) if p.scale == "log" else v)
        out[p.name] = np.stack(chans, -1)
        if p.role == "fresnel":
            out[p.name] = np.full((height, width, n), p.default)
    return out


def block_maps(model, height: int, width: int, block: int, kinds: int = 4, seed: int = 0) -> dict[str, np.ndarray]:
    """Per-parameter maps (H, W, size) of a textured surface: ``block`` x ``block`` squares, each one of
    ``kinds`` materials at random, their parameters drawn as :func:`smooth_maps` draws them (a texel's
    neighbours often hold another material; ``block`` 1: any texel's)."""
    sets = smooth_maps(model, kinds, kinds, seed=seed)
    rng = np.random.default_rng(seed + 1)
    labels = rng.integers(0, kinds, (-(-height // block), -(-width // block)))
    labels = np.repeat(np.repeat(labels, block, axis=0), block, axis=1)[:height, :width]
    return {name: v[np.arange(kinds), np.arange(kinds)][labels] for name, v in sets.items()}


def model_tables(model, maps: Mapping[str, np.ndarray], *, chunk: int = 4096):
    """Yield (light index, (H, W, 81, C) f_r of that light's 81 views) for parameter maps."""
    import jax
    import jax.numpy as jnp

    from ..fitting.problem import resolve_model

    mdl = resolve_model(model, 3)
    shapes = {np.shape(v)[:2] for v in maps.values()}
    if len(shapes) != 1:
        raise UsageError(f"parameter maps differ in size: {sorted(shapes)}")
    (h, w), = shapes
    flat = {k: np.asarray(v, np.float64).reshape(h * w, -1) for k, v in maps.items()}
    wi, wo = ubo_pairs()
    wi = wi.reshape(UBO_SIZE, UBO_SIZE, 3)
    wo = wo.reshape(UBO_SIZE, UBO_SIZE, 3)
    one = jax.jit(jax.vmap(lambda p, a, b: mdl.eval(p, a, b), in_axes=(0, None, None)))
    for light in range(UBO_SIZE):
        parts = []
        for s in range(0, h * w, chunk):
            p = {k: jnp.asarray(v[s : s + chunk]) for k, v in flat.items()}
            parts.append(np.asarray(one(p, jnp.asarray(wi[light]), jnp.asarray(wo[light]))))
        f = np.concatenate(parts)  # (H*W, 81, C)
        yield light, f.reshape(h, w, UBO_SIZE, -1)


def _writer(fmt: str, exposure: float):
    if fmt == "exr":
        import OpenEXR

        def write(img, target):
            img = np.asarray(img, np.float32)
            chans = {"RGB": img} if img.shape[-1] == 3 else {"Y": img[..., 0]}
            header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
            OpenEXR.File(header, chans).write(str(target))

        return write
    if fmt == "hdr":
        from ..io.hdr import write_hdr

        return lambda img, target: write_hdr(np.broadcast_to(img, img.shape[:2] + (3,)), target)
    if fmt in ("png", "jpg"):
        from PIL import Image

        def write(img, target):
            code = np.round(linear_to_srgb(np.asarray(img, np.float64) * exposure) * 255).astype(np.uint8)
            code = code[..., 0] if code.shape[-1] == 1 else code
            if fmt == "jpg":  # 4:4:4: no chroma subsampling (it would blur colours across texels)
                Image.fromarray(code).save(target, format="JPEG", quality=100, subsampling=0)
            else:
                Image.fromarray(code).save(target, format="PNG")

        return write
    raise UsageError(f"unknown image format {fmt!r}; known: {', '.join(FORMATS)}")


def _write_tables(path, tables, *, fmt, noise, seed, spaces, per_view, exposure, archive) -> Path:
    """Write (light, (H, W, 81, C)) blocks as 6561 images in a folder (or a zip if ``archive``)."""
    path = Path(path)
    write = _writer(fmt, exposure)
    rng = np.random.default_rng(seed)
    ext = "jpg" if fmt == "jpg" else fmt
    if archive:
        zf = zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED)
        scratch = scratch_dir("brdffit-gen-")
    else:
        path.mkdir(parents=True, exist_ok=True)
    try:
        for light, block in tables:
            if noise:
                block = block * (1.0 + noise * rng.standard_normal(block.shape))
            for view in range(UBO_SIZE):
                stem = direction_name(light, view)
                if spaces:
                    stem = stem.replace("_", " ")
                sep = " " if spaces else "_"
                rel = Path(f"{stem[12:]}".replace("_", sep)) / f"{stem}.{ext}" if per_view else Path(f"{stem}.{ext}")
                if archive:
                    f = scratch / f"image.{ext}"
                    write(block[:, :, view], f)
                    zf.write(f, rel.as_posix())
                else:
                    (path / rel).parent.mkdir(parents=True, exist_ok=True)
                    write(block[:, :, view], path / rel)
    finally:
        if archive:
            zf.close()
            remove_scratch(scratch)
    return path


def write_model_btf(
    path,
    model,
    maps: Mapping[str, np.ndarray],
    *,
    format: str = "exr",  # noqa: A002
    noise: float = 0.0,
    seed: int = 0,
    spaces: bool = False,
    per_view: bool = False,
    exposure: float = 1.0,
    archive: bool = False,
) -> Path:
    """A UBO BTF of ``model`` at per-texel parameters ``maps`` (name -> (H, W) or (H, W, size));
    ``noise``: relative standard deviation of multiplicative Gaussian noise. Returns ``path``."""
    maps = {k: (np.asarray(v)[..., None] if np.ndim(v) == 2 else np.asarray(v)) for k, v in maps.items()}
    return _write_tables(path, model_tables(model, maps), fmt=format, noise=noise, seed=seed, spaces=spaces,
                         per_view=per_view, exposure=exposure, archive=archive)


def mosaic_labels(height: int, width: int, n: int, layout: str = "stripes") -> np.ndarray:
    """(H, W) int region index: ``stripes`` (n vertical stripes) or ``grid`` (ceil(sqrt n) blocks a side)."""
    if layout == "stripes":
        return np.broadcast_to((np.arange(width) * n) // width, (height, width)).copy()
    if layout == "grid":
        k = int(np.ceil(np.sqrt(n)))
        r = (np.arange(height) * k) // height
        c = (np.arange(width) * k) // width
        return np.minimum(r[:, None] * k + c[None, :], n - 1)
    raise UsageError(f"unknown mosaic layout {layout!r} (stripes or grid)")


def write_mosaic_btf(
    path,
    sources: Sequence,
    *,
    height: int = 16,
    width: int = 16,
    layout: str = "stripes",
    format: str = "exr",  # noqa: A002
    noise: float = 0.0,
    seed: int = 0,
    spaces: bool = False,
    archive: bool = False,
) -> tuple[Path, np.ndarray, list]:
    """A BTF whose regions carry the UBO-81 tables of ``sources`` (paths ``brdffit.load`` reads, or
    Measurements). Returns (path, labels (H, W), the measurements)."""
    from ..io import load
    from ..measurement import Measurement

    ms = [s if isinstance(s, Measurement) else load(s) for s in sources]
    for m in ms:
        if m.grid != "ubo81":
            raise UsageError(f"{m.name}: a mosaic needs UBO-81 tables (got grid={m.grid!r})")
    labels = mosaic_labels(height, width, len(ms), layout)
    tables = np.stack([np.asarray(m.table(), np.float64) for m in ms])  # (n, 81, 81, C)

    def blocks():
        for light in range(UBO_SIZE):
            yield light, tables[labels, light]  # (H, W, 81, C)

    out = _write_tables(path, blocks(), fmt=format, noise=noise, seed=seed, spaces=spaces, per_view=False,
                        exposure=1.0, archive=archive)
    return out, labels, ms


def model_btf(model, maps: Mapping[str, np.ndarray], folder, *, noise: float = 0.0, seed: int = 0, tile: int = 16,
              name: str = "generated"):
    """A ``BTF`` of ``model`` at per-texel parameters ``maps`` written straight into a cache file (the layout ``load_btf`` writes)
    in ``folder`` (no images: for benchmarks at sizes whose 6561 images would take longer to write and read
    than to fit; the values are those :func:`write_model_btf` writes to EXR, as float32)."""
    import hashlib
    import json

    from .reader import BTF, N_PAIRS

    maps = {k: (np.asarray(v)[..., None] if np.ndim(v) == 2 else np.asarray(v)) for k, v in maps.items()}
    (h, w), = {np.shape(v)[:2] for v in maps.values()}
    nr, nc = -(-h // tile), -(-w // tile)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stamp = json.dumps({"model": str(getattr(model, "name", model)), "shape": [h, w], "noise": noise, "seed": seed,
                        "tile": tile, "maps": hashlib.sha256(b"".join(np.ascontiguousarray(maps[k]).tobytes()
                                                                      for k in sorted(maps))).hexdigest()})
    signature = hashlib.sha256(stamp.encode()).hexdigest()[:20]
    cache = folder / f"btf-{signature}.f32"
    arr = np.memmap(cache, dtype=np.float32, mode="w+", shape=(nr * nc, tile * tile, N_PAIRS, 3))
    rng = np.random.default_rng(seed)
    for light, block in model_tables(model, maps):  # (H, W, 81, C)
        if noise:
            block = block * (1.0 + noise * rng.standard_normal(block.shape))
        pad = np.zeros((nr * tile, nc * tile, UBO_SIZE, block.shape[-1]), np.float32)
        pad[:h, :w] = block
        tiles = pad.reshape(nr, tile, nc, tile, UBO_SIZE, -1).transpose(0, 2, 1, 3, 4, 5)
        arr[:, :, light * UBO_SIZE : (light + 1) * UBO_SIZE] = tiles.reshape(nr * nc, tile * tile, UBO_SIZE, -1)
    arr.flush()
    del arr
    meta = {"signature": signature, "options": {"generated": True, "tile": tile}, "format": "generated",
            "read_buffer_bytes": 0}
    return BTF(name=name, source=str(cache), height=h, width=w, channels=3, tile=tile, cache=cache, meta=meta)
