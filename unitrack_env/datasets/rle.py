"""COCO compressed run-length encodings of binary masks (MOTS txt files, YouTube-VIS JSON).

Encoding and decoding go through ``pycocotools.mask`` (as :data:`mask_api`, which keeps
pycocotools' known-harmless numpy 2 warning from becoming an error under ``-W error``);
:func:`rle_runs` and :func:`check_rle` read the run lengths without building a mask, so
readers can validate a file cheaply.
"""

from __future__ import annotations

import contextlib
import functools
import warnings
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

#: pycocotools 2.0.x's ``__array__`` lacks numpy 2's ``copy`` keyword; numpy falls back to a
#: copy and warns. Harmless, but a user project running with ``-W error`` (or pytest's
#: ``filterwarnings = error``) would otherwise see it as a failure of its own data.
_COPY_KEYWORD_WARNING = r"__array__ implementation doesn't accept a copy keyword"


@contextlib.contextmanager
def quiet_pycocotools() -> Iterator[None]:
    """Silence pycocotools' known-harmless numpy 2 warning (and only it) inside the block.

    Wraps every pycocotools call of the readers and scorers, including TrackEval's scoring,
    which calls pycocotools itself. Other warnings keep the user's filters.
    """
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=_COPY_KEYWORD_WARNING,
                                category=DeprecationWarning)
        yield


class _MaskAPI:
    """``pycocotools.mask`` with every function called inside :func:`quiet_pycocotools`."""

    def __getattr__(self, name: str) -> Callable[..., Any]:
        # lazy: start-up cost (pycocotools)
        from pycocotools import mask

        function = getattr(mask, name)

        @functools.wraps(function)
        def call(*args: Any, **kwargs: Any) -> Any:
            with quiet_pycocotools():
                return function(*args, **kwargs)

        return call


#: Use as ``from unitrack_env.datasets.rle import mask_api as mask_utils``.
mask_api = _MaskAPI()


def encode_masks(masks: np.ndarray) -> list[bytes]:
    """Return the COCO compressed RLE strings of an ``(n, H, W)`` stack of binary masks."""
    mask_utils = mask_api
    masks = np.asarray(masks)
    if masks.ndim != 3:
        raise ValueError(f"masks must be (n, H, W), got shape {masks.shape}")
    if not len(masks):
        return []
    fortran = np.asfortranarray(masks.transpose(1, 2, 0).astype(np.uint8))
    return [rle["counts"] for rle in mask_utils.encode(fortran)]


def decode_masks(counts: Sequence[bytes], height: int, width: int) -> np.ndarray:
    """Decode COCO compressed RLE strings of ``height x width`` masks to ``(n, H, W)`` bool."""
    mask_utils = mask_api
    if not len(counts):
        return np.zeros((0, height, width), dtype=bool)
    rles = [{"size": [int(height), int(width)], "counts": c} for c in counts]
    decoded = mask_utils.decode(rles)  # (H, W, n) uint8, Fortran order
    return np.ascontiguousarray(decoded.transpose(2, 0, 1)).astype(bool)


def rle_runs(counts: bytes) -> np.ndarray:
    """Decode a COCO compressed RLE string to its run lengths (no mask is built).

    The string holds one number per run, 5 bits per character (offset 48, bit 5 = "more
    characters follow", bit 4 of the last character = sign); from the fourth run on, each
    number is the difference to the run two places before. Bad text raises ValueError.
    """
    codes = np.frombuffer(counts, dtype=np.uint8).astype(np.int64) - 48
    if not len(codes):
        return np.zeros(0, dtype=np.int64)
    if codes.min() < 0 or codes.max() > 63:
        bad = int(np.argmax((codes < 0) | (codes > 63)))
        raise ValueError(f"character {chr(counts[bad])!r} at position {bad} is not RLE text")
    ends = (codes & 0x20) == 0
    if not ends[-1]:
        raise ValueError("the last number is cut short")
    stops = np.flatnonzero(ends)
    starts = np.concatenate([[0], stops[:-1] + 1])
    group = np.repeat(np.arange(len(starts)), stops - starts + 1)
    position = np.arange(len(codes)) - starts[group]
    values = np.bincount(group, weights=(codes & 0x1F) << (5 * position)).astype(np.int64)
    sizes = stops - starts + 1
    negative = (codes[stops] & 0x10) != 0
    values[negative] -= np.left_shift(1, 5 * sizes[negative])
    runs = values.copy()
    runs[1::2] = np.cumsum(values[1::2])
    runs[2::2] = np.cumsum(values[2::2])
    return runs


def check_rle(counts: bytes, height: int, width: int) -> str | None:
    """Return why a compressed RLE is not a ``height x width`` mask, or None when it is."""
    try:
        runs = rle_runs(counts)
    except ValueError as exc:
        return f"corrupt RLE ({exc})"
    if len(runs) and runs.min() < 0:
        return "corrupt RLE (a negative run length)"
    total = int(runs.sum())
    if total != height * width:
        return (f"RLE run lengths sum to {total} pixels, but a {height}x{width} mask has "
                f"{height * width}")
    return None


def resolve_overlaps(masks: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """Give each pixel claimed by several masks to the highest-scored one (MOTS: disjoint).

    Ties keep the earlier mask. Returns a new ``(n, H, W)`` bool stack.
    """
    masks = np.asarray(masks, dtype=bool)
    out = np.zeros_like(masks)
    taken = np.zeros(masks.shape[1:], dtype=bool)
    for i in np.argsort(-np.asarray(scores, dtype=np.float64), kind="stable"):
        out[i] = masks[i] & ~taken
        taken |= out[i]
    return out
