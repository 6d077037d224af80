"""Gymnasium vector environments with shared memory for the variable-size spaces.

``AsyncVectorEnv`` passes observations through shared memory by default; Gymnasium's three
shared-memory hooks are registered here for ``Image``, ``MaskStack`` and ``LabelMap``, whose
arrays vary in size: each environment gets one slot sized for the space's bounds, in an
anonymous mapping whose pages exist only once written (a 4K bound costs nothing at 1080p).
Gymnasium reads the buffer once, so the reader returns :class:`LiveSlots`, which reads each
slot when indexed (the latest step) and deep-copies to a tuple of copies (``copy=True``).
"""

from __future__ import annotations

from collections.abc import Iterator
from collections.abc import Sequence as SequenceABC
from multiprocessing.heap import Arena
from typing import Any

import numpy as np
from gymnasium.vector.utils.shared_memory import (
    create_shared_memory,
    read_from_shared_memory,
    write_to_shared_memory,
)

from unitrack_env.spaces.arrays import Image, LabelMap, MaskStack

#: Header of a slot: the number of dimensions, then up to three sizes (int64 each).
_HEADER = 4


def _max_shape(space: Image | MaskStack | LabelMap) -> tuple[int, ...]:
    if isinstance(space, Image):
        return (space.max_height, space.max_width, space.channels)
    if isinstance(space, MaskStack):
        return (space.max_count, space.max_height, space.max_width)
    return (space.max_height, space.max_width)


class SlotBuffer:
    """``n`` slots of one variable-size array each, in memory shared with worker processes.

    The :class:`~multiprocessing.heap.Arena` travels to the workers as a file descriptor
    (``multiprocessing`` handles it when it starts them); its file is already unlinked, so
    nothing is left behind when the processes end.
    """

    def __init__(self, n: int, dtype: np.dtype, max_shape: tuple[int, ...],
                 arena: Arena | None = None) -> None:
        self.n = int(n)
        self.dtype = np.dtype(dtype)
        self.max_shape = tuple(int(s) for s in max_shape)
        data = int(np.prod(self.max_shape)) * self.dtype.itemsize
        self.slot_bytes = _HEADER * 8 + -(-data // 8) * 8
        self.arena = arena if arena is not None else Arena(max(1, self.n * self.slot_bytes))

    def __reduce__(self) -> tuple[Any, ...]:
        return (SlotBuffer, (self.n, self.dtype.str, self.max_shape, self.arena))

    def _slot(self, index: int) -> tuple[np.ndarray, memoryview]:
        start = index * self.slot_bytes
        view = memoryview(self.arena.buffer)[start:start + self.slot_bytes]
        header = np.frombuffer(view[:_HEADER * 8], dtype=np.int64)
        return header, view[_HEADER * 8:]

    def write(self, index: int, array: np.ndarray) -> None:
        """Store ``array`` (within the bounds) in slot ``index``."""
        array = np.ascontiguousarray(array, dtype=self.dtype)
        if array.ndim != len(self.max_shape) or any(
                s > m for s, m in zip(array.shape, self.max_shape, strict=True)):
            raise ValueError(f"array of shape {array.shape} exceeds the shared slot "
                             f"{self.max_shape}")
        header, data = self._slot(index)
        np.frombuffer(data, dtype=np.uint8, count=array.nbytes)[:] = array.reshape(-1).view(
            np.uint8)
        header[:] = (array.ndim, *array.shape, *([0] * (_HEADER - 1 - array.ndim)))

    def read(self, index: int) -> np.ndarray:
        """The array in slot ``index`` (a view into shared memory)."""
        header, data = self._slot(index)
        shape = tuple(int(s) for s in header[1:1 + int(header[0])])
        count = int(np.prod(shape)) if shape else 0
        return np.frombuffer(data, dtype=self.dtype, count=count).reshape(shape)


class LiveSlots(SequenceABC):
    """The arrays of every environment, read from shared memory when indexed."""

    def __init__(self, buffer: SlotBuffer) -> None:
        self._buffer = buffer

    def __len__(self) -> int:
        return self._buffer.n

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            return tuple(self[i] for i in range(*index.indices(len(self))))
        if not -len(self) <= index < len(self):
            raise IndexError(index)
        return self._buffer.read(index % len(self))

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self[i] for i in range(len(self)))

    def __deepcopy__(self, memo: dict) -> tuple[np.ndarray, ...]:
        return tuple(np.array(array, copy=True) for array in self)

    def __repr__(self) -> str:
        return f"LiveSlots({[a.shape for a in self]})"


@create_shared_memory.register(Image)
@create_shared_memory.register(MaskStack)
@create_shared_memory.register(LabelMap)
def _create(space: Any, n: int = 1, ctx: Any = None) -> SlotBuffer:
    return SlotBuffer(n, space.dtype, _max_shape(space))


@read_from_shared_memory.register(Image)
@read_from_shared_memory.register(MaskStack)
@read_from_shared_memory.register(LabelMap)
def _read(space: Any, shared_memory: SlotBuffer, n: int = 1) -> LiveSlots:
    return LiveSlots(shared_memory)


@write_to_shared_memory.register(Image)
@write_to_shared_memory.register(MaskStack)
@write_to_shared_memory.register(LabelMap)
def _write(space: Any, index: int, value: np.ndarray, shared_memory: SlotBuffer) -> None:
    shared_memory.write(index, value)


__all__ = ["LiveSlots", "SlotBuffer"]
