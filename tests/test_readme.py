"""Every code block of the README runs as written, in a fresh temporary folder (docs/DESIGN.md#where-users-meet-brdffit, defect 1).

- ``python`` blocks run as scripts; the one made of ``# conftest.py`` and ``# test_*.py`` parts is
  written out as those files and run by pytest against the shared data (skipped, with the reason,
  without them). A block whose first line is ``# needs: PROGRAM`` (``sbatch``: a SLURM cluster) runs
  where that program is found; elsewhere it must compile and every module it imports be installed.
- ``sh`` blocks are checked with ``bash -n``. They start long runs (``make demo`` / ``make test``
  set up a venv; ``brdffit fit/validate/compare`` on real data take minutes), so they are not
  run: every ``make`` target must exist (``make -n`` parses it), and every ``brdffit`` sub-command
  and option they use must be one the CLI accepts (checked against ``--help``).
- Blocks without a language are diagrams.
"""

from __future__ import annotations

import ast
import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO, data_dir

README = REPO / "README.md"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
NEEDS = re.compile(r"^# needs: (\S+)\n")


def blocks(lang: str) -> list[str]:
    return [body for language, body in FENCE.findall(README.read_text()) if language == lang]


def _env(tmp_path: Path, **extra) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(x for x in (str(REPO), env.get("PYTHONPATH")) if x)
    env["MPLBACKEND"] = "Agg"  # a headless child: no display (brdffit itself never sets a backend)
    env.update(extra)
    return env


def _split_files(block: str) -> dict[str, str] | None:
    """{file name: text} for a block made of '# name.py' sections, else None."""
    parts = re.split(r"^# (\w+\.py)\n", block, flags=re.M)
    if len(parts) < 3:
        return None
    return {parts[k]: parts[k + 1] for k in range(1, len(parts), 2)}


def test_readme_has_the_blocks_this_test_checks():
    kinds = [language for language, _ in FENCE.findall(README.read_text())]
    assert set(kinds) <= {"", "python", "sh"}, kinds
    assert any(_split_files(b) for b in blocks("python")), "the pytest example is missing"
    assert any(not _split_files(b) for b in blocks("python")), "the Python example is missing"


@pytest.mark.slow
def test_python_blocks_run_as_written(tmp_path):
    scripts = [b for b in blocks("python") if not _split_files(b)]
    for k, block in enumerate(scripts):
        need = NEEDS.match(block)
        if need and shutil.which(need.group(1)) is None:
            continue  # test_blocks_that_need_a_missing_program_compile_and_import
        path = tmp_path / f"block{k}.py"
        path.write_text(block)
        run = subprocess.run([sys.executable, str(path)], cwd=tmp_path, env=_env(tmp_path), capture_output=True,
                             text=True, timeout=900)
        assert run.returncode == 0, f"README python block {k} failed:\n{block}\n{run.stderr[-3000:]}"
    assert (tmp_path / "fit.json").exists() and (tmp_path / "pareto.png").stat().st_size > 10_000
    assert (tmp_path / "validation" / "metrics.json").exists()


def test_blocks_that_need_a_missing_program_compile_and_import():
    """The blocks this machine cannot run (``# needs: sbatch``) are still Python that compiles, and
    every module they import is installed (the SLURM example's ``dask_jobqueue``: brdffit[cluster])."""
    needing = [b for b in blocks("python") if NEEDS.match(b)]
    assert needing, "the SLURM example is missing"
    for block in needing:
        tree = ast.parse(block)
        names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        names += [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module]
        assert names
        for name in names:
            assert importlib.util.find_spec(name.split(".")[0]) is not None, f"{name} is not installed:\n{block}"


@pytest.mark.slow
def test_pytest_block_passes_against_the_shared_data(tmp_path):
    data = data_dir()
    if data is None:
        pytest.skip("real measurements not found: set BRDFFIT_DATA or place them in ../shared/data")
    (files,) = [f for f in map(_split_files, blocks("python")) if f]
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    run = subprocess.run([sys.executable, "-m", "pytest", "-rs", "-q", "-p", "no:cacheprovider", str(tmp_path)],
                         cwd=tmp_path, env=_env(tmp_path, BRDFFIT_DATA=str(data)), capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:]
    assert re.search(r"\b2 passed\b", run.stdout) and "skipped" not in run.stdout, run.stdout[-2000:]


def test_pytest_block_skip_says_where_it_looked(tmp_path):
    """Without the data, the README's fixture skips and the reason names the places looked in."""
    (files,) = [f for f in map(_split_files, blocks("python")) if f]
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    env = _env(tmp_path, BRDFFIT_DATA=str(tmp_path / "nowhere"))
    run = subprocess.run([sys.executable, "-m", "pytest", "-rs", "-q", "-p", "no:cacheprovider", "-k", "test_fit",
                          str(tmp_path)], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout[-3000:]
    assert "1 skipped" in run.stdout
    assert str(tmp_path / "nowhere") in run.stdout and "shared/data" in run.stdout, run.stdout[-2000:]


def test_shell_blocks_parse_and_name_real_commands(tmp_path):
    from click.testing import CliRunner

    from brdffit.cli import _load_commands, cli

    _load_commands()
    runner = CliRunner()
    for block in blocks("sh"):
        check = subprocess.run(["bash", "-n"], input=block, capture_output=True, text=True)
        assert check.returncode == 0, f"{block}\n{check.stderr}"
        for line in block.splitlines():
            words = shlex.split(line, comments=True)
            if not words:
                continue
            if words[0] == "make":
                dry = subprocess.run(["make", "-n", "-C", str(REPO), *words[1:]], capture_output=True, text=True,
                                     env={**os.environ, "PYTHON": "false"})
                assert "No rule to make target" not in dry.stderr, line
                continue
            assert words[0] == "brdffit", f"unexpected command in a README shell block: {line}"
            sub = words[1]
            help_text = runner.invoke(cli, [sub, "--help"]).output
            assert help_text.startswith("Usage:"), f"{line}: `brdffit {sub}` is not a command"
            for w in words[2:]:
                if w.startswith("-"):
                    assert re.search(rf"(^|[\s,]){re.escape(w)}\b", help_text), f"{line}: {w} not in `brdffit {sub} --help`"
