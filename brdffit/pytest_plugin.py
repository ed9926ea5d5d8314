"""Opt-in pytest fixtures for users' suites: ``pytest_plugins = ["brdffit.pytest_plugin"]``.

- ``brdffit_data``: the folder of real measurements ($BRDFFIT_DATA, else ../shared/data from the
  rootdir); the test is skipped, with the reason, when there is none.
- ``ubo_pairs``: the UBO-81 (wi, wo) pairs, (6561, 3) each, sample k = light * 81 + view.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def brdffit_data(request) -> Path:
    candidates = [os.environ.get("BRDFFIT_DATA"), str(Path(request.config.rootpath).parent / "shared" / "data")]
    for c in candidates:
        if c and (Path(c) / "measured").is_dir():
            return Path(c)
    pytest.skip("no real measurements: set BRDFFIT_DATA to a folder holding measured/")


@pytest.fixture(scope="session")
def ubo_pairs():
    from .grid import ubo_pairs as pairs

    return pairs()
