"""Errors that users see.

Bad input is reported as one line naming the file and the problem (docs/cli.md#bad-input): raise
``InputError(path, problem)`` anywhere; the CLI prints ``str(error)`` and exits with status 2.
"""

from __future__ import annotations

import os


class InputError(ValueError):
    """A source (file, folder, parameter file) cannot be used; ``str()`` is the one-line message."""

    def __init__(self, path: str | os.PathLike | None, problem: str):
        self.path = None if path is None else os.fspath(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}" if self.path is not None else problem)


class UsageError(InputError):
    """A command-line or API argument is invalid (no file to blame)."""

    def __init__(self, problem: str):
        super().__init__(None, problem)


class BrdffitWarning(UserWarning):
    """Data that can be used but look suspect (e.g. every value negative); the CLI shows one line."""
