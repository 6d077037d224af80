"""Exceptions with messages that say what to fix.

Every error about input data names the file and, where it applies, the 1-based line and
the field, so that a user never has to decode a traceback from deep inside numpy.
"""

from __future__ import annotations

from pathlib import Path


class DataFormatError(ValueError):
    """A data file is missing, unreadable or malformed."""

    def __init__(
        self,
        path: str | Path,
        message: str,
        *,
        line: int | None = None,
        field: str | None = None,
    ) -> None:
        self.path = Path(path)
        self.line = line
        self.field = field
        where = str(self.path)
        if line is not None:
            where += f", line {line}"
        if field is not None:
            where += f", field '{field}'"
        super().__init__(f"{where}: {message}")


class InvalidActionError(ValueError):
    """An agent's action does not fit the environment's action contract."""


class UnknownSequenceError(KeyError):
    """A sequence name that the data set does not contain."""

    def __str__(self) -> str:  # KeyError quotes its argument; show the message as is.
        return str(self.args[0])
