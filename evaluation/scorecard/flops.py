"""A model's GFLOP per megapixel known before torch is imported: the scorecard's first ETA.

:func:`~unitrack_env.agents.appearance.architectures.network_gflops` counts a built network's
multiply-adds at 224 x 224 (convolutions and linear layers, ``pixels``; ViT attention,
``pixels2``) and scales them to each input. Building a network needs torch (seconds of
imports), so the scorecard first estimates from the same counts kept here: a table for the
CNNs (per architecture and deepest output layer; the counts of a stride-8 layer do not depend
on the other layers asked for) and a closed form for the ViTs. Then the real count replaces
the estimate. tests/evaluation/test_scorecard_flops.py checks every table entry, and the
closed form on every ViT size, patch, register and stride option, against
``network_gflops``. A model whose architecture is known only from its checkpoint's keys gets
EfficientNet-Lite0's figure until then.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence

from .eta import LITE0_GFLOP_PER_MP, input_size

REFERENCE_SIZE: int = 224
"""Input side at which the counts are taken (``network_gflops``'s)."""

#: Multiply-adds at 224 x 224 up to each stride-8 output layer (``network_gflops`` / 2e-9):
#: EfficientNet-Lite0 (later stages at stride 8 when asked for) and the ResNets (stride 8).
CNN_MACS: dict[str, dict[str, int]] = {
    "efficientnet-lite0": {"stage3": 113748992, "stage4": 265217792, "stage5": 609249536,
                           "stage6": 1890769664, "stage7": 2361320192, "head": 2682446592},
    "resnet18": {"layer2": 991477760, "layer3": 2635644928, "layer4": 9212313600},
    "resnet34": {"layer2": 1685110784, "layer3": 7028654080, "layer4": 17304698880},
    "resnet50": {"layer2": 1813561344, "layer3": 7362625536, "layer4": 19077316608},
    "resnet101": {"layer2": 1813561344, "layer3": 22211510272, "layer4": 33926201344},
}
#: ViT embedding width and depth per size (agents/appearance/vit.py), MLP width over the
#: embedding's, registers of the ``_reg4`` variants.
VIT_WIDTHS: dict[str, int] = {"small": 384, "base": 768, "large": 1024}
VIT_DEPTHS: dict[str, int] = {"small": 12, "base": 12, "large": 24}
VIT_MLP_RATIO: int = 4
VIT_REGISTERS: int = 4
_VIT = re.compile(r"vit_(?P<size>[a-z]+)_patch(?P<patch>\d+)(?P<reg>_reg4)?")

#: Named weights -> their architecture, and each architecture's default output layer
#: (agents/appearance/weights.py and architectures.py; the test checks both).
NAMED_ARCHS: dict[str, str] = {"imagenet-lite0": "efficientnet-lite0", "random": "resnet18"}
DEFAULT_CNN_LAYERS: dict[str, str] = {"efficientnet-lite0": "stage5", "resnet18": "layer3",
                                      "resnet34": "layer3", "resnet50": "layer3",
                                      "resnet101": "layer3"}


def vit_shape(arch: str) -> tuple[int, int, int, int] | None:
    """(width, patch, registers, depth) of a ViT named ``vit_<size>_patch<p>[_reg4]``."""
    match = _VIT.fullmatch(arch)
    if match is None or match["size"] not in VIT_WIDTHS:
        return None
    return (VIT_WIDTHS[match["size"]], int(match["patch"]),
            VIT_REGISTERS if match["reg"] else 0, VIT_DEPTHS[match["size"]])


def vit_macs(arch: str, layers: Sequence[str], stride: str | None = None,
             ) -> tuple[int, int] | None:
    """(``pixels``, ``pixels2``) multiply-adds of a ViT at 224 x 224 (None: not a ViT).

    Per block: the qkv, output and MLP projections of every token (``12 N D^2``) and the
    attention products (``2 N^2 D``); ``N`` is the class token, the registers and the patch
    grid at the embedding's stride (``stride="s-overlap"``: ``s``; else the patch).
    """
    shape = vit_shape(arch)
    if shape is None:
        return None
    dim, patch, registers, _ = shape
    step = patch
    if stride:
        value, _, mode = str(stride).partition("-")
        step = int(value) if (mode or "overlap") == "overlap" else patch
    blocks = max(int(layer.removeprefix("block")) for layer in layers)
    tokens = 1 + registers + math.ceil(REFERENCE_SIZE / step) ** 2
    per_block = tokens * dim * dim * (4 + 2 * VIT_MLP_RATIO)
    return blocks * per_block, blocks * 2 * tokens * tokens * dim


def reference_macs(arch: str, layer: str | None, stride: str | None = None,
                   ) -> tuple[int, int] | None:
    """(``pixels``, ``pixels2``) multiply-adds at 224 x 224, or None if not in the table."""
    if arch in CNN_MACS:
        layers = (layer or DEFAULT_CNN_LAYERS[arch]).split("+")
        known = CNN_MACS[arch]
        if stride or not all(name in known for name in layers):
            return None  # refused when the model is built
        return max(known[name] for name in layers), 0
    shape = vit_shape(arch)
    if shape is None:
        return None
    layers = (layer or f"block{shape[3]}").split("+")
    if not all(re.fullmatch(r"block\d+", name) for name in layers):
        return None
    return vit_macs(arch, layers, stride)


def estimated_megapixel_gflops(weights: str, arch: str | None, layer: str | None,
                               stride: str | None, tasks: Sequence[str]) -> dict[str, float]:
    """GFLOP per megapixel of each task's input, as ``megapixel_gflops`` will count them.

    ``weights``, ``arch``, ``layer``, ``stride``: a scorecard model's options. A checkpoint
    file without ``arch=`` (its keys tell), or anything not in the table: Lite0's figure.
    """
    arch = arch or NAMED_ARCHS.get(weights)
    macs = reference_macs(arch, layer, stride) if arch else None
    if macs is None:
        return dict.fromkeys(tasks, LITE0_GFLOP_PER_MP)
    pixels, pixels2 = macs
    out = {}
    for task in tasks:
        height, width = input_size(task)[1:]
        scale = height * width / REFERENCE_SIZE**2
        out[task] = 2e-9 * (pixels * scale + pixels2 * scale * scale) / (height * width / 1e6)
    return out
