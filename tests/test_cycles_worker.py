"""The Blender worker (brdffit.cycles): where its interpreter comes from, its protocol, its errors,
and Cycles measured through it against values computed by hand (a Lambertian plane and sphere)."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from brdffit import cycles
from brdffit.errors import UsageError

LAMBERT = {"distribution": "GGX", "inputs": {"Base Color": [0.8, 0.5, 0.2], "Metallic": 0.0,
                                             "Specular IOR Level": 0.0}}  # no specular layer at all


def test_without_an_environment_every_path_says_so_in_one_line(monkeypatch, tmp_path):
    monkeypatch.delenv(cycles.ENV_VAR, raising=False)
    monkeypatch.setattr(cycles, "project_root", lambda: tmp_path)
    monkeypatch.setattr(cycles, "_SHARED", None)  # as in a process that has not started one
    for call in (cycles.blender_python, cycles.worker,
                 lambda: cycles.gonio(LAMBERT, [[0, 0, 1]], [[0, 0, 1]]),
                 lambda: cycles.render_sphere(LAMBERT, [[0, 0, 1]], size=8)):
        with pytest.raises(UsageError) as info:
            call()
        msg = str(info.value)
        assert "\n" not in msg and str(tmp_path / ".venv-blender") in msg and "setup_blender.sh" in msg
    assert cycles.available() == msg


def test_a_named_interpreter_that_is_not_there(monkeypatch, tmp_path):
    monkeypatch.setenv(cycles.ENV_VAR, str(tmp_path / "nope" / "python"))
    with pytest.raises(UsageError, match=r"BRDFFIT_BLENDER_PYTHON=.*nope.*no such Python interpreter"):
        cycles.blender_python()


def test_an_interpreter_without_bpy_fails_to_start_with_the_reason():
    # this test's own interpreter has no bpy: the worker's import fails, and the error names it
    with pytest.raises(UsageError) as info:
        cycles.Worker(sys.executable, start_timeout=60)
    assert "did not start" in str(info.value) and "bpy" in str(info.value)
    assert "\n" not in str(info.value)


def test_default_interpreter_is_the_project_folders(monkeypatch, tmp_path):
    monkeypatch.delenv(cycles.ENV_VAR, raising=False)
    monkeypatch.setattr(cycles, "project_root", lambda: tmp_path)
    py = tmp_path / ".venv-blender" / "bin" / "python"
    py.parent.mkdir(parents=True)
    py.write_text("")
    assert cycles.blender_python() == py


def test_protocol_answers_and_refusals(blender):
    w = blender.Worker()
    try:
        assert w.blender == "5.0.1"
        assert w.call("ping", {}) == {"blender": "5.0.1"}
        with pytest.raises(blender.BlenderError, match="unknown operation 'render'"):
            w.call("render", {})
        with pytest.raises(blender.BlenderError, match="unknown Principled BSDF input 'Colour'"):
            w.call("gonio", {"material": {"distribution": "GGX", "inputs": {"Colour": 1}},
                             "pairs": [[[0, 0, 1], [0, 0, 1]]]}, "/tmp")
        with pytest.raises(blender.BlenderError, match="distribution 'BECKMANN'"):
            w.call("gonio", {"material": {"distribution": "BECKMANN", "inputs": {}},
                             "pairs": [[[0, 0, 1], [0, 0, 1]]]}, "/tmp")
        assert w.call("ping", {})["blender"] == "5.0.1"  # a refused request leaves the worker serving
    finally:
        w.close()
    assert not w.alive


def test_a_dead_worker_is_an_error_and_the_shared_one_restarts(blender):
    w = blender.worker()
    w._proc.kill()
    w._proc.wait()
    with pytest.raises(blender.BlenderError, match="has ended"):
        w.call("ping", {})
    assert blender.worker() is not w and blender.worker().call("ping", {})["blender"] == "5.0.1"


def test_gonio_lambert_equals_the_hand_value(blender):
    """f = rho/pi, so the plane's radiance is rho/pi (n.wi) E, whatever the view."""
    rng = np.random.default_rng(1)
    theta = np.radians(rng.uniform(0, 80, (6, 2)))
    phi = rng.uniform(0, 2 * np.pi, (6, 2))
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)
    wi, wo = d[:, 0], d[:, 1]
    got = blender.gonio(LAMBERT, wi, wo, irradiance=2.5)
    want = np.array([0.8, 0.5, 0.2]) / math.pi * wi[:, 2:3] * 2.5
    np.testing.assert_allclose(got, want, rtol=1e-5)
    below = blender.gonio(LAMBERT, [[0, 0, 1]], [[1, 0, -0.1]])
    assert np.all(np.isnan(below))


def test_sphere_framing_lambert_equals_the_closed_form(blender):
    """docs/validation.md#validation-rendering: pixel (i, j) centre at x = 2(j+0.5)/size - 1, y = 1 - 2(i+0.5)/size; a Lambertian
    sphere renders rho/pi max(n.l, 0) E with n = (x, y, sqrt(1 - x^2 - y^2))."""
    size = 48
    light = np.array([0.6, 0.3, 0.74])
    light /= np.linalg.norm(light)
    img = blender.render_sphere(LAMBERT, [light], size=size, irradiance=1.0, spp=16)[0]
    c = (np.arange(size) + 0.5) * 2 / size - 1
    x, y = np.meshgrid(c, -c)
    r2 = x * x + y * y
    n = np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], -1)
    want = np.array([0.8, 0.5, 0.2]) / math.pi * np.clip(n @ light, 0, None)[..., None]
    inner = r2 < 0.8  # away from the silhouette, where a pixel is partly background
    assert np.abs(img[inner] - want[inner]).mean() / want[inner].mean() < 0.01
    assert np.all(img[r2 > 1.2] == 0)  # black world, nothing outside the disc
