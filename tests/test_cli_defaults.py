"""One source for names and defaults (docs/DESIGN.md#layers): the CLI's help states the defaults the code uses
(read here from the functions the commands call, not from the help's own source), and the relative
RMSE is ``rel_rmse`` in every output; a fit file that calls it ``relative_rmse`` is read as that."""

from __future__ import annotations

import copy
import inspect
import re

import numpy as np
import pytest
from click.testing import CliRunner

from brdffit.cli import _load_commands, cli


def _help(*command: str) -> str:
    _load_commands()
    result = CliRunner().invoke(cli, [*command, "--help"])
    assert result.exit_code == 0, result.output
    return " ".join(result.output.split())


def _default(function, parameter: str):
    return inspect.signature(function).parameters[parameter].default


def test_fit_help_states_the_extra_starts_the_api_solves():
    """The help promised 3 extra starts for a composite with repeated lobes; the API solved 0."""
    from brdffit import models
    from brdffit.fitting.options import default_starts

    text = _help("fit")
    said = re.search(r"Further grid starts solved beside the best one \[default: (\d+)"
                     r"(?:, or (\d+) for a composite with repeated lobes)?\]", text)
    assert said is not None, text
    single, composite = int(said.group(1)), int(said.group(2) or said.group(1))
    assert single == default_starts(models.get("ggx")) - 1
    assert composite == default_starts(models.get("lambert+ggx+ggx")) - 1


def test_validate_help_states_the_samples_per_pixel_validate_renders_with():
    from brdffit.render.validate import validate

    assert f"--spp INTEGER RANGE Samples per pixel. [default: {_default(validate, 'spp')}]" in _help("validate")


def test_compare_help_states_the_losses_compare_runs():
    from brdffit.fitting.compare import compare

    assert f"--losses TEXT Losses. [default: {', '.join(_default(compare, 'losses'))}]" in _help("compare")


def test_fit_btf_help_states_fit_btf_s_loss_and_fit_batch_s_solver():
    from brdffit.btf.fit import fit_btf
    from brdffit.fitting.api import fit_batch
    from brdffit.fitting.losses import LOSSES

    text = _help("fit-btf")
    assert f"--loss TEXT {' | '.join(LOSSES)} [default: {_default(fit_btf, 'loss')}]" in text
    assert f"--solver TEXT Solver of fit_batch. [default: {_default(fit_batch, 'solver')}]" in text


def test_validate_btf_help_counts_the_default_pairs():
    from brdffit.btf.validate import DEFAULT_PAIRS_DEG, validate_btf

    assert _default(validate_btf, "pairs") is DEFAULT_PAIRS_DEG
    assert f"[default: {len(DEFAULT_PAIRS_DEG)} pairs from head-on to grazing]" in _help("validate-btf")


def test_code_default_reads_a_constant_and_a_signature():
    from brdffit.cli._help import code_default

    assert code_default("brdffit._fit_defaults:DEFAULT_MAX_STEPS") == 200
    assert code_default("brdffit.fitting.compare:compare(losses)") == ("log",)


def test_the_relative_rmse_is_rel_rmse_in_image_metrics_and_fit_metrics():
    """Image metrics (validations: sphere, BTF, scene) and a fit's metrics: one key, the same
    value for the same numbers: sqrt(sum d^2 / sum ref^2) = 0.5 here by hand."""
    from brdffit.fitting.losses import values_metrics
    from brdffit.fitting.problem import prepare
    from brdffit.measurement import Measurement
    from brdffit.render.metrics import image_metrics

    ref = np.full((4, 4, 3), 2.0)
    img = image_metrics(ref, ref * 1.5, np.ones((4, 4), bool))
    assert "relative_rmse" not in img and img["rel_rmse"] == pytest.approx(0.5, rel=1e-12)
    wi = np.tile([[0.0, 0.0, 1.0]], (4, 1))
    m = Measurement(wi, wi, np.full((4, 3), 2.0))
    data = prepare(m).data
    fit = {k: float(v) for k, v in values_metrics(np.full((4, 3), 3.0), data, ("log",)).items()}
    assert "relative_rmse" not in fit and fit["rel_rmse"] == pytest.approx(0.5, rel=1e-12)


def test_a_fit_file_s_relative_rmse_is_read_as_rel_rmse():
    from brdffit.fitting.result import FitResult
    from test_fit_result_doc import FULL

    old = copy.deepcopy(FULL)
    old["metrics"] = {"rmse": 0.1, "relative_rmse": 0.3}
    assert FitResult.from_dict(old).metrics == {"rmse": 0.1, "rel_rmse": 0.3}
    both = copy.deepcopy(FULL)
    both["metrics"] = {"relative_rmse": 0.9, "rel_rmse": 0.3}
    assert FitResult.from_dict(both).metrics == {"rel_rmse": 0.3}
