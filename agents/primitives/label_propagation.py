"""Label propagation with a memory bank (UniTrack level 2: mask and pose propagation).

More in docs/module-notes.md.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

from .label_search import (
    MemorySearch,
    grid_positions,
    merge_topk,
    rescore,
    search_dense,
    stage,
)
from .label_search_tiled import TiledSearch
from .label_windows import WindowSearch

MEMORY_SIZE: int = 6
"""``M``: frames in the memory bank, the first frame plus the ``M - 1`` latest (appendix B.2)."""

RADIUS_STRIDE: int = 8
"""Feature stride the default radius is given for (UniTrack's stride-8 maps)."""

LOCAL_RADIUS: float = 12.0
"""``r``: local attention radius in feature pixels (Euclidean) for the recent frames."""

TOP_K: int = 10
"""``k`` of the k-NN: memory locations kept per query (appendix B.2)."""

TEMPERATURE: float = 0.05
"""``tau``: softmax temperature over the kept affinities (appendix B.2)."""

TILE_SIZE: int = 8
"""Query tile side of the local search (feature pixels). Larger tiles mean larger matmuls
but more keys outside a query's radius (``t^2 + 4 t r + pi r^2`` keys per tile against
``pi r^2`` per query) and smaller tiles a larger window ring (each key is copied into
``~(t + 2 r)^2 / t^2`` windows); 8 measured fastest here at 480p for r = 12
(``benchmarks/propagation.py --parts stages``)."""

MAX_AFFINITY_ELEMENTS: int = 1 << 22
"""Most affinity numbers (float32) held at once, per search: 4 Mi = 16 MiB. Measured per
480p step on DAVIS dog / blackswan (2 cores, AVX-512): 137 / 134 ms, against 148 / 142 ms at
8 Mi and 138 / 134 ms at 2 Mi (smaller blocks: more Python-level calls)."""

PRECISIONS: tuple[str, ...] = ("float32", "bf16")
"""Allowed ``propagation_precision`` values (docs/design-decisions.md)."""

CANDIDATE_FACTOR: int = 2
"""``bf16`` precision: candidates per query scored again in float32, in multiples of
``topk`` (docs/design-decisions.md has the measurement that chose it)."""

NATIVE_BF16_FLAGS: tuple[str, ...] = ("avx512_bf16", "amx_bf16")
"""CPU flags (Linux ``/proc/cpuinfo``) of native bfloat16 matrix products."""

NORM_EPS: float = 1e-12
"""Guard of the L2 normalisation of all-zero features."""


@dataclass(frozen=True)
class LabelPropagationConfig:
    """Hyper-parameters of :class:`LabelPropagator` (defaults: the paper's table B.2).

    Attributes:
        memory_size: ``M``, the first frame plus ``M - 1`` latest frames (>= 1).
        radius: Local attention radius of the recent frames (feature pixels at
            ``radius_stride``); None: dense, slow.
        first_frame_radius: Radius for the first frame; None (default): no limit.
        radius_stride: The stride the radii are given for (8); other strides get the same reach
            in pixels through :meth:`for_stride`. None: the model's own feature pixels.
        topk: Memory locations kept per query.
        temperature: Softmax temperature over the kept affinities.
        normalize: L2-normalise every location's feature (cosine affinities).
        tile_size: Query tile side of the local search (speed and memory only).
        max_affinity_elements: Most affinity values held at once.
        propagation_precision: ``"float32"`` (default, the paper's exact formulation) or
            ``"bf16"``: bfloat16 affinities pick ``CANDIDATE_FACTOR * topk`` candidates per
            query, rescored in float32 (float32's result unless its top-k falls outside
            them); CPUs with native bfloat16 only (docs/design-decisions.md).
    """

    memory_size: int = MEMORY_SIZE
    radius: float | None = LOCAL_RADIUS
    first_frame_radius: float | None = None
    radius_stride: int | None = RADIUS_STRIDE
    topk: int = TOP_K
    temperature: float = TEMPERATURE
    normalize: bool = True
    tile_size: int = TILE_SIZE
    max_affinity_elements: int = MAX_AFFINITY_ELEMENTS
    propagation_precision: str = "float32"

    def for_stride(self, stride: int) -> LabelPropagationConfig:
        """These options for a model whose feature cell is ``stride`` pixels (radii rescaled)."""
        if self.radius_stride is None or stride == self.radius_stride:
            return self
        scale = self.radius_stride / stride
        return replace(self, radius_stride=stride, **{
            name: None if getattr(self, name) is None else getattr(self, name) * scale
            for name in ("radius", "first_frame_radius")})

    def __post_init__(self) -> None:
        if self.propagation_precision not in PRECISIONS:
            raise ValueError(
                f"propagation_precision must be one of {', '.join(map(repr, PRECISIONS))}, "
                f"got {self.propagation_precision!r}"
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


def cpu_flags() -> set[str] | None:
    """The CPU's feature flags from Linux ``/proc/cpuinfo`` (None: not readable)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        return None
    return None


def check_precision(precision: str) -> None:
    """Refuse ``"bf16"`` on a CPU without native bfloat16, naming the reason and the fix."""
    if precision != "bf16":
        return
    flags = cpu_flags()
    if flags is not None and flags & set(NATIVE_BF16_FLAGS):
        return
    seen = ("the CPU flags could not be read from /proc/cpuinfo" if flags is None
            else "this CPU has neither (/proc/cpuinfo)")
    raise ValueError(
        f"propagation_precision='bf16' needs a CPU with native bfloat16 (flag "
        f"{' or '.join(NATIVE_BF16_FLAGS)}), and {seen}: emulated bfloat16 is slower than "
        "float32. Use propagation_precision='float32' (the default, exact)"
    )


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



def propagate_dense(
    query: torch.Tensor,
    memory_features: list[torch.Tensor],
    memory_labels: list[torch.Tensor],
    radii: list[float | None],
    *,
    topk: int = TOP_K,
    temperature: float = TEMPERATURE,
) -> torch.Tensor:
    """Reference definition: dense affinity to every memory location, masked by ``radii``.

    ``O((h w)^2 M)`` memory, for tests and small maps; features are used as given.
    Returns ``(K, h, w)`` propagated labels.
    """
    c, h, w = query.shape
    q = query.reshape(c, -1).t()
    grid = grid_positions(h, w, query.device)
    distance = torch.cdist(grid, grid)
    values, labels = [], []
    for feats, lab, radius in zip(memory_features, memory_labels, radii, strict=True):
        _check_pair(feats, lab)
        aff = q @ feats.reshape(c, -1)
        if radius is not None:
            aff = aff.masked_fill(distance > radius, float("-inf"))
        values.append(aff)
        labels.append(lab.reshape(lab.shape[0], -1).t().unsqueeze(0).expand(h * w, -1, -1))
    out = merge_topk(values, labels, topk, temperature)
    return out.t().reshape(-1, h, w)


class LabelPropagator:
    """Stateful label propagation over a memory bank (first frame + latest predictions).

    ``reset(features_0, labels_0)`` then ``labels_t = step(features_t)`` per frame.
    ``reference=True`` searches with the formulation the default replaced
    (:mod:`~unitrack_env.agents.primitives.label_search_tiled`): same results, slower.
    ``"bf16"`` precision: the same searches see bfloat16 features, ``CANDIDATE_FACTOR *
    topk`` and, as labels, each location's row in a float32 memory bank, from which
    :func:`~unitrack_env.agents.primitives.label_search.rescore` scores the candidates
    again; refused (ValueError) on a CPU without native bfloat16.
    """

    def __init__(self, config: LabelPropagationConfig | None = None, *,
                 reference: bool = False) -> None:
        self.config = config or LabelPropagationConfig()
        check_precision(self.config.propagation_precision)
        self.bf16 = self.config.propagation_precision == "bf16"
        search_config = (replace(self.config, topk=self.config.topk * CANDIDATE_FACTOR)
                         if self.bf16 else self.config)
        self.search: MemorySearch = (TiledSearch if reference else WindowSearch)(search_config)
        self._first: tuple[torch.Tensor, torch.Tensor] | None = None
        self._recent: deque[tuple[torch.Tensor, torch.Tensor]] = deque(
            maxlen=self.config.memory_size - 1
        )
        self._slots: deque[int] = deque()  # ring slots in use, oldest first
        # bf16: float32 features (N, C) and labels (N, K) of every memory location, N =
        # M h w (row r h w + p: position p of the first frame, r = 0, or of ring slot r - 1).
        self._bank: tuple[torch.Tensor, torch.Tensor] | None = None
        self._labels = 0  # label maps of the current video

    # ------------------------------------------------------------------ memory
    def _prepare(self, features: torch.Tensor) -> torch.Tensor:
        features = features.detach()
        if features.ndim == 4 and features.shape[0] == 1:
            features = features[0]
        if features.ndim != 3:
            raise ValueError(
                f"features must be (C, h, w) or (1, C, h, w); got {tuple(features.shape)}"
            )
        with stage("normalize"):
            return (normalize_features(features) if self.config.normalize
                    else features.float())

    def _searched(self, row: int, feats: torch.Tensor, labels: torch.Tensor
                  ) -> tuple[torch.Tensor, torch.Tensor]:
        """What the search sees of a frame in bank row ``row``; bf16: also fills that row."""
        if not self.bf16:
            return feats.contiguous(), labels.contiguous()
        c, h, w = feats.shape
        if self._bank is None or row == 0:
            size = self.config.memory_size * h * w
            self._bank = (feats.new_empty(size, c), labels.new_empty(size, labels.shape[0]))
        rows = slice(row * h * w, (row + 1) * h * w)
        self._bank[0][rows] = feats.reshape(c, -1).t()
        self._bank[1][rows] = labels.reshape(labels.shape[0], -1).t()
        ids = torch.arange(rows.start, rows.stop, dtype=torch.float32, device=feats.device)
        return feats.to(torch.bfloat16).contiguous(), ids.view(1, h, w)

    def reset(self, features: torch.Tensor, labels: torch.Tensor) -> None:
        """Start a video: the first frame's features ``(C, h, w)`` and labels ``(K, h, w)``."""
        feats = self._prepare(features)
        labels = labels.detach().float().to(feats.device)
        _check_pair(feats, labels)
        self._labels = labels.shape[0]
        self._first = self._searched(0, feats, labels)
        self._recent.clear()
        self._slots.clear()
        self.search.clear()

    def push(self, features: torch.Tensor, labels: torch.Tensor) -> None:
        """Add a frame with its (predicted) labels to the recent memory (oldest dropped)."""
        first = self._require()
        feats = self._prepare(features)
        labels = labels.detach().float().to(feats.device)
        _check_pair(feats, labels)
        if feats.shape != first[0].shape or labels.shape[0] != self._labels:
            raise ValueError(
                f"frame features {tuple(feats.shape)} / labels {tuple(labels.shape)} do not match "
                f"the first frame's {tuple(first[0].shape)} / {self._labels} label maps"
            )
        self._remember(feats, labels)

    def step(self, features: torch.Tensor) -> torch.Tensor:
        """Propagate to a new frame and remember it with its prediction; ``(K, h, w)``."""
        feats = self._prepare(features)
        labels = self._propagate_prepared(feats)
        self._remember(feats, labels)
        return labels

    def propagate(self, features: torch.Tensor) -> torch.Tensor:
        """Labels ``(K, h, w)`` of a new frame from the memory, without remembering it."""
        return self._propagate_prepared(self._prepare(features))

    def _remember(self, feats: torch.Tensor, labels: torch.Tensor) -> None:
        """Append to the recent memory; the search copies it into its ring slot."""
        slots = self.config.memory_size - 1
        if slots < 1:
            return
        # The oldest frame's slot is overwritten once the ring is full.
        slot = self._slots.popleft() if len(self._slots) == slots else len(self._slots)
        searched = self._searched(1 + slot, feats, labels)
        self._recent.append(searched)
        with torch.inference_mode():
            self.search.write(slot, *searched)
        self._slots.append(slot)

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
        first = self._require()
        if query.shape != first[0].shape:
            raise ValueError(
                f"query features {tuple(query.shape)} differ from the first frame's "
                f"{tuple(first[0].shape)} (frames of one video must have one size)"
            )
        c, h, w = query.shape
        cfg = self.config
        searched = query.to(torch.bfloat16) if self.bf16 else query
        with torch.inference_mode():
            values, labels = self.search.candidates(searched, first, list(self._recent),
                                                    list(self._slots))
            if self._bank is None:  # float32
                out = merge_topk(values, labels, cfg.topk, cfg.temperature)
            else:
                q = query.reshape(c, -1).t().contiguous()
                out = rescore(q, values, labels, *self._bank, self.search.config.topk,
                              cfg.topk, cfg.temperature, cfg.max_affinity_elements)
        return out.t().reshape(-1, h, w).clone()

    # Stage entry points of benchmarks/runtime.py (one search each, as the heads run them).
    def _search_first(self, q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int,
                      w: int) -> tuple[torch.Tensor, torch.Tensor]:
        cfg = self.search.config
        return search_dense(q, feats, lbl, h, w, cfg.first_frame_radius, cfg.topk,
                            cfg.max_affinity_elements)

    def _search_local(self, query: torch.Tensor, h: int,
                      w: int) -> tuple[torch.Tensor, torch.Tensor]:
        return self.search.search_recent(query, list(self._slots))
