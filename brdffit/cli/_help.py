"""Help texts that state the code's own defaults, so that ``--help`` cannot drift from them.

A default that lives in a module the CLI must not import when it starts (one that imports JAX or
Mitsuba) is read when the help is shown: :class:`DefaultFrom`; so is a list the code keeps (the
material formats), :class:`HelpFrom`.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable

import click


def code_default(where: str):
    """The value named by ``"module:NAME"``, or the default of a parameter, ``"module:function(param)"``."""
    module, _, name = where.partition(":")
    holder = importlib.import_module(module)
    if name.endswith(")"):
        function, _, param = name[:-1].partition("(")
        return inspect.signature(getattr(holder, function)).parameters[param].default
    return getattr(holder, name)


class DefaultFrom(click.Option):
    """An option whose help ends with ``[default: X]``, X read from the code (``default_from``, as
    :func:`code_default` takes it; ``describe`` words it) when the help is shown."""

    def __init__(self, *args, default_from: str, describe: Callable[[object], str] = str, **kwargs):
        super().__init__(*args, **kwargs)
        self._text, self._default_from, self._describe = self.help or "", default_from, describe

    def get_help_record(self, ctx):
        default = self._describe(code_default(self._default_from))
        self.help = f"{self._text} [default: {default}]".strip()
        return super().get_help_record(ctx)


class HelpFrom(click.Option):
    """An option whose help names what the code holds, read when the help is shown: each ``{}`` of
    the help is the text a function returns (``help_from``: "module:function" names, in order)."""

    def __init__(self, *args, help_from: tuple[str, ...], **kwargs):
        super().__init__(*args, **kwargs)
        self._text, self._help_from = self.help or "", help_from

    def get_help_record(self, ctx):
        self.help = self._text.format(*(code_default(where)() for where in self._help_from))
        return super().get_help_record(ctx)
