"""What determines a feature map: the model identity that keys feature caches."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import nn

from .runtime import TORCH

DIGEST_LENGTH: int = 16
"""Hex characters of the SHA-256 weights digest kept in :class:`ModelIdentity`."""


@dataclass(frozen=True)
class ModelIdentity:
    """Everything that determines a feature map, for cache keys and reports.

    ``digest`` hashes the weights of every module that computes the output layer. Runtimes
    agree to float rounding, not bit for bit, so caches keep them apart.
    """

    arch: str
    layer: str
    weights: str
    digest: str
    mean: tuple[float, ...]
    std: tuple[float, ...]
    runtime: str = TORCH

    def key(self) -> str:
        """A short stable string that changes whenever the features could change.

        The torch runtime keeps its historic key (old caches stay valid); others add their name.
        """
        text = f"{self.arch}|{self.layer}|{self.digest}|{self.mean}|{self.std}"
        if self.runtime != TORCH:
            text += f"|{self.runtime}"
        return hashlib.sha256(text.encode()).hexdigest()[:DIGEST_LENGTH]


def weights_digest(module: nn.Module, prefixes: Sequence[str] | None = None) -> str:
    """SHA-256 prefix (:data:`DIGEST_LENGTH` hex digits) of a state dict's ``prefixes`` keys."""
    sha = hashlib.sha256()
    for key, value in sorted(module.state_dict().items()):
        if prefixes is not None and not any(key.startswith(p) for p in prefixes):
            continue
        tensor = value.detach().to("cpu").contiguous()
        sha.update(f"{key}|{tensor.dtype}|{tuple(tensor.shape)}|".encode())
        sha.update(tensor.reshape(-1).view(torch.uint8).numpy().tobytes())
    return sha.hexdigest()[:DIGEST_LENGTH]
