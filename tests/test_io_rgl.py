"""RGL .bsdf reader: equals a direct Mitsuba `measured` evaluation, in docs/formats.md#readers-and-writers's light/view order."""

from __future__ import annotations

import numpy as np
import pytest

import brdffit
from brdffit.errors import InputError
from brdffit.grid import ubo_pairs
from conftest import RGL_FILES, rgl_params


def direct_mitsuba(path, light, view):
    """Independent reference: one Mitsuba eval per pair, converted with cos(theta_light). Where the
    plugin's atan2(y, x) would see a vector at the pole (a view along the normal; a mirrored pair, its
    half vector the normal) the answer turns on the sign of a zero, so the reference reads there at
    azimuth 0, by its own hand: that view, or that pair's light, turned by 1e-6 rad towards +x."""
    from brdffit._mitsuba import mitsuba

    mi = mitsuba()
    import drjit as dr

    light, view = np.array(light, np.float64), np.array(view, np.float64)
    at_pole = (view[:, 0] == 0) & (view[:, 1] == 0)
    view[at_pole] = [np.sin(1e-6), 0.0, np.cos(1e-6)]
    mirrored = (light[:, 0] + view[:, 0] == 0) & (light[:, 1] + view[:, 1] == 0)
    for k in np.flatnonzero(mirrored):  # a rotation of the light by 1e-6 rad about the y axis
        x, z = light[k, 0], light[k, 2]
        light[k, 0], light[k, 2] = x * np.cos(1e-6) + z * np.sin(1e-6), z * np.cos(1e-6) - x * np.sin(1e-6)
    light, view = light.astype(np.float32), view.astype(np.float32)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    si = dr.zeros(mi.SurfaceInteraction3f, light.shape[0])  # every field defined, at the batch's width
    si.wi = mi.Vector3f(view[:, 0], view[:, 1], view[:, 2])
    value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(light[:, 0], light[:, 1], light[:, 2]))
    return np.stack([np.array(value[0]), np.array(value[1]), np.array(value[2])], axis=1) / light[:, 2:3]


def test_a_view_at_the_pole_reads_one_azimuth_whatever_the_sign_of_its_zeros():
    """Mitsuba's measured plugin reads a direction's azimuth as atan2(y, x): at the pole that is 0 or
    pi by the sign of a zero, and Dr.Jit's kernels did not keep the sign the same from one process
    state to another (the UBO table's pairs with the view at the pole came out mirrored after other
    renders). The reader reads the pole at azimuth 0 whatever zeros it is given."""
    from brdffit.render.measured import eval_measured

    path = rgl_params()[0]
    path = getattr(path, "values", [path])[0]
    c, s = np.cos(np.radians(75)), np.sin(np.radians(75))
    light = np.array([[-s, 0.0, c], [s, 0.0, c], [0.0, s, c]])
    at_the_pole = [eval_measured(path, light, np.tile(view, (3, 1)))
                   for view in ([0.0, 0.0, 1.0], [-0.0, 0.0, 1.0], [0.0, -0.0, 1.0], [-0.0, -0.0, 1.0])]
    for f in at_the_pole[1:]:
        np.testing.assert_array_equal(f, at_the_pole[0])
    near = eval_measured(path, light, np.tile([1e-4, 0.0, np.sqrt(1 - 1e-8)], (3, 1)))  # azimuth 0, off the pole
    np.testing.assert_allclose(at_the_pole[0], near, rtol=1e-3, atol=1e-7)
    assert not np.allclose(at_the_pole[0][0], at_the_pole[0][1], rtol=1e-2)  # the light's azimuth is seen


@pytest.mark.parametrize("path", rgl_params())
def test_rgl_equals_mitsuba_on_ubo81(path):
    m = brdffit.load(path)
    wi, wo = ubo_pairs()
    assert m.grid == "ubo81" and m.values.shape == (6561, 3)
    np.testing.assert_allclose(np.asarray(m.wi), wi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(m.wo), wo, rtol=0, atol=1e-12)
    ref = direct_mitsuba(path, wi.astype(np.float32), wo.astype(np.float32))
    v = np.asarray(m.values)
    # Both sides are float32 evaluations by Mitsuba, compiled separately (Dr.Jit may fuse differently):
    # near-zero values differ by rounding of their larger neighbours, ~1e-10 of the table's maximum
    # (seen: 1.2e-4 relative on a value 1e-6 of the maximum). Allowed: 1e-5 relative, plus a tenth
    # of float32's epsilon of the maximum -- far below any convention error (those are whole values).
    tol = 1e-5 * np.abs(ref) + 0.1 * np.finfo(np.float32).eps * np.abs(ref).max()
    assert np.all(np.abs(v - ref) <= tol), np.max(np.abs(v - ref) - tol)
    assert m.meta["format"] == "rgl" and m.table().shape == (81, 81, 3)


@pytest.mark.skipif(not RGL_FILES, reason="real measurements not found")
def test_rgl_order_light_view_matters():
    # The RGL data are not exactly reciprocal: the light/view order of docs/formats.md#readers-and-writers must be the one used.
    path = next(p for p in RGL_FILES if "golden" in p.stem or "ibiza" in p.stem)
    m = brdffit.load(path)
    t = m.table()
    swapped = np.transpose(t, (1, 0, 2))
    assert np.max(np.abs(t - swapped)) > 1e-4 * np.abs(t).max()
    wi, wo = ubo_pairs()
    ref = direct_mitsuba(path, wi.astype(np.float32), wo.astype(np.float32))
    np.testing.assert_allclose(np.asarray(m.values), ref, rtol=1e-5, atol=1e-6 * np.abs(ref).max())


@pytest.mark.skipif(not RGL_FILES, reason="real measurements not found")
def test_rgl_at_given_directions():
    path = RGL_FILES[0]
    rng = np.random.default_rng(1)
    th_i, th_o = rng.uniform(0, 1.3, 50), rng.uniform(0, 1.3, 50)
    ph_i, ph_o = rng.uniform(0, 2 * np.pi, 50), rng.uniform(0, 2 * np.pi, 50)
    wi = brdffit.grid.spherical_to_cartesian(th_i, ph_i)
    wo = brdffit.grid.spherical_to_cartesian(th_o, ph_o)
    m = brdffit.load(path, wi=wi, wo=wo)
    assert m.grid is None and m.n_samples == 50
    ref = direct_mitsuba(path, wi.astype(np.float32), wo.astype(np.float32))
    np.testing.assert_allclose(np.asarray(m.values), ref, rtol=1e-5, atol=1e-7)


def test_rgl_header_checks(tmp_path):
    bad = tmp_path / "bad.bsdf"
    bad.write_bytes(b"tensor_fil\0\1\0")
    with pytest.raises(InputError, match="wrong magic"):
        brdffit.load(bad)


@pytest.mark.skipif(not RGL_FILES, reason="real measurements not found")
def test_rgl_truncated_is_input_error(tmp_path):
    data = RGL_FILES[0].read_bytes()
    for cut in (20, 300, len(data) // 2, len(data) - 4):
        p = tmp_path / f"cut{cut}.bsdf"
        p.write_bytes(data[:cut])
        with pytest.raises(InputError, match="truncated") as e:
            brdffit.load(p)
        assert str(p) in str(e.value)


@pytest.mark.skipif(not RGL_FILES, reason="real measurements not found")
def test_rgl_inconsistent_shapes_rejected_before_mitsuba(tmp_path):
    import struct

    data = bytearray(RGL_FILES[0].read_bytes())
    at = data.index(b"\x07\x00theta_i") + 2 + 7  # after the name: ndim u16, dtype u8, offset u64, shape
    ndim = struct.unpack_from("<H", data, at)[0]
    assert ndim == 1
    struct.pack_into("<Q", data, at + 2 + 1 + 8, 7)  # 8 -> 7 elevations: disagrees with 'rgb'
    p = tmp_path / "shapes.bsdf"
    p.write_bytes(bytes(data))
    with pytest.raises(InputError, match=r"'rgb' has shape .* expected \(1, 7,"):
        brdffit.load(p)


def test_rgl_lights_at_or_below_the_horizon_give_zero_silently(tmp_path):
    """A generated material (tests/tensor_file.py, closed form: stored value = rgb0 + (rgb1 - rgb0) *
    theta_view / (pi/2)). Mitsuba's own eval is 0 for a light on or below the horizon, and so is f_r,
    with no NumPy warning for the 0/0 at the horizon; above it, f_r = stored / cos(theta_light)."""
    import warnings

    from brdffit._mitsuba import mitsuba
    from brdffit.render.measured import eval_measured
    from tensor_file import isotropic_material

    rgb0, rgb1 = np.array([0.2, 0.4, 0.6]), np.array([1.0, 0.9, 0.3])
    path = isotropic_material(tmp_path / "m.bsdf", rgb0, rgb1)
    light = np.array([[0.6, 0.0, 0.8], [1.0, 0.0, 0.0], [0.0, -0.6, -0.8], [0.0, 0.0, 1.0]])
    view = np.tile([[0.0, 0.6, 0.8]], (4, 1))
    mi = mitsuba()  # the variant choice may warn once (no usable libLLVM): not what is checked here
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(0.0, 0.6, 0.8)
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    for at_or_below in light[[1, 2]]:  # Mitsuba's eval itself (f_r cos, before any division)
        value = bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, at_or_below)))
        assert np.array(value).ravel().tolist() == [0.0, 0.0, 0.0]
    stored = rgb0 + (rgb1 - rgb0) * np.arccos(0.8) / (np.pi / 2)
    expected = np.array([stored / 0.8, [0.0] * 3, [0.0] * 3, stored / 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        f = eval_measured(path, light, view)
        m = brdffit.load(path, wi=light, wo=view)
    np.testing.assert_allclose(f, expected, rtol=2e-6, atol=0)
    np.testing.assert_allclose(np.asarray(m.values), expected, rtol=2e-6, atol=0)
    assert np.asarray(m.weights).tolist() == [1.0, 0.0, 0.0, 1.0]
    # what the table says of itself (brdffit info, fit.json's data fields)
    meta = m.meta
    assert meta["format"] == "rgl" and meta["fields"] == tuple(sorted(
        ("description", "jacobian", "theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb", "valid")))
    assert meta["evaluation"].startswith("mitsuba measured: f_r(light, view) = eval(si.wi=view, wo=light)")


def test_rgl_non_finite_value_deep_in_a_2d_field_is_refused(tmp_path):
    """Every value of a field is checked, not just its first row: a NaN in the last NDF cell."""
    from tensor_file import isotropic_material

    ndf = np.ones((8, 8), np.float32)
    ndf[7, 7] = np.nan
    path = isotropic_material(tmp_path / "nan.bsdf", [0.2, 0.4, 0.6], [1.0, 0.9, 0.3], ndf=ndf)
    with pytest.raises(InputError) as info:
        brdffit.load(path)
    assert info.value.path == str(path) and info.value.problem == "field 'ndf' holds 1 non-finite value(s)"


def test_rgl_mitsuba_plugin_refusal_is_a_one_line_input_error(tmp_path, monkeypatch):
    """Should a file Mitsuba's plugin refuses get past our checks (here a two-entry 'jacobian', with
    the check bypassed), the refusal is an InputError naming the file, carrying Mitsuba's own message
    with its whitespace collapsed to single spaces (one line) and cut to 300 characters."""
    from brdffit._mitsuba import mitsuba
    from brdffit.io import rgl
    from brdffit.render.measured import load_measured
    from tensor_file import isotropic_material

    path = isotropic_material(tmp_path / "jac.bsdf", [0.2, 0.4, 0.6], [1.0, 0.9, 0.3], jacobian=np.zeros(2, np.uint8))
    with pytest.raises(InputError, match=r"'jacobian' has shape \(2,\)"):
        rgl.check_tensor_file(path)  # what normally stops it
    with pytest.raises(Exception) as raw:  # noqa: PT011 - Mitsuba's own exception type
        mitsuba().load_dict({"type": "measured", "filename": str(path)})
    mitsuba_says = " ".join(str(raw.value).split())
    assert "Invalid file structure" in mitsuba_says and len(mitsuba_says) > 300 and "\n" in str(raw.value)
    monkeypatch.setattr(rgl, "check_tensor_file", lambda p: {})
    with pytest.raises(InputError) as info:
        load_measured(path)
    assert info.value.path == str(path)
    assert info.value.problem == "Mitsuba's measured plugin cannot read it: " + mitsuba_says[:300]
    # a failure while evaluating (after the plugin loaded the file) is reported the same way

    def failing(path, light, view):
        raise RuntimeError("drjit:\n  evaluation   failed " + "x" * 400)

    monkeypatch.setattr(rgl, "eval_measured", failing)  # what rgl.read evaluates with
    with pytest.raises(InputError) as info:
        rgl.read(path)
    said = ("drjit: evaluation failed " + "x" * 400)[:300]
    assert str(info.value) == f"{path}: Mitsuba's measured plugin cannot read it: {said}"


_F32 = np.float32
_TOO_SMALL_THETA = {"theta_i": np.array([0.5], _F32), "rgb": np.ones((1, 1, 3, 8, 8), _F32),
                    "vndf": np.ones((1, 1, 8, 8), _F32), "luminance": np.ones((1, 1, 8, 8), _F32)}


@pytest.mark.parametrize("replace, problem", [
    ({"vndf": None}, "tensor_file lacks the field(s) vndf of an RGL RGB material"),
    ({"vndf": None, "sigma": None}, "tensor_file lacks the field(s) sigma, vndf of an RGL RGB material"),
    ({"ndf": np.ones((1, 8), _F32)}, "field(s) ndf too small to interpolate"),
    ({"ndf": np.ones((8, 1), _F32), "sigma": np.ones((1, 8), _F32)}, "field(s) ndf, sigma too small to interpolate"),
    (_TOO_SMALL_THETA, "field(s) theta_i too small to interpolate"),
    ({"theta_i": np.array([np.pi / 2, 0.0], _F32)}, "field 'theta_i' must rise strictly within 0..pi/2"),
    ({"theta_i": np.array([0.0, np.pi / 2 + 1e-3], _F32)}, "field 'theta_i' must rise strictly within 0..pi/2"),
    ({"theta_i": np.array([-0.1, 1.0], _F32)}, "field 'theta_i' must rise strictly within 0..pi/2"),
    ({"phi_i": np.array([7.0], _F32)}, "field 'phi_i' must rise strictly within -pi..2pi"),
    ({"ndf": np.full((8, 8), -1.0, _F32)}, "field 'ndf' holds negative values (min -1); it is a distribution"),
    ({"sigma": np.where(np.eye(8, dtype=bool), np.nan, 1.0).astype(_F32)}, "field 'sigma' holds 8 non-finite value(s)"),
    ({"rgb": np.ones((1, 2, 3, 8, 8), np.uint8)},
     "field 'rgb' is u1 with shape (1, 2, 3, 8, 8), expected <f4 with 5 axes"),
    ({"vndf": np.ones((1, 3, 8, 8), _F32)},
     "field 'vndf' has shape (1, 3, 8, 8), expected (1, 2, 8, 8) (from phi_i, theta_i, rgb)"),
])
def test_check_tensor_file_refusals_in_full(tmp_path, replace, problem):
    """Each problem the checker finds before Mitsuba's plugin may read the file, message in full
    (small materials written here by tests/tensor_file.py, no shared data)."""
    from brdffit.io.rgl import check_tensor_file
    from tensor_file import isotropic_material

    p = isotropic_material(tmp_path / "bad.bsdf", [0.1] * 3, [0.2] * 3, **replace)
    with pytest.raises(InputError) as err:
        check_tensor_file(p)
    assert str(err.value) == f"{p}: {problem}"


def test_check_tensor_file_header_refusals_in_full(tmp_path):
    from brdffit.io.rgl import check_tensor_file
    from tensor_file import isotropic_material

    good = isotropic_material(tmp_path / "good.bsdf", [0.1] * 3, [0.2] * 3)
    assert check_tensor_file(good)["rgb"] == (10, (1, 2, 3, 8, 8))
    data = good.read_bytes()
    cases = {
        "empty.bsdf": (b"", "empty file (expected an RGL tensor_file .bsdf)"),
        "magic.bsdf": (b"tensor_fil\0" + data[11:], "not a Mitsuba tensor_file (wrong magic; expected 'tensor_file\\0')"),
        "v2.bsdf": (data[:12] + b"\x02\x00" + data[14:], "unsupported tensor_file version 2.0 (expected 1.0)"),
        "count.bsdf": (data[:14] + b"\0\0\0\0" + data[18:], "implausible tensor_file field count 0"),
        "short.bsdf": (data[:16], "truncated tensor_file header at byte 14 of 16"),
    }
    for name, (content, problem) in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        with pytest.raises(InputError) as err:
            check_tensor_file(p)
        assert str(err.value) == f"{p}: {problem}"
    with pytest.raises(InputError) as err:
        check_tensor_file(tmp_path)
    assert str(err.value) == f"{tmp_path}: is a folder, not an RGL tensor_file .bsdf"


def test_check_tensor_file_names_overlapping_fields_and_unreadable_files(tmp_path):
    import struct

    from brdffit.io.rgl import check_tensor_file
    from tensor_file import isotropic_material

    data = bytearray(isotropic_material(tmp_path / "good.bsdf", [0.1] * 3, [0.2] * 3).read_bytes())

    def offset_at(name: bytes) -> int:  # after the name: ndim u16, type u8, then the u64 offset
        return data.index(struct.pack("<H", len(name)) + name) + 2 + len(name) + 3

    phi_offset = struct.unpack_from("<Q", data, offset_at(b"phi_i"))[0]
    struct.pack_into("<Q", data, offset_at(b"theta_i"), phi_offset)  # theta_i (8 bytes) over phi_i (4)
    p = tmp_path / "overlap.bsdf"
    p.write_bytes(bytes(data))
    with pytest.raises(InputError) as err:
        check_tensor_file(p)
    assert str(err.value) == f"{p}: garbled field table: fields 'phi_i' and 'theta_i' overlap"
    with pytest.raises(InputError) as err:
        check_tensor_file(tmp_path / "missing.bsdf")
    assert str(err.value) == f"{tmp_path / 'missing.bsdf'}: cannot read: No such file or directory"


def test_check_tensor_file_names_a_field_cut_short(tmp_path):
    import re
    import struct

    from brdffit.io.rgl import check_tensor_file
    from tensor_file import isotropic_material

    data = isotropic_material(tmp_path / "good.bsdf", [0.1] * 3, [0.2] * 3).read_bytes()
    at = data.index(b"\x05\x00valid") + 2 + 5 + 3  # the last field, 64 bytes of uint8
    offset = struct.unpack_from("<Q", data, at)[0]
    p = tmp_path / "cut.bsdf"
    p.write_bytes(data[:offset + 60])
    with pytest.raises(InputError) as err:
        check_tensor_file(p)
    assert re.fullmatch(rf"{re.escape(str(p))}: truncated or garbled: field 'valid' declares bytes {offset}\.\.{offset + 64}, "
                        rf"the file has {offset + 60} \(header ends at \d+\)", str(err.value)), str(err.value)


def test_rgl_directions_at_the_horizon_get_weight_zero(tmp_path):
    """docs/conventions.md#conventions: a sample with the light or the view at or below the horizon is not measured (weight 0,
    value 0), also exactly at the horizon (z = 0)."""
    from tensor_file import isotropic_material

    p = isotropic_material(tmp_path / "h.bsdf", [0.1] * 3, [0.2] * 3)
    up, horizon = [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]
    m = brdffit.load(p, wi=[up, up, horizon], wo=[up, horizon, up])
    np.testing.assert_array_equal(np.asarray(m.weights), [1.0, 0.0, 0.0])
    np.testing.assert_array_equal(np.asarray(m.values)[1:], 0.0)
    assert np.all(np.asarray(m.values)[0] > 0)


def test_check_tensor_file_accepts_phi_from_minus_pi(tmp_path):
    """RGL's phi_i axes run over -pi..pi or 0..2pi: a first angle of -pi (float32, a hair below
    it) is within the accepted range."""
    from brdffit.io.rgl import check_tensor_file
    from tensor_file import isotropic_material

    p = isotropic_material(tmp_path / "m.bsdf", [0.2, 0.2, 0.2], [0.5, 0.5, 0.5], phi_i=np.array([-np.pi], np.float32))
    assert float(np.float32(-np.pi)) < -np.pi  # the stored value lies below -pi, by 9e-8
    assert check_tensor_file(p)["phi_i"] == (10, (1,))
