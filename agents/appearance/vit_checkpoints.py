"""How the published ViT checkpoints store their encoder: the key rules of their remaps.

:data:`VIT_REMAP_FIELDS` holds each family's :class:`KeyRemap` fields (``DEFAULT_REMAPS``
builds remaps from them, so ``remap="auto"`` or ``"dino"`` work as for ResNets);
:func:`apply_key_rules` drops the keys that are not the encoder and renames the rest.

* DINO: released backbones are plain state dicts; training checkpoints wrap ``teacher`` /
  ``student`` (the teacher is evaluated) with ``backbone.`` (``module.backbone.``) before
  the encoder and a projection ``head.`` beside it.
* DINOv2: plain state dicts with ``ls1.gamma`` / ``ls2.gamma``, a ``mask_token`` (unused)
  and, for ``_reg4`` models, ``register_tokens``; training checkpoints wrap ``teacher``
  with ``backbone.`` beside ``dino_head.`` / ``ibot_head.``.
* MAE: ``{"model": ...}``; pre-training files hold the decoder (``decoder_*``, its
  ``mask_token``); fine-tuned ones with global pooling have ``fc_norm`` (renamed to the final
  norm) and a ``head``.
* timm: a plain state dict with a classifier ``head.``.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import torch

VIT_REMAP_FIELDS: Mapping[str, Mapping[str, Any]] = MappingProxyType({
    "dino": MappingProxyType({
        "containers": ("teacher", "student", "state_dict", "model"),
        "strip_prefixes": ("module.backbone.", "backbone.", "module."),
        "drop_prefixes": ("head.",),
        "description": "DINO ViT: ckpt['teacher'] (or 'student', or plain), strip "
                       "'backbone.' / 'module.backbone.', drop 'head.'",
    }),
    "dinov2": MappingProxyType({
        "containers": ("teacher", "model", "state_dict"),
        "strip_prefixes": ("backbone.", "module."),
        "drop_prefixes": ("mask_token", "dino_head.", "ibot_head.", "head."),
        "description": "DINOv2 ViT (with or without registers): plain or ckpt['teacher'], "
                       "strip 'backbone.', drop 'mask_token' and the heads",
    }),
    "mae": MappingProxyType({
        "containers": ("model",),
        "strip_prefixes": ("module.",),
        "drop_prefixes": ("decoder_", "mask_token", "head."),
        "rename_prefixes": (("fc_norm.", "norm."),),
        "description": "MAE encoder: ckpt['model'], drop 'decoder_*' / 'mask_token' / "
                       "'head.', 'fc_norm' as 'norm' when there is no 'norm'",
    }),
    "timm-vit": MappingProxyType({
        "containers": ("state_dict", "model"),
        "strip_prefixes": ("module.",),
        "drop_prefixes": ("head.",),
        "rename_prefixes": (("fc_norm.", "norm."),),
        "description": "timm ViT: a plain state dict, drop the classifier 'head.'",
    }),
})
"""Remap fields of each ViT checkpoint family (read-only)."""


def apply_key_rules(
    state: Mapping[str, torch.Tensor],
    drop_prefixes: tuple[str, ...],
    rename_prefixes: tuple[tuple[str, str], ...],
) -> dict[str, torch.Tensor]:
    """``state`` without the keys under ``drop_prefixes``, prefixes renamed.

    Each ``(old, new)`` prefix is renamed when no key already starts with ``new`` (so a file
    with both keeps its ``new``).
    """
    kept = {k: v for k, v in state.items() if not k.startswith(drop_prefixes)}
    for old, new in rename_prefixes:
        if any(k.startswith(new) for k in kept):
            continue
        kept = {(new + k[len(old):] if k.startswith(old) else k): v for k, v in kept.items()}
    return kept
