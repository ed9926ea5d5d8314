"""``brdffit`` command line (SPEC 7).

Exit status: 0 success; 1 a fit ran but did not converge (results still written, marked);
2 bad input or usage (one line naming the file and the problem, no traceback unless --debug);
3 an internal error (a bug: please report it with the --debug traceback).
Each sub-command lives in its own module of this package and registers itself on ``cli``.
"""

from __future__ import annotations

import sys

import click

from ..errors import InputError

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT, EXIT_INTERNAL = 0, 1, 2, 3
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


def main(argv: list[str] | None = None) -> int:
    """Entry point: run the CLI and map errors to SPEC 7 exit statuses."""
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    _load_commands()
    try:
        result = cli.main(args=argv, prog_name="brdffit", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("brdffit: aborted", err=True)
        return EXIT_BAD_INPUT
    except _NO_ARGS_IS_HELP as exc:  # pragma: no cover - click version dependent
        click.echo(exc.format_message() if hasattr(exc, "format_message") else str(exc), err=True)
        return EXIT_BAD_INPUT
    except click.ClickException as exc:
        click.echo(f"brdffit: {exc.format_message()}", err=True)
        return EXIT_BAD_INPUT
    except InputError as exc:
        if debug:
            raise
        click.echo(f"brdffit: {exc}", err=True)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        click.echo("brdffit: interrupted", err=True)
        return 130
    except Exception as exc:  # noqa: BLE001 - last line of defence: one line, not a traceback
        if debug:
            raise
        click.echo(f"brdffit: internal error: {type(exc).__name__}: {exc} (run with --debug for the traceback)", err=True)
        return EXIT_INTERNAL
    return int(result or 0)


def entry() -> None:
    """The ``brdffit`` executable: ``main()`` and a normal interpreter exit.

    (It used to skip the teardown with ``os._exit`` to save ~0.4 s; that also hid the abort at exit
    of issue 13 -- a daemon compile thread -- which is fixed in the library now, and skipped
    atexit handlers such as coverage's.)
    """
    sys.exit(main())


if __name__ == "__main__":  # pragma: no cover
    entry()
