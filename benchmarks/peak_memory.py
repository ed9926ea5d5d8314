"""The peak resident memory of a benchmark's child process, its own: every child that reports memory
(bench_memory, bench_native, bench_plugin) begins with :data:`CHILD_PRELUDE` and calls ``peak_mb()``.

VmHWM (Linux) is the high-water mark of the address space that exec created. ``ru_maxrss`` is not:
Linux carries the parent's peak over exec, so a child of a pytest worker that had grown to 4 GB
"peaked" at 4 GB before it ran a line. ``ru_maxrss`` stays as the fallback where there is no /proc.
"""

from __future__ import annotations

import resource
from pathlib import Path


def peak_mb() -> float:
    """This process's peak resident memory in MB."""
    try:
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) / 1024.0 for line in f if line.startswith("VmHWM:"))
    except (OSError, StopIteration):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


#: The first line of a child's source (``python -c``): ``peak_mb`` from this file, whatever the cwd.
CHILD_PRELUDE = f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parent)!r}); from peak_memory import peak_mb\n"
