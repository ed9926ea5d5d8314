"""brdffit's one progress bar (rich, on stderr: stdout stays for results), for ``fit_batch``,
``fit_btf`` and ``compare``: items done of a total, the time spent and left, optionally a rate."""

from __future__ import annotations

import contextlib


class _Off:
    """A bar that is not shown: every call does nothing."""

    def advance(self, n: int = 1) -> None:
        pass

    def describe(self, text: str) -> None:
        pass

    def skip(self, n: int) -> None:
        pass


class _Bar:
    def __init__(self, bar, task, total: int):
        self._bar, self._task, self._total = bar, task, total

    def advance(self, n: int = 1) -> None:
        self._bar.advance(self._task, n)

    def describe(self, text: str) -> None:
        self._bar.update(self._task, description=text)

    def skip(self, n: int) -> None:
        # found done after all (a resumed run's tiles): out of the total, so that they do not count
        # as work done now in the rate and the time left
        if n:
            self._total -= n
            self._bar.update(self._task, total=self._total)


@contextlib.contextmanager
def progress_bar(label: str, total: int, *, shown: bool = True, done: int = 0, rate: str | None = None):
    """A bar over ``total`` items (``done`` of them already) while the block runs; yields an object
    with ``advance(n)``, ``describe(text)`` and ``skip(n)`` (n items need no work after all: the
    total shrinks), which do nothing when not ``shown``. ``rate``: a unit to show items per second
    in ("texels")."""
    if not shown:
        yield _Off()
        return
    from rich.console import Console
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, ProgressColumn, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)
    from rich.text import Text

    columns = [TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn()]
    if rate is not None:
        class Speed(ProgressColumn):
            def render(self, task):
                return Text(f"{task.speed:.1f} {rate}/s" if task.speed else f"- {rate}/s")

        columns.append(Speed())
    columns += [TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn()]
    with Progress(*columns, console=Console(stderr=True), transient=False) as bar:
        yield _Bar(bar, bar.add_task(label, total=total, completed=done), total)
