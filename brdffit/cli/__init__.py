"""``brdffit`` command line (docs/cli.md#the-command-line-and-set-up).

Exit status: 0 success; 1 a fit ran but did not converge (results still written, marked);
2 bad input or usage (one line naming the file and the problem, no traceback unless --debug,
which is accepted anywhere on the line); 130 interrupted (Ctrl-C; nothing half-written);
3 an internal error (a bug: please report it with the --debug traceback).
Warnings about suspect data are shown as one ``brdffit: warning:`` line each, after a successful
run; library noise (NumPy RuntimeWarnings) only with --debug.
Each sub-command lives in its own module of this package and registers itself on ``cli``.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
import time
import warnings

import click

from ..errors import BrdffitWarning, InputError, UsageError

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
# click >= 8.2 calls it NoArgsIsHelpError, older versions NoArgsIsHelp (an empty tuple catches nothing)
_NO_ARGS_IS_HELP = getattr(click.exceptions, "NoArgsIsHelpError", getattr(click.exceptions, "NoArgsIsHelp", ()))


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, help="Show full tracebacks.")
@click.version_option(package_name="brdffit")
@click.pass_context
def cli(ctx: click.Context, debug: bool) -> None:
    """Fit analytic BRDF models to measured reflectance and validate them in Mitsuba 3."""
    ctx.ensure_object(dict)
    ctx.obj["debug"] = debug


def _load_commands() -> None:
    import importlib
    import pkgutil

    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")


class Interrupted(BaseException):
    """Ctrl-C while a command runs. Not a KeyboardInterrupt, so that click does not turn it into
    its own "Aborted!"; like one, it unwinds through every ``finally`` (temporary results are
    removed, locks released)."""


@contextlib.contextmanager
def _interrupts_raise():
    """Ctrl-C raises :class:`Interrupted` and sets ``STOP_REQUESTED``, which stops any result from
    being committed even where the exception is swallowed (a signal landing in a garbage-collection
    callback or a ``__del__``); ``main`` then reports the run as interrupted."""
    from .._files import STOP_REQUESTED
    from .._interrupt import ends_process_on_interrupt

    if threading.current_thread() is not threading.main_thread() or ends_process_on_interrupt():
        yield  # the executable: its Ctrl-C ends the process from a watcher thread (_files)
        return

    def on_sigint(signum, frame):
        STOP_REQUESTED.set()
        raise Interrupted()

    def quiet_about_swallowed_interrupts(unraisable):
        if not isinstance(unraisable.exc_value, Interrupted):
            previous_hook(unraisable)

    STOP_REQUESTED.clear()
    previous_hook, sys.unraisablehook = sys.unraisablehook, quiet_about_swallowed_interrupts
    previous = signal.signal(signal.SIGINT, on_sigint)
    try:
        try:
            yield
        except Interrupted:
            raise
        except BaseException as exc:
            # Once Ctrl-C came, whatever failed failed because of it: the handler's exception may have
            # been turned into another (raised in an extension module's initialisation it becomes
            # "ImportError: initialization failed", which a reader reports as unreadable input).
            if STOP_REQUESTED.is_set():
                raise Interrupted() from exc
            raise
        if STOP_REQUESTED.is_set():
            raise Interrupted()  # the handler's exception was swallowed and the command ran to its end
    finally:
        signal.signal(signal.SIGINT, previous)
        sys.unraisablehook = previous_hook
        STOP_REQUESTED.clear()


#: How long a command that failed after Ctrl-C waits for the executable's watcher thread, which is
#: ending the process (it stops helper processes and removes outputs first: well under this).
_WATCHER_GRACE_S = 60.0


def _stop_if_interrupted() -> None:
    """A command failed after Ctrl-C: the failure is the interrupt's doing (the executable's watcher
    thread stops the Blender worker, so the command sees it end). Say nothing of it: in the
    executable, wait for the watcher to end the process with its one line; else raise
    :class:`Interrupted`."""
    from .._files import STOP_REQUESTED
    from .._interrupt import ends_process_on_interrupt

    if not STOP_REQUESTED.is_set():
        return
    if ends_process_on_interrupt():
        time.sleep(_WATCHER_GRACE_S)
    raise Interrupted()


def check_model(name: str, channels: int = 3):
    """The model ``name`` (e.g. ``lambert+ggx``), or a usage error (exit 2) for names that cannot
    make a model: unknown, ``lafortune0``, ``lafortune100000``, ``lambert+lambert``..."""
    from ..fitting.problem import resolve_model

    try:
        return resolve_model(name, channels)
    except InputError:
        raise
    except (KeyError, ValueError, OverflowError, MemoryError) as exc:
        raise UsageError(f"--model {name!r}: {' '.join(str(exc).split()) or type(exc).__name__}") from None


def _split_debug(argv: list[str]) -> tuple[list[str], bool]:
    """``--debug`` anywhere before a ``--`` (before or after the sub-command)."""
    end = argv.index("--") if "--" in argv else len(argv)
    debug = "--debug" in argv[:end]
    return [a for a in argv[:end] if a != "--debug"] + argv[end:], debug


def _show_warnings(caught, debug: bool) -> None:
    seen = set()
    for w in caught:
        ours = issubclass(w.category, BrdffitWarning)
        if not (ours or debug):
            continue  # library noise (e.g. NumPy RuntimeWarnings): --debug shows it
        line = f"brdffit: warning: {' '.join(str(w.message).split())}"
        if line not in seen:
            seen.add(line)
            click.echo(line, err=True)


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI and map errors to docs/cli.md#the-command-line-and-set-up exit statuses."""
    argv, debug = _split_debug(list(sys.argv[1:] if argv is None else argv))
    from .._files import forget_committed

    forget_committed()
    caught: list = []
    try:
        with warnings.catch_warnings(record=True) as caught, _interrupts_raise():
            warnings.simplefilter("always")
            _load_commands()  # inside: a Ctrl-C during the imports is an interrupt like any other
            try:
                result = cli.main(args=(["--debug"] if debug else []) + argv, prog_name="brdffit",
                                  standalone_mode=False)
            except Exception:
                _stop_if_interrupted()
                raise
    except (Interrupted, KeyboardInterrupt, click.exceptions.Abort):
        click.echo("brdffit: interrupted", err=True)
        return EXIT_INTERRUPTED
    except _NO_ARGS_IS_HELP as exc:  # pragma: no cover - click version dependent
        click.echo(exc.format_message() if hasattr(exc, "format_message") else str(exc), err=True)
        return EXIT_BAD_INPUT
    except click.ClickException as exc:
        click.echo(f"brdffit: {' '.join(exc.format_message().split())}", err=True)
        return EXIT_BAD_INPUT
    except InputError as exc:
        if debug:
            raise
        click.echo(f"brdffit: {' '.join(str(exc).split())}", err=True)
        return EXIT_BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - last line of defence: one line, not a traceback
        if debug:
            raise
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        click.echo(f"brdffit: internal error: {message} (run with --debug for the traceback)", err=True)
        return EXIT_INTERNAL
    _show_warnings(caught, debug)
    return int(result or 0)


#: Collection thresholds of the ``brdffit`` process (Python's default: 700, 10, 10).
GC_THRESHOLDS = (100_000, 50, 1000)


def entry() -> None:
    """The ``brdffit`` executable: ``main()`` and a normal interpreter exit.

    The cyclic garbage collector is tuned for a process that imports JAX, matplotlib and rich
    (about a million long-lived objects) and then works for seconds: young collections every
    ``GC_THRESHOLDS[0]`` allocations (cyclic garbage is still freed while a long command runs),
    full ones rarely; and the objects are frozen before the interpreter exits, so that its
    teardown does not walk all of them again. Measured on a second-process ``brdffit fit``: the
    default settings cost ~0.8 s CPU of ~3.3 s, most of it in that teardown (atexit handlers
    and module teardown still run; the exit is not skipped). Ctrl-C ends the process from a watcher
    thread (``brdffit._interrupt``; the package's first line installs it already).
    (It used to skip the teardown with ``os._exit`` to save ~0.4 s; that also hid the abort at exit
    of docs/DESIGN.md#tests-that-fail-when-the-code-is-wrong -- a daemon compile thread -- which is fixed in the library now, and skipped
    atexit handlers such as coverage's.)
    """
    import gc

    from .._interrupt import end_process_on_interrupt

    end_process_on_interrupt()  # done already unless run as `python -m brdffit`
    gc.set_threshold(*GC_THRESHOLDS)
    try:
        status = main()
    finally:
        # The command has ended and said so: a Ctrl-C from here on (the interpreter's teardown, the
        # Blender worker's shutdown) changes nothing. Left to the default it ended the process with
        # -2 after "wrote ...", the result in place. (Python's teardown keeps an ignored signal ignored.)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        gc.freeze()
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    entry()
