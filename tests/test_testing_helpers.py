"""brdffit.testing and the opt-in pytest plugin, as a user's suite would use them."""

import subprocess
import sys
import textwrap
from types import SimpleNamespace

import numpy as np
import pytest

from brdffit.testing import assert_fit_quality, assert_reciprocal


def test_assert_reciprocal_passes_for_ggx_and_fails_for_phong_classic():
    assert_reciprocal("ggx")
    with pytest.raises(AssertionError, match="phong_classic: not reciprocal"):
        assert_reciprocal("phong_classic")


def test_assert_fit_quality_reports_each_failure():
    good = SimpleNamespace(converged=True, status="converged", metrics={"rmse": 0.01, "log_rmse": 0.02},
                           model_name="ggx", data_name="paper")
    assert_fit_quality(good, max_log_rmse=0.05, max_rmse=0.1)
    bad = SimpleNamespace(converged=False, status="max steps reached", metrics={"rmse": 0.5, "log_rmse": np.nan},
                          model_name="ggx", data_name="paper")
    with pytest.raises(AssertionError) as info:
        assert_fit_quality(bad, max_log_rmse=0.05, max_rmse=0.1)
    message = str(info.value)
    assert "did not converge: max steps reached" in message
    assert "rmse 0.5 > 0.1" in message and "log_rmse nan > 0.05" in message


def test_pytest_plugin_fixtures_in_a_users_suite(tmp_path):
    (tmp_path / "test_user.py").write_text(textwrap.dedent(
        """
        def test_pairs(ubo_pairs):
            wi, wo = ubo_pairs
            assert wi.shape == (6561, 3) and (wi[81] == wi[81 + 80]).all()

        def test_data(brdffit_data):
            assert (brdffit_data / "measured").is_dir()
        """
    ))
    env_missing = {"BRDFFIT_DATA": str(tmp_path / "nowhere"), "PATH": "/usr/bin:/bin"}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-p", "brdffit.pytest_plugin", "-q", "-rs", str(tmp_path)],
                          capture_output=True, text=True, env=env_missing, cwd=tmp_path, timeout=300)
    assert "1 passed, 1 skipped" in proc.stdout, proc.stdout[-2000:]
    assert "no real measurements" in proc.stdout


def test_model_checker_reports_negative_and_non_finite_values():
    from brdffit.testing import model_problems

    assert model_problems("lambert") == []
    # kd < 0 makes f_r = kd/pi negative everywhere: the checker must say so
    problems = model_problems("lambert", param_sets=[{"kd": -0.5}])
    assert problems and "negative" in problems[0] and "kd=-0.5" in problems[0]
    problems = model_problems("lambert", param_sets=[{"kd": float("nan")}])
    assert problems and "non-finite" in problems[0]


def test_model_problems_flags_a_formula_that_mixes_channels_or_a_false_linear_declaration():
    import jax.numpy as jnp

    from brdffit.models.base import Model, Param
    from brdffit.testing import model_problems

    kd = Param("kd", 3, 0.0, 1.0, 0.5, "albedo", linear=True)
    ks = Param("ks", 3, 0.0, 1.0, 0.5, "albedo", linear=True)
    good = Model("good", (kd, ks), lambda p, wi, wo: p["kd"] / jnp.pi + p["ks"] * wo[:, 2:3], citation="test")
    mixes = Model("mixes", (kd,), lambda p, wi, wo: jnp.broadcast_to(jnp.mean(p["kd"]) / jnp.pi, (wi.shape[0], 3)),
                  citation="test")
    squared = Model("squared", (kd, ks), lambda p, wi, wo: p["kd"] / jnp.pi + p["ks"] ** 2 * wo[:, 2:3],
                    citation="test")
    assert model_problems(good) == []
    assert any("channel by channel" in s for s in model_problems(mixes))
    assert any("not affine" in s for s in model_problems(squared))
