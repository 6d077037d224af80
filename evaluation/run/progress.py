"""Console output of the commands: a progress bar and this package's warnings.

The bar runs over frames with FPS and ETA (rich) and is silent when disabled; warnings of
this package are shown as one ``warning: ...`` line.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from types import TracebackType

from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text

_default_format = warnings.formatwarning


@functools.cache
def _package_folders() -> tuple[str, ...]:
    """Where this package's modules live (in a clone: three folders beside each other)."""
    folders = []
    for name in ("unitrack_env", "unitrack_env.agents", "unitrack_env.evaluation"):
        spec = importlib.util.find_spec(name)
        folders += [str(Path(p).resolve()) + os.sep
                    for p in (spec.submodule_search_locations or []) if spec]
    return tuple(folders)


def format_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                   line: str | None = None) -> str:
    """A ``warnings.formatwarning``: this package's warnings as one ``warning: ...`` line.

    A command's output, not a source location and a line of code; other libraries'
    warnings keep Python's format.
    """
    if str(Path(filename).resolve()).startswith(_package_folders()):
        return f"warning: {message}\n"
    return _default_format(message, category, filename, lineno, line)


#: The messages shown by each open :func:`one_line_warnings` block, innermost last.
_SHOWN: list[set[str]] = []


def show_warnings_once(shown: set[str]) -> None:
    """From now on, show warnings as by :func:`format_warning`, each message once.

    ``shown``: the messages not to show (grows with each one shown). A worker process calls
    this with its parent's :func:`shown_warnings`, so that a data warning the parent gave at
    the door is not given again by the worker that reads the same file.
    """
    previous_show = warnings.showwarning

    def show_once(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if str(message) not in shown:
            shown.add(str(message))
            previous_show(message, category, filename, lineno, file, line)

    warnings.formatwarning = format_warning
    warnings.showwarning = show_once


def shown_warnings() -> frozenset[str]:
    """The messages the innermost open :func:`one_line_warnings` block has shown."""
    return frozenset(_SHOWN[-1]) if _SHOWN else frozenset()


@contextlib.contextmanager
def one_line_warnings() -> Iterator[None]:
    """Within the block, warnings are formatted by :func:`format_warning`, each message once.

    Python's own once-per-location memory is reset whenever a ``catch_warnings`` block ends
    (every scorecard cell has one), so a data warning would be repeated for each cell.
    """
    previous = warnings.formatwarning, warnings.showwarning
    shown: set[str] = set()
    show_warnings_once(shown)
    _SHOWN.append(shown)
    try:
        yield
    finally:
        _SHOWN.pop()
        warnings.formatwarning, warnings.showwarning = previous


class _FpsColumn(ProgressColumn):
    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        return Text(f"{speed:6.1f} FPS" if speed else "   -- FPS", style="cyan")


class RunProgress:
    """Context manager: ``advance()`` once per frame, ``start_sequence(name)`` per episode."""

    def __init__(self, total_frames: int, *, enabled: bool = True) -> None:
        self.enabled = enabled and total_frames > 0
        self._progress: Progress | None = None
        self._task = None
        self._total = total_frames

    def __enter__(self) -> RunProgress:
        if self.enabled:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                _FpsColumn(), TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                transient=False,
            )
            self._progress.__enter__()
            self._task = self._progress.add_task("frames", total=self._total)
        return self

    def start_sequence(self, name: str) -> None:
        """Show which sequence is playing."""
        if self._progress is not None:
            self._progress.update(self._task, description=name)

    def advance(self, frames: int = 1) -> None:
        """Count finished frames."""
        if self._progress is not None:
            self._progress.advance(self._task, frames)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if self._progress is not None:
            self._progress.__exit__(exc_type, exc, tb)
