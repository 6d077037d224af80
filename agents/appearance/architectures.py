"""The backbones an appearance model can build, their output layers and hypercolumns."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from .efficientnet_lite import LITE0_LAYERS, EfficientNetLite0
from .resnet import RESNET_SPECS, ResNet
from .vit import VIT_SPECS, Attention, StrideOption, VisionTransformer

FEATURE_STRIDE: int = 8
"""Stride of every CNN feature map this model produces (UniTrack's r = 8); a ViT's map has
the stride of its patches (or of its ``stride`` option), which the heads read from the model."""

EFFICIENTNET_LITE0: str = "efficientnet-lite0"
"""Architecture name of the default backbone."""

ARCHITECTURES: tuple[str, ...] = (EFFICIENTNET_LITE0, *RESNET_SPECS, *VIT_SPECS)
"""Architectures :class:`AppearanceModel` can build."""

DEFAULT_LAYERS: Mapping[str, str] = MappingProxyType(
    {EFFICIENTNET_LITE0: "stage5", **{name: "layer3" for name in RESNET_SPECS},
     **{name: spec.layers[-1] for name, spec in VIT_SPECS.items()}}
)
"""Default output layer per architecture.

ResNet: layer3, as in the paper. EfficientNet-Lite0: stage5 (112 channels) with the stride
of stage4 set to 1, the paper's own construction (as for ResNet's layer3) applied to this
network. Measured here with the ImageNet weights and the ``unitrack-vos`` head (DAVIS J-mean,
official rules, blackswan / dog): stage3 (native stride 8, 40 channels) 0.925 / 0.523,
stage4 0.888 / 0.659, stage5 0.905 / 0.854, stage6 0.790 / 0.741; the hypercolumn
``"stage3+stage5"`` 0.924 / 0.854, but it loses OTB Human3 with ``unitrack-dcf`` (AUC 0.21
vs 0.71), so it is an option, not the default. MOT17 ground-truth boxes (frame 1 vs last,
four sequences) all matched by RSM at every stage, mean margin to the best wrong match
0.575 (stage5) vs 0.543 (stage3). Cost on 2 CPU threads at 1088 x 608: ~0.25 s (stage5) vs
~0.14 s (stage3), about ResNet-18 layer3's ~0.20 s. Use ``layer="stage3"`` for the fastest
features. ViT: the last block (``block12``, ``block24`` for ViT-L), as DINO's video
evaluation uses."""

LAYER_SEPARATOR: str = "+"
"""Joins several layers into one hypercolumn output, e.g. ``"stage3+stage5"``."""

REFERENCE_SIZE: int = 224
"""Input side at which :func:`network_gflops` counts (a multiple of 8, 14 and 16)."""

NORM_EPS: float = 1e-12
"""Guards the L2 normalisation of hypercolumn parts against all-zero feature vectors."""


def split_layers(layer: str) -> tuple[str, ...]:
    """The layers of a ``layer`` option: ``"stage5"`` -> one, ``"stage3+stage5"`` -> two.

    Several make a *hypercolumn* (Hariharan et al., CVPR 2015): each map L2-normalised, scaled
    by ``1/sqrt(n)`` and concatenated, so a dot product is the mean per-layer cosine.
    """
    parts = tuple(part.strip() for part in str(layer).split(LAYER_SEPARATOR))
    if not all(parts) or len(set(parts)) != len(parts):
        raise ValueError(f"layer {layer!r}: give one layer or distinct layers joined by "
                         f"{LAYER_SEPARATOR!r}, e.g. 'stage3+stage5'")
    return parts


def combine_layers(maps: list[torch.Tensor]) -> torch.Tensor:
    """One layer's map as is; several as a hypercolumn (see :func:`split_layers`)."""
    if len(maps) == 1:
        return maps[0]
    scale = 1.0 / math.sqrt(len(maps))  # unit vectors per layer, equal weights, unit norm
    return torch.cat([F.normalize(m, dim=1, eps=NORM_EPS) * scale for m in maps], 1)


def build_network(arch: str, layers: tuple[str, ...], seed: int,
                  stride: int | str | StrideOption | None = None) -> nn.Module:
    """The randomly initialised network of ``arch`` whose ``layers`` all have stride 8.

    ``stride`` is for ViTs only; an unknown layer or a CNN layer of another stride raises
    ValueError.
    """
    if arch in VIT_SPECS:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            vit = VisionTransformer(arch, stride=stride)
        for layer in layers:
            vit.layer_stride(layer)  # validates the name
        return vit
    if stride is not None:
        raise ValueError(f"stride={stride!r} applies to ViT architectures only; {arch} "
                         f"always produces stride-{FEATURE_STRIDE} maps")
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        if arch == EFFICIENTNET_LITE0:
            for layer in layers:
                if layer not in LITE0_LAYERS:
                    raise ValueError(
                        f"unknown {arch} layer {layer!r}; valid: {LITE0_LAYERS}")
            # Later stages run at stride 8 (first-block strides set to 1) when asked for.
            stride8 = any(EfficientNetLite0.stride_of(layer, stride8=False)
                          != FEATURE_STRIDE for layer in layers)
            module: nn.Module = EfficientNetLite0(stride8=stride8)
        else:
            module = ResNet(arch, stride8=True)
    for layer in layers:
        if module.layer_stride(layer) != FEATURE_STRIDE:
            raise ValueError(
                f"layer {layer!r} of {arch} has stride {module.layer_stride(layer)}, but "
                f"the appearance model must produce stride-{FEATURE_STRIDE} maps; choose "
                "a later layer"
            )
    return module


def required_prefixes(module: nn.Module, layers: tuple[str, ...]) -> tuple[str, ...]:
    """Module prefixes the output ``layers`` depend on (what a checkpoint must cover)."""
    return tuple(dict.fromkeys(
        p for name in layers for p in module.required_prefixes(name)))


def network_gflops(module: nn.Module, layers: tuple[str, ...],
                   sizes: Sequence[tuple[int, int]]) -> list[float]:
    """GFLOP (2 per multiply-add) of one image of each ``(height, width)`` through ``layers``.

    For cost estimates such as the scorecard's ETA. Counted once, at 224 x 224, by hooks on
    the convolutions, linear layers and ViT attention, then scaled: convolutions and linear
    layers grow with the pixels, attention with their square. (torch's FlopCounterMode
    would cost 1.5 s of imports on first use.)
    """
    macs = {"pixels": 0, "pixels2": 0}

    def conv(mod: nn.Conv2d, _: Any, out: torch.Tensor) -> None:
        macs["pixels"] += out.numel() * mod.in_channels // mod.groups * math.prod(mod.kernel_size)

    def linear(mod: nn.Linear, _: Any, out: torch.Tensor) -> None:
        macs["pixels"] += out.numel() * mod.in_features

    def attention(_: nn.Module, inputs: tuple[torch.Tensor, ...], __: Any) -> None:
        batch, tokens, dim = inputs[0].shape
        macs["pixels2"] += 2 * batch * tokens * tokens * dim  # q @ k.T and weights @ v

    kinds = ((nn.Conv2d, conv), (nn.Linear, linear), (Attention, attention))
    hooks = [m.register_forward_hook(hook) for m in module.modules()
             for kind, hook in kinds if isinstance(m, kind)]
    try:
        with torch.no_grad():
            module.forward_layers(torch.zeros(1, 3, REFERENCE_SIZE, REFERENCE_SIZE), layers)
    finally:
        for hook in hooks:
            hook.remove()
    scales = [height * width / REFERENCE_SIZE**2 for height, width in sizes]
    return [2e-9 * (macs["pixels"] * k + macs["pixels2"] * k * k) for k in scales]
