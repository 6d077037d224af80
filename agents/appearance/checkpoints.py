"""Loading backbone checkpoints safely, with key remapping and a loud report.

Every checkpoint is read with ``torch.load(..., map_location="cpu", weights_only=True)``: no
pickled code runs. The state dict is unwrapped and renamed by a :class:`KeyRemap` (the
tables record how each self-supervised release stores its backbone, per the UniTrack code
facts), compared key by key with the model, and loaded only when every key the chosen output
layer depends on is present with the right shape. Unlike the reference implementation, which
silently drops non-matching keys (so a wrong checkpoint runs on random weights), a partial
load is an error unless ``allow_partial=True``; either way a :class:`LoadReport` lists
matched, missing, unexpected and shape-mismatched keys. Remap tables are read-only; extend
one by building a new mapping, e.g. ``{**DEFAULT_REMAPS, "mine": KeyRemap("mine",
containers=("net",), strip_prefixes=("backbone.",))}``, passed as ``remaps=``.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import torch
from torch import nn

from unitrack_env.errors import CheckpointError  # defined there so that it pickles

from .vit_checkpoints import VIT_REMAP_FIELDS, apply_key_rules

IMAGENET_MEAN: tuple[float, float, float] = (0.485, 0.456, 0.406)
"""ImageNet RGB mean of inputs scaled to [0, 1] (torchvision's models and most SSL models)."""

IMAGENET_STD: tuple[float, float, float] = (0.229, 0.224, 0.225)
"""ImageNet RGB standard deviation of inputs scaled to [0, 1]."""

CIFAR_MEAN: tuple[float, float, float] = (0.4914, 0.4822, 0.4465)
"""CIFAR-style RGB mean that CRW checkpoints were trained with (UniTrack code facts)."""

CIFAR_STD: tuple[float, float, float] = (0.2023, 0.1994, 0.2010)
"""CIFAR-style RGB standard deviation that CRW checkpoints were trained with."""

OPTIONAL_KEY_SUFFIXES: tuple[str, ...] = ("num_batches_tracked", "ls1.gamma", "ls2.gamma")
"""Keys whose absence is reported but never fatal: buffers that do not affect inference
(older torchvision files, e.g. ``resnet18-5c106cde.pth``, lack them) and a ViT's layer
scale, which only DINOv2 trains (kept at ones, the identity, for DINO, MAE and timm files)."""

MAX_DETAIL_CHARS: int = 300
"""Longest excerpt of torch's own loading error quoted in a :class:`CheckpointError`."""

MAX_KEYS_IN_MESSAGE: int = 8
"""How many offending keys an error message lists before abbreviating."""


@dataclass(frozen=True)
class KeyRemap:
    """How one checkpoint family stores a torchvision-layout backbone.

    ``containers`` may wrap the state dict (tried in order); the first matching
    ``strip_prefixes`` is removed; ``drop_prefixes`` are not the backbone (DINO ``head.``);
    ``rename_prefixes`` apply when no key starts with the new prefix; ``squeeze_5d`` flattens
    TimeCycle's ``(out, in, 1, k, k)`` kernels; ``mean``/``std`` None: ImageNet's.
    """

    name: str
    containers: tuple[str, ...] = ("state_dict", "model")
    strip_prefixes: tuple[str, ...] = ()
    squeeze_5d: bool = False
    drop_prefixes: tuple[str, ...] = ()
    rename_prefixes: tuple[tuple[str, str], ...] = ()
    mean: tuple[float, float, float] | None = None
    std: tuple[float, float, float] | None = None
    description: str = ""


def _plain(name: str, what: str) -> KeyRemap:
    return KeyRemap(
        name, strip_prefixes=("module.",),
        description=f"{what}: a plain torchvision ResNet state dict (optionally DataParallel)",
    )


DEFAULT_REMAPS: Mapping[str, KeyRemap] = MappingProxyType({
    "torchvision": _plain("torchvision", "torchvision / ImageNet-supervised"),
    "crw": KeyRemap(
        "crw", containers=("model",), strip_prefixes=("encoder.model.",),
        mean=CIFAR_MEAN, std=CIFAR_STD,
        description="CRW (Jabri et al. 2020): ckpt['model'], strip 'encoder.model.', CIFAR stats",
    ),
    "moco": KeyRemap(
        "moco", containers=("state_dict",), strip_prefixes=("module.encoder_q.", "encoder_q."),
        description="MoCo v1/v2: ckpt['state_dict'], strip 'module.encoder_q.' (DataParallel) "
                    "or 'encoder_q.' (one GPU)",
    ),
    "uvc": KeyRemap(
        "uvc", containers=("state_dict",), strip_prefixes=("module.gray_encoder.",),
        description="UVC: ckpt['state_dict'], strip 'module.gray_encoder.'",
    ),
    "timecycle": KeyRemap(
        "timecycle", containers=("state_dict",), strip_prefixes=("module.encoderVideo.",),
        squeeze_5d=True,
        description="TimeCycle: ckpt['state_dict'], strip 'module.encoderVideo.', squeeze 5-D",
    ),
    **{
        key: _plain(key, what) for key, what in (
            ("byol", "BYOL"), ("swav", "SwAV"), ("simclr", "SimCLR v1/v2"),
            ("barlowtwins", "Barlow Twins"), ("deepcluster", "DeepCluster v2"),
            ("insdis", "InsDis"), ("pirl", "PIRL"), ("pcl", "PCL v1/v2"), ("sela", "SeLa v2"),
            ("infomin", "InfoMin"), ("detco", "DetCo"), ("pixpro", "PixPro"),
        )
    },
    **{key: KeyRemap(key, **fields) for key, fields in VIT_REMAP_FIELDS.items()},
})
"""Read-only remap table: checkpoint family -> :class:`KeyRemap`. Names listed in the
UniTrack code facts; the plain-R50 families share one rule and are listed for discoverability."""


@dataclass
class LoadReport:
    """What happened when a state dict was loaded into a module.

    ``matched``, ``missing`` (model keys absent), ``unexpected`` (checkpoint keys the model
    lacks) and ``mismatched`` ``(key, checkpoint_shape, model_shape)`` keys;
    ``required_prefixes`` are the module prefixes the output layer depends on.
    """

    source: str
    remap: str | None = None
    matched: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    unexpected: list[str] = field(default_factory=list)
    mismatched: list[tuple[str, tuple[int, ...], tuple[int, ...]]] = field(default_factory=list)
    required_prefixes: tuple[str, ...] = ()

    def _required(self, key: str) -> bool:
        return any(key.startswith(p) for p in self.required_prefixes)

    @property
    def critical_missing(self) -> list[str]:
        """Missing keys the output layer needs (inference-neutral buffers excluded)."""
        return [
            k for k in self.missing
            if self._required(k) and not k.endswith(OPTIONAL_KEY_SUFFIXES)
        ]

    @property
    def critical_mismatched(self) -> list[tuple[str, tuple[int, ...], tuple[int, ...]]]:
        """Shape-mismatched keys the output layer needs."""
        return [m for m in self.mismatched if self._required(m[0])]

    @property
    def critical_unexpected(self) -> list[str]:
        """Unexpected keys inside the output layer's modules.

        Such keys mean a different architecture, e.g. a ResNet-34 file in a ResNet-18.
        """
        return [k for k in self.unexpected if self._required(k)]

    @property
    def complete(self) -> bool:
        """True when everything the output layer depends on was loaded."""
        return not (self.critical_missing or self.critical_mismatched or self.critical_unexpected)

    def summary(self) -> str:
        """One line: counts of matched / missing / unexpected / mismatched keys."""
        return (
            f"{self.source} (remap {self.remap}): {len(self.matched)} matched, "
            f"{len(self.missing)} missing ({len(self.critical_missing)} needed), "
            f"{len(self.unexpected)} unexpected ({len(self.critical_unexpected)} inside the "
            f"backbone), {len(self.mismatched)} shape-mismatched"
        )


def _abbrev(items: list[Any]) -> str:
    shown = ", ".join(str(i) for i in items[:MAX_KEYS_IN_MESSAGE])
    more = len(items) - MAX_KEYS_IN_MESSAGE
    return shown + (f", ... ({more} more)" if more > 0 else "")


def read_checkpoint(path: str | os.PathLike[str]) -> Any:
    """Read a checkpoint file with ``weights_only=True`` on the CPU; CheckpointError if not."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(path, "checkpoint file not found")
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types: UnpicklingError, RuntimeError, ...
        lines = str(exc).splitlines() or [""]
        detail = next((line for line in lines if "Unsupported" in line), lines[0])
        detail = detail.split(". ")[0][:MAX_DETAIL_CHARS]  # torch's first sentence
        raise CheckpointError(
            path,
            f"not a readable PyTorch checkpoint ({path.stat().st_size:,} bytes; corrupt, "
            "truncated, not a torch.save file, or containing objects that weights_only=True "
            f"refuses): {type(exc).__name__}: {detail}",
        ) from exc


def extract_state_dict(
    obj: Any, remap: KeyRemap, *, path: str | os.PathLike[str] | None = None
) -> dict[str, torch.Tensor]:
    """Unwrap a loaded checkpoint, rename its keys by ``remap``, drop non-tensor entries."""
    if not isinstance(obj, Mapping):
        raise CheckpointError(path, f"expected a dict-like checkpoint, got {type(obj).__name__}")
    state: Any = obj
    for container in remap.containers:
        inner = obj.get(container)
        if isinstance(inner, Mapping):
            state = inner
            break
    tensors = {k: v for k, v in state.items() if isinstance(k, str) and isinstance(v, torch.Tensor)}
    if not tensors:
        raise CheckpointError(
            path,
            f"no tensors found (remap {remap.name!r} looked in {list(remap.containers)} and at "
            f"top level; top-level keys: {_abbrev(list(obj.keys()))})",
        )
    renamed: dict[str, torch.Tensor] = {}
    for key, value in tensors.items():
        for prefix in remap.strip_prefixes:
            if key.startswith(prefix):
                key = key[len(prefix):]
                break
        if remap.squeeze_5d and value.ndim == 5 and value.shape[2] == 1:
            value = value[:, :, 0]
        renamed[key] = value
    if remap.drop_prefixes or remap.rename_prefixes:
        renamed = apply_key_rules(renamed, remap.drop_prefixes, remap.rename_prefixes)
    return renamed


def compare_state_dicts(
    model_state: Mapping[str, torch.Tensor],
    state: Mapping[str, torch.Tensor],
    *,
    source: str,
    remap: str | None,
    required_prefixes: Iterable[str],
) -> LoadReport:
    """Compare a checkpoint's keys and shapes with a model's, without loading anything."""
    report = LoadReport(source=source, remap=remap, required_prefixes=tuple(required_prefixes))
    for key, target in model_state.items():
        if key not in state:
            report.missing.append(key)
        elif tuple(state[key].shape) != tuple(target.shape):
            report.mismatched.append((key, tuple(state[key].shape), tuple(target.shape)))
        else:
            report.matched.append(key)
    report.unexpected = [k for k in state if k not in model_state]
    return report


def choose_remap(
    obj: Any,
    model_state: Mapping[str, torch.Tensor],
    remaps: Mapping[str, KeyRemap],
    *,
    path: str | os.PathLike[str] | None = None,
) -> KeyRemap:
    """Pick the remap under which the most model keys match.

    Ties: the fewest keys left over, then table order.
    """
    best: tuple[tuple[int, int], KeyRemap] | None = None
    errors = []
    for remap in remaps.values():
        try:
            state = extract_state_dict(obj, remap, path=path)
        except CheckpointError as exc:
            errors.append(str(exc))
            continue
        matched = sum(
            1 for k, v in state.items()
            if k in model_state and tuple(v.shape) == tuple(model_state[k].shape)
        )
        score = (matched, -len(state.keys() - model_state.keys()))
        if best is None or score > best[0]:
            best = (score, remap)
    if best is None:
        raise CheckpointError(path, f"no remap could read this checkpoint: {errors[0]}")
    return best[1]


def _prefix_hint(state: Mapping[str, Any], model_state: Mapping[str, Any]) -> str:
    """`` Every key starts with 'p.' ...`` when the keys fit the model once ``p.`` is cut."""
    heads = {key.partition(".")[0] for key in state}
    if len(heads) != 1 or not all("." in key for key in state):
        return ""
    prefix = f"{heads.pop()}."
    fits = sum(key[len(prefix):] in model_state for key in state)
    if not fits:
        return ""
    return (f" Every key starts with {prefix!r} and {fits} keys fit the backbone without it: "
            "save the backbone's own state_dict (or strip the prefix) and load that file.")


def check_values(state: Mapping[str, torch.Tensor], keys: Iterable[str],
                 path: str | os.PathLike[str] | None = None) -> None:
    """Refuse tensors holding NaN or infinity, and weights that are all zero.

    ``keys``: the tensors to be loaded. CheckpointError names the offending tensors (the first
    :data:`MAX_KEYS_IN_MESSAGE` and their count); a checkpoint that passes is loaded exactly.
    """
    floats = [k for k in keys if state[k].is_floating_point()]
    bad = [k for k in floats if not bool(torch.isfinite(state[k]).all())]
    if bad:
        raise CheckpointError(
            path, f"{len(bad)} of {len(floats)} tensors hold NaN or infinite values: "
                  f"{_abbrev(bad)}. The file is damaged or its training diverged; load "
                  "another checkpoint")
    weights = [k for k in floats if state[k].ndim >= 2]  # kernels, matrices, embeddings
    if weights and not any(bool(state[k].any()) for k in weights):
        raise CheckpointError(
            path, f"every weight tensor is zero ({len(weights)} tensors: {_abbrev(weights)}): "
                  "not a trained model (an empty or wiped file?); load another checkpoint, "
                  "or weights='random' for the random-weights baseline")


def load_state_into(
    module: nn.Module,
    state: Mapping[str, torch.Tensor],
    *,
    required_prefixes: Iterable[str],
    source: str,
    remap: str | None = None,
    allow_partial: bool = False,
    path: str | os.PathLike[str] | None = None,
) -> LoadReport:
    """Copy the matching tensors of ``state`` into ``module`` and report what happened.

    A missing, mismatched or unexpected key under ``required_prefixes`` makes the load
    incomplete: CheckpointError naming the file and keys, nothing modified, unless
    ``allow_partial``. Tensors with NaN/infinity, or all-zero weights, are refused
    (:func:`check_values`).
    """
    model_state = module.state_dict()
    report = compare_state_dicts(
        model_state, state, source=source, remap=remap, required_prefixes=required_prefixes
    )
    if not report.complete and not allow_partial:
        parts = []
        if report.critical_missing:
            parts.append(f"missing keys: {_abbrev(report.critical_missing)}")
        if report.critical_mismatched:
            parts.append(
                "shape mismatches (key, checkpoint, model): "
                + _abbrev(report.critical_mismatched)
            )
        if report.critical_unexpected:
            parts.append(
                "keys the architecture does not have (wrong depth?): "
                + _abbrev(report.critical_unexpected)
            )
        raise CheckpointError(
            path,
            f"checkpoint does not fit the backbone (remap {remap!r}); "
            + "; ".join(parts)
            + f". {report.summary()}.{_prefix_hint(state, model_state)} Pick the right "
            "architecture/remap, or pass allow_partial=True to load only the matching keys.",
        )
    check_values(state, report.matched, path)
    new_state = dict(model_state)
    for key in report.matched:
        new_state[key] = state[key].to(dtype=model_state[key].dtype)
    module.load_state_dict(new_state, strict=True)
    return report


def load_checkpoint(
    module: nn.Module,
    path: str | os.PathLike[str],
    *,
    required_prefixes: Iterable[str],
    remap: str | KeyRemap = "auto",
    remaps: Mapping[str, KeyRemap] = DEFAULT_REMAPS,
    allow_partial: bool = False,
    checkpoint: Any = None,
) -> tuple[LoadReport, KeyRemap]:
    """Read a checkpoint file and load it into ``module``; return the report and the remap used.

    ``remap`` is a name in ``remaps``, a :class:`KeyRemap`, or ``"auto"`` (the one matching the
    most keys); ``checkpoint`` is the file's content when already read. Raises CheckpointError.
    """
    obj = read_checkpoint(path) if checkpoint is None else checkpoint
    if isinstance(remap, KeyRemap):
        chosen = remap
    elif remap == "auto":
        chosen = choose_remap(obj, module.state_dict(), remaps, path=path)
    elif remap in remaps:
        chosen = remaps[remap]
    else:
        raise CheckpointError(
            path, f"unknown remap {remap!r}; valid: 'auto', {', '.join(map(repr, remaps))}"
        )
    state = extract_state_dict(obj, chosen, path=path)
    report = load_state_into(
        module, state, required_prefixes=required_prefixes, source=str(path),
        remap=chosen.name, allow_partial=allow_partial, path=path,
    )
    return report, chosen
