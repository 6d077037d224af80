"""What data set readers share: named sequences, counted and iterated in order.

A reader lists its sequences in ``sequence_names`` (in the benchmark's order) and loads one
with ``load(name)``; :class:`SequenceDataset` gives it ``len()`` and iteration over the
loaded sequences.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from typing import Generic, TypeVar

from unitrack_env.errors import UnknownSequenceError

SequenceT = TypeVar("SequenceT")


class SequenceDataset(ABC, Generic[SequenceT]):
    """A data set of named sequences: subclasses set ``sequence_names`` and implement load."""

    sequence_names: list[str]

    def __len__(self) -> int:
        return len(self.sequence_names)

    def __iter__(self) -> Iterator[SequenceT]:
        for name in self.sequence_names:
            yield self.load(name)

    @abstractmethod
    def load(self, name: str) -> SequenceT:
        """Read one sequence by name."""

    def resolve(self, name: str) -> str:
        """The data set's spelling of ``name`` (default: ``name`` itself, if it is one)."""
        if name not in self.sequence_names:
            raise UnknownSequenceError(f"no sequence '{name}' in {type(self).__name__}; "
                                       f"available: {', '.join(self.sequence_names)}")
        return name
