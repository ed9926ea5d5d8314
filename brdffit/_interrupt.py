"""The ``brdffit`` executable's Ctrl-C (docs/cli.md#the-command-line-and-set-up): one line, exit 130, nothing left, at any moment.

:func:`end_process_on_interrupt` is installed by the package's first line when the process is the
``brdffit`` executable (:func:`is_the_executable`), before the package imports anything else, so
that a Ctrl-C while NumPy or JAX import is handled as one later on; ``cli.entry`` installs it too
(``python -m brdffit``). This module imports only os, signal and sys before the handler is in
place (tempfile and threading after); a Ctrl-C before that (the package's first lines) is answered by the
executable's own module, ``brdffit_main.py`` beside the package, with the same line and 130, so what is
left is the interpreter's own start-up, where the signal is Python's (see ``brdffit_main.py``: nothing
of brdffit ran, nothing written); it reaches
``brdffit._files`` only once that is imported (nothing can have been written before).
"""

from __future__ import annotations

import os
import signal
import sys

EXIT_INTERRUPTED = 130
_WATCHING: list[bool] = []


def ends_process_on_interrupt() -> bool:
    """Whether :func:`end_process_on_interrupt` is in force in this process."""
    return bool(_WATCHING)


def is_the_executable() -> bool:
    """Whether this process is the ``brdffit`` executable (its console script is ``__main__``)."""
    script = getattr(sys.modules.get("__main__"), "__file__", None)
    return bool(sys.argv and script) and os.path.basename(sys.argv[0]) == "brdffit" and \
        os.path.abspath(script) == os.path.abspath(sys.argv[0])


def _stop_this_run() -> None:
    """What the watcher does before ending the process: stop helper processes and remove what this
    run wrote (``_files.remove_this_runs_outputs``, which waits for a commit in progress)."""
    files = sys.modules.get("brdffit._files")
    if files is not None and hasattr(files, "remove_this_runs_outputs"):  # imported (completely)
        files.STOP_REQUESTED.set()
        files.remove_this_runs_outputs()


def end_process_on_interrupt() -> None:
    """Make Ctrl-C end this process at once, whatever it is doing, leaving nothing written (a second
    call does nothing).

    An exception raised by a signal handler lands wherever the interpreter is: inside a compiler's
    callback or an extension module's initialisation it aborted the process (-6), crashed it (-11)
    or hung it, inside an import it printed a ``KeyboardInterrupt`` traceback, and after a commit it
    reported 130 with the result written (benchmarks/bench_interrupt.py sweeps the moments). So the
    handler raises nothing: the C-level signal handler writes the signal's number to a pipe
    (``signal.set_wakeup_fd``), a daemon thread waiting on it wakes within milliseconds even while
    the main thread runs native code, stops this run (:func:`_stop_this_run`), says so in one line
    and ends the process with 130 (``os._exit``: no teardown of native libraries in their work)."""
    if _WATCHING:
        return
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    # the pipe and the handler first, the thread last: a Ctrl-C from here on waits in the pipe
    try:
        signal.set_wakeup_fd(write_end, warn_on_full_buffer=False)
    except ValueError:  # not the main thread: Python's own handling stays
        os.close(read_end)
        os.close(write_end)
        return
    signal.signal(signal.SIGINT, _nothing)  # the watcher acts; a C-level handler is needed
    _WATCHING.append(True)
    _look_at_the_temporary_folder()
    # The line goes to the standard error of now: while a reader captures what a C library writes to
    # descriptor 2 (io._common.native_stderr_captured), a line written there was lost with the capture.
    try:
        stderr = os.dup(2)
    except OSError:  # no standard error (closed): nothing to say it on
        stderr = -1
    import threading

    threading.Thread(target=_watch, args=(read_end, stderr), name="brdffit-interrupt", daemon=True).start()


def _nothing(signum, frame) -> None:
    pass


def _look_at_the_temporary_folder() -> None:
    """Python's first ``tempfile`` call of a process finds the temporary folder by writing a probe file
    there (a name of 8 random characters) and removing it; a Ctrl-C in between, ending the process at
    once, left the file behind (seen in CI). Made here, before the watcher runs, a Ctrl-C waits in the
    pipe until it is done; later calls reuse the folder found. Where there is none to be found, the
    command that needs one says so."""
    import contextlib
    import tempfile

    with contextlib.suppress(OSError):
        tempfile.gettempdir()


def _watch(read_end: int, stderr: int) -> None:
    while signal.SIGINT not in os.read(read_end, 64):
        pass
    _stop_this_run()
    try:
        os.write(stderr, b"brdffit: interrupted\n")
    except OSError:
        pass
    os._exit(EXIT_INTERRUPTED)
