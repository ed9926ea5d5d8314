"""``brdffit.load_btf``: a UBO BTF, every texel its own 81x81 table (docs/btf.md#btfs-per-texel-fitting).

Sources: an image folder of the layouts ``brdffit.load`` reads (flat, or per-view sub-folders
``tvTTT_pvPPP/``; png / jpg / exr / hdr; names with ``_`` or spaces between the fields), or a
``.zip`` archive of one, read straight from the archive (the Bonn database ships UBO2003 as
256x256 JPEGs named ``tl015 pl060 tv000 pv000.jpg`` and ATRIUM as Radiance ``.hdr`` with the
same names). Decoding is :func:`brdffit.io.images.read_image` (sRGB EOTF for 8/16-bit images,
EXR and HDR linear), and the value options are those of ``load``: ``scale``, ``includes_cos``.

Memory. A BTF is usually larger than the RAM (a 256x256 UBO2003 BTF is 6561 x 256 x 256 x 3
values: 5.2 GB as float32), so it is never held in memory. Each image is decoded exactly once and
its texels are scattered into a *tile-major cache file* (float32): the texels are grouped in tiles of
``tile x tile`` (16 x 16 by default), and inside a tile each texel's 6561 x C values are contiguous, so
the fit reads one tile with one sequential read straight into the layout it fits (texel by texel, no
transposed copy, and with a plain file read, not a memory map whose pages would count as the process's
memory). While reading, at
most ``buffer_mb`` of decoded images are held before they are flushed to the cache; while
fitting, one tile (6561 x 256 x 3 float32 = 20 MB) at a time. ``BTF.memory()`` reports the three
figures. The cache lives in ``cache_dir`` (default: a temporary folder, removed with the BTF
object) and is reused when the same source is loaded again with the same options into the same
folder (it is keyed by the source's path, size, modification time and the options).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import dataclasses
import functools
import hashlib
import io
import json
import os
import weakref
import zipfile
from pathlib import Path, PurePosixPath

import numpy as np

from .._files import remove_scratch, scratch_dir, scratch_file
from ..errors import InputError, UsageError
from ..grid import UBO_SIZE, ubo_pairs
from ..io import images as _images
from ..measurement import Measurement

if TYPE_CHECKING:  # annotations only: jaxtyping's import (~45 ms) is not needed to run
    from jaxtyping import Float


N_PAIRS = UBO_SIZE * UBO_SIZE
#: Default tile edge in texels (a tile is the unit of streaming, fitting and resuming).
TILE = 16


@dataclasses.dataclass(frozen=True, eq=False)
class BTF:
    """A UBO BTF on disk: ``height x width`` texels, each with 6561 (light, view) values of
    ``channels`` channels (f_r, 1/sr, linear). Texel (r, c) is pixel row r, column c of every
    photograph (after ``region`` and ``step``)."""

    name: str
    source: str
    height: int
    width: int
    channels: int
    tile: int
    cache: Path  # tile-major float32 file, shape (n_tiles, tile * tile, 6561, channels)
    meta: dict
    _owner: object = dataclasses.field(default=None, repr=False)  # keeps a temporary cache alive

    # layout -------------------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        return (self.height, self.width)

    @property
    def tiles_shape(self) -> tuple[int, int]:
        return (-(-self.height // self.tile), -(-self.width // self.tile))

    @property
    def n_tiles(self) -> int:
        a, b = self.tiles_shape
        return a * b

    def tile_box(self, t: int) -> tuple[int, int, int, int]:
        """(row0, row1, col0, col1) of tile ``t`` (tiles in row-major order; edge tiles smaller)."""
        _, nc = self.tiles_shape
        r0, c0 = (t // nc) * self.tile, (t % nc) * self.tile
        return r0, min(r0 + self.tile, self.height), c0, min(c0 + self.tile, self.width)

    def _array(self, mode: str = "r") -> np.memmap:
        return np.memmap(self.cache, dtype=np.float32, mode=mode,
                         shape=(self.n_tiles, self.tile * self.tile, N_PAIRS, self.channels))

    # access -------------------------------------------------------------------------------------
    def tile_values(self, t: int, out: np.ndarray | None = None) -> Float[np.ndarray, "h w 6561 C"]:
        """Values of tile ``t`` as (h, w, 6561, C) float32: one sequential read of the file (no memory
        map), straight into ``out`` (any array of h * w * 6561 * C float32, e.g. a slice of a larger
        buffer) when given and the tile is whole; an edge tile's texels picked out of it."""
        r0, r1, c0, c1 = self.tile_box(t)
        h, w = r1 - r0, c1 - c0
        size = self.tile * self.tile * N_PAIRS * self.channels
        whole = (h, w) == (self.tile, self.tile)
        if out is not None and whole:
            a = out.reshape(-1)
            with open(self.cache, "rb") as f:
                f.seek(t * size * 4)
                if f.readinto(memoryview(a).cast("B")) != size * 4:
                    raise InputError(self.cache, f"truncated cache file (tile {t})")
            return out.reshape(h, w, N_PAIRS, self.channels)
        a = np.fromfile(self.cache, dtype=np.float32, count=size, offset=t * size * 4)
        a = a.reshape(self.tile, self.tile, N_PAIRS, self.channels)
        a = a if whole else np.ascontiguousarray(a[:h, :w])
        if out is not None:
            out.reshape(h, w, N_PAIRS, self.channels)[...] = a
            return out.reshape(h, w, N_PAIRS, self.channels)
        return a

    def texel(self, row: int, col: int) -> Measurement:
        """The 81x81 table of one texel as a UBO-81 Measurement."""
        if not (0 <= row < self.height and 0 <= col < self.width):
            raise UsageError(f"texel ({row}, {col}) outside the BTF's {self.height} x {self.width}")
        t = (row // self.tile) * self.tiles_shape[1] + col // self.tile
        k = (row % self.tile) * self.tile + col % self.tile
        values = np.asarray(self._array()[t, k], np.float64)
        return self._measurement(values, f"{self.name}[{row},{col}]")

    def _measurement(self, values: np.ndarray, name: str) -> Measurement:
        wi, wo, weights = _texel_arrays()
        return Measurement(wi=wi, wo=wo, values=values, weights=weights, name=name, source=self.source, grid="ubo81",
                           extra={"format": "btf texel"})

    def image(self, light: int, view: int) -> Float[np.ndarray, "H W C"]:
        """The photograph of one (light, view) pair as stored (f_r per texel, float32)."""
        k = int(light) * UBO_SIZE + int(view)
        arr = self._array()
        out = np.empty((self.height, self.width, self.channels), np.float32)
        for t in range(self.n_tiles):
            r0, r1, c0, c1 = self.tile_box(t)
            block = np.asarray(arr[t, :, k]).reshape(self.tile, self.tile, self.channels)
            out[r0:r1, c0:c1] = block[: r1 - r0, : c1 - c0]
        return out

    def memory(self) -> dict[str, int]:
        """Bytes: the cache file on disk, the read buffer, one tile while fitting."""
        return {
            "cache_file": int(self.n_tiles * N_PAIRS * self.tile * self.tile * self.channels * 4),
            "read_buffer": int(self.meta.get("read_buffer_bytes", 0)),
            "tile": int(N_PAIRS * self.tile * self.tile * self.channels * 4),
        }

    def signature(self) -> str:
        """Identifies the content (source, options, shape): a resumed fit checks it."""
        return self.meta["signature"]

    def __repr__(self) -> str:
        mb = self.memory()["cache_file"] / 2**20
        return (f"BTF({self.name!r}: {self.height} x {self.width} texels, {self.channels} channels, "
                f"{self.n_tiles} tiles of {self.tile} x {self.tile}, cache {mb:.1f} MB at {self.cache})")


@functools.cache
def _texel_arrays():
    """The directions and unit weights every texel shares, as JAX arrays made once: a texel's
    Measurement then converts only its values (measured: 0.29 instead of 0.79 ms per texel, a
    BTF builds one per texel)."""
    import jax.numpy as jnp

    wi, wo = ubo_pairs()
    return jnp.asarray(wi), jnp.asarray(wo), jnp.ones(N_PAIRS)


# -- sources ---------------------------------------------------------------------------------------
class _Folder:
    def __init__(self, path: Path):
        self.path = path
        self.files = _images.collect(path)

    def keys(self):
        return self.files

    def label(self, key) -> str:
        return str(self.files[key])

    def read(self, key, srgb: bool) -> np.ndarray:
        return _images.read_image(self.files[key], srgb=srgb)

    def close(self):
        pass


class _Zip:
    """Members of a zip archive, named like the files of an image folder (flat or per view)."""

    def __init__(self, path: Path):
        self.path = path
        self._scratch: Path | None = None  # where an EXR member is read from (made at the first)
        try:
            self.zf = zipfile.ZipFile(path)
        except (zipfile.BadZipFile, OSError) as exc:
            raise InputError(path, f"not a readable zip archive: {exc}") from None
        self.files = self._collect()

    def _collect(self) -> dict[tuple[int, int], str]:
        found: dict[tuple[int, int], str] = {}
        for name in self.zf.namelist():
            p = PurePosixPath(name)
            if name.endswith("/") or p.name.startswith(".") or p.suffix.lower() not in _images.IMAGE_EXTENSIONS:
                continue
            if any(part.startswith(".") or part == "__MACOSX" for part in p.parts[:-1]):
                continue
            full, short = _images.FULL_NAME.match(p.stem), _images.SHORT_NAME.match(p.stem)
            where = f"{self.path}:{name}"
            if full is not None:
                key = _images._index(self.path, where, full["tl"], full["pl"], full["tv"], full["pv"])
            elif short is not None and len(p.parts) > 1 and _images.VIEW_DIR.match(p.parts[-2]):
                view = _images.VIEW_DIR.match(p.parts[-2])
                key = _images._index(self.path, where, short["tl"], short["pl"], view["tv"], view["pv"])
            else:
                raise InputError(where, "unparsable image name (expected tlTTT plPPP tvTTT pvPPP.ext, with _ or spaces)")
            if key in found:
                raise InputError(self.path, f"duplicated direction {_images.direction_name(*key)}: {found[key]} and {name}")
            found[key] = name
        if not found:
            raise InputError(self.path, "no images found in the archive (expected tlTTT plPPP tvTTT pvPPP.{jpg,png,exr,hdr})")
        missing = N_PAIRS - len(found)
        if missing:
            first = next(_images.direction_name(i, j) for i in range(UBO_SIZE) for j in range(UBO_SIZE) if (i, j) not in found)
            raise InputError(self.path, f"incomplete image set: {missing} of 6561 UBO pairs missing, e.g. {first}")
        return found

    def keys(self):
        return self.files

    def label(self, key) -> str:
        return f"{self.path}:{self.files[key]}"

    def read(self, key, srgb: bool) -> np.ndarray:
        name = self.files[key]
        if name.lower().endswith(".exr"):  # the OpenEXR binding reads files only: through a scratch folder
            if self._scratch is None:
                self._scratch = scratch_dir("brdffit-zip-")
            f = self._scratch / f"pair-{key[0]}-{key[1]}.exr"  # (light, view): unique, should reads overlap
            try:
                f.write_bytes(self.zf.read(name))
                return _images.read_image(f, srgb=srgb)
            except InputError as exc:  # said of the member: the scratch file is gone by then
                raise InputError(self.label(key), str(exc.problem).replace(str(f), name)) from None
            except Exception as exc:  # noqa: BLE001 - the same
                raise _unreadable(self.label(key), exc, str(f), name) from exc
            finally:
                f.unlink(missing_ok=True)
        with self.zf.open(name) as fh:
            data = io.BytesIO(fh.read())
        data.name = name
        return _images.read_image(data, srgb=srgb)

    def close(self):
        self.zf.close()
        if self._scratch is not None:
            remove_scratch(self._scratch)
            self._scratch = None


def _open(path: Path):
    if path.is_dir():
        return _Folder(path)
    if path.is_file() and path.suffix.lower() == ".zip":
        return _Zip(path)
    if not path.exists():
        raise InputError(path, "no such file or folder")
    raise InputError(path, "not a BTF (expected an image folder or a .zip archive of one)")


def _signature(path: Path, options: dict) -> str:
    st = path.stat()
    # ``layout``: the cache file's (texel-major inside a tile); a cache of another layout is not reused.
    stamp = {"path": str(path.resolve()), "size": st.st_size, "mtime": st.st_mtime_ns, "layout": 2, **options}
    if path.is_dir():  # a folder's own mtime misses edits of its files: add the newest of them
        stamp["newest"] = max((f.stat().st_mtime_ns for f in path.rglob("*") if f.is_file()), default=0)
    return hashlib.sha256(json.dumps(stamp, sort_keys=True, default=str).encode()).hexdigest()[:20]


def load_btf(
    source,
    *,
    region=None,
    step: int = 1,
    includes_cos: bool = False,
    scale: float = 1.0,
    srgb: bool = True,
    tile: int = TILE,
    cache_dir=None,
    buffer_mb: float = 256.0,
    name: str | None = None,
    progress: bool = False,
) -> BTF:
    """Read a UBO BTF (image folder or zip archive) into a tile-major cache; see the module docstring.

    ``region=(row0, row1, col0, col1)`` (Python slice bounds on the photographs) and ``step`` (every
    ``step``-th texel in both directions) select the texels. ``includes_cos``, ``scale``, ``srgb``:
    as for ``brdffit.load`` of an image folder. ``progress=True`` shows a bar on a terminal.
    """
    path = Path(source)
    step = int(step)
    tile = int(tile)
    if step < 1 or tile < 1:
        raise UsageError("step and tile must be >= 1")
    if region is not None:
        region = tuple(int(x) for x in region)
        if len(region) != 4:
            raise UsageError("region must be (row0, row1, col0, col1)")
    src = _open(path)
    try:
        options = {"region": region, "step": step, "includes_cos": bool(includes_cos), "scale": float(scale),
                   "srgb": bool(srgb), "tile": tile}
        signature = _signature(path, options)
        keys = [(i, j) for i in range(UBO_SIZE) for j in range(UBO_SIZE)]
        first = _first_image(src, srgb, region, step)
        h, w, c = first.shape
        if cache_dir is None:
            folder = scratch_dir("brdffit-btf-")  # a Ctrl-C of the executable removes it too
            owner = _TempOwner(folder)
        else:
            folder = Path(cache_dir)
            folder.mkdir(parents=True, exist_ok=True)
            owner = None
        cache = folder / f"btf-{signature}.f32"
        done_marker = cache.with_suffix(".json")
        nr, nc = -(-h // tile), -(-w // tile)
        shape = (nr * nc, tile * tile, N_PAIRS, c)
        per_image = h * w * c * 4
        batch = max(1, min(N_PAIRS, int(buffer_mb * 2**20 // max(per_image, 1))))
        meta = {"signature": signature, "options": options, "format": "zip" if isinstance(src, _Zip) else "images",
                "read_buffer_bytes": batch * per_image}
        reuse = done_marker.is_file() and cache.is_file() and cache.stat().st_size == int(np.prod(shape)) * 4
        if reuse:
            meta.update(json.loads(done_marker.read_text()).get("meta", {}))
        else:
            tmp = cache.with_suffix(f".part{os.getpid()}")
            light_cos = ubo_pairs()[0][:, 2]
            buf = np.zeros((batch, nr * tile, nc * tile, c), np.float32)
            from ..io import PROGRESS

            # listed while it is written (a Ctrl-C of the executable removes it, in cache_dir too); gone on an error
            with scratch_file(tmp):
                arr = np.memmap(tmp, dtype=np.float32, mode="w+", shape=shape)
                token = PROGRESS.set(bool(progress))
                try:
                    for k in _images._with_progress(iter(range(N_PAIRS)), N_PAIRS, f"reading {path.name}"):
                        img = first if k == 0 else _decode(src, keys[k], srgb, region, step)
                        if img.shape != (h, w, c):
                            raise InputError(src.label(keys[k]),
                                             f"has shape {img.shape}, {src.label(keys[0])} has {(h, w, c)}")
                        factor = float(scale) / (light_cos[k] if includes_cos else 1.0)
                        buf[k % batch, :h, :w] = img * factor
                        if k % batch == batch - 1 or k == N_PAIRS - 1:
                            k0 = k - k % batch
                            n = k - k0 + 1
                            # (n, nr*t, nc*t, c) -> (nr, nc, t*t, n, c): per tile and texel, a run of n pairs
                            blocks = buf[:n].reshape(n, nr, tile, nc, tile, c).transpose(1, 3, 2, 4, 0, 5)
                            arr[:, :, k0 : k0 + n] = blocks.reshape(nr * nc, tile * tile, n, c)
                finally:
                    PROGRESS.reset(token)
                arr.flush()
                del arr
                os.replace(tmp, cache)
            done_marker.write_text(json.dumps({"meta": meta}))
    except BaseException:
        if cache_dir is None and "folder" in locals():
            remove_scratch(folder)
        raise
    finally:
        src.close()
    return BTF(name=name or path.stem, source=str(path), height=h, width=w, channels=c, tile=tile, cache=cache,
               meta=meta, _owner=owner)


def btf_shape(source, *, region=None, step: int = 1, srgb: bool = True) -> tuple[int, int, int]:
    """(height, width, channels) of the BTF that ``load_btf(source, region=..., step=...)`` reads,
    from one image; the source's image set is checked as ``load_btf`` checks it (an InputError
    names the file)."""
    src = _open(Path(source))
    try:
        return _first_image(src, srgb, None if region is None else tuple(int(x) for x in region), int(step)).shape
    finally:
        src.close()


def _first_image(src, srgb, region, step) -> np.ndarray:
    key = (0, 0)
    img = _decode(src, key, srgb, region, step)
    if img.shape[0] == 0 or img.shape[1] == 0:
        raise InputError(src.label(key), f"region {region} with step {step} selects no texels of this image")
    return img


class _TempOwner:
    """Removes a temporary cache folder (a scratch folder of the run) when the last BTF using it is gone."""

    def __init__(self, folder: Path):
        self.folder = folder
        self._finalizer = weakref.finalize(self, remove_scratch, folder)


def _unreadable(label: str, exc: Exception, path: str | None = None, member: str | None = None) -> InputError:
    """The one line for an image that cannot be decoded; ``path`` (a scratch copy) said as ``member``."""
    said = " ".join(str(exc).split())
    if path is not None:
        said = said.replace(path, member)
    return InputError(label, f"unreadable image: {type(exc).__name__}: {said[:200]}")


def _decode(src, key, srgb, region, step) -> np.ndarray:
    try:
        img = src.read(key, srgb)
    except InputError:
        raise
    except Exception as exc:  # noqa: BLE001 - a broken image is named by its file
        raise _unreadable(src.label(key), exc) from exc
    if region is not None:
        r0, r1, c0, c1 = region
        img = img[r0:r1, c0:c1]
    return np.asarray(img[::step, ::step], np.float32)
