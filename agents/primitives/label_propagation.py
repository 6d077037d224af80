"""Label propagation with a memory bank (UniTrack level 2: mask and pose propagation).

UniTrack (Wang et al., NeurIPS 2021), section 2.3 and appendix B.2, propagates a label map
``z`` (one channel per object, or one Gaussian belief map per joint) from a memory of past
frames to the current one through the affinity of their stride-8 feature maps:

* ``K_m^t[i, j] = softmax_j(<x_t^i, x_m^j> / tau)`` over the memory locations ``j`` of the
  query location ``i``, keeping only the ``k`` largest affinities of each query (top-k, as
  in CRW) and taking the softmax over those ``k`` (the authors' code: top-10, then
  ``softmax(A / 0.05)`` over them);
* ``z_t = K_m^t z_m``: each query location receives the convex combination of its top-k
  memory labels, so labels stay in ``[0, 1]`` and per-location sums are preserved;
* the memory bank holds the first frame (the given ground truth) and the ``M - 1`` latest
  predictions (``M = 6``); predicted *soft* labels are written back (recurrent);
* local attention (MAST / CRW): a query only sees memory locations of the *recent* frames
  within Euclidean radius ``r = 12`` feature pixels of its own position. The first frame
  has no radius limit (``OFFICIAL-CODE-FACTS.md``, "Mask and pose propagation").

Features are L2-normalised per location (the inner product of the paper is then a cosine,
the scale the temperature 0.05 is meant for).

Implementation (CPU-friendly, memory bounded). The top-k of the union of several candidate
sets is the top-k of the union of each set's top-k, so the two kinds of context are
searched separately and merged exactly:

* first frame: dense affinity ``(queries, h*w)``, processed in chunks of queries so that no
  more than ``max_affinity_elements`` numbers exist at once;
* recent frames: the query grid is cut into ``tile_size`` x ``tile_size`` tiles; each tile
  only needs the memory window ``(tile_size + 2 r)^2`` around it, so one batched matmul per
  group of tiles replaces the dense ``(h*w)^2`` affinity. A distance mask keeps exactly the
  locations within the radius of each query (plus a validity mask at the image borders).

:func:`propagate_dense` is the plain (slow, memory-hungry) definition used as the
reference in the tests; :class:`LabelPropagator` is the fast stateful version the heads use.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import torch
import torch.nn.functional as F

MEMORY_SIZE: int = 6
"""``M``: frames in the memory bank, the first frame plus the ``M - 1`` latest (appendix B.2)."""

LOCAL_RADIUS: float = 12.0
"""``r``: local attention radius in feature pixels (Euclidean) for the recent frames."""

TOP_K: int = 10
"""``k`` of the k-NN: memory locations kept per query (appendix B.2)."""

TEMPERATURE: float = 0.05
"""``tau``: softmax temperature over the kept affinities (appendix B.2)."""

TILE_SIZE: int = 16
"""Query tile side of the local search (feature pixels). Larger tiles mean fewer, larger
matmuls but more wasted window area ((t + 2r)^2 keys per t^2 queries); 16 measured
fastest here at 480p for r = 12."""

MAX_AFFINITY_ELEMENTS: int = 1 << 23
"""Most affinity numbers (float32) held at once, per search: 8 Mi = 32 MiB."""

AFFINITY_DTYPES: dict[str, torch.dtype] = {"float32": torch.float32, "bfloat16": torch.bfloat16}
"""Allowed ``affinity_dtype`` names and their torch dtypes."""

NORM_EPS: float = 1e-12
"""Guard of the L2 normalisation of all-zero features."""


@dataclass(frozen=True)
class LabelPropagationConfig:
    """Hyper-parameters of :class:`LabelPropagator` (defaults: the paper's table B.2).

    Attributes:
        memory_size: ``M``, the first frame plus ``M - 1`` latest frames (>= 1).
        radius: Local attention radius (feature pixels, Euclidean) for the recent frames;
            None: no limit (dense affinity over every recent frame, slow).
        first_frame_radius: Radius for the first frame; None (default): no limit.
        topk: Memory locations kept per query.
        temperature: Softmax temperature over the kept affinities.
        normalize: L2-normalise every location's feature (cosine affinities).
        tile_size: Query tile side of the local search (speed only; results do not depend
            on it beyond float rounding).
        max_affinity_elements: Memory bound: most affinity values held at once.
        affinity_dtype: ``"float32"`` (default, exact) or ``"bfloat16"``: dtype of the stored
            features and of the affinity matmuls (accumulated in float32 by oneDNN). On CPUs
            with AVX512-BF16 the matmuls run several times faster (measured here: 3.4x for
            the 480p first-frame affinity) at the cost of ~3 significant digits in the
            affinities; on CPUs without native bfloat16 it can be much slower.
    """

    memory_size: int = MEMORY_SIZE
    radius: float | None = LOCAL_RADIUS
    first_frame_radius: float | None = None
    topk: int = TOP_K
    temperature: float = TEMPERATURE
    normalize: bool = True
    tile_size: int = TILE_SIZE
    max_affinity_elements: int = MAX_AFFINITY_ELEMENTS
    affinity_dtype: str = "float32"

    def __post_init__(self) -> None:
        if self.affinity_dtype not in AFFINITY_DTYPES:
            raise ValueError(
                f"affinity_dtype must be one of {sorted(AFFINITY_DTYPES)}, "
                f"got {self.affinity_dtype!r}"
            )
        if self.memory_size < 1:
            raise ValueError(f"memory_size must be >= 1 (the first frame), got {self.memory_size}")
        for name in ("radius", "first_frame_radius"):
            value = getattr(self, name)
            if value is not None and not value >= 0:
                raise ValueError(f"{name} must be >= 0 or None, got {value}")
        if self.topk < 1:
            raise ValueError(f"topk must be >= 1, got {self.topk}")
        if not self.temperature > 0:
            raise ValueError(f"temperature must be > 0, got {self.temperature}")
        if self.tile_size < 1:
            raise ValueError(f"tile_size must be >= 1, got {self.tile_size}")
        if self.max_affinity_elements < 1:
            raise ValueError("max_affinity_elements must be >= 1")


def normalize_features(features: torch.Tensor) -> torch.Tensor:
    """L2-normalise a ``(C, h, w)`` feature map along the channels (float32)."""
    return F.normalize(features.float(), dim=0, eps=NORM_EPS)


def _check_pair(features: torch.Tensor, labels: torch.Tensor) -> None:
    if features.ndim != 3 or labels.ndim != 3:
        raise ValueError(
            f"features must be (C, h, w) and labels (K, h, w); got {tuple(features.shape)} and "
            f"{tuple(labels.shape)}"
        )
    if features.shape[1:] != labels.shape[1:]:
        raise ValueError(
            f"labels {tuple(labels.shape)} must have the feature map's size "
            f"{tuple(features.shape[1:])}; downsample them to the feature grid first"
        )


def _grid(h: int, w: int, device: torch.device) -> torch.Tensor:
    """``(h*w, 2)`` float (row, column) of every location, row-major."""
    rows, cols = torch.meshgrid(
        torch.arange(h, device=device, dtype=torch.float32),
        torch.arange(w, device=device, dtype=torch.float32), indexing="ij",
    )
    return torch.stack([rows.reshape(-1), cols.reshape(-1)], dim=1)


def _merge_topk(
    values: list[torch.Tensor], labels: list[torch.Tensor], topk: int, temperature: float
) -> torch.Tensor:
    """Top-k over candidate groups, softmax over the kept ones, weighted labels.

    Args:
        values: Per group ``(Q, k_g)`` affinities (``-inf`` = not a candidate).
        labels: Per group ``(Q, k_g, K)`` labels of those candidates.
        topk: Candidates kept over all groups.
        temperature: Softmax temperature.

    Returns:
        ``(Q, K)`` propagated labels.
    """
    value = torch.cat(values, dim=1)
    label = torch.cat(labels, dim=1)
    k = min(topk, value.shape[1])
    best, index = value.topk(k, dim=1)
    kept = torch.gather(label, 1, index.unsqueeze(-1).expand(-1, -1, label.shape[2]))
    weights = torch.softmax(best / temperature, dim=1)  # -inf entries get weight 0
    return torch.einsum("qk,qkc->qc", weights, kept)


def propagate_dense(
    query: torch.Tensor,
    memory_features: list[torch.Tensor],
    memory_labels: list[torch.Tensor],
    radii: list[float | None],
    *,
    topk: int = TOP_K,
    temperature: float = TEMPERATURE,
) -> torch.Tensor:
    """Reference definition: dense affinity to every memory location, masked by radius.

    Features are used as given (normalise them first for cosine affinities). Slow and
    ``O((h w)^2 M)`` in memory: for tests and small maps.

    Args:
        query: ``(C, h, w)`` features of the current frame.
        memory_features: ``M`` maps ``(C, h, w)``.
        memory_labels: ``M`` label maps ``(K, h, w)``.
        radii: Per memory frame, the Euclidean radius of the locations a query may attend
            to (None: all).
        topk: Kept affinities per query.
        temperature: Softmax temperature.

    Returns:
        ``(K, h, w)`` propagated labels.
    """
    c, h, w = query.shape
    q = query.reshape(c, -1).t()
    grid = _grid(h, w, query.device)
    distance = torch.cdist(grid, grid)
    values, labels = [], []
    for feats, lab, radius in zip(memory_features, memory_labels, radii, strict=True):
        _check_pair(feats, lab)
        aff = q @ feats.reshape(c, -1)
        if radius is not None:
            aff = aff.masked_fill(distance > radius, float("-inf"))
        values.append(aff)
        labels.append(lab.reshape(lab.shape[0], -1).t().unsqueeze(0).expand(h * w, -1, -1))
    out = _merge_topk(values, labels, topk, temperature)
    return out.t().reshape(-1, h, w)


class LabelPropagator:
    """Stateful label propagation over a memory bank (first frame + latest predictions).

    Usage per video::

        prop = LabelPropagator()
        prop.reset(features_0, labels_0)        # (C, h, w), (K, h, w) of the first frame
        for features_t in later_frames:
            labels_t = prop.step(features_t)    # propagate, then remember (recurrent)

    Args:
        config: Hyper-parameters (default: the paper's).

    Attributes:
        config: The hyper-parameters.
    """

    def __init__(self, config: LabelPropagationConfig | None = None) -> None:
        self.config = config or LabelPropagationConfig()
        self._first: tuple[torch.Tensor, torch.Tensor] | None = None
        self._recent: deque[tuple[torch.Tensor, torch.Tensor]] = deque(
            maxlen=self.config.memory_size - 1
        )
        self._mask_cache: dict[tuple[int, int, int, int], torch.Tensor] = {}

    # ------------------------------------------------------------------ memory
    def _prepare(self, features: torch.Tensor) -> torch.Tensor:
        features = features.detach()
        if features.ndim == 4 and features.shape[0] == 1:
            features = features[0]
        if features.ndim != 3:
            raise ValueError(
                f"features must be (C, h, w) or (1, C, h, w); got {tuple(features.shape)}"
            )
        features = normalize_features(features) if self.config.normalize else features.float()
        return features.to(AFFINITY_DTYPES[self.config.affinity_dtype])

    def reset(self, features: torch.Tensor, labels: torch.Tensor) -> None:
        """Start a video: the first frame's features ``(C, h, w)`` and labels ``(K, h, w)``."""
        feats = self._prepare(features)
        labels = labels.detach().float().to(feats.device)
        _check_pair(feats, labels)
        self._first = (feats.contiguous(), labels.contiguous())
        self._recent.clear()

    def push(self, features: torch.Tensor, labels: torch.Tensor) -> None:
        """Add a frame with its (predicted) labels to the recent memory (oldest dropped)."""
        first = self._require()
        feats = self._prepare(features)
        labels = labels.detach().float().to(feats.device)
        _check_pair(feats, labels)
        if feats.shape != first[0].shape or labels.shape[0] != first[1].shape[0]:
            raise ValueError(
                f"frame features {tuple(feats.shape)} / labels {tuple(labels.shape)} do not match "
                f"the first frame's {tuple(first[0].shape)} / {tuple(first[1].shape)}"
            )
        if self.config.memory_size > 1:
            self._recent.append((feats.contiguous(), labels.contiguous()))

    def step(self, features: torch.Tensor) -> torch.Tensor:
        """Propagate to a new frame and remember it with its prediction; ``(K, h, w)``."""
        feats = self._prepare(features)
        labels = self._propagate_prepared(feats)
        if self.config.memory_size > 1:
            self._recent.append((feats.contiguous(), labels.contiguous()))
        return labels

    def propagate(self, features: torch.Tensor) -> torch.Tensor:
        """Labels ``(K, h, w)`` of a new frame from the memory, without remembering it."""
        return self._propagate_prepared(self._prepare(features))

    @property
    def memory_length(self) -> int:
        """Frames in the memory bank (first frame included; 0 before :meth:`reset`)."""
        return 0 if self._first is None else 1 + len(self._recent)

    def _require(self) -> tuple[torch.Tensor, torch.Tensor]:
        if self._first is None:
            raise RuntimeError("call reset(features, labels) with the first frame first")
        return self._first

    # ------------------------------------------------------------------ propagation
    def _propagate_prepared(self, query: torch.Tensor) -> torch.Tensor:
        first_feats, first_labels = self._require()
        if query.shape != first_feats.shape:
            raise ValueError(
                f"query features {tuple(query.shape)} differ from the first frame's "
                f"{tuple(first_feats.shape)} (frames of one video must have one size)"
            )
        cfg = self.config
        c, h, w = query.shape
        num_labels = first_labels.shape[0]
        with torch.inference_mode():
            q = query.reshape(c, -1).t().contiguous()  # (Q, C)
            values: list[torch.Tensor] = []
            labels: list[torch.Tensor] = []
            v, lab = self._search_first(q, first_feats, first_labels, h, w)
            values.append(v)
            labels.append(lab)
            if self._recent:
                if cfg.radius is None:
                    for feats, lbl in self._recent:
                        v, lab = self._search_dense(q, feats, lbl, h, w, None)
                        values.append(v)
                        labels.append(lab)
                else:
                    v, lab = self._search_local(query, h, w)
                    values.append(v)
                    labels.append(lab)
            out = _merge_topk(values, labels, cfg.topk, cfg.temperature)
        return out.t().reshape(num_labels, h, w).clone()

    def _search_first(self, q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int,
                      w: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self._search_dense(q, feats, lbl, h, w, self.config.first_frame_radius)

    def _search_dense(
        self, q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int, w: int,
        radius: float | None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Top-k of every query over one whole memory frame, in chunks of queries."""
        cfg = self.config
        size = h * w
        keys = feats.reshape(feats.shape[0], -1)  # (C, S)
        flat_labels = lbl.reshape(lbl.shape[0], -1).t()  # (S, K)
        k = min(cfg.topk, size)
        chunk = max(1, cfg.max_affinity_elements // size)
        grid = _grid(h, w, q.device) if radius is not None else None
        out_v, out_l = [], []
        for start in range(0, q.shape[0], chunk):
            aff = q[start:start + chunk] @ keys
            if grid is not None:
                aff.masked_fill_(torch.cdist(grid[start:start + chunk], grid) > radius,
                                 float("-inf"))
            best, index = aff.topk(k, dim=1)
            out_v.append(best.float())
            out_l.append(flat_labels[index])  # (n, k, K)
        return torch.cat(out_v), torch.cat(out_l)

    def _local_mask(self, h: int, w: int, tile: int, pad: int) -> torch.Tensor:
        """``(tiles_y, tiles_x, tile*tile, (tile+2 pad)^2)`` bool: key not allowed.

        A window location is excluded when it lies outside the query's radius or outside
        the feature map (padding). Cached per map size (one video has one size).
        """
        key = (h, w, tile, pad)
        cached = self._mask_cache.get(key)
        if cached is not None:
            return cached
        radius = float(self.config.radius or 0.0)
        win = tile + 2 * pad
        qy, qx = torch.meshgrid(torch.arange(tile), torch.arange(tile), indexing="ij")
        ky, kx = torch.meshgrid(torch.arange(win), torch.arange(win), indexing="ij")
        dy = (ky.reshape(1, -1) - pad) - qy.reshape(-1, 1)
        dx = (kx.reshape(1, -1) - pad) - qx.reshape(-1, 1)
        outside = (dy * dy + dx * dx).float() > radius * radius  # (T2, L)
        tiles_y, tiles_x = math.ceil(h / tile), math.ceil(w / tile)
        rows = torch.arange(tiles_y).view(-1, 1) * tile + ky.reshape(1, -1) - pad  # (Ty, L)
        cols = torch.arange(tiles_x).view(-1, 1) * tile + kx.reshape(1, -1) - pad  # (Tx, L)
        off_map = (
            ((rows < 0) | (rows >= h)).view(tiles_y, 1, 1, -1)
            | ((cols < 0) | (cols >= w)).view(1, tiles_x, 1, -1)
        )
        mask = outside.view(1, 1, tile * tile, -1) | off_map
        self._mask_cache.clear()  # keep one size only: bounded memory
        self._mask_cache[key] = mask
        return mask

    @staticmethod
    def _pad_channels_last(maps: torch.Tensor, pad: int, extra_h: int,
                           extra_w: int) -> torch.Tensor:
        """``(R, X, h, w)`` -> zero-padded channels-last ``(R, h + 2 pad + eh, w + ..., X)``."""
        padded = F.pad(maps, (pad, pad + extra_w, pad, pad + extra_h))
        return padded.permute(0, 2, 3, 1).contiguous()

    def _search_local(self, query: torch.Tensor, h: int,
                      w: int) -> tuple[torch.Tensor, torch.Tensor]:
        """Top-k of every query over the radius windows of all recent frames (tiled)."""
        cfg = self.config
        pad = int(math.floor(float(cfg.radius or 0.0)))
        tile = max(1, min(cfg.tile_size, max(h, w)))
        tiles_y, tiles_x = math.ceil(h / tile), math.ceil(w / tile)
        hp, wp = tiles_y * tile, tiles_x * tile
        feats = torch.stack([f for f, _ in self._recent])  # (R, C, h, w)
        lbls = torch.stack([lab for _, lab in self._recent])  # (R, K, h, w)
        frames, c = feats.shape[:2]
        num_labels = lbls.shape[1]
        keys = self._pad_channels_last(feats, pad, hp - h, wp - w)  # (R, H', W', C)
        key_labels = self._pad_channels_last(lbls, pad, hp - h, wp - w)  # (R, H', W', K)
        queries = F.pad(query, (0, wp - w, 0, hp - h)).permute(1, 2, 0)  # (hp, wp, C)
        win = tile + 2 * pad
        window = win * win
        t2 = tile * tile
        mask = self._local_mask(h, w, tile, pad).to(query.device)  # (Ty, Tx, T2, L)
        per_tile = t2 * frames * window
        tiles_per_chunk = max(1, cfg.max_affinity_elements // per_tile)
        k = min(cfg.topk, frames * window)
        out_v = torch.empty(hp, wp, k, device=query.device)
        out_l = torch.empty(hp, wp, k, num_labels, device=query.device)
        for ty in range(tiles_y):
            # Overlapping windows as strided views (no copy), copied once per chunk below.
            strip_k = keys[:, ty * tile:ty * tile + win].unfold(2, win, tile)  # (R,win,X,C,win)
            strip_l = key_labels[:, ty * tile:ty * tile + win].unfold(2, win, tile)
            q_rows = queries[ty * tile:(ty + 1) * tile]  # (T, wp, C)
            q_tiles = q_rows.reshape(tile, tiles_x, tile, c).permute(1, 0, 2, 3).reshape(
                tiles_x, t2, c)
            for x0 in range(0, tiles_x, tiles_per_chunk):
                x1 = min(tiles_x, x0 + tiles_per_chunk)
                n = x1 - x0
                # (n, R*L, C): frame-major, then window row, then window column.
                k_chunk = strip_k[:, :, x0:x1].permute(2, 0, 1, 4, 3).reshape(
                    n, frames * window, c)
                aff = torch.bmm(q_tiles[x0:x1], k_chunk.transpose(1, 2))  # (n, T2, R*L)
                aff = aff.view(n, t2, frames, window).masked_fill_(
                    mask[ty, x0:x1].unsqueeze(2), float("-inf")).view(n, t2, frames * window)
                best, index = aff.topk(k, dim=2)  # (n, T2, k)
                l_chunk = strip_l[:, :, x0:x1].permute(2, 0, 1, 4, 3).reshape(
                    n, frames * window, num_labels)
                gathered = torch.gather(
                    l_chunk.unsqueeze(1).expand(n, t2, frames * window, num_labels), 2,
                    index.unsqueeze(-1).expand(n, t2, k, num_labels),
                )
                out_v[ty * tile:(ty + 1) * tile, x0 * tile:x1 * tile] = best.view(
                    n, tile, tile, k).permute(1, 0, 2, 3).reshape(tile, n * tile, k)
                out_l[ty * tile:(ty + 1) * tile, x0 * tile:x1 * tile] = gathered.view(
                    n, tile, tile, k, num_labels).permute(1, 0, 2, 3, 4).reshape(
                    tile, n * tile, k, num_labels)
        return (out_v[:h, :w].reshape(h * w, k),
                out_l[:h, :w].reshape(h * w, k, num_labels))
