"""Opt-in pytest fixtures for users' suites: ``pytest_plugins = ["brdffit.pytest_plugin"]``.

- ``brdffit_data``: the folder of real measurements (the one holding ``measured/``): $BRDFFIT_DATA,
  else ../shared/data beside pytest's rootdir; the test is skipped when there is none, with a
  reason that names every place looked in (``pytest -rs`` prints it).
- ``ubo_pairs``: the UBO-81 (wi, wo) pairs, (6561, 3) each, sample k = light * 81 + view.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest


def data_candidates(rootpath: Path) -> list[tuple[str, Path | None]]:
    """Where ``brdffit_data`` looks, in order: $BRDFFIT_DATA, then ../shared/data beside the
    project (pytest's rootdir)."""
    env = os.environ.get("BRDFFIT_DATA")
    return [("$BRDFFIT_DATA", Path(env) if env else None), ("rootdir/../shared/data", Path(rootpath).parent / "shared" / "data")]


@pytest.fixture(scope="session")
def brdffit_data(request) -> Path:
    candidates = data_candidates(request.config.rootpath)
    for _, c in candidates:
        if c is not None and (c / "measured").is_dir():
            return c
    looked = "; ".join(f"{name} = {'unset' if c is None else c}" for name, c in candidates)
    pytest.skip(f"no real measurements (a folder holding measured/): looked in {looked}; "
                "set BRDFFIT_DATA to the data folder")


@pytest.fixture(scope="session")
def ubo_pairs():
    from .grid import ubo_pairs as pairs

    return pairs()
