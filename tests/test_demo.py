"""`brdffit demo` (the README's first command) runs the whole pipeline on the bundled sample."""

import json

import numpy as np
import pytest

from brdffit.cli import main
from brdffit.fitting import FitResult
from brdffit.sample import TRUTH


@pytest.mark.slow
def test_demo_writes_the_whole_pipeline_and_recovers_the_generator(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out)]) == 0
    for name in ("sample_ubo81.npz", "table.png", "fit/fit.json", "fit/fit.png", "compare/report.csv",
                 "compare/report.json", "compare/pareto.png", "validation/metrics.json", "validation/table.png"):
        assert (out / name).is_file(), name
    assert len(list((out / "validation").glob("panel_*.png"))) == 5
    result = FitResult.from_json(out / "fit" / "fit.json")
    assert result.converged
    p = {k: np.asarray(v) for k, v in result.params.items()}
    sharp, broad = sorted((1, 2), key=lambda k: p[f"ggx{k}.alpha"][0])
    np.testing.assert_allclose(p["kd"], TRUTH["kd"], rtol=0.03)
    np.testing.assert_allclose(p[f"ggx{sharp}.alpha"], TRUTH["sharp"]["alpha"], rtol=0.03)
    np.testing.assert_allclose(p[f"ggx{broad}.alpha"], TRUTH["broad"]["alpha"], rtol=0.03)
    metrics = json.loads((out / "validation" / "metrics.json").read_text())
    assert metrics["overall"]["psnr"] > 30 and metrics["overall"]["flip"] < 0.2
    # a second run does not replace the results without --force
    assert main(["demo", "-o", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
