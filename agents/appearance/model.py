"""The shared appearance model (UniTrack level 1): images in, stride-8 feature maps out.

UniTrack uses one appearance model ``phi`` for every task. :class:`AppearanceModel` wraps
one network with what the heads need: input normalisation, batched inference under
``torch.inference_mode()``, thread and device settings, the JDE letterbox for MOT (the whole
frame to 1088 x 608), and a :class:`ModelIdentity` (architecture, layer, weights digest,
runtime) that keys on-disk feature caches. The network runs in eager torch (the reference,
the only runtime on CUDA) or exported to ONNX and compiled for the CPU (``runtime=``:
:mod:`~unitrack_env.agents.appearance.runtime`). Weights are resolved by
:func:`~unitrack_env.agents.appearance.weights.load_weights`.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from unitrack_env.provenance import note_runtime

from .architectures import combine_layers
from .checkpoints import DEFAULT_REMAPS, KeyRemap, LoadReport
from .identity import ModelIdentity, weights_digest
from .runtime import (
    TORCH,
    CompiledBackbone,
    FeatureNetwork,
    is_auto,
    resolve_runtime,
)
from .weights import (
    DEFAULT_WEIGHT_LOADERS,
    LoadedWeights,
    WeightsLoader,
    check_arch,
    load_weights,
)

__all__ = ["AppearanceModel", "torch_threads"]


@contextlib.contextmanager
def torch_threads(num_threads: int | None) -> Iterator[None]:
    """Run the body with ``torch.set_num_threads(num_threads)`` (None: leave it), then restore."""
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


class AppearanceModel:
    """One backbone producing stride-8 feature maps, shared by every UniTrack head.

    Args:
        weights: Named weights (``"imagenet-lite0"`` default, ``"random"``), a
            ``"torchvision:<Enum>.<MEMBER>"`` string, or a checkpoint file path.
        arch: ``"efficientnet-lite0"``, ``"resnet18"`` .. ``"resnet101"`` or a ViT
            (:data:`~.vit.VIT_SPECS`). None: the weights' own architecture.
        layer: Output layer (ResNet ``"layer2"``..``"layer4"``; EfficientNet ``"stage3"``..
            ``"head"``; ViT ``"block1"``..``"block12"``), or several joined by ``"+"`` (a
            hypercolumn). None: :data:`DEFAULT_LAYERS`. CNN layers must have stride 8.
        device: Torch device for the network and the returned features.
        num_threads: ``torch.set_num_threads`` during each forward pass.
        mean, std: RGB normalisation (of RGB / 255). None: what the weights expect.
        remap: For checkpoint files: a remap name, a :class:`KeyRemap` or ``"auto"``.
        remaps, loaders: Remap and named-weights tables (defaults :data:`DEFAULT_REMAPS`,
            :data:`DEFAULT_WEIGHT_LOADERS`).
        allow_partial: Accept a checkpoint that does not cover the whole backbone.
        seed: Seed of the random initialisation (the global torch RNG is left untouched).
        channels_last: Run the network channels-last (same numbers up to rounding).
        runtime: ``"torch"`` (the reference; the only one for CUDA), ``"openvino"``,
            ``"onnxruntime"`` (optional extras), ``"auto"`` (the fastest installed, checked
            against torch) or None (``$UNITRACK_RUNTIME``, default ``"auto"``).
        runtime_cache: Directory of exported graphs (None: ``$UNITRACK_RUNTIME_CACHE`` or
            ``~/.cache/unitrack_env/runtime``).
        stride: ViT only: ``8`` / ``"8-overlap"`` or ``"8-upsample"`` (see :mod:`.vit`).
            None: the patch size.

    ``module`` is the eval-mode network, ``identity`` keys feature caches, ``load_report`` is
    None for random init, ``channels`` sums the output ``layers``' channels, ``stride`` is the
    pixels per feature cell (heads read it here), ``runtime`` the concrete runtime.

    Example:
        >>> model = AppearanceModel(runtime="torch")  # EfficientNet-Lite0, ImageNet, offline
        >>> frame = np.zeros((120, 160, 3), np.uint8)
        >>> model.features(frame).shape
        torch.Size([1, 112, 15, 20])
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
        stride: int | str | None = None,
    ) -> None:
        if num_threads is not None and num_threads < 1:
            raise ValueError(f"num_threads must be >= 1 or None, got {num_threads}")
        check_arch(arch)
        self.device = torch.device(device)
        self.num_threads = num_threads
        self.runtime = resolve_runtime(runtime, self.device)
        loaded = load_weights(weights, arch=arch, layer=layer, remap=remap, remaps=remaps,
                              loaders=loaders, allow_partial=allow_partial, seed=seed,
                              stride=stride)
        self._place(loaded, mean, std, channels_last)
        option = getattr(self.module, "stride_option", None)  # a ViT's non-default stride
        self.identity = ModelIdentity(
            self.arch, self.layer if option is None else f"{self.layer}@stride{option}",
            loaded.name, weights_digest(self.module, loaded.required),
            self.mean, self.std, self.runtime,
        )
        self._prepare_inference(runtime_cache, verify=is_auto(runtime))

    # ------------------------------------------------------------------ construction
    def _place(self, loaded: LoadedWeights, mean: Sequence[float] | None,
               std: Sequence[float] | None, channels_last: bool) -> None:
        """Adopt the loaded network: normalisation, eval mode, device, memory format."""
        self.arch, self.layer, self.layers = loaded.arch, loaded.layer, loaded.layers
        self.module = loaded.module
        self.load_report: LoadReport | None = loaded.report
        self.mean, self.std = loaded.normalisation(mean, std)
        self.channels_last = channels_last
        self.module.eval().to(self.device)
        if channels_last:
            self.module.to(memory_format=torch.channels_last)
        self.channels = sum(self.module.layer_channels(name) for name in self.layers)
        self.stride: int = self.module.layer_stride(self.layers[0])

    def _prepare_inference(self, runtime_cache: str | os.PathLike[str] | None,
                           verify: bool = False) -> None:
        """The network the features come from (eager, or compiled for ``self.runtime``)."""
        self._network = FeatureNetwork(self.module, self.layers, combine_layers)
        self._compiled: CompiledBackbone | None = None
        if self.runtime != TORCH:
            self._compiled = CompiledBackbone(
                self.runtime, self._network, replace(self.identity, runtime=TORCH).key(),
                num_threads=self.num_threads, cache_dir=runtime_cache, verify=verify,
            )
        self._mean_t = torch.tensor(self.mean, device=self.device).view(1, 3, 1, 1)
        self._std_t = torch.tensor(self.std, device=self.device).view(1, 3, 1, 1)

    # ------------------------------------------------------------------ inference
    @contextlib.contextmanager
    def _threads(self) -> Iterator[None]:
        with torch_threads(self.num_threads):
            yield

    def preprocess(self, images: np.ndarray | Sequence[np.ndarray] | torch.Tensor) -> torch.Tensor:
        """Turn RGB images (one, a batch or a list) into a normalised ``(B, 3, H, W)`` batch.

        Images are uint8, or float32 arrays of unrounded pixel values in ``[0, 255]`` (e.g.
        the SOT heads' exact bilinear crops). A float ``(B, 3, H, W)`` or ``(3, H, W)``
        tensor is taken as normalised and only moved.
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
        if batch.ndim != 4 or batch.shape[3] != 3 or batch.dtype not in (np.uint8, np.float32):
            raise ValueError(
                f"images must be uint8 or float32 (pixel values) RGB (H, W, 3) or (B, H, W, 3); "
                f"got {batch.dtype} {batch.shape}. Normalised inputs must be torch tensors "
                "(B, 3, H, W)."
            )
        x = torch.from_numpy(np.ascontiguousarray(batch)).to(self.device)
        # not in place: a float32 batch shares memory with the caller's array
        x = x.permute(0, 3, 1, 2).to(torch.float32).div(255.0)
        return (x - self._mean_t) / self._std_t

    def features(self, images: np.ndarray | Sequence[np.ndarray] | torch.Tensor) -> torch.Tensor:
        """Feature maps ``(B, C, ceil(H / s), ceil(W / s))``, ``s`` = :attr:`stride` (float32)."""
        with self._threads(), torch.inference_mode():
            x = self.preprocess(images)
            if self._compiled is not None:
                out = self._compiled(x)
            else:
                if self.channels_last:
                    x = x.contiguous(memory_format=torch.channels_last)
                out = self._network(x).contiguous()
        expected = (math.ceil(x.shape[2] / self.stride), math.ceil(x.shape[3] / self.stride))
        if tuple(out.shape[2:]) != expected:  # an architecture bug, never user input
            raise RuntimeError(
                f"feature map {tuple(out.shape)} is not stride {self.stride} of {x.shape}")
        note_runtime(self.runtime_label(int(x.shape[2]), int(x.shape[3])))
        return out

    __call__ = features

    def runtime_label(self, height: int, width: int) -> str:
        """What computes the features of ``height x width`` inputs, as run records name it.

        ``torch``, ``openvino``, ``openvino (auto, checked against torch)`` or, where the
        check failed, ``torch (auto: openvino differed)``.
        """
        compiled = self._compiled
        if compiled is None:
            return TORCH
        if (height, width) in compiled.fallbacks:
            return f"{TORCH} (auto: {self.runtime} differed)"
        return f"{self.runtime} (auto, checked against torch)" if compiled.verify else self.runtime

    def feature_shape(self, height: int, width: int) -> tuple[int, int, int]:
        """Shape ``(C, h, w)`` of the feature map of one ``height`` x ``width`` image."""
        return self.channels, math.ceil(height / self.stride), math.ceil(width / self.stride)

    def map_extent(self, height: int, width: int) -> tuple[int, int]:
        """Pixels ``(rows, columns)`` from the top-left that the feature map of one image spans.

        A ViT's patches tile ``ceil(H / s) * s`` pixels (the image zero-padded); a CNN's map
        is taken to span the image itself, as UniTrack resizes masks to it. The propagation
        heads place labels and keypoints on the cells with it.
        """
        extent = getattr(self.module, "map_extent", None)
        return extent(height, width) if extent is not None else (height, width)

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
