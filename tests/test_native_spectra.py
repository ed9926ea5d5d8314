"""A ``mitsuba:roughconductor`` export keeps its fitted colour in Mitsuba's spectral variants (docs/materials.md#native-materials-and-exports):
its eta and k are spectra that Mitsuba's RGB variants integrate back to the fitted RGB values and whose
Fresnel reflectance has the fitted colour per wavelength. Written as RGB they were upsampled channel by
channel and clipped to [0, 1]: a purple gem rendered olive."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import brdffit
from brdffit.materials import export
from brdffit.models._spectra import WAVELENGTHS, colour_error, conductor_spectra, srgb_projection

pytestmark = pytest.mark.mitsuba

#: A purple conductor: normal-incidence reflectance about (0.57, 0.31, 0.72).
GEM = {"alpha": 0.2, "eta": [1.8, 2.5, 1.2], "k": [3.0, 1.5, 3.5]}
#: Complex IORs of other colours: gold-like, copper-like, a green one, a grey one.
OTHERS = [([0.2, 0.45, 1.4], [3.6, 2.4, 1.8]), ([0.27, 0.68, 1.3], [3.6, 2.6, 2.3]), ([2.9, 0.8, 0.3], [0.5, 4.0, 6.0]),
          ([1.5, 1.5, 1.5], [2.0, 2.0, 2.0])]


def test_the_projection_is_mitsubas():
    """srgb_projection is what Mitsuba integrates a spectrum property to in RGB variants."""
    from brdffit._mitsuba import mitsuba

    mi = mitsuba()
    rng = np.random.default_rng(0)
    for _ in range(4):
        v = rng.uniform(0.1, 4.0, len(WAVELENGTHS))
        theirs = np.asarray(mi.spectrum_list_to_srgb(list(WAVELENGTHS), list(v), False, True), np.float64)
        np.testing.assert_allclose(srgb_projection() @ v, theirs, rtol=2e-5)


@pytest.mark.parametrize("eta, k", [(GEM["eta"], GEM["k"]), *OTHERS])
def test_the_spectra_give_back_the_fit_in_rgb_and_its_colour_per_wavelength(eta, k):
    e, kk = conductor_spectra(eta, k)
    assert np.all(e > 0) and np.all(kk >= 0)
    np.testing.assert_allclose(srgb_projection() @ e, eta, rtol=1e-7)  # Mitsuba integrates in float32
    np.testing.assert_allclose(srgb_projection() @ kk, k, rtol=1e-7, atol=1e-7)
    assert colour_error(eta, k, e, kk) < 0.02


RENDER = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    import numpy as np
    import mitsuba as mi                     # plain Mitsuba: no brdffit in this process
    folder = Path(sys.argv[1])
    scene_xml = folder / "scene.xml"
    scene_xml.write_text('''<scene version="3.0.0">
        <include filename="gem.xml"/>
        <integrator type="path"><integer name="max_depth" value="3"/></integrator>
        <sensor type="orthographic">
            <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="48"/><integer name="height" value="48"/>
                <rfilter type="box"/></film>
        </sensor>
        <shape type="sphere"><ref id="gem"/></shape>
        <emitter type="constant"/>
    </scene>''')
    out = {}
    c = (np.arange(48) + 0.5) / 24 - 1
    inside = np.hypot(*np.meshgrid(c, c)) < 0.9
    for variant in sys.argv[2].split(","):
        mi.set_variant(variant)
        image = np.asarray(mi.render(mi.load_file(str(scene_xml)), spp=64, seed=1))[..., :3]
        out[variant] = image[inside].mean(axis=0).tolist()
    print("RESULT", json.dumps(out))
""")


def test_a_purple_gem_keeps_its_colour_in_spectral_variants(tmp_path):
    """The export (.xml, as `brdffit export` writes it) rendered by plain Mitsuba: a sphere under a
    white sky has within 5 % the same colour in spectral variants as in RGB ones."""
    fit = brdffit.FitResult.from_dict({"model": "mitsuba:roughconductor", "params": GEM, "converged": True})
    export(fit, tmp_path / "gem.xml", bsdf_id="gem")
    assert '<spectrum name="eta" value="360.0:' in (tmp_path / "gem.xml").read_text()
    variants = ["llvm_ad_rgb", "scalar_rgb", "llvm_ad_spectral", "scalar_spectral"]
    run = subprocess.run([sys.executable, "-c", RENDER, str(tmp_path), ",".join(variants)], capture_output=True,
                         text=True, timeout=900)
    assert run.returncode == 0 and "RESULT " in run.stdout, run.stdout[-1000:] + run.stderr[-3000:]
    means = {k: np.asarray(v) for k, v in json.loads(run.stdout.rsplit("RESULT ", 1)[1].splitlines()[0]).items()}
    rgb = means["llvm_ad_rgb"]
    assert rgb[1] < 0.8 * min(rgb[0], rgb[2])  # purple
    for variant in variants[1:]:
        assert np.all(np.abs(means[variant] - rgb) <= 0.05 * rgb), (variant, means[variant], rgb)
