"""Radiance ``.hdr`` (RGBE) reading and writing (brdffit.io.hdr) against bytes and values computed
by hand from the format's description (Greg Ward, "Real Pixels", Graphics Gems II): a pixel
(r, g, b, e) is (byte + 0.5) * 2^(e - 136) per channel and exactly 0 where e = 0; the encoder stores
the brightest channel's frexp exponent + 128 and floor(value * 256 / 2^exponent) per channel.
Expected values are literals or plain Python / NumPy arithmetic on hand-written bytes, never the
output of brdffit itself (the round trips are in addition)."""

from __future__ import annotations

import io
import re
import warnings

import numpy as np
import pytest

from brdffit.io.hdr import decode_hdr, encode_hdr, read_hdr, write_hdr

HEADER = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n"


def hdr(h: int, w: int, body, header: bytes = HEADER) -> bytes:
    """A file: the header, the resolution line, then the pixel bytes as given."""
    return header + f"-Y {h} +X {w}\n".encode() + bytes(body)


def expected(rgbe) -> np.ndarray:
    """Decoded float32 (H, W, 3) of hand-written (H, W, 4) RGBE bytes: (m + 0.5) * 2^(e - 136), 0 at e = 0."""
    b = np.asarray(rgbe, np.float64)
    e = b[..., 3:]
    return np.where(e > 0, (b[..., :3] + 0.5) * 2.0 ** (e - 136), 0.0).astype(np.float32)


def message(text: str) -> str:
    """A ``match`` pattern for exactly this message (pytest.raises searches the message)."""
    return rf"^{re.escape(text)}\Z"


def decode_fails(data: bytes, text: str) -> None:
    with pytest.raises(ValueError, match=message(text)):
        decode_hdr(data)


# -- moved from test_btf_io.py ----------------------------------------------------------------------
def test_rgbe_decoder_hand_values():
    # Header, then one flat scanline of 2 pixels (width < 8: never run-length encoded).
    # (128, 64, 32, e=129): (m + 0.5) * 2^(129 - 136) -> 128.5/128, 64.5/128, 32.5/128.
    # (0, 0, 0, e=0): zero.
    data = b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 2\n" + bytes([128, 64, 32, 129, 0, 0, 0, 0])
    img = decode_hdr(data)
    assert img.shape == (1, 2, 3)
    np.testing.assert_allclose(img[0, 0], [128.5 / 128, 64.5 / 128, 32.5 / 128], rtol=1e-7)
    np.testing.assert_array_equal(img[0, 1], 0.0)


def test_rgbe_decoder_run_length_scanline_hand_values():
    # Width 8, new-style RLE: marker 2,2,0,8; then per component: R as a run of 8 x 200,
    # G as 8 literal bytes 0..7 (count 8), B as a run of 8 x 10, E as a run of 8 x 130.
    # R = 200.5 * 2^(130-136) = 200.5/64; G_k = (k + 0.5)/64; B = 10.5/64. EXPOSURE=2 halves all.
    body = bytes([2, 2, 0, 8, 128 + 8, 200, 8, *range(8), 128 + 8, 10, 128 + 8, 130])
    data = b"#?RADIANCE\nEXPOSURE=2\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 8\n" + body
    img = decode_hdr(data)
    np.testing.assert_allclose(img[0, :, 0], 200.5 / 64 / 2, rtol=1e-7)
    np.testing.assert_allclose(img[0, :, 1], (np.arange(8) + 0.5) / 64 / 2, rtol=1e-7)
    np.testing.assert_allclose(img[0, :, 2], 10.5 / 64 / 2, rtol=1e-7)


def test_rgbe_round_trip_and_bad_input():
    rng = np.random.default_rng(1)
    img = rng.uniform(0, 5, (9, 11, 3))
    back = decode_hdr(encode_hdr(img))
    # RGBE keeps 8 bits of mantissa relative to the brightest channel of each pixel
    assert np.all(np.abs(back - img) <= img.max(axis=-1, keepdims=True) / 256)
    with pytest.raises(ValueError, match="not a Radiance"):
        decode_hdr(b"P6\n1 1\n255\n\0\0\0")
    with pytest.raises(ValueError, match="truncated"):
        decode_hdr(encode_hdr(img)[:-40])


# -- header -----------------------------------------------------------------------------------------
def test_both_signatures_are_read():
    body = [100, 50, 25, 137]  # 2^(137 - 136) = 2: 201, 101, 51
    for header in (b"#?RADIANCE\n\n", b"#?RGBE\n\n", b"#?RGBE\nFORMAT=32-bit_rle_rgbe\n\n"):
        img = decode_hdr(hdr(1, 1, body, header))
        np.testing.assert_array_equal(img, np.float32([[[201.0, 101.0, 51.0]]]))


@pytest.mark.parametrize(
    "data",
    [b"", b"P6\n1 1\n255\n\0\0\0", b"#?RADIANC\n\n-Y 1 +X 1\n\0\0\0\0", b" #?RADIANCE\n\n-Y 1 +X 1\n\0\0\0\0",
     b"#?radiance\n\n-Y 1 +X 1\n\0\0\0\0", b"#?rgbe\n\n-Y 1 +X 1\n\0\0\0\0", b"#?RGB\n\n-Y 1 +X 1\n\0\0\0\0"],
)
def test_signature_is_required(data):
    decode_fails(data, "not a Radiance HDR image (no #?RADIANCE / #?RGBE signature)")


@pytest.mark.parametrize(
    "data", [b"#?RADIANCE", b"#?RGBE", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n", b"#?RADIANCE\nEXPOSURE=1"]
)
def test_header_without_its_empty_line_is_truncated(data):
    decode_fails(data, "truncated header")


def test_other_pixel_formats_are_refused_by_name():
    decode_fails(hdr(1, 1, [0, 0, 0, 0], b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n"),
                 "unsupported pixel format 32-bit_rle_xyze (only 32-bit_rle_rgbe)")
    decode_fails(hdr(1, 1, [0, 0, 0, 0], b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe_x\n\n"),
                 "unsupported pixel format 32-bit_rle_rgbe_x (only 32-bit_rle_rgbe)")
    # bytes that are not UTF-8 are shown as U+FFFD, not an error of their own
    decode_fails(hdr(1, 1, [0, 0, 0, 0], b"#?RADIANCE\nFORMAT=\xff\xfe\n\n"),
                 "unsupported pixel format \ufffd\ufffd (only 32-bit_rle_rgbe)")
    # lines are compared without surrounding white space; other keys and comments are ignored
    header = b"#?RADIANCE\n# made by hand\nSOFTWARE=none\nFORMAT=32-bit_rle_rgbe  \r\n\n"
    np.testing.assert_array_equal(decode_hdr(hdr(1, 1, [7, 0, 0, 136], header)), np.float32([[[7.5, 0.5, 0.5]]]))


def test_exposure_lines_multiply():
    # stored values are divided by the product of all EXPOSURE= values: 2.5 * 4 = 10
    header = b"#?RADIANCE\nEXPOSURE=2.5\nFORMAT=32-bit_rle_rgbe\nEXPOSURE=4\n\n"
    img = decode_hdr(hdr(1, 2, [100, 20, 0, 137, 0, 0, 0, 0], header))  # 2^(137 - 136) = 2
    np.testing.assert_allclose(img, [[[201.0 / 10, 41.0 / 10, 1.0 / 10], [0.0, 0.0, 0.0]]], rtol=1e-6)
    assert img.dtype == np.float32
    # one line divides by its value alone; none divides by 1
    one = decode_hdr(hdr(1, 1, [100, 20, 0, 137], b"#?RADIANCE\nEXPOSURE=8\n\n"))
    np.testing.assert_array_equal(one, np.float32([[[201.0 / 8, 41.0 / 8, 1.0 / 8]]]))


@pytest.mark.parametrize(
    "tail",
    [b"", b"\n", b"+Y 1 +X 1\n\0\0\0\0", b"-Y 1 -X 1\n\0\0\0\0", b"+X 1 -Y 1\n\0\0\0\0", b"-Y one +X 1\n\0\0\0\0",
     b"-Y 1 +X 1 extra\n\0\0\0\0",
     # no newline after it: not a resolution line (not even "-Y 1 +X 1" plus one byte of data)
     b"-Y 1 +X 12", b"-Y 1 +X 1 "],
)
def test_resolution_line_is_required(tail):
    decode_fails(HEADER + tail, "unsupported or missing resolution line (expected '-Y H +X W')")


def test_rows_top_to_bottom_columns_left_to_right():
    # -Y 3 +X 2: three rows of two pixels, stored row by row; all e = 136 (scale 1)
    body = [10, 0, 0, 136, 11, 0, 0, 136, 20, 0, 0, 136, 21, 0, 0, 136, 30, 0, 0, 136, 31, 0, 0, 136]
    img = decode_hdr(hdr(3, 2, body))
    assert img.shape == (3, 2, 3) and img.dtype == np.float32
    np.testing.assert_array_equal(img[..., 0], [[10.5, 11.5], [20.5, 21.5], [30.5, 31.5]])
    np.testing.assert_array_equal(img[..., 1:], 0.5)


# -- pixel values -----------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "e, scale",
    [(1, 2.0**-135), (2, 2.0**-134), (100, 2.0**-36), (128, 1 / 256), (135, 0.5), (136, 1.0), (137, 2.0),
     (200, 2.0**64), (255, 2.0**119)],
)
def test_value_formula_at_each_exponent(e, scale):
    img = decode_hdr(hdr(1, 2, [0, 2, 127, e, 255, 128, 64, e]))
    want = np.float32([[[0.5 * scale, 2.5 * scale, 127.5 * scale], [255.5 * scale, 128.5 * scale, 64.5 * scale]]])
    assert img.dtype == np.float32 and img.shape == (1, 2, 3)
    np.testing.assert_array_equal(img, want)  # exact: 9 significant bits at most, in float32's range


def test_zero_exponent_is_exactly_zero():
    img = decode_hdr(hdr(1, 3, [7, 9, 11, 0, 255, 255, 255, 0, 0, 0, 0, 0]))
    np.testing.assert_array_equal(img, np.zeros((1, 3, 3), np.float32))
    assert not np.any(np.signbit(img))


def test_flat_scanlines_narrow_image():
    # width 6 < 8: flat even where a line starts 2, 2 (the run-length marker); single 1s are data,
    # only (1, 1, 1) in r, g, b is the old-style repeat marker
    rows = [
        [(2, 2, 1, 130), (1, 5, 5, 129), (5, 1, 5, 128), (5, 5, 1, 136), (1, 1, 5, 200), (1, 5, 1, 255)],
        [(5, 1, 1, 1), (7, 9, 11, 0), (10, 0, 255, 137), (0, 0, 0, 0), (255, 255, 255, 136), (128, 64, 32, 129)],
    ]
    img = decode_hdr(hdr(2, 6, [b for row in rows for px in row for b in px]))
    assert img.shape == (2, 6, 3) and img.dtype == np.float32
    np.testing.assert_array_equal(img, expected(rows))
    # spot checks written out
    assert img[0, 0].tolist() == [2.5 / 64, 2.5 / 64, 1.5 / 64]
    assert img[1, 2].tolist() == [21.0, 1.0, 511.0]


def test_flat_scanlines_wide_image_without_marker():
    # width 8 allows run-length lines, but lines not starting 2, 2, <128 are flat
    rows = [
        [(2, 3, 4, 130)] + [(k, 2 * k, 3 * k, 136) for k in range(7)],
        [(3, 2, 4, 130)] + [(k, 10, 0, 120) for k in range(7)],
        [(2, 2, 200, 130)] + [(255 - k, k, 1, 140) for k in range(7)],
        [(1, 2, 2, 131)] + [(9, 9, 9, 0) for k in range(7)],
    ]
    img = decode_hdr(hdr(4, 8, [b for row in rows for px in row for b in px]))
    np.testing.assert_array_equal(img, expected(rows))
    assert img[0, 7].tolist() == [6.5, 12.5, 18.5]


@pytest.mark.parametrize(
    "h, w, body",
    [(1, 1, [1, 1, 1, 5]), (1, 2, [0, 0, 0, 0, 1, 1, 1, 0]),
     (2, 8, [3, 3, 3, 130] * 8 + [3, 3, 3, 130] * 3 + [1, 1, 1, 2] + [3, 3, 3, 130] * 4)],
)
def test_old_style_run_length_is_refused(h, w, body):
    decode_fails(hdr(h, w, body), "old-style run-length encoding is not supported")


def test_run_length_runs_and_literals():
    # per component, in order R, G, B, E; a count > 128 repeats the next byte count - 128 times, a
    # count <= 128 copies that many bytes
    row0 = [2, 2, 0, 8,
            129, 200, 1, 17, 128 + 6, 10,        # R: run of 1, literal of 1, run of 6
            3, 0, 1, 2, 128 + 5, 255,            # G: literal of 3, run of 5
            8, 1, 2, 3, 4, 5, 6, 7, 8,           # B: literal of 8
            128 + 8, 131]                        # E: run of 8 (row ends with a run)
    row1 = [2, 2, 0, 8,
            128 + 8, 50,                         # R: run of 8
            8, 10, 20, 30, 40, 50, 60, 70, 80,   # G: literal of 8 (has a byte 10, '\n')
            128 + 4, 3, 4, 9, 8, 7, 6,           # B: run of 4, literal of 4
            8, 120, 121, 122, 123, 124, 125, 126, 127]  # E: literal of 8 (the data ends in a literal)
    img = decode_hdr(hdr(2, 8, row0 + row1))
    rgbe = np.zeros((2, 8, 4))
    rgbe[0, :, 0] = [200, 17, 10, 10, 10, 10, 10, 10]
    rgbe[0, :, 1] = [0, 1, 2, 255, 255, 255, 255, 255]
    rgbe[0, :, 2] = [1, 2, 3, 4, 5, 6, 7, 8]
    rgbe[0, :, 3] = 131
    rgbe[1, :, 0] = 50
    rgbe[1, :, 1] = [10, 20, 30, 40, 50, 60, 70, 80]
    rgbe[1, :, 2] = [3, 3, 3, 3, 9, 8, 7, 6]
    rgbe[1, :, 3] = [120, 121, 122, 123, 124, 125, 126, 127]
    assert img.shape == (2, 8, 3) and img.dtype == np.float32
    np.testing.assert_array_equal(img, expected(rgbe))
    assert img[0, 0].tolist() == [200.5 / 32, 0.5 / 32, 1.5 / 32]  # 2^(131 - 136)


def test_run_length_longest_run_and_literal():
    # width 130 (low byte of the width >= 128): runs of 127 (count 255), a literal of 128 (count 128)
    body = [2, 2, 0, 130,
            255, 7, 128 + 3, 9,                  # R: 127 x 7, 3 x 9
            128, *range(128), 2, 200, 201,       # G: literal 0..127, literal 200, 201
            255, 0, 128 + 3, 1,                  # B: 127 x 0, 3 x 1
            255, 136, 128 + 3, 137]              # E: 127 x 136, 3 x 137
    img = decode_hdr(hdr(1, 130, body))
    r = np.array([7] * 127 + [9] * 3) + 0.5
    g = np.array([*range(128), 200, 201]) + 0.5
    b = np.array([0] * 127 + [1] * 3) + 0.5
    scale = np.array([1.0] * 127 + [2.0] * 3)
    np.testing.assert_array_equal(img[0], np.stack([r * scale, g * scale, b * scale], axis=-1).astype(np.float32))


def test_run_length_width_over_255():
    # width 300 = 1 * 256 + 44: the marker's width is big-endian over two bytes
    body = [2, 2, 1, 44]
    for v1, v2, v3 in [(10, 20, 30), (40, 50, 60), (70, 80, 90), (136, 137, 138)]:  # R, G, B, E
        body += [255, v1, 255, v2, 128 + 46, v3]  # 127 + 127 + 46 = 300
    img = decode_hdr(hdr(1, 300, body))
    assert img.shape == (1, 300, 3)
    seg = [slice(0, 127), slice(127, 254), slice(254, 300)]
    for s, (r, g, b, scale) in zip(seg, [(10, 40, 70, 1.0), (20, 50, 80, 2.0), (30, 60, 90, 4.0)]):
        want = [(r + 0.5) * scale, (g + 0.5) * scale, (b + 0.5) * scale]
        np.testing.assert_array_equal(img[0, s], np.float32([want] * (s.stop - s.start)))


def _row8():
    """A valid run-length line of width 8 (all four components runs of 8)."""
    return [2, 2, 0, 8, 136, 1, 136, 2, 136, 3, 136, 136]


@pytest.mark.parametrize(
    "h, body, text",
    [
        # the marker's width must be the image's
        (1, [2, 2, 0, 9, 137, 1, 137, 2, 137, 3, 137, 136],
         "scanline 0: run-length width does not match the image width 8"),
        (1, [2, 2, 0, 9], "scanline 0: run-length width does not match the image width 8"),
        (1, [2, 2, 1, 8] + _row8()[4:], "scanline 0: run-length width does not match the image width 8"),
        (2, _row8() + [2, 2, 0, 7], "scanline 1: run-length width does not match the image width 8"),
        # data ending: before a line, inside the marker, before a count, before a run's byte, inside a literal
        (1, [], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8, 136, 5], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8, 136], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8, 8, 1, 2, 3, 4, 5, 6, 7], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8, 8, 1, 2, 3, 4, 5, 6], "truncated pixel data in scanline 0"),
        (1, [2, 2, 0, 8, 136, 1, 136, 2, 136, 3, 4, 1, 2, 3, 4, 132], "truncated pixel data in scanline 0"),
        (2, _row8() + [2, 2, 0, 8, 136], "truncated pixel data in scanline 1"),
        (2, _row8(), "truncated pixel data in scanline 1"),
        # runs past the end of the line
        (1, [2, 2, 0, 8, 137, 5], "scanline 0: run overflows the line"),
        (1, [2, 2, 0, 8, 133, 5, 132, 6], "scanline 0: run overflows the line"),
        (2, _row8() + [2, 2, 0, 8, 136, 1, 136, 2, 136, 3, 255, 136], "scanline 1: run overflows the line"),
        # literals of 0 or past the end of the line
        (1, [2, 2, 0, 8, 0, 136, 5, 136, 1, 136, 2, 136, 136], "scanline 0: bad run"),
        (1, [2, 2, 0, 8, 9, *range(9)], "scanline 0: bad run"),
        (1, [2, 2, 0, 8, 5, 1, 2, 3, 4, 5, 4, 1, 2, 3, 4], "scanline 0: bad run"),
        (2, _row8() + [2, 2, 0, 8, 136, 1, 136, 2, 136, 3, 4, 1, 2, 3, 4, 5, 1, 2, 3, 4, 5], "scanline 1: bad run"),
    ],
)
def test_run_length_errors(h, body, text):
    decode_fails(hdr(h, 8, body), text)


@pytest.mark.parametrize("h, w, n", [(1, 2, 7), (1, 1, 0), (2, 2, 12), (2, 3, 23)])
def test_flat_truncated(h, w, n):
    decode_fails(hdr(h, w, [9] * n), f"truncated pixel data in scanline {(n // (4 * w))}")


def test_width_32768_is_flat():
    # run-length lines are at most 32767 wide: at 32768 a line starting 2, 2, 0 is flat data
    w = 32768
    img = decode_hdr(hdr(1, w, [2, 2, 0, 5] + [0] * (4 * (w - 1))))
    assert img.shape == (1, w, 3)
    assert img[0, 0].tolist() == [2.5 * 2.0**-131, 2.5 * 2.0**-131, 0.5 * 2.0**-131]
    assert not np.any(img[0, 1:])
    # and it is written flat
    assert encode_hdr(np.zeros((1, w, 3))) == HEADER + b"-Y 1 +X 32768\n" + bytes(4 * w)


# -- read_hdr -----------------------------------------------------------------------------------------
def test_read_hdr_from_path_and_open_file(tmp_path):
    data = hdr(1, 2, [100, 50, 10, 137, 1, 2, 3, 135])
    want = [[[201.0, 101.0, 21.0], [0.75, 1.25, 1.75]]]
    path = tmp_path / "a b.hdr"
    path.write_bytes(data)
    for img in (read_hdr(path), read_hdr(str(path))):
        assert img.dtype == np.float64
        np.testing.assert_array_equal(img, want)
    with open(path, "rb") as f:
        img = read_hdr(f)
    assert img.dtype == np.float64
    np.testing.assert_array_equal(img, want)
    img = read_hdr(io.BytesIO(data))
    assert img.dtype == np.float64
    np.testing.assert_array_equal(img, want)


# -- encode_hdr / write_hdr -----------------------------------------------------------------------------
def test_encode_flat_hand_bytes():
    # width 7 < 8: flat. Per pixel: peak = brightest channel = mant * 2^exp (mant in [0.5, 1));
    # e = exp + 128 (at most 255); byte = floor(value * 256 / 2^exp); peak <= 1e-32 -> all zero.
    img = np.array([
        [(0.9, 0.3, 0.1),        # exp 0: 230.4, 76.8, 25.6 -> 230, 76, 25; e 128
         (0.0, 0.0, 0.0),        # black
         (2.0**-100, 0.0, 0.0),  # 0.5 * 2^-99: 128, e 29
         (1e-32, 1e-33, 0.0),    # at the threshold: black
         (2.0**130, 0.0, 0.0),   # 0.5 * 2^131: 128, e 259 saturates at 255
         (1.0, 0.5, -3.0),       # exp 1: 128, 64, 0 (negative clipped); e 129
         (3.0, 6.0, 1.5)],       # 6 = 0.75 * 2^3: x 32 -> 96, 192, 48; e 131
        [(0.25, 0.125, 0.0625),  # exp -1: x 512 -> 128, 64, 32; e 127
         (100.0, 50.0, 0.01),    # 100 = 0.78125 * 2^7: x 2 -> 200, 100, 0; e 135
         (0.001, 0.002, 0.003),  # 0.003 = 0.768 * 2^-8: x 65536 -> 65.5, 131.1, 196.6; e 120
         (7.0, 7.0, 7.0),        # 0.875 * 2^3: 224; e 131
         (0.5, 0.5, 0.5),        # exp 0: 128; e 128
         (1e-40, 0.0, 0.0),      # below the threshold: black
         (-1.0, 2.0**-20, 0.0)], # 0.5 * 2^-19: 0, 128, 0; e 109
    ])
    pixels = [
        230, 76, 25, 128, 0, 0, 0, 0, 128, 0, 0, 29, 0, 0, 0, 0, 128, 0, 0, 255, 128, 64, 0, 129, 96, 192, 48, 131,
        128, 64, 32, 127, 200, 100, 0, 135, 65, 131, 196, 120, 224, 224, 224, 131, 128, 128, 128, 128, 0, 0, 0, 0,
        0, 128, 0, 109,
    ]
    assert encode_hdr(img) == b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 2 +X 7\n" + bytes(pixels)
    # a nested list is an image too
    assert encode_hdr(img.tolist()) == encode_hdr(img)


def test_encode_negative_values_clipped_without_warnings():
    img = np.array([[(-np.inf, -np.inf, -np.inf), (-1.0, -2.0, -3.0), (0.75, -5.0, -np.inf), (-0.0, 0.0, 0.5)]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = encode_hdr(img)
    assert data == HEADER + b"-Y 1 +X 4\n" + bytes([0, 0, 0, 0, 0, 0, 0, 0, 192, 0, 0, 128, 0, 0, 128, 128])


@pytest.mark.skipif(np.finfo(np.longdouble).nmant <= np.finfo(np.float64).nmant, reason="longdouble is float64 here")
def test_encode_works_in_float64():
    # the image is rounded to float64 first, so every platform writes the same bytes:
    # 1 - 2^-60 is 1.0 in float64 (0.5 * 2^1: 128, e 129), not 0.99.. (255, e 128)
    one = np.longdouble(1) - np.longdouble(2) ** -60
    img = np.array([[[one, 0, 0]]], dtype=np.longdouble)
    assert encode_hdr(img) == HEADER + b"-Y 1 +X 1\n" + bytes([128, 0, 0, 129])


def test_encode_run_length_hand_bytes():
    # width 8: marker 2, 2, 0, 8, then each component as one literal chunk of 8 (count 8)
    k = np.arange(8)
    img = np.stack([(128 + k) / 256, k / 256, (255 - k) / 256], axis=-1)[None]  # peaks in [0.5, 1): e 128, x 256
    body = [2, 2, 0, 8,
            8, 128, 129, 130, 131, 132, 133, 134, 135,
            8, 0, 1, 2, 3, 4, 5, 6, 7,
            8, 255, 254, 253, 252, 251, 250, 249, 248,
            8, 128, 128, 128, 128, 128, 128, 128, 128]
    assert encode_hdr(img) == HEADER + b"-Y 1 +X 8\n" + bytes(body)
    # two rows: a marker per row
    assert encode_hdr(np.concatenate([img, img])) == HEADER + b"-Y 2 +X 8\n" + bytes(body + body)


def test_encode_run_length_literal_chunks_of_128():
    # width 300 = 1 * 256 + 44: literal chunks of 128, 128 and 44 per component
    w = 300
    k = np.arange(w)
    img = np.stack([(128 + k % 128) / 256, (k % 256) / 256, (255 - k % 256) / 256], axis=-1)[None]
    lines = [[128 + i % 128 for i in range(w)], [i % 256 for i in range(w)], [255 - i % 256 for i in range(w)],
             [128] * w]
    body = [2, 2, 1, 44]
    for line in lines:
        body += [128] + line[:128] + [128] + line[128:256] + [44] + line[256:]
    data = encode_hdr(img)
    assert data == HEADER + b"-Y 1 +X 300\n" + bytes(body)
    # and it reads back: (byte + 0.5) / 256
    np.testing.assert_array_equal(decode_hdr(data)[0], (np.floor(img[0] * 256) + 0.5) / 256)


def test_write_hdr_writes_encode_bytes(tmp_path):
    img = np.array([[(0.9, 0.3, 0.1), (0.0, 0.0, 0.0)]])
    write_hdr(img, tmp_path / "a.hdr")
    write_hdr(img, str(tmp_path / "b.hdr"))
    want = HEADER + b"-Y 1 +X 2\n" + bytes([230, 76, 25, 128, 0, 0, 0, 0])
    assert (tmp_path / "a.hdr").read_bytes() == want == encode_hdr(img)
    assert (tmp_path / "b.hdr").read_bytes() == want
    # overwrites, not appends
    write_hdr(img[:, :1], tmp_path / "a.hdr")
    assert (tmp_path / "a.hdr").read_bytes() == HEADER + b"-Y 1 +X 1\n" + bytes([230, 76, 25, 128])


@pytest.mark.parametrize("shape", [(3, 5, 3), (2, 8, 3), (2, 129, 3), (1, 300, 3)])
def test_round_trip(shape, tmp_path):
    rng = np.random.default_rng(shape[1])
    img = rng.uniform(0, 5, shape) * rng.choice([1e-3, 1.0, 1e3], shape[:2])[..., None]
    img[0, 0] = 0.0
    write_hdr(img, tmp_path / "x.hdr")
    back = read_hdr(tmp_path / "x.hdr")
    assert back.shape == shape and back.dtype == np.float64
    assert back[0, 0].tolist() == [0.0, 0.0, 0.0]
    peak = img.max(axis=-1, keepdims=True)
    assert np.all(np.abs(back - img) <= peak / 256)
