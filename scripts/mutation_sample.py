"""Draw a uniform random sample of mutmut's mutants, for a score in the time one machine has.

brdffit/fitting alone has ~5,900 mutants and its tests compile and run fits: ~8 hours on a 2-core
machine. A uniform random sample of n of them estimates the package's score with a known error
(``scripts/mutation_report.py --sample FILE`` prints the 95 % Wilson interval), and the survivors it
finds are a fair sample of the tests' gaps. The draw is seeded and listed in order of the shuffle,
so a run cut short still leaves a uniform sample: run the list's first k and report those.

The names are the ones mutmut itself gives: each source file matching ``[tool.mutmut]``'s
``only_mutate`` (and not ``do_not_mutate``) is mutated with mutmut's own generator, in memory.

Usage: python scripts/mutation_sample.py N [PATTERN ...] [--seed S] > names.txt
       e.g.  python scripts/mutation_sample.py 400 'brdffit.fitting.*' --seed 20261202
N counts per package (``brdffit.fitting``, ``brdffit.io``, ...), so each package's estimate has
the same error whatever its size.
"""

from __future__ import annotations

import argparse
import fnmatch
import random
import sys
from collections import defaultdict
from pathlib import Path


def mutant_names(root: Path) -> list[str]:
    """Every mutant mutmut makes of the configured sources, by mutmut's own generator."""
    from mutmut.mutation.file_mutation import mutate_file_contents
    from mutmut.utils.format_utils import get_mutant_name

    from mutation_report import mutated_sources

    is_mutated = mutated_sources(root)
    names = []
    for path in sorted(root.glob("brdffit/**/*.py")):
        source = str(path.relative_to(root))
        if not is_mutated(source):
            continue
        mutated = mutate_file_contents(source, path.read_text())
        names += [get_mutant_name(Path(source), name) for name in mutated.mutant_names]
    return names


def draw(names: list[str], n: int, seed: int) -> list[str]:
    """n mutants per package, uniformly without replacement, in the order the shuffle gives them."""
    by_package: dict[str, list[str]] = defaultdict(list)
    for name in sorted(names):
        by_package[".".join(name.split(".")[:2])].append(name)
    rng = random.Random(seed)
    sample = []
    for package in sorted(by_package):
        sample += rng.sample(by_package[package], min(n, len(by_package[package])))
    # interleave the packages by a second shuffle so that any prefix covers them all
    rng.shuffle(sample)
    return sample


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("n", type=int, help="mutants per package")
    parser.add_argument("patterns", nargs="*", default=["*"], help="fnmatch patterns of mutant names")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    names = [m for m in mutant_names(Path(".")) if any(fnmatch.fnmatch(m, p) for p in args.patterns)]
    print("\n".join(draw(names, args.n, args.seed)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
