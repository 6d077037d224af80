"""A progress bar over frames with FPS and ETA (rich), silent when disabled."""

from __future__ import annotations

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
