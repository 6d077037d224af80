"""Addresses of feature-cache entries: what determines a frame's features, as a key.

:func:`content_key` hashes every byte of a decoded frame (with its shape, dtype and the
transform that turns it into the network input); :class:`CacheKey` joins it with the model
identity and the network input size. Part of the feature cache
(:mod:`~unitrack_env.agents.appearance.feature_cache`).
"""

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

    Args:
        image: The array to address (e.g. the decoded frame).
        transform: Names what turns ``image`` into the network input (e.g.
            ``"letterbox 1088x608 pad 128"``); empty when ``image`` is the network input. Two
            preprocessings of the same frame never share an entry.
    """
    array = np.ascontiguousarray(image)
    digest = hashlib.new(CONTENT_HASH)
    digest.update(f"{transform}|{array.dtype.str}|{array.shape}|".encode())
    digest.update(array.reshape(-1).view(np.uint8))
    return digest.hexdigest()[: 2 * CONTENT_DIGEST_BYTES]


@dataclass(frozen=True)
class CacheKey:
    """Identity of one cached feature map.

    Attributes:
        model: :meth:`ModelIdentity.key` of the appearance model.
        input_size: ``(height, width)`` of the network input.
        content: :func:`content_key` of the frame (hex).
    """

    model: str
    input_size: tuple[int, int]
    content: str

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[0-9a-f]{4,128}", self.content):
            raise ValueError(f"content must be a hex digest (content_key), got {self.content!r}")
        if not re.fullmatch(r"[A-Za-z0-9._-]+", self.model):
            raise ValueError(f"model key must be a plain identifier, got {self.model!r}")
