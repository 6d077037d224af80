"""Exceptions with messages that say what to fix.

Errors about input data name the file and, where it applies, the 1-based line and field.
Every exception survives ``pickle`` with its message and attributes, so worker processes
can send the real error to the parent (not a ``BrokenProcessPool``).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any


class DataFormatError(ValueError):
    """A data file is missing, unreadable or malformed."""

    def __init__(
        self,
        path: str | os.PathLike[str],
        message: str,
        *,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.path = Path(path)
        self.message = message
        self.line = line
        self.field = field
        where = str(self.path)
        if line is not None:
            where += f", line {line}"
        if field is not None:
            where += f", field '{field}'"
        super().__init__(f"{where}: {message}")

    def __reduce__(self) -> tuple[Any, ...]:
        rebuild = functools.partial(type(self), line=self.line, field=self.field)
        return (rebuild, (self.path, self.message), self.__dict__)


class CheckpointError(ValueError):
    """A checkpoint file is unreadable, or does not fit the model it is loaded into."""

    def __init__(self, path: str | os.PathLike[str] | None, message: str) -> None:
        self.path = None if path is None else Path(path)
        self.message = message
        where = "<in-memory state dict>" if path is None else str(path)
        super().__init__(f"{where}: {message}")

    def __reduce__(self) -> tuple[Any, ...]:
        return (type(self), (self.path, self.message), self.__dict__)


class InvalidActionError(ValueError):
    """An agent's action does not fit the environment's action contract."""


class UnknownSequenceError(KeyError):
    """A sequence name that the data set does not contain."""

    def __str__(self) -> str:  # KeyError quotes its argument; show the message as is.
        return str(self.args[0])
