"""The ``brdffit`` executable's first module, outside the package so that it runs before ``import brdffit``.

The package's first lines put brdffit's Ctrl-C handling in place (``brdffit/_interrupt.py``: one line,
exit 130, nothing left); a Ctrl-C while those lines are still being reached used to print Python's
``KeyboardInterrupt`` traceback from the console script's import. Here that moment is one line too.
What is left before this is the interpreter's own start-up and the console script's import line: a
Ctrl-C there is Python's (killed by the signal, or "Fatal Python error" while importing ``site``, exit 1),
with nothing of brdffit run and nothing written.
"""

from __future__ import annotations

import sys


def entry() -> None:
    try:
        from brdffit.cli import entry as run
    except KeyboardInterrupt:  # only before the package's handler is in place: after, Ctrl-C raises nothing
        sys.stderr.write("brdffit: interrupted\n")
        sys.exit(130)
    run()
