"""Ctrl-C at any moment (issue 28): SIGINT sent to a running ``brdffit fit`` at a sweep of moments.

For each moment, a fresh ``brdffit fit SOURCE --model lambert+ggx+ggx -o DIR`` (compile cache off, so
that it works for seconds) gets SIGINT after that many seconds; the table shows its exit status,
how long it took to end after the signal, and what it left in its output folder's parent (nothing is
the only right answer after an interrupt; a run that ended before the signal exits 0 with its
result). Statuses: 130 (brdffit's own interrupt), -2 (ended by the signal itself, before brdffit's
handler was installed), 0 (finished before the signal). Anything else, a hang (over 5 s after
the signal) or a leftover is a failure, counted at the end.

    .venv/bin/python benchmarks/bench_interrupt.py [--moments 0.05 0.1 ...] [--model M] [--source FILE]
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MOMENTS = [round(0.05 + 0.1 * k, 2) for k in range(30)]  # 0.05 .. 2.95 s
HANG_S = 5.0


def _deliverable_sigint() -> None:  # the child gets a terminal's default SIGINT disposition
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def one(moment: float, source: str, model: str) -> tuple[int | None, float, list[str], bool]:
    """(exit status or None for a hang, seconds from the signal to the end, leftovers, finished)."""
    work = Path(tempfile.mkdtemp(prefix="brdffit-int-"))
    out = work / "fit"
    exe = shutil.which("brdffit", path=str(Path(sys.executable).parent)) or "brdffit"
    env = {**os.environ, "BRDFFIT_CACHE": "off"}
    p = subprocess.Popen([exe, "fit", source, "--model", model, "-o", str(out)], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, env=env, preexec_fn=_deliverable_sigint)
    time.sleep(moment)
    finished = p.poll() is not None
    sent = time.monotonic()
    if not finished:
        p.send_signal(signal.SIGINT)
    try:
        code = p.wait(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        code = None
        p.kill()
        p.wait()
    took = time.monotonic() - sent
    left = sorted(e.name for e in work.iterdir())
    shutil.rmtree(work, ignore_errors=True)
    return code, took, left, finished or code == 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moments", type=float, nargs="+", default=DEFAULT_MOMENTS)
    ap.add_argument("--model", default="lambert+ggx+ggx")
    ap.add_argument("--source", default=str(ROOT / "data" / "sample_ubo81.exr"))
    args = ap.parse_args()
    print(f"{'after s':>7s} {'status':>6s} {'ended in s':>10s}  left behind")
    bad = 0
    for moment in args.moments:
        code, took, left, finished = one(moment, args.source, args.model)
        ok = (code in (130, -2) and not left) or (finished and code == 0 and left == ["fit"])
        bad += not ok
        shown = "hang" if code is None else str(code)
        print(f"{moment:7.2f} {shown:>6s} {took:10.2f}  {', '.join(left) or '-'}{'' if ok else '   <- FAILED'}",
              flush=True)
    print(f"{len(args.moments) - bad} of {len(args.moments)} moments right")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
