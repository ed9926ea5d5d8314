"""Mitsuba's LLVM back end aborts the process with libLLVM 14/15: brdffit must pick a newer one or
fall back to the scalar variant with a warning, and never crash."""

import os
import subprocess
import sys
import textwrap

import pytest

from brdffit._mitsuba import find_libllvm, llvm_version

SNIPPET = textwrap.dedent(
    """
    import warnings
    warnings.simplefilter("always")
    from brdffit._mitsuba import mitsuba
    mi = mitsuba()
    import drjit as dr
    # dr.maximum is what makes libLLVM 14/15 abort ("Cannot select ... fmaximum")
    if mi.variant().startswith("scalar"):
        x = [dr.maximum(mi.Float(v), 2.0) for v in (1.0, 2.0, 3.0)]
    else:
        x = list(dr.maximum(mi.Float([1.0, 2.0, 3.0]), 2.0))
    print("variant", mi.variant(), "max", [float(v) for v in x])
    """
)


@pytest.mark.parametrize(
    "name, version",
    [
        ("/usr/lib/x86_64-linux-gnu/libLLVM-19.so", 19),
        ("/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1", 19),
        ("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1", 15),
        ("/usr/lib/llvm-17/lib/libLLVM.so", 17),
        ("/opt/x/libfoo.so", None),
    ],
)
def test_llvm_version_from_file_name(name, version):
    assert llvm_version(name) == version


def _run(env_updates):
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env.update(env_updates)
    return subprocess.run([sys.executable, "-c", SNIPPET], env=env, capture_output=True, text=True, timeout=300)


def test_falls_back_to_scalar_with_warning_when_only_old_llvm():
    old = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"
    env = {"BRDFFIT_LLVM_GLOBS": "/usr/lib/x86_64-linux-gnu/libLLVM-1[45]*.so*", "DRJIT_LIBLLVM_PATH": old}
    proc = _run(env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "variant scalar_rgb" in proc.stdout
    assert "no libLLVM >= 16 found" in proc.stderr
    assert "max [2.0, 2.0, 3.0]" in proc.stdout


@pytest.mark.skipif(find_libllvm() is None, reason="no libLLVM >= 16 on this machine (setup installs libllvm19 as root)")
def test_uses_llvm_variant_even_if_user_points_at_old_llvm():
    proc = _run({"DRJIT_LIBLLVM_PATH": "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "variant llvm_ad_rgb" in proc.stdout
    assert "max [2.0, 2.0, 3.0]" in proc.stdout
