"""A generated corpus of malformed inputs through the CLI (docs/cli.md#the-command-line-and-set-up, docs/cli.md#bad-input), and hostile but valid ones (docs/fitting.md#hostile-but-valid-data).

Every reader (UBO image folder, EXR, NPZ, RGL tensor_file, Cornell, MERL, UTIA) and fit.json gets
truncations at many offsets, byte flips in its header and its data, wrong sizes, wrong types,
empty files and folders where a file belongs. Each case goes through ``info`` and one of
``convert`` / ``fit`` / ``validate`` (in-process ``main(argv)``; a sample through the real
executable) and must give: exit 2, exactly one stderr line naming the file, no traceback, nothing
on stdout from a native library, nothing written. Nothing binary is committed: every file is made
here from brdffit's own writers or from the published layouts.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import brdffit
from brdffit.cli import main
from brdffit.grid import ubo_pairs
from brdffit.io.images import direction_name

REPO = Path(__file__).resolve().parents[1]
SAMPLE = REPO / "data" / "sample_ubo81.exr"
MAGIC = b"tensor_file\0"


# -- valid sources, made here ----------------------------------------------------------------------
def good_measurement():
    wi, wo = ubo_pairs()
    v = np.random.default_rng(0).uniform(0.05, 0.5, size=(6561, 3))
    return brdffit.Measurement(wi=wi, wo=wo, values=v, grid="ubo81", name="good")


def tensor_file(fields: list[tuple[str, np.ndarray]]) -> bytes:
    """Mitsuba's tensor_file layout: magic, version 1.0, u32 field count, per field (u16 name
    length, name, u16 axes, u8 type, u64 offset, u64 shape[axes]), then the data, 8-aligned."""
    codes = {np.dtype("u1"): 1, np.dtype("<u4"): 5, np.dtype("<f4"): 10}
    header_size = len(MAGIC) + 2 + 4 + sum(2 + len(n) + 2 + 1 + 8 + 8 * a.ndim for n, a in fields)
    offset = (header_size + 7) // 8 * 8
    head, body = [MAGIC, struct.pack("<BBI", 1, 0, len(fields))], b""
    for name, a in fields:
        a = np.ascontiguousarray(a)
        head.append(struct.pack("<H", len(name)) + name.encode() + struct.pack("<HBQ", a.ndim, codes[a.dtype], offset)
                    + struct.pack(f"<{a.ndim}Q", *a.shape))
        pad = (-len(a.tobytes())) % 8
        body += a.tobytes() + bytes(pad)
        offset += len(a.tobytes()) + pad
    out = b"".join(head)
    return out + bytes((header_size + 7) // 8 * 8 - len(out)) + body


def small_rgl() -> bytes:
    """A small isotropic RGL material (a rough diffuse-like lobe), laid out as the RGL files are."""
    n_theta, n = 4, 8
    theta = np.linspace(0, np.pi / 2, n_theta).astype("<f4")
    u = np.linspace(0, 1, n, dtype=np.float64)
    lobe = np.exp(-((u[:, None]) ** 2) / 0.3) * np.ones((1, n))  # over (u_theta_m, u_phi_m)
    vndf = np.broadcast_to(lobe, (1, n_theta, n, n)).astype("<f4")
    lum = np.broadcast_to(np.ones((n, n)), (1, n_theta, n, n)).astype("<f4")
    rgb = (0.4 * np.stack([lum * 1.0, lum * 0.7, lum * 0.3], axis=2)).astype("<f4")
    ndf = np.broadcast_to(np.exp(-np.linspace(0, 1, 16) ** 2 / 0.3), (2, 16)).astype("<f4")
    sigma = np.ones((2, 16), "<f4")
    return tensor_file([
        ("version", np.array([1, 0], "<u4")),
        ("description", np.frombuffer(b"brdffit synthetic test material", "u1")),
        ("phi_i", np.zeros(1, "<f4")),
        ("theta_i", theta),
        ("sigma", sigma),
        ("ndf", ndf),
        ("vndf", np.ascontiguousarray(vndf)),
        ("luminance", np.ascontiguousarray(lum)),
        ("rgb", np.ascontiguousarray(rgb)),
        ("jacobian", np.ones(1, "u1")),
        ("valid", np.ones(n * n, "u1")),
    ])


def cornell_text(n_samples: int = 40) -> str:
    rng = np.random.default_rng(1)
    lines = ["# synthetic Cornell file", "3", "450 550 650"]
    for _ in range(n_samples):
        ti, to = rng.uniform(0, 1.3, 2)
        lines.append(f"{ti:.6f} 0.000000 {to:.6f} {rng.uniform(0, 6.28):.6f} 0.300000 0.400000 0.500000")
    return "\n".join(lines) + "\n"


# -- the corpus ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Case:
    name: str
    make: Callable[[Path], tuple[Path, Path]]  # folder -> (source or fit file, the path the line must name)
    role: str = "source"  # "source" (a measurement) or "fit" (a fit.json given to validate)
    only: str | None = None  # the one command for which the input is malformed


def _write(name: str, data: bytes | str, is_dir: bool = False):
    def make(d: Path):
        p = d / name
        if is_dir:
            p.mkdir()
        elif isinstance(data, str):
            p.write_text(data)
        else:
            p.write_bytes(data)
        return p, p

    return make


def offsets(size: int, count: int, start: int = 0) -> list[int]:
    """``count`` distinct cut points in [start, size): dense at the start (headers), then spread."""
    dense = list(range(start, min(size, start + 24), 3))
    spread = np.unique(np.geomspace(max(start, 1) + 24, size - 1, max(count - len(dense), 2)).astype(int)).tolist()
    return sorted(set(dense + [s for s in spread if start <= s < size]))[:count]


def flipped(data: bytes, at: int, value: int | None = None) -> bytes:
    b = bytearray(data)
    b[at] = (b[at] ^ 0xFF) if value is None else value
    return bytes(b)


def corpus(work: Path) -> list[Case]:
    cases: list[Case] = []
    add = cases.append

    # EXR: brdffit's own writer
    exr = brdffit.save(good_measurement(), work / "good.exr").read_bytes()
    for k in offsets(len(exr), 40):
        add(Case(f"exr-trunc-{k}", _write(f"t{k}.exr", exr[:k])))
    # the structural header (magic, version, channel list) and the chunk offset table
    structural = [0, 1, 2, 3, 4, 5]  # magic and version
    at = exr.index(b"chlist\0") + 7 + 4  # the channel list: name\0, type i32, pLinear u8, 3 reserved, xs, ys
    while exr[at] != 0:
        end = exr.index(b"\0", at)
        structural += [at, end + 1, end + 1 + 8, end + 1 + 12]  # name, pixel type, x and y sampling
        at = end + 1 + 16
    for k in structural:
        add(Case(f"exr-flip-{k}", _write(f"f{k}.exr", flipped(exr, k))))
    header_end = exr.index(b"\0" * 1, exr.index(b"lineOrder")) + 1
    data_start = len(exr) - (len(exr) - header_end) // 2
    for k in np.linspace(data_start, len(exr) - 8, 12).astype(int):
        add(Case(f"exr-data-{k}", _write(f"d{k}.exr", exr[:k] + bytes(8) + exr[k + 8:])))  # zeroed compressed bytes
    add(Case("exr-empty", _write("e.exr", b"")))
    add(Case("exr-folder", _write("dir.exr", b"", is_dir=True)))
    add(Case("exr-text", _write("text.exr", "81 81\n" * 50)))

    # NPZ: brdffit's own writer; any truncation or flipped byte breaks the zip (CRC)
    npz = brdffit.save(good_measurement(), work / "good.npz").read_bytes()
    for k in offsets(len(npz), 30):
        add(Case(f"npz-trunc-{k}", _write(f"t{k}.npz", npz[:k])))
    # inside the members' compressed data (CRC-checked); local header names and dates are ignored by readers
    for k in np.linspace(100, npz.index(b"PK\x01\x02") - 40, 20).astype(int):
        add(Case(f"npz-flip-{k}", _write(f"f{k}.npz", flipped(npz, int(k)))))
    wi, wo = ubo_pairs()
    v = np.full((6561, 3), 0.3)
    wrong = {
        "shape": dict(wi=wi[:10], wo=wo, values=v),
        "values3d": dict(wi=wi, wo=wo, values=v[:, :, None]),
        "strings": dict(wi=wi, wo=wo, values=np.array(["x"] * 6561)),
        "complex": dict(wi=wi, wo=wo, values=v * (1 + 1j)),
        "nonunit": dict(wi=wi * 3, wo=wo, values=v),
        "zerodir": dict(wi=wi * 0, wo=wo, values=v),
        "nan": dict(wi=wi, wo=wo, values=v * np.nan),
        "weights0": dict(wi=wi, wo=wo, values=v, weights=np.zeros(6561)),
        "weights-shape": dict(wi=wi, wo=wo, values=v, weights=np.ones(5)),
        "nowi": dict(wo=wo, values=v),
        "empty": dict(wi=np.zeros((0, 3)), wo=np.zeros((0, 3)), values=np.zeros((0, 3))),
        "below": dict(wi=wi * np.array([1, 1, -1]), wo=wo, values=v),
        "onepair": dict(wi=np.tile(wi[3], (60, 1)), wo=np.tile(wo[3], (60, 1)), values=v[:60]),
        "meta": dict(wi=wi, wo=wo, values=v, metadata=np.array("{not json")),
    }
    for name, arrays in wrong.items():
        def make(d, name=name, arrays=arrays):
            p = d / f"{name}.npz"
            np.savez(p, **arrays)
            return p, p
        # samples at a single direction pair can be shown and fitted, not interpolated to a grid
        add(Case(f"npz-{name}", make, only="convert" if name == "onepair" else None))
    add(Case("npz-empty", _write("e.npz", b"")))
    add(Case("npz-folder", _write("dir.npz", b"", is_dir=True)))

    # RGL tensor_file: a small material in Mitsuba's layout
    rgl = small_rgl()
    for k in offsets(len(rgl), 40):
        add(Case(f"rgl-trunc-{k}", _write(f"t{k}.bsdf", rgl[:k])))
    # the field table of the fields the plugin computes with ('version', 'description' and 'valid' are not read)
    computed = range(rgl.index(b"\x05\x00phi_i"), rgl.index(b"\x05\x00valid"))
    for k in list(range(0, 18)) + list(computed[:: max(1, len(computed) // 40)]):
        if rgl[k:k + 1] == b"\0" and 18 <= k:
            value = 0xFF  # a zero byte in a size field: make it huge rather than leaving it
        else:
            value = None
        add(Case(f"rgl-flip-{k}", _write(f"f{k}.bsdf", flipped(rgl, k, value))))
    # values the plugin would compute with: NaN / negative distribution / unsorted angles
    for field, value in (("theta_i", np.nan), ("ndf", -1.0), ("vndf", np.inf), ("rgb", np.nan), ("luminance", -2.0),
                         ("sigma", np.nan), ("phi_i", np.nan)):
        name_at = rgl.index(struct.pack("<H", len(field)) + field.encode())
        at = struct.unpack_from("<Q", rgl, name_at + 2 + len(field) + 3)[0]
        add(Case(f"rgl-value-{field}", _write(f"v{field}.bsdf", rgl[:at] + np.float32(value).tobytes() + rgl[at + 4:])))
    theta_at = struct.unpack_from("<Q", rgl, rgl.index(b"\x07\x00theta_i") + 2 + 7 + 3)[0]
    add(Case("rgl-theta-unsorted", _write("unsorted.bsdf", rgl[:theta_at] + np.float32(1.5).tobytes() + rgl[theta_at + 4:])))
    add(Case("rgl-version2", _write("v2.bsdf", rgl[:12] + b"\x02\x00" + rgl[14:])))
    add(Case("rgl-empty", _write("e.bsdf", b"")))
    add(Case("rgl-folder", _write("dir.bsdf", b"", is_dir=True)))
    add(Case("rgl-random", _write("r.bsdf", MAGIC + b"\x01\x00" + np.random.default_rng(2).bytes(4000))))

    # Cornell text: truncations that leave a partial sample, binary and non-number content
    text = cornell_text()
    body = text.index("\n", text.index("450")) + 1
    row = len(text.splitlines()[3]) + 1
    cuts = [body + r * row + c for r in range(0, 38, 2) for c in (6, 20)]  # mid-sample, never at a row's end
    for k in cuts:
        add(Case(f"cornell-trunc-{k}", _write(f"t{k}.brdf", text[:k])))
    for k in range(0, 10):
        add(Case(f"cornell-flip-{k}", _write(f"f{k}.brdf", text.replace("0.300000", "0.3oo000", k + 1)
                                             .replace("450 550 650", "450 55x 650") if k % 2 else
                                             text[: body + k * row + 3] + "\x00\xff" + text[body + k * row + 5:])))
    add(Case("cornell-empty", _write("e.brdf", "")))
    add(Case("cornell-comments", _write("c.brdf", "# nothing\n# but comments\n")))
    add(Case("cornell-nan", _write("n.brdf", text.replace("0.400000", "nan"))))
    add(Case("cornell-deg", _write("deg.brdf", cornell_text().replace("\n0.", "\n80.").replace("\n1.", "\n85."))))
    add(Case("cornell-wl", _write("wl.brdf", text.replace("450 550 650", "-4 0 1e9"))))
    add(Case("cornell-folder", _write("dir.brdf", "", is_dir=True)))

    # MERL: int32 header (90, 90, 180) + 3 x 90 x 90 x 180 float64
    merl_header = np.array([90, 90, 180], "<i4").tobytes()
    merl_size = 12 + 8 * 3 * 90 * 90 * 180
    for k in offsets(merl_size, 16):
        add(Case(f"merl-trunc-{k}", _write(f"t{k}.binary", (merl_header + bytes(max(0, k - 12)))[:k])))
    for dims in ((90, 90, 90), (0, 0, 0), (-1, 90, 180), (2**30, 2**30, 4), (180, 90, 90)):
        add(Case(f"merl-dims-{dims[0]}-{dims[2]}", _write(f"dims{dims[0]}_{dims[2]}.binary",
                                                          np.array(dims, "<i4").tobytes() + bytes(800))))
    add(Case("merl-empty", _write("e.binary", b"")))
    add(Case("merl-folder", _write("dir.binary", b"", is_dir=True)))

    def merl_negative(d):  # every sample unmeasured: no usable sample
        p = d / "neg.binary"
        with open(p, "wb") as fh:
            fh.write(merl_header)
            np.full(3 * 90 * 90 * 180, -1.0, "<f8").tofile(fh)
        return p, p
    add(Case("merl-all-unmeasured", merl_negative))

    # UTIA: 3 x 6 x 48 x 6 x 48 float64, nothing else
    utia_size = 8 * 3 * 6 * 48 * 6 * 48
    for k in offsets(utia_size, 12, start=1):
        add(Case(f"utia-trunc-{k}", _write(f"t{k}.bin", bytes(k))))
    add(Case("utia-long", _write("long.bin", bytes(utia_size + 8))))
    add(Case("utia-empty", _write("e.bin", b"")))
    add(Case("utia-folder", _write("dir.bin", b"", is_dir=True)))

    def utia_nan(d):
        p = d / "nan.bin"
        np.full(utia_size // 8, np.nan, "<f8").tofile(p)
        return p, p
    add(Case("utia-nan", utia_nan))

    # image folders (the full 81 x 81 set is a module fixture, see test_image_folder_corpus)
    def images(name, stems, content=None):
        def make(d):
            p = d / name
            p.mkdir()
            for s in stems:
                if content is None:
                    Image.fromarray(np.zeros((2, 2, 3), np.uint8)).save(p / f"{s}.png")
                else:
                    (p / f"{s}.png").write_bytes(content)
            return p, p
        return make
    add(Case("images-empty", images("empty_btf", [])))
    add(Case("images-partial", images("partial_btf", [direction_name(0, 0), direction_name(3, 4)])))
    add(Case("images-dup", images("dup_btf", ["a_" + direction_name(0, 0), "b_" + direction_name(0, 0)])))
    add(Case("images-offgrid", images("off_btf", ["tl013_pl000_tv000_pv000"])))
    add(Case("images-names", images("names_btf", ["hello", "tl15_pl0"])))

    # fit.json: a real fit's file, then truncations, flips and wrong types in every field
    good_fit = json.loads(_good_fit_text())
    fit_text = json.dumps(good_fit, indent=2)
    for k in offsets(len(fit_text) - 2, 30):
        add(Case(f"fit-trunc-{k}", _write(f"t{k}.json", fit_text[:k]), role="fit"))
    for k in np.linspace(0, len(fit_text) - 2, 10).astype(int):
        add(Case(f"fit-flip-{k}", _write(f"f{k}.json", flipped(fit_text.encode(), int(k), 0xFF)), role="fit"))
    wrong_values = ("text", [1, "x"], {"a": 1}, None, True, -3)
    for field in ("model", "channels", "params", "loss", "loss_value", "metrics", "steps", "converged", "status",
                  "seconds", "solver", "data_name", "n_used", "n_excluded", "excluded", "stderr", "start", "options"):
        for w in wrong_values:
            if _type_ok(field, w):
                continue
            doc = dict(good_fit, **{field: w})
            add(Case(f"fit-type-{field}-{type(w).__name__}", _write(f"{field}_{type(w).__name__}.json",
                                                                     json.dumps(doc)), role="fit"))
    for name, params in (("nan", {"kd": [float("nan")] * 3}), ("inf", {"kd": [float("inf")] * 3}),
                         ("neg", {"kd": [5, -1, 0.2]}), ("size", {"kd": [0.1, 0.2]}), ("extra", {"kd": [0.1] * 3, "x": [1]}),
                         ("missing", {}), ("str", {"kd": ["0.1"] * 3})):
        add(Case(f"fit-params-{name}", _write(f"p_{name}.json", json.dumps(dict(good_fit, params=params))), role="fit"))
    for model in ("nosuch", "lafortune0", "lambert+lambert", ""):
        add(Case(f"fit-model-{model}", _write(f"m_{model or 'empty'}.json", json.dumps(dict(good_fit, model=model))),
                 role="fit"))
    add(Case("fit-array", _write("array.json", "[1, 2, 3]"), role="fit"))
    add(Case("fit-empty", _write("e.json", ""), role="fit"))
    add(Case("fit-folder", _write("dir.json", "", is_dir=True), role="fit"))
    add(Case("fit-not-json", _write("fit.txt", "model: lambert\n"), role="fit"))
    add(Case("fit-bounds", _write("bounds.json", json.dumps(dict(good_fit, bounds={"kd": [0.5, 0.1]}))), role="fit"))
    return cases


_FIT_TEXT: list[str] = []


def _good_fit_text() -> str:
    """A fit.json as ``brdffit fit`` writes it (a Lambert fit of the bundled sample)."""
    if not _FIT_TEXT:
        from brdffit.fitting import fit

        m = brdffit.load(SAMPLE)
        _FIT_TEXT.append(fit(m, "lambert").to_json())
    return _FIT_TEXT[0]


def _type_ok(field: str, value) -> bool:
    """Whether ``value`` is a legitimate value of ``field`` (then the case is not malformed)."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if field in ("loss", "status", "solver", "data_name"):
        return isinstance(value, str)
    if field == "loss_value":
        return number or value is None  # null: a loss that was not a number, as strict JSON writes it
    if field == "converged":
        return isinstance(value, bool)
    if field in ("metrics", "seconds", "excluded", "stderr", "start", "options"):
        return value == {"a": 1}
    return False


# -- running ---------------------------------------------------------------------------------------
def commands(case: Case, src: Path, out: Path, k: int, good_fit: Path) -> Iterator[list[str]]:
    if case.only == "convert":
        yield ["convert", str(src), str(out / "table.exr")]
        return
    if case.role == "fit":
        yield ["validate", str(SAMPLE), str(src), "-o", str(out / "v"), "--size", "8", "--lights", "1"]
        return
    yield ["info", str(src)]
    other = k % 3
    if other == 0:
        yield ["convert", str(src), str(out / "table.exr")]
    elif other == 1:
        yield ["fit", str(src), "--model", "lambert", "-o", str(out / "fit")]
    else:
        yield ["validate", str(src), str(good_fit), "-o", str(out / "v"), "--size", "8", "--lights", "1"]


def check(code: int, out: str, err: str, named: Path, out_dir: Path) -> str | None:
    """None when the run behaved as docs/cli.md#the-command-line-and-set-up says; else what went wrong."""
    lines = err.strip("\n").split("\n") if err.strip() else []
    if code != 2:
        return f"exit {code}"
    if len(lines) != 1:
        return f"{len(lines)} stderr lines: {err!r}"
    if "Traceback" in err or str(named) not in lines[0]:
        return f"line does not name {named}: {lines[0]!r}"
    if out.strip():
        return f"stdout not empty: {out[:200]!r}"
    left = sorted(p.name for p in out_dir.iterdir())
    if left:
        return f"wrote {left}"
    return None


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("corpus")


@pytest.mark.slow
def test_malformed_corpus(work, capfd, request):
    """At least 300 malformed inputs: each exits 2 with one line naming the file, nothing written."""
    cases = corpus(work)
    good_fit = work / "good_fit.json"
    good_fit.write_text(_good_fit_text())
    failures, runs = [], 0
    for k, case in enumerate(cases):
        d = work / f"c{k}"
        d.mkdir()
        src, named = case.make(d)
        out = work / f"o{k}"
        out.mkdir()
        for argv in commands(case, src, out, k, good_fit):
            capfd.readouterr()
            code = main(argv)
            captured = capfd.readouterr()
            runs += 1
            problem = check(code, captured.out, captured.err, named, out)
            if problem:
                failures.append(f"{case.name} [{argv[0]}]: {problem}")
    passed = len(cases) - len({f.split(' [')[0] for f in failures})
    request.config.brdffit_corpus_tally = (len(cases), passed, runs)
    assert len(cases) >= 300
    assert not failures, f"{len(failures)} of {runs} runs misbehaved:\n" + "\n".join(failures[:40])


def test_image_folder_corpus(full_folder, tmp_path, capfd):
    """A complete UBO folder with one image broken in turn (truncated at several offsets, text,
    a folder in its place, removed): exit 2 naming the broken image (or the folder)."""
    victim = full_folder / f"{direction_name(40, 12)}.png"
    good = victim.read_bytes()
    breaks = [("trunc", good[:k]) for k in (0, 8, 20, 33, len(good) // 2)] + [("text", b"not an image")]
    out = tmp_path / "o"
    out.mkdir()
    try:
        for what, content in breaks + [("folder", None), ("missing", None)]:
            victim.unlink() if victim.is_file() else victim.rmdir() if victim.exists() else None
            if what == "folder":
                victim.mkdir()
            elif content is not None:
                victim.write_bytes(content)
            named = full_folder if what in ("missing", "folder") else victim
            capfd.readouterr()
            code = main(["convert", str(full_folder), str(out / "t.npz")])
            c = capfd.readouterr()
            assert check(code, c.out, c.err, named, out) is None, (what, c.err)
    finally:
        if victim.is_dir():
            victim.rmdir()
        victim.write_bytes(good)
    assert main(["convert", str(full_folder), str(out / "t.npz")]) == 0


def test_corpus_sample_through_real_executable(tmp_path):
    """The first case of each reader (and a damaged RGL field table, the input that crashed Mitsuba)
    through the installed ``brdffit`` in its own process: same rules, and no signal kills it."""
    exe = Path(sys.executable).with_name("brdffit")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "brdffit"]
    src_dir = tmp_path / "src"
    src_dir.mkdir()
    cases = corpus(src_dir)
    first: dict[str, Case] = {}
    for case in cases:
        first.setdefault(case.name.split("-")[0], case)
    picked = [*first.values(), next(c for c in cases if c.name == "rgl-value-theta_i")]
    good_fit = tmp_path / "good_fit.json"
    good_fit.write_text(_good_fit_text())
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    for k, case in enumerate(picked):
        d = tmp_path / f"s{k}"
        d.mkdir()
        src, named = case.make(d)
        out = tmp_path / f"so{k}"
        out.mkdir()
        argv = next(iter(commands(case, src, out, k, good_fit)))
        r = subprocess.run([*cmd, *argv], capture_output=True, text=True, timeout=300, env=env)
        assert r.returncode == 2, (case.name, r.returncode, r.stderr)  # negative: killed by a signal
        assert check(r.returncode, r.stdout, r.stderr, named, out) is None, (case.name, r.stderr)


# -- hostile but valid: the same table in another unit --------------------------------------------------

@pytest.mark.parametrize("factor", [1e-12, 1e12])
@pytest.mark.parametrize("solver", ["lm", "scipy"])
def test_a_table_in_another_unit_fits_as_the_original_through_the_cli(tmp_path, factor, solver):
    """The bundled sample written again times 1e-12 and 1e12 (a radiometric unit change) and fitted by
    ``brdffit fit`` under a loss a unit only rescales (cosine_l2; the log loss has a unit of its own, see
    tests/test_robust_inputs.py): exit 0, the same status, the scales times the factor and the shape
    parameters as for the original table (false "converged" 1.7x-300x worse once)."""
    m = brdffit.load(SAMPLE)
    fits = {}
    for name, s in (("original", 1.0), ("scaled", factor)):
        src = tmp_path / f"{name}.npz"
        brdffit.save(brdffit.Measurement(m.wi, m.wo, np.asarray(m.values) * s, grid="ubo81", name=name), src)
        assert main(["fit", str(src), "--model", "ggx", "--loss", "cosine_l2", "--solver", solver,
                     "-o", str(tmp_path / name)]) == 0
        fits[name] = json.loads((tmp_path / name / "fit.json").read_text())
    a, b = fits["original"], fits["scaled"]
    assert a["converged"] == b["converged"] and a["status"] == b["status"]
    for key in ("kd", "ks"):
        np.testing.assert_allclose(np.asarray(b["params"][key]) / factor, a["params"][key], rtol=1e-5)
    for key in ("alpha", "f0"):
        np.testing.assert_allclose(b["params"][key], a["params"][key], rtol=1e-5, atol=1e-9)
