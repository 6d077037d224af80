"""An optional on-disk cache of frame feature maps.

Comparing heads or hyper-parameters on the same frames should not recompute the backbone.
:class:`FeatureCache` stores one ``.npy`` file per frame under a directory named after
everything that determines the features::

    <root>/<model key>-<H>x<W>/<sequence>/<frame:06d>-<pixel fingerprint>.npy

where ``<model key>`` is :meth:`ModelIdentity.key` (architecture, layer, SHA-256 digest of
the weights, input normalisation) and ``H x W`` the network input size. A ``model.json``
next to the sequence folders records the identity in readable form.

Two ways to use it:

* :meth:`FeatureCache.get_or_compute` ``(key, fn)`` for any array-producing function;
* :class:`CachedAppearanceModel`, a drop-in wrapper whose ``features(images, sequence=,
  frames=)`` runs the backbone only on the frames not yet cached (in one batch).

Entries are written atomically (temporary file in the same folder, then ``os.replace``),
so an interrupted run leaves either a complete entry or none. A corrupt entry (truncated
file, bad header, wrong dtype or shape) is reported once with a :class:`FeatureCacheWarning`
and recomputed. Values are stored as float16 by default (half the disk, ~1e-3 relative
error); features returned by the cache are always the stored values converted back to
float32, on a hit and on a miss alike, so results do not depend on whether the cache was warm.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import tempfile
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from unitrack_env.agents.appearance.model import AppearanceModel

DEFAULT_CACHE_DTYPE: type[np.floating] = np.float16
"""On-disk dtype of cached features."""

FRAME_DIGITS: int = 6
"""Zero-padding of frame numbers in entry file names."""

_SAFE_NAME = re.compile(r"^[A-Za-z0-9._-]+$")
NAME_HASH_LENGTH: int = 8
"""Hex digits of the hash appended to sequence names that needed sanitising."""


class FeatureCacheWarning(UserWarning):
    """A cache entry was unreadable and is being recomputed."""


@dataclass(frozen=True)
class CacheKey:
    """Identity of one cached feature map.

    Attributes:
        model: :meth:`ModelIdentity.key` of the appearance model (includes the weights digest
            and the layer).
        input_size: ``(height, width)`` of the network input.
        sequence: Sequence name.
        frame: Frame index (the benchmark's own numbering).
        content: Fingerprint of the frame's pixels (:func:`image_fingerprint`), so that two
            data sets with the same sequence names, or a frame that changed on disk, never
            share an entry. Empty: key by name and index only.
    """

    model: str
    input_size: tuple[int, int]
    sequence: str
    frame: int
    content: str = ""


FINGERPRINT_STRIDE: int = 61
"""Every this-many-th byte of a frame enters its fingerprint (fast; ~35 kB of a 1088x608
frame, enough to tell different frames apart)."""


def image_fingerprint(image: np.ndarray) -> str:
    """A short hex digest of an image's shape and a strided sample of its bytes."""
    flat = np.ascontiguousarray(image).reshape(-1)
    digest = hashlib.blake2b(digest_size=8)
    digest.update(repr(image.shape).encode())
    digest.update(flat[::FINGERPRINT_STRIDE].tobytes())
    return digest.hexdigest()


def _safe(name: str) -> str:
    if _SAFE_NAME.match(name) and name not in (".", ".."):
        return name
    digest = hashlib.sha256(name.encode()).hexdigest()[:NAME_HASH_LENGTH]
    return re.sub(r"[^A-Za-z0-9._-]", "_", name).strip(".") + "-" + digest


def _atomic_write_bytes(path: Path, write: Callable[[object], None]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


class FeatureCache:
    """Feature maps on disk, one ``.npy`` file per (model, input size, sequence, frame).

    Args:
        root: Cache directory (created on first write).
        dtype: On-disk dtype (default float16; float32 for exact storage).

    Attributes:
        hits: Entries read from disk.
        misses: Entries computed because they were absent.
        recomputed: Entries computed because the stored file was corrupt.
    """

    def __init__(
        self, root: str | os.PathLike[str], *, dtype: type[np.floating] = DEFAULT_CACHE_DTYPE
    ) -> None:
        self.root = Path(root)
        self.dtype = np.dtype(dtype)
        if self.dtype.kind != "f":
            raise ValueError(f"cache dtype must be a float type, got {self.dtype}")
        self.hits = 0
        self.misses = 0
        self.recomputed = 0
        self._reported: set[Path] = set()

    def path(self, key: CacheKey) -> Path:
        """File that holds ``key``'s entry."""
        height, width = key.input_size
        suffix = f"-{key.content}" if key.content else ""
        return (
            self.root / f"{key.model}-{height}x{width}" / _safe(key.sequence)
            / f"{key.frame:0{FRAME_DIGITS}d}{suffix}.npy"
        )

    def _report(self, path: Path, reason: str) -> None:
        if path not in self._reported:
            self._reported.add(path)
            warnings.warn(
                f"{path}: corrupt feature-cache entry ({reason}); recomputing it",
                FeatureCacheWarning, stacklevel=3,
            )

    def get(
        self, key: CacheKey, expected_shape: tuple[int, ...] | None = None
    ) -> np.ndarray | None:
        """The stored array, or None when absent or corrupt (corruption is warned about)."""
        path = self.path(key)
        if not path.is_file():
            return None
        try:
            array = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            self._report(path, f"{type(exc).__name__}: {exc}")
            return None
        if array.dtype != self.dtype:
            self._report(path, f"dtype {array.dtype}, expected {self.dtype}")
            return None
        if expected_shape is not None and tuple(array.shape) != tuple(expected_shape):
            self._report(path, f"shape {array.shape}, expected {tuple(expected_shape)}")
            return None
        return array

    def put(self, key: CacheKey, array: np.ndarray | torch.Tensor) -> np.ndarray:
        """Store ``array`` atomically; return the stored (dtype-converted) values."""
        if isinstance(array, torch.Tensor):
            array = array.detach().to("cpu").numpy()
        stored = np.ascontiguousarray(array, dtype=self.dtype)
        _atomic_write_bytes(self.path(key), lambda handle: np.save(handle, stored))
        return stored

    def get_or_compute(
        self,
        key: CacheKey,
        compute: Callable[[], np.ndarray | torch.Tensor],
        *,
        expected_shape: tuple[int, ...] | None = None,
    ) -> torch.Tensor:
        """Return the cached features for ``key``, computing and storing them if needed.

        Args:
            key: Entry identity.
            compute: Zero-argument function producing the array (called on a miss only).
            expected_shape: When given, a stored entry of another shape counts as corrupt.

        Returns:
            A float32 CPU tensor holding the stored values.
        """
        path = self.path(key)
        existed = path.is_file()
        array = self.get(key, expected_shape)
        if array is not None:
            self.hits += 1
        else:
            if existed:
                self.recomputed += 1
            else:
                self.misses += 1
            array = self.put(key, compute())
        return torch.from_numpy(array.astype(np.float32))


class CachedAppearanceModel:
    """An :class:`AppearanceModel` whose per-frame features go through a :class:`FeatureCache`.

    Args:
        model: The appearance model.
        cache: A cache, or a directory to create one in (float16).

    Example:
        >>> cached = CachedAppearanceModel(AppearanceModel(), "/tmp/feats")  # doctest: +SKIP
        >>> maps = cached.features(frames, sequence="MOT17-02", frames=[1, 2])  # doctest: +SKIP
    """

    def __init__(
        self, model: AppearanceModel, cache: FeatureCache | str | os.PathLike[str]
    ) -> None:
        self.model = model
        self.cache = cache if isinstance(cache, FeatureCache) else FeatureCache(cache)
        self.identity = model.identity
        self.channels = model.channels
        self.stride = model.stride
        self._model_key = model.identity.key()

    def describe(self) -> dict[str, object]:
        """The wrapped model's description plus the cache location."""
        return {**self.model.describe(), "cache": str(self.cache.root)}

    def _write_identity(self, input_size: tuple[int, int]) -> None:
        folder = self.cache.path(CacheKey(self._model_key, input_size, "_", 0)).parents[1]
        info = folder / "model.json"
        if not info.is_file():
            text = json.dumps(asdict(self.identity), indent=2, sort_keys=True).encode()
            _atomic_write_bytes(info, lambda handle: handle.write(text))

    def lookup(
        self, input_size: tuple[int, int], sequence: str, frame: int, content: str
    ) -> torch.Tensor | None:
        """The cached ``(1, C, h, w)`` map of one frame, or None (no computation).

        Args:
            input_size: ``(height, width)`` of the network input.
            sequence: Sequence name.
            frame: Frame index.
            content: Fingerprint the entry was stored under (see ``fingerprints`` of
                :meth:`features`).
        """
        key = CacheKey(self._model_key, tuple(input_size), sequence, int(frame), content)
        array = self.cache.get(key, self.model.feature_shape(*input_size))
        if array is None:
            return None
        self.cache.hits += 1
        return torch.from_numpy(array.astype(np.float32))[None]

    def features(
        self,
        images: np.ndarray | Sequence[np.ndarray],
        *,
        sequence: str,
        frames: Sequence[int] | int,
        fingerprints: Sequence[str] | None = None,
    ) -> torch.Tensor:
        """Feature maps ``(B, C, h, w)`` for frames of one sequence, from the cache when possible.

        Args:
            images: uint8 RGB frames ``(H, W, 3)`` (one, a ``(B, H, W, 3)`` array, or a list),
                all of the same size (letterbox first).
            sequence: Sequence name (part of the key).
            frames: Frame index of each image.
            fingerprints: Content fingerprints to key the entries by (default: of
                ``images``). A caller that looks entries up before preparing its input (e.g.
                by the original frame, to skip the letterbox on a hit) passes its own.

        Returns:
            float32 CPU tensor of the stored (e.g. float16-rounded) features.
        """
        batch = np.asarray(images) if not isinstance(images, np.ndarray) else images
        if batch.ndim == 3:
            batch = batch[None]
        frame_list = [frames] if isinstance(frames, int) else list(frames)
        if len(frame_list) != batch.shape[0]:
            raise ValueError(f"{batch.shape[0]} images but {len(frame_list)} frame indices")
        input_size = (int(batch.shape[1]), int(batch.shape[2]))
        expected = self.model.feature_shape(*input_size)
        if fingerprints is None:
            fingerprints = [image_fingerprint(img) for img in batch]
        keys = [CacheKey(self._model_key, input_size, sequence, int(f), fp)
                for f, fp in zip(frame_list, fingerprints, strict=True)]
        found: dict[int, np.ndarray] = {}
        todo: list[int] = []
        for i, key in enumerate(keys):
            existed = self.cache.path(key).is_file()
            array = self.cache.get(key, expected)
            if array is not None:
                self.cache.hits += 1
                found[i] = array
            else:
                todo.append(i)
                if existed:
                    self.cache.recomputed += 1
                else:
                    self.cache.misses += 1
        if todo:
            self._write_identity(input_size)
            computed = self.model.features(batch[todo]).to("cpu")
            for row, i in enumerate(todo):
                found[i] = self.cache.put(keys[i], computed[row])
        return torch.from_numpy(np.stack([found[i] for i in range(len(keys))]).astype(np.float32))
