"""docs/DESIGN.md#tests-that-fail-when-the-code-is-wrong's hand mutations: each deliberate bug of the mutation trial, applied alone to a copy of
the tree, must make at least one of the named test files fail, without the shared data.

mutmut mutates models/, fitting/ and io/ only; these bugs also sit in the CLI, the file writer, the
render metrics, the model checker and the Mitsuba boundary (where the cosine conventions live).

Usage: python scripts/mutation_by_hand.py [INDEX ...]     (``make mutation-by-hand``)
Prints one line per mutation (caught by which test, or NOT CAUGHT); exit status 1 if any was not
caught. The copy is the tracked and untracked (not ignored) files of this tree, in a temporary
folder; this tree is never changed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Mutation:
    what: str
    path: str
    old: str  # must occur exactly once in path
    new: str
    tests: tuple[str, ...]


RENDER_TESTS = ("tests/test_mitsuba_conventions.py", "tests/test_render_sphere.py", "tests/test_bsdf_sampling.py")

MUTATIONS = (
    Mutation("Cornell: the XYZ -> RGB matrix transposed", "brdffit/io/cornell.py",
             "m = xyz_bar @ xyz_to_rgb.T", "m = xyz_bar @ xyz_to_rgb",
             ("tests/test_io_cornell.py", "tests/test_io_cornell_reader.py")),
    Mutation("scipy status 0 (max_nfev reached) reported as converged", "brdffit/fitting/solver_scipy.py",
             "(1 if sol.status == 0 else 4)", "(0 if sol.status == 0 else 4)", ("tests/test_fit_status.py",)),
    Mutation("a result worse than the start (fall back to the start) reported as converged", "brdffit/fitting/driver.py",
             "np.where(finite, np.where(ok, 0, 2), 3)", "np.where(finite, np.where(ok, 0, 0), 3)",
             ("tests/test_fit_status.py",)),
    Mutation("atomic_file writes straight to the target: no temporary file, no rename", "brdffit/_files.py",
             "    with _atomic(Path(path), force, False, lambda p: _new_file(p, suffix)) as tmp:\n        yield tmp\n",
             "    with reserve(Path(path), force, folder=False):\n        yield Path(path)\n",
             ("tests/test_output_safety.py", "tests/test_readme_claims.py")),
    Mutation("internal errors exit 2 instead of 3", "brdffit/cli/__init__.py",
             "        return EXIT_INTERNAL\n", "        return EXIT_BAD_INPUT\n",
             ("tests/test_readme_claims.py", "tests/test_cli_io.py")),
    Mutation("overall PSNR as 20 log10 instead of 10 log10", "brdffit/render/metrics.py",
             "psnr = float(10 * np.log10(1.0 / mse_t))", "psnr = float(20 * np.log10(1.0 / mse_t))",
             ("tests/test_render_metrics.py",)),
    Mutation("pooled PSNR of the lights as 20 log10", "brdffit/render/metrics.py",
             '"psnr": float(10 * np.log10(1.0 / mse_t))', '"psnr": float(20 * np.log10(1.0 / mse_t))',
             ("tests/test_render_metrics.py",)),
    Mutation("the model checker ignoring negative values", "brdffit/testing.py",
             "bad = (~np.isfinite(v) | (v < 0)).any(axis=1)", "bad = (~np.isfinite(v)).any(axis=1)",
             ("tests/test_testing_helpers.py",)),
    Mutation("oren_nayar sigma's upper bound pi/2 -> 1.0 (the physical range)", "brdffit/models/oren_nayar.py",
             "physical=(0.0, math.pi / 2)", "physical=(0.0, 1.0)",
             ("tests/test_models_doc_tables.py", "tests/test_models_registry.py")),
    Mutation("ggx ks's upper bound 1 -> 10 (the physical range)", "brdffit/models/ggx.py",
             'doc="specular scale", physical=(0.0, 1.0)', 'doc="specular scale", physical=(0.0, 10.0)',
             ("tests/test_models_doc_tables.py", "tests/test_models_registry.py")),
    Mutation("eval_bsdf (the RGL reader, the validation's reference table) keeps Mitsuba's cosine",
             "brdffit/_mitsuba.py",
             "return np.where(cos_l > 0, out / np.where(cos_l > 0, cos_l, 1.0), 0.0)",
             "return np.where(cos_l > 0, out, 0.0)", ("tests/test_mitsuba_conventions.py", "tests/test_io_rgl.py")),
    Mutation("the rendered BSDF's eval without the light's cosine", "brdffit/render/bsdf.py",
             "value[up] = f * light[up, 2:3]", "value[up] = f", RENDER_TESTS),
    Mutation("the rendered BSDF's eval with the view's cosine instead of the light's", "brdffit/render/bsdf.py",
             "value[up] = f * light[up, 2:3]", "value[up] = f * view[up, 2:3]", RENDER_TESTS),
)


def copy_tree(dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=ROOT,
                           check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)


def run(mutation: Mutation, tree: Path) -> tuple[bool, str]:
    """(caught, the first failing test or pytest's last line), with mutation applied to tree."""
    path = tree / mutation.path
    source = path.read_text()
    if source.count(mutation.old) != 1:
        return False, f"does not apply: {mutation.path} holds the text {source.count(mutation.old)} times"
    path.write_text(source.replace(mutation.old, mutation.new))
    try:
        env = dict(os.environ, PYTHONPATH=str(tree), BRDFFIT_DATA=str(tree / "no-shared-data"),
                   BRDFFIT_CACHE="off", PYTHONDONTWRITEBYTECODE="1")
        result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider",
                                 *mutation.tests], cwd=tree, env=env, capture_output=True, text=True)
        lines = result.stdout.strip().splitlines()
        failed = [line for line in lines if line.startswith(("FAILED", "ERROR"))]
        # exit 1: tests failed; anything else (2 usage, 4/5 collection, a crash) is no verdict
        return result.returncode == 1, (failed or lines[-1:] or [result.stderr[-200:]])[0]
    finally:
        path.write_text(source)


def main(argv: list[str]) -> int:
    chosen = [MUTATIONS[int(i)] for i in argv] if argv else list(MUTATIONS)
    missed = 0
    with tempfile.TemporaryDirectory(prefix="brdffit-mutation-") as tmp:
        tree = Path(tmp)
        copy_tree(tree)
        for mutation in chosen:
            t0 = time.perf_counter()
            caught, detail = run(mutation, tree)
            missed += not caught
            print(f"{'caught' if caught else 'NOT CAUGHT':10} {time.perf_counter() - t0:5.0f} s  {mutation.what}: {detail}",
                  flush=True)
    print(f"{len(chosen) - missed} of {len(chosen)} caught (without the shared data)")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
