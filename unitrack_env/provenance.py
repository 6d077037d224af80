"""Which runtime computed the features of an episode, noted where they are computed.

The appearance model notes every batch it serves (``note_runtime("openvino (auto, checked
against torch)")``); the episode loop reads what was noted while it played and stores it in
the sequence's record, so a table built from stored results names the runtime that made
them, not the one of the command that assembled it. Torch-free, so every layer may use it.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

_OPEN: list[set[str]] = []
"""One set per open :func:`recording_runtimes` block of this process (innermost last)."""


def note_runtime(label: str) -> None:
    """Say that features were just computed (or served from a cache) by ``label``."""
    for seen in _OPEN:
        seen.add(label)


@contextlib.contextmanager
def recording_runtimes() -> Iterator[set[str]]:
    """The runtime labels noted inside the block (empty for appearance-free agents)."""
    seen: set[str] = set()
    _OPEN.append(seen)
    try:
        yield seen
    finally:
        _OPEN.remove(seen)
