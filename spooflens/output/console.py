"""Terminal output shared by every command: consoles, progress bars, and click groups whose
subcommands are imported only when used (so `spooflens --help` does not load numba kernels)."""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

err_console = Console(stderr=True)
Report = Callable[[str, int, int], None]


def console() -> Console:
    """Stdout console; wide when not a terminal, so piped tables are not truncated."""
    return Console() if sys.stdout.isatty() else Console(width=160)


def show_progress() -> bool:
    return sys.stderr.isatty()


@contextmanager
def progress(enabled: bool) -> Iterator[Report]:
    """Yields report(task, done, total); draws rich bars on stderr when enabled."""
    if not enabled:
        yield lambda task, done, total: None
        return
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=err_console,
        transient=True,
    ) as bar:
        tasks: dict[str, Any] = {}

        def report(task: str, done: int, total: int) -> None:
            if task not in tasks:
                tasks[task] = bar.add_task(task, total=max(total, 1))
            bar.update(tasks[task], completed=done, total=max(total, 1))

        yield report


def fmt(v: float | None, digits: int = 2) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


class LazyGroup(click.Group):
    """A click group whose subcommands live in other modules: name -> "module:attribute"."""

    def __init__(self, *args: Any, lazy: dict[str, str] | None = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def list_commands(self, ctx: click.Context) -> list[str]:
        return sorted({*super().list_commands(ctx), *self.lazy})

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name in self.lazy:
            module, _, attr = self.lazy[cmd_name].partition(":")
            command: click.Command = getattr(importlib.import_module(module), attr)
            return command
        return super().get_command(ctx, cmd_name)
