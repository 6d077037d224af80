"""ResNet backbones in the torchvision state-dict layout, with the UniTrack stride-8 option.

He et al. (CVPR 2016) with the "v1.5" bottleneck; parameter names follow torchvision so its
and most self-supervised checkpoints load by key. ``stride8=True`` (UniTrack) sets every
stride in ``layer3`` and ``layer4`` to 1, without dilation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

import torch
from torch import nn

RESNET_LAYERS: tuple[str, ...] = ("layer1", "layer2", "layer3", "layer4")
"""Names of the feature outputs, in network order."""

BN_EPS: float = 1e-5
"""Batch-norm epsilon of torchvision's ResNets (PyTorch's default)."""

NUM_CLASSES: int = 1000
"""ImageNet-1k classes of the ``fc`` layer."""


@dataclass(frozen=True)
class ResNetSpec:
    """Depth configuration of one ResNet variant (``blocks`` in ``layer1`` .. ``layer4``)."""

    name: str
    bottleneck: bool
    blocks: tuple[int, int, int, int]

    @property
    def expansion(self) -> int:
        """Output channels of a block divided by its width."""
        return 4 if self.bottleneck else 1

    def layer_channels(self, layer: str) -> int:
        """Output channels of ``layer`` (``layer1`` .. ``layer4``)."""
        return LAYER_WIDTHS[_layer_index(layer)] * self.expansion


LAYER_WIDTHS: tuple[int, int, int, int] = (64, 128, 256, 512)
"""Block widths of layer1..layer4 (output channels of basic blocks)."""

RESNET_SPECS: Mapping[str, ResNetSpec] = MappingProxyType({
    "resnet18": ResNetSpec("resnet18", False, (2, 2, 2, 2)),
    "resnet34": ResNetSpec("resnet34", False, (3, 4, 6, 3)),
    "resnet50": ResNetSpec("resnet50", True, (3, 4, 6, 3)),
    "resnet101": ResNetSpec("resnet101", True, (3, 4, 23, 3)),
})
"""Supported ResNet depths (read-only)."""


def _layer_index(layer: str) -> int:
    if layer not in RESNET_LAYERS:
        raise ValueError(f"unknown ResNet layer {layer!r}; valid: {RESNET_LAYERS}")
    return RESNET_LAYERS.index(layer)


def _conv(in_ch: int, out_ch: int, kernel: int, stride: int = 1) -> nn.Conv2d:
    return nn.Conv2d(in_ch, out_ch, kernel, stride=stride, padding=kernel // 2, bias=False)


class BasicBlock(nn.Module):
    """Two 3x3 convolutions with an identity (or 1x1 projection) shortcut."""

    def __init__(self, in_ch: int, width: int, stride: int) -> None:
        super().__init__()
        self.conv1 = _conv(in_ch, width, 3, stride)
        self.bn1 = nn.BatchNorm2d(width, eps=BN_EPS)
        self.conv2 = _conv(width, width, 3)
        self.bn2 = nn.BatchNorm2d(width, eps=BN_EPS)
        self.relu = nn.ReLU(inplace=True)
        self.downsample: nn.Module | None = None
        if stride != 1 or in_ch != width:
            self.downsample = nn.Sequential(
                _conv(in_ch, width, 1, stride), nn.BatchNorm2d(width, eps=BN_EPS)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        shortcut = x if self.downsample is None else self.downsample(x)
        y = self.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        return self.relu(y + shortcut)


class Bottleneck(nn.Module):
    """1x1 reduce, 3x3 (strided, "v1.5"), 1x1 expand by 4, with a shortcut."""

    def __init__(self, in_ch: int, width: int, stride: int) -> None:
        super().__init__()
        out_ch = width * 4
        self.conv1 = _conv(in_ch, width, 1)
        self.bn1 = nn.BatchNorm2d(width, eps=BN_EPS)
        self.conv2 = _conv(width, width, 3, stride)
        self.bn2 = nn.BatchNorm2d(width, eps=BN_EPS)
        self.conv3 = _conv(width, out_ch, 1)
        self.bn3 = nn.BatchNorm2d(out_ch, eps=BN_EPS)
        self.relu = nn.ReLU(inplace=True)
        self.downsample: nn.Module | None = None
        if stride != 1 or in_ch != out_ch:
            self.downsample = nn.Sequential(
                _conv(in_ch, out_ch, 1, stride), nn.BatchNorm2d(out_ch, eps=BN_EPS)
            )

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102
        shortcut = x if self.downsample is None else self.downsample(x)
        y = self.relu(self.bn1(self.conv1(x)))
        y = self.relu(self.bn2(self.conv2(y)))
        y = self.bn3(self.conv3(y))
        return self.relu(y + shortcut)


class ResNet(nn.Module):
    """A ResNet with torchvision parameter names and named feature outputs.

    ``stride8`` gives stride-8 maps at layer3 and layer4 (else 16 / 32).

    Example:
        >>> net = ResNet("resnet18").eval()
        >>> net.forward_features(torch.zeros(1, 3, 64, 96), "layer3").shape
        torch.Size([1, 256, 8, 12])
    """

    def __init__(
        self, arch: str = "resnet18", *, stride8: bool = True, num_classes: int = NUM_CLASSES
    ) -> None:
        super().__init__()
        if arch not in RESNET_SPECS:
            raise ValueError(f"unknown ResNet architecture {arch!r}; valid: {list(RESNET_SPECS)}")
        self.spec = RESNET_SPECS[arch]
        self.stride8 = stride8
        block_cls = Bottleneck if self.spec.bottleneck else BasicBlock
        self.conv1 = nn.Conv2d(3, 64, 7, stride=2, padding=3, bias=False)
        self.bn1 = nn.BatchNorm2d(64, eps=BN_EPS)
        self.relu = nn.ReLU(inplace=True)
        self.maxpool = nn.MaxPool2d(3, stride=2, padding=1)
        in_ch = 64
        for index, (width, count) in enumerate(zip(LAYER_WIDTHS, self.spec.blocks, strict=True)):
            stride = 1 if index == 0 or (stride8 and index >= 2) else 2
            blocks = []
            for b in range(count):
                blocks.append(block_cls(in_ch, width, stride if b == 0 else 1))
                in_ch = width * self.spec.expansion
            setattr(self, RESNET_LAYERS[index], nn.Sequential(*blocks))
        self.avgpool = nn.AdaptiveAvgPool2d(1)
        self.fc = nn.Linear(in_ch, num_classes)
        self._init_weights()

    def _init_weights(self) -> None:
        """He-normal convolutions (fan-out), unit/zero batch norm: torchvision's init."""
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            elif isinstance(m, nn.BatchNorm2d):
                nn.init.ones_(m.weight)
                nn.init.zeros_(m.bias)

    def layer_channels(self, layer: str) -> int:
        """Output channels of ``layer``."""
        return self.spec.layer_channels(layer)

    def layer_stride(self, layer: str) -> int:
        """Total stride of ``layer`` for this instance."""
        index = _layer_index(layer)
        stride = 4
        for i in range(1, index + 1):
            if not (self.stride8 and i >= 2):
                stride *= 2
        return stride

    @staticmethod
    def required_prefixes(layer: str) -> tuple[str, ...]:
        """State-dict key prefixes of every module that computes ``layer``."""
        index = _layer_index(layer)
        return ("conv1.", "bn1.") + tuple(f"{name}." for name in RESNET_LAYERS[: index + 1])

    def forward_features(self, x: torch.Tensor, layer: str = "layer3") -> torch.Tensor:
        """Run the network up to the end of ``layer`` and return that feature map."""
        return self.forward_layers(x, (layer,))[0]

    def forward_layers(self, x: torch.Tensor, layers: tuple[str, ...]) -> list[torch.Tensor]:
        """Run the network once, up to the deepest of ``layers``; their maps in that order."""
        deepest = max(_layer_index(layer) for layer in layers)
        x = self.maxpool(self.relu(self.bn1(self.conv1(x))))
        out = {}
        for name in RESNET_LAYERS[: deepest + 1]:
            x = getattr(self, name)(x)
            out[name] = x
        return [out[layer] for layer in layers]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Classify: logits ``(B, num_classes)`` (meaningful with the standard strides)."""
        x = self.forward_features(x, "layer4")
        return self.fc(torch.flatten(self.avgpool(x), 1))


def infer_resnet_arch(keys: set[str] | list[str]) -> str | None:
    """The :data:`RESNET_SPECS` name matching torchvision-layout keys' block counts, or None."""
    keys = set(keys)
    bottleneck = any(k.startswith("layer1.0.conv3.") for k in keys)
    counts = []
    for name in RESNET_LAYERS:
        indices = {
            int(k.split(".")[1]) for k in keys
            if k.startswith(f"{name}.") and k.split(".")[1].isdigit()
        }
        counts.append(max(indices) + 1 if indices else 0)
    for spec in RESNET_SPECS.values():
        if spec.bottleneck == bottleneck and tuple(counts) == spec.blocks:
            return spec.name
    # Checkpoints truncated after layer3 (some SSL releases drop layer4): match a prefix.
    for spec in RESNET_SPECS.values():
        prefix_match = tuple(counts[:3]) == spec.blocks[:3]
        if spec.bottleneck == bottleneck and counts[3] == 0 and prefix_match:
            return spec.name
    return None
