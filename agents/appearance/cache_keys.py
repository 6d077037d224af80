"""Addresses of feature-cache entries: what determines a frame's features, as a key."""

from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass

import numpy as np

CONTENT_HASH: str = "sha256"
"""hashlib algorithm of :func:`content_key`. SHA-256 runs on the CPU's SHA instructions through
OpenSSL (x86 since Ice Lake / Zen, ARMv8): 3.4 ms per 1080p frame here, against 6.5 ms for
BLAKE2b and 17 ms for MD5 (``benchmarks/feature_cache.py``)."""

CONTENT_DIGEST_BYTES: int = 16
"""Bytes of the content digest kept (128 bits: 32 hex digits in entry names)."""


def content_key(image: np.ndarray, transform: str = "") -> str:
    """Hex digest (128 bits) of every byte of ``image``, its shape and dtype, and ``transform``.

    ``transform`` names what turns ``image`` into the network input (e.g. ``"letterbox
    1088x608 pad 128"``), so two preprocessings of one frame never share an entry.
    """
    array = np.ascontiguousarray(image)
    digest = hashlib.new(CONTENT_HASH)
    digest.update(f"{transform}|{array.dtype.str}|{array.shape}|".encode())
    digest.update(array.reshape(-1).view(np.uint8))
    return digest.hexdigest()[: 2 * CONTENT_DIGEST_BYTES]


@dataclass(frozen=True)
class CacheKey:
    """Identity of one cached feature map: model key, input size, content key."""

    model: str
    input_size: tuple[int, int]
    content: str

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[0-9a-f]{4,128}", self.content):
            raise ValueError(f"content must be a hex digest (content_key), got {self.content!r}")
        if not re.fullmatch(r"[A-Za-z0-9._-]+", self.model):
            raise ValueError(f"model key must be a plain identifier, got {self.model!r}")
