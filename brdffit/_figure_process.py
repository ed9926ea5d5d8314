"""Draw a figure in a process of its own while this one works (``brdffit fit``'s fit.png).

Why: in a second-process ``brdffit fit`` (the compile cache full) the fit itself takes ~0.3 s, while
importing JAX takes ~0.8 s and importing matplotlib and drawing fit.png ~1.2 s more, all of it
holding the interpreter lock of one process: one core. A worker started before this process
imports JAX (``import brdffit`` and the CLI do not) imports matplotlib on another core meanwhile,
receives the figure's data (``brdffit.plot.FigureData``: arrays and text, no JAX) when the fit is
done, and writes the PNG; this process then only waits for it.

The worker is a plain Python child running :func:`main`: it starts the same way on every platform,
and it needs nothing from this process but the pickled data and the target path on its standard
input. Its own session (a Ctrl-C at the terminal reaches this process only, which stops
it); it reads its standard input, so it also ends when this process is gone. Whatever goes wrong
in it (it cannot start, it fails, it is killed), :meth:`FigureProcess.savefig` draws the figure
here instead: the worker makes the command faster, never different.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

#: The folder this brdffit is imported from (a source tree or site-packages).
_ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
#: The worker: :func:`main` of this module, in a Python that imports this same brdffit (its folder
#: goes first on ``sys.path`` only where another brdffit, or none, would be found: never
#: site-packages ahead of the standard library).
WORKER = [sys.executable, "-c",
          "import os, sys, importlib.util as u\n"
          "s = u.find_spec('brdffit')\n"
          "if s is None or os.path.dirname(os.path.dirname(os.path.realpath(s.origin))) != sys.argv[1]:\n"
          "    sys.path.insert(0, sys.argv[1])\n"
          "from brdffit._figure_process import main\n"
          "main()\n", _ROOT]
#: Seconds to wait for the worker's PNG before drawing it here (a figure takes ~1 s).
WAIT_S = 300.0


class FigureProcess:
    """A worker that will draw one figure (:meth:`savefig`); :meth:`close` ends it if it was not
    used. Use it as a context manager, started as early as possible."""

    def __init__(self, command: list[str] | None = None):
        command = list(command or WORKER)
        self._proc = None
        if not command[0]:  # no Python executable known (an embedded interpreter): draw here
            return
        try:
            self._proc = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                          stderr=subprocess.DEVNULL, start_new_session=True)
        except OSError:
            self._proc = None

    def savefig(self, data, path, dpi: float) -> None:
        """Write ``data.draw()`` (a ``brdffit.plot.FigureData``) to ``path``: by the worker if it
        writes it, else here."""
        path = Path(path)
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                with proc.stdin:
                    pickle.dump((data, str(path), dpi), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                if proc.wait(timeout=WAIT_S) == 0 and path.is_file():
                    return
            except (OSError, pickle.PicklingError, subprocess.TimeoutExpired):
                pass
            finally:
                _stop(proc)
        data.draw().savefig(path, dpi=dpi)

    def close(self) -> None:
        """End the worker if :meth:`savefig` did not use it (an error or an interrupt before)."""
        proc, self._proc = self._proc, None
        if proc is not None:
            _stop(proc)

    def __enter__(self) -> FigureProcess:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.kill()
    proc.wait()
    if proc.stdin is not None:
        try:
            proc.stdin.close()
        except OSError:  # a broken pipe: the worker is gone anyway
            pass


def main() -> None:
    """The worker: import matplotlib (the slow part, before the data arrive), read (FigureData,
    path, dpi) from standard input, write the PNG, exit 0; any failure: exit 1 without a word (the
    parent draws the figure itself). It ends without the interpreter's teardown: the parent waits
    for its exit."""
    import gc

    gc.set_threshold(100_000, 50, 1000)  # matplotlib's import: many objects, little garbage
    try:
        import matplotlib.backends.backend_agg  # noqa: F401 - what savefig's PNG needs, imported meanwhile

        from brdffit.plot import _figure  # noqa: F401 - the figures and matplotlib's Figure

        data, path, dpi = pickle.load(sys.stdin.buffer)
        data.draw().savefig(path, dpi=dpi)
    except BaseException:  # noqa: BLE001 - the parent draws the figure instead
        os._exit(1)
    os._exit(0)

