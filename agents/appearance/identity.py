"""What determines a feature map: the model identity that keys feature caches.

:class:`ModelIdentity` names the architecture, layer, weights digest, normalisation and
runtime of an appearance model; :meth:`ModelIdentity.key` is the short string that on-disk
feature caches and exported runtime graphs are keyed by, and :func:`weights_digest` hashes
the weights that compute the output layer.
"""

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

    Attributes:
        arch: Architecture name.
        layer: Output layer.
        weights: Weights name or file.
        digest: First :data:`DIGEST_LENGTH` hex digits of the SHA-256 of the weights of every
            module that computes the output layer (names, dtypes, shapes and values).
        mean: Input normalisation mean.
        std: Input normalisation standard deviation.
        runtime: Engine that computes the features (``"torch"``, ``"openvino"``,
            ``"onnxruntime"``; see :mod:`~unitrack_env.agents.appearance.runtime`). Engines
            agree to float rounding (cosine >= 0.9999), not bit for bit, so caches keep them
            apart.
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

        The torch runtime keeps the key it had before runtimes existed (old caches stay
        valid); every other runtime adds its name.
        """
        text = f"{self.arch}|{self.layer}|{self.digest}|{self.mean}|{self.std}"
        if self.runtime != TORCH:
            text += f"|{self.runtime}"
        return hashlib.sha256(text.encode()).hexdigest()[:DIGEST_LENGTH]


def weights_digest(module: nn.Module, prefixes: Sequence[str] | None = None) -> str:
    """SHA-256 (first :data:`DIGEST_LENGTH` hex digits) of a module's state dict.

    Args:
        module: The network.
        prefixes: Only hash keys starting with one of these (None: all keys).
    """
    sha = hashlib.sha256()
    for key, value in sorted(module.state_dict().items()):
        if prefixes is not None and not any(key.startswith(p) for p in prefixes):
            continue
        tensor = value.detach().to("cpu").contiguous()
        sha.update(f"{key}|{tensor.dtype}|{tuple(tensor.shape)}|".encode())
        sha.update(tensor.reshape(-1).view(torch.uint8).numpy().tobytes())
    return sha.hexdigest()[:DIGEST_LENGTH]
