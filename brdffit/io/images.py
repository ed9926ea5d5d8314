"""UBO / UTIA / Bonn BTF image folders (docs/formats.md#readers-and-writers).

A folder holds one image per (light, view) pair of the UBO-81 grid, named
``[prefix_]tlTTT_plPPP_tvTTT_pvPPP.{png,jpg,jpeg,exr}`` (integer degrees: theta/phi of the light,
then of the view), either flat or in per-view sub-folders ``tvTTT_pvPPP/`` (inside those, the short
name ``[prefix_]tlTTT_plPPP.ext`` is accepted too). Files that are not images (README, .txt, ...)
and hidden files are ignored; an image whose name does not parse is an error.

The set must be exactly the 81 x 81 UBO pairs: a missing, duplicated, unparsable or off-grid
direction is an ``InputError`` that names it.

Values: the BRDF of a pair is the mean over the image's texels (or over ``region=(row0, row1,
col0, col1)``, Python slice bounds). 8- and 16-bit images (PNG, JPEG) are sRGB-encoded and are
decoded to linear with the exact IEC 61966-2-1 sRGB EOTF (``srgb=False`` to take the codes as
linear); EXR images are linear already. By default pixel values are taken as proportional to
f_r: ``value = scale * mean``. For data whose pixels include the foreshortening of the light
(radiance under a fixed irradiance at normal incidence), pass ``includes_cos=True``:
``value = scale * mean / cos(theta_light)``.

UTIA light shift: in the UTIA gonioreflectometer the light is moved slightly off the nominal
direction where light and view would coincide. File names hold only the nominal integer-degree
grid, so by default the nominal directions are recorded (``extra["light_directions"] =
"nominal"``); a caller who has the true directions passes ``true_wi`` ((6561, 3) or (81, 81, 3)
unit vectors, [light, view] order) and they are recorded as the sample's ``wi``
(``"true (given)"``). The table layout (which pair a value belongs to) always follows the names.
"""

from __future__ import annotations

import re
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..errors import InputError, UsageError
from ..grid import UBO_SIZE, ubo_angles_deg, ubo_index, ubo_pairs
from ..measurement import Measurement

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".exr", ".hdr")
# Fields are separated by "_" or, as in the Bonn database's zip archives, by spaces
# ("tl015 pl060 tv000 pv000.jpg"); both forms are accepted everywhere.
_ANGLES = r"tl(?P<tl>\d{3})[_ ]pl(?P<pl>\d{3})"
FULL_NAME = re.compile(rf"^(?:(?P<prefix>.*?)[_ ])?{_ANGLES}[_ ]tv(?P<tv>\d{{3}})[_ ]pv(?P<pv>\d{{3}})$", re.IGNORECASE)
SHORT_NAME = re.compile(rf"^(?:(?P<prefix>.*?)[_ ])?{_ANGLES}$", re.IGNORECASE)
VIEW_DIR = re.compile(r"^tv(?P<tv>\d{3})[_ ]pv(?P<pv>\d{3})$", re.IGNORECASE)


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """Exact sRGB EOTF (IEC 61966-2-1) for codes in [0, 1]."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_to_linear` (for writers and tests)."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    # break point 0.04045 / 12.92 (= 0.0031308 to 7 digits), so that this inverts srgb_to_linear exactly
    return np.where(x <= 0.04045 / 12.92, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def direction_name(light: int, view: int) -> str:
    """File-name stem of a UBO pair, e.g. ``tl015_pl060_tv000_pv000``."""
    a = ubo_angles_deg().astype(int)
    return f"tl{a[light, 0]:03d}_pl{a[light, 1]:03d}_tv{a[view, 0]:03d}_pv{a[view, 1]:03d}"


def _is_image(p: Path) -> bool:
    return p.is_file() and p.suffix.lower() in IMAGE_EXTENSIONS and not p.name.startswith(".")


def _index(folder: Path, f: Path, tl, pl, tv, pv) -> tuple[int, int]:
    try:
        light = ubo_index(int(tl), int(pl))
    except KeyError:
        raise InputError(f, f"light direction tl{tl}_pl{pl} is not on the UBO-81 grid") from None
    try:
        view = ubo_index(int(tv), int(pv))
    except KeyError:
        raise InputError(f, f"view direction tv{tv}_pv{pv} is not on the UBO-81 grid") from None
    return light, view


def collect(folder: Path) -> dict[tuple[int, int], Path]:
    """Map (light, view) -> image file, checking that the set is exactly the UBO-81 pairs."""
    found: dict[tuple[int, int], Path] = {}

    def add(key, f):
        if key in found:
            raise InputError(folder, f"duplicated direction {direction_name(*key)}: {found[key]} and {f}")
        found[key] = f

    for entry in sorted(folder.iterdir()):
        if entry.name.startswith("."):
            continue
        if entry.is_dir():
            view_match = VIEW_DIR.match(entry.name)
            images = [f for f in sorted(entry.iterdir()) if _is_image(f)]
            if not images:
                continue
            if view_match is None:
                raise InputError(entry, "unparsable view folder name (expected tvTTT_pvPPP)")
            tv, pv = view_match["tv"], view_match["pv"]
            for f in images:
                full, short = FULL_NAME.match(f.stem), SHORT_NAME.match(f.stem)
                if full is not None:
                    if (int(full["tv"]), int(full["pv"]) % 360) != (int(tv), int(pv) % 360):
                        raise InputError(f, f"view tv{full['tv']}_pv{full['pv']} in the name disagrees with its folder {entry.name}")
                    add(_index(folder, f, full["tl"], full["pl"], tv, pv), f)
                elif short is not None:
                    add(_index(folder, f, short["tl"], short["pl"], tv, pv), f)
                else:
                    raise InputError(f, "unparsable image name (expected [prefix_]tlTTT_plPPP[_tvTTT_pvPPP].ext)")
        elif _is_image(entry):
            full = FULL_NAME.match(entry.stem)
            if full is None:
                raise InputError(entry, "unparsable image name (expected [prefix_]tlTTT_plPPP_tvTTT_pvPPP.ext)")
            add(_index(folder, entry, full["tl"], full["pl"], full["tv"], full["pv"]), entry)
    if not found:
        raise InputError(
            folder,
            "no images found (expected tlTTT_plPPP_tvTTT_pvPPP.{png,jpg,exr}, flat or in tvTTT_pvPPP/ folders)",
        )
    missing = [(i, j) for i in range(UBO_SIZE) for j in range(UBO_SIZE) if (i, j) not in found]
    if missing:
        first = ", ".join(direction_name(*k) for k in missing[:3])
        raise InputError(folder, f"incomplete image set: {len(missing)} of 6561 UBO pairs missing, e.g. {first}")
    return found


def read_image(f: Path, *, srgb: bool = True) -> np.ndarray:
    """Linear (H, W, C) float64 of one image (C = 1 or 3).

    ``f``: a path, or an open binary file with a ``name`` (a member of a zip archive) for every
    type but EXR. Radiance ``.hdr`` (RGBE) images are linear already.
    """
    suffix = Path(getattr(f, "name", f)).suffix.lower()
    if suffix == ".hdr":
        from .hdr import read_hdr

        return read_hdr(f)
    if suffix == ".exr":
        import OpenEXR

        from .exr import colour_channels

        exr = OpenEXR.File(str(f), separate_channels=True)
        ch = {k: np.asarray(v.pixels, dtype=np.float64) for k, v in exr.channels().items()}
        names = colour_channels(ch)
        if names is None:
            raise ValueError(f"no R,G,B or Y channels (has {', '.join(sorted(ch))})")
        return np.stack([ch[n] for n in names], axis=-1)
    from PIL import Image

    with Image.open(f) as im:
        im.load()
        mode = im.mode
        if mode in ("I;16", "I;16B", "I;16L", "I"):
            a = np.asarray(im, dtype=np.float64) / 65535.0
            a = a[..., None]
        elif mode == "F":
            return np.asarray(im, dtype=np.float64)[..., None]
        else:
            if mode in ("RGB", "L"):
                a = np.asarray(im)
            elif mode in ("LA",):
                a = np.asarray(im.convert("L"))
            else:  # RGBA, P, CMYK, YCbCr ...
                a = np.asarray(im.convert("RGB"))
            bits = 16 if a.dtype == np.uint16 else 8
            a = a.astype(np.float64) / (2**bits - 1)
            if a.ndim == 2:
                a = a[..., None]
    return srgb_to_linear(a) if srgb else a


def _mean(f: Path, region, srgb: bool) -> np.ndarray:
    try:
        img = read_image(f, srgb=srgb)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - a broken image inside the folder is named by its file
        raise InputError(f, f"unreadable image: {type(exc).__name__}: {' '.join(str(exc).split())[:200]}") from exc
    if region is not None:
        r0, r1, c0, c1 = region
        img = img[r0:r1, c0:c1]
    if img.size == 0:
        raise InputError(f, f"region {tuple(region) if region is not None else None} selects no texels of this image")
    return img.reshape(-1, img.shape[-1]).mean(axis=0)


def _with_progress(items, total: int, label: str):
    """Yield from ``items``, with a transient progress bar when asked (load(progress=True)) on a terminal."""
    import sys

    from . import PROGRESS

    if not (PROGRESS.get() and sys.stderr.isatty()):
        yield from items
        return
    from rich.console import Console
    from rich.progress import track

    yield from track(items, total=total, description=label, transient=True, console=Console(stderr=True))


def read(
    path,
    *,
    region=None,
    includes_cos: bool = False,
    scale: float = 1.0,
    srgb: bool = True,
    true_wi=None,
    name: str | None = None,
    workers: int = 4,
) -> Measurement:
    """Read an image folder into a UBO-81 Measurement (see the module docstring)."""
    folder = Path(path)
    if not folder.is_dir():
        raise InputError(folder, "not a folder")
    if region is not None:
        region = tuple(int(x) for x in region)
        if len(region) != 4:
            raise UsageError("region must be (row0, row1, col0, col1)")
    files = collect(folder)
    keys = [(i, j) for i in range(UBO_SIZE) for j in range(UBO_SIZE)]
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:  # decoders release the GIL
        results = pool.map(lambda k: _mean(files[k], region, srgb), keys)
        means = list(_with_progress(results, len(keys), f"reading {folder.name}"))
    channels = {m.shape[0] for m in means}
    if len(channels) != 1:
        counts = [m.shape[0] for m in means]
        k = keys[next(i for i, c in enumerate(counts) if c != counts[0])]
        raise InputError(files[k], f"has {means[keys.index(k)].shape[0]} channels, {files[keys[0]].name} has {counts[0]}")
    values = np.stack(means) * float(scale)
    wi, wo = ubo_pairs()
    if includes_cos:
        values = values / wi[:, 2:3]
    light_dirs = "nominal (file names)"
    if true_wi is not None:
        true_wi = np.asarray(true_wi, dtype=np.float64).reshape(-1, 3)
        if true_wi.shape != (UBO_SIZE * UBO_SIZE, 3):
            raise UsageError(f"true_wi must be (6561, 3) or (81, 81, 3), got {np.shape(true_wi)}")
        wi = true_wi / np.linalg.norm(true_wi, axis=1, keepdims=True)
        light_dirs = "true (given)"
    exts = sorted({f.suffix.lower() for f in files.values()})
    layout = "per-view folders" if any(f.parent != folder for f in files.values()) else "flat"
    return Measurement(
        wi=wi,
        wo=wo,
        values=values,
        name=name or folder.name,
        source=str(folder),
        grid="ubo81",
        extra={
            "format": "images",
            "layout": layout,
            "image_types": tuple(exts),
            "decoding": "sRGB EOTF (IEC 61966-2-1) for 8/16-bit, EXR linear" if srgb else "codes taken as linear",
            "region": region,
            "includes_cos": bool(includes_cos),
            "scale": float(scale),
            "light_directions": light_dirs,
        },
    )
