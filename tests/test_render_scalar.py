"""Without libLLVM >= 16 rendering falls back to scalar_rgb: it warns, renders, and agrees with the
LLVM variant (run in a subprocess: the variant is chosen once per process)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np

from brdffit.render import render_sphere

PARAMS = {"kd": [0.2, 0.3, 0.1], "ks": 0.5, "alpha": 0.3, "f0": 0.1}
LIGHTS = [[0.0, 0.0, 1.0], [0.5, 0.0, 0.8660254]]
SNIPPET = textwrap.dedent(
    f"""
    import sys, warnings
    import numpy as np
    warnings.simplefilter("always")
    from brdffit.render import render_sphere
    from brdffit._mitsuba import mitsuba
    img = render_sphere(("ggx", {PARAMS!r}), {LIGHTS!r}, size=12, spp=16)
    print("variant", mitsuba().variant())
    np.save(sys.argv[1], img)
    """
)


def test_scalar_fallback_renders(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "DRJIT_LIBLLVM_PATH"}
    env["BRDFFIT_LLVM_GLOBS"] = "/usr/lib/x86_64-linux-gnu/libLLVM-1[45]*.so*"
    env["DRJIT_LIBLLVM_PATH"] = "/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"
    out = tmp_path / "img.npy"
    proc = subprocess.run([sys.executable, "-c", SNIPPET, str(out)], env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "variant scalar_rgb" in proc.stdout
    assert "no libLLVM >= 16 found" in proc.stderr
    scalar = np.load(out)
    assert scalar.shape == (2, 12, 12, 3) and np.all(np.isfinite(scalar)) and np.all(scalar >= 0)
    llvm = render_sphere(("ggx", PARAMS), LIGHTS, size=12, spp=16)
    assert np.abs(scalar - llvm).sum() / llvm.sum() < 0.03
