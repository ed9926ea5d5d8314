"""Ctrl-C at any moment: SIGINT sent to a running ``brdffit`` command at a sweep of moments.

For each moment, a fresh command (``fit SOURCE --model lambert+ggx+ggx -o DIR`` with the compile
cache off, so that it works for seconds; or with ``--blend`` a ``.blend`` export, which drives the
Blender worker) runs in a process group of its own with a private TMPDIR and gets SIGINT after that
many seconds, sent to its whole group as a terminal does. The table shows its exit status, how long
it took to end after the signal, whether it printed a traceback, and what it left in its output
folder's parent and in TMPDIR (nothing is the only right answer after an interrupt; a run that
ended before the signal exits 0 with its result). Statuses: 130 (brdffit's own interrupt, one
line), -2 (ended by the signal itself: only in the interpreter's start-up, before brdffit's first
line), 0 (finished before the signal). A traceback, a hang (over 5 s after the signal), any other
status or a leftover is a failure, counted at the end.

    .venv/bin/python benchmarks/bench_interrupt.py [--moments 0.05 0.1 ...] [--model M] [--source FILE] [--blend]
"""

from __future__ import annotations

import argparse
import json
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
BLENDER_FIT = {"model": "blender:principled", "converged": True, "data_name": "bench",
               "params": {"base_color": [0.5, 0.3, 0.2], "metallic": [0.1], "roughness": [0.3], "ior": [1.5],
                          "specular_tint": [1.0]}}


def _deliverable_sigint() -> None:  # the child gets a terminal's default SIGINT disposition
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def one(moment: float, argv_of) -> tuple[int | None, float, str, list[str], bool]:
    """(exit status or None for a hang, seconds from the signal to the end, stderr, leftovers, finished)."""
    work = Path(tempfile.mkdtemp(prefix="brdffit-int-"))
    tmp = work / "tmp"
    (work / "out").mkdir()
    tmp.mkdir()
    exe = shutil.which("brdffit", path=str(Path(sys.executable).parent)) or "brdffit"
    env = {**os.environ, "BRDFFIT_CACHE": "off", "TMPDIR": str(tmp)}
    p = subprocess.Popen([exe, *argv_of(work / "out")], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True, env=env, preexec_fn=_deliverable_sigint, start_new_session=True)
    time.sleep(moment)
    finished = p.poll() is not None
    sent = time.monotonic()
    if not finished:
        os.killpg(p.pid, signal.SIGINT)
    try:
        code = p.wait(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        code = None
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    took = time.monotonic() - sent
    time.sleep(0.5)  # what outlives the command would write now
    left = sorted(str(e.relative_to(work)) for e in (work / "out").iterdir()) + \
        sorted(str(e.relative_to(work)) for e in tmp.iterdir())
    shutil.rmtree(work, ignore_errors=True)
    return code, took, p.stderr.read(), left, finished or code == 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moments", type=float, nargs="+", default=DEFAULT_MOMENTS)
    ap.add_argument("--model", default="lambert+ggx+ggx")
    ap.add_argument("--source", default=str(ROOT / "data" / "sample_ubo81.exr"))
    ap.add_argument("--blend", action="store_true", help="interrupt `brdffit export FIT.json -o x.blend` instead")
    args = ap.parse_args()
    fit_dir = Path(tempfile.mkdtemp(prefix="brdffit-int-fit-"))
    try:
        return sweep(args, fit_dir)
    finally:
        shutil.rmtree(fit_dir, ignore_errors=True)


def sweep(args, fit_dir: Path) -> int:
    if args.blend:
        fit_json = fit_dir / "fit.json"
        fit_json.write_text(json.dumps(BLENDER_FIT))
        argv_of, result = (lambda out: ["export", str(fit_json), "-o", str(out / "x.blend")]), ["out/x.blend"]
    else:
        argv_of, result = (lambda out: ["fit", args.source, "--model", args.model, "-o", str(out / "fit")]), ["out/fit"]
    print(f"{'after s':>7s} {'status':>6s} {'ended in s':>10s} {'traceback':>9s}  left behind")
    bad = 0
    for moment in args.moments:
        code, took, err, left, finished = one(moment, argv_of)
        traceback = "Traceback" in err
        ok = not traceback and ((code in (130, -2) and not left) or (finished and code == 0 and left == result))
        bad += not ok
        shown = "hang" if code is None else str(code)
        print(f"{moment:7.2f} {shown:>6s} {took:10.2f} {'yes' if traceback else 'no':>9s}  {', '.join(left) or '-'}"
              f"{'' if ok else '   <- FAILED'}", flush=True)
    print(f"{len(args.moments) - bad} of {len(args.moments)} moments right")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
