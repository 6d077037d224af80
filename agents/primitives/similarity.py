"""Appearance similarity between tracks and detections: RSM and the paper's baselines.

Every object is a *set* of ``(s_i, C)`` location features (40 for a box pooled to 10 x 4,
the covered cells for a mask). Metrics return an ``(N, M)`` float64 similarity (higher =
more alike; the cost is ``1 - similarity``) and empty arrays for empty inputs; features are
L2-normalised first by default, as UniTrack does. :data:`SIMILARITIES` maps the names to
the functions (an unknown name's KeyError lists the valid ones): ``"rsm"`` the
Reconstruction Similarity Metric (section 2.4, :func:`rsm`); the baselines of appendix D,
``"cf"`` centre feature, ``"gf"`` global feature (equal sizes only), ``"gpf"``
global-pooled feature.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch
import torch.nn.functional as F

RSM_TEMPERATURE: float = 0.01
"""Softmax temperature of RSM. The paper writes ``Softmax(T D^T)``; the authors' code uses
``softmax(100 * affinity)``, i.e. temperature 0.01, which makes each location's attention
nearly one-hot on its best matches."""

NORM_EPS: float = 1e-12
"""Guard against division by zero in L2 normalisation and cosines (all-zero features)."""

COSINE_EPS: float = 1e-8
"""Floor of each norm in RSM's cosines, as in ``torch.nn.functional.cosine_similarity``
(``x.y / (max(|x|, eps) * max(|y|, eps))``). It gives RSM the property the paper states: as
the attention weights of a pair vanish, so does its reconstruction and hence its score (a
pure cosine would be scale-invariant and could stay high on a vanishing reconstruction)."""

CENTRE_TIE_TOLERANCE: float = 1e-6
"""Locations whose distance to the centre of mass is within this of the minimum are averaged
(a 10 x 4 box grid has four equidistant central cells: their mean is the bilinear centre)."""

DEFAULT_GRID_SHAPE: tuple[int, int] = (10, 4)
"""(rows, columns) assumed for objects given without positions whose size matches it."""


@dataclass(frozen=True)
class ObjectFeatures:
    """The ``(s, C)`` location features of one observation, optionally ``(s, 2)`` grid positions."""

    features: torch.Tensor
    positions: torch.Tensor | None = None


ObjectSet = torch.Tensor | np.ndarray | Sequence["torch.Tensor | np.ndarray | ObjectFeatures"]
"""A set of objects: a uniform ``(N, s, C)`` array/tensor, or a sequence of ``(s_i, C)``
arrays/tensors or :class:`ObjectFeatures`."""


class Similarity(Protocol):
    """Signature shared by the metrics in :data:`SIMILARITIES`."""

    def __call__(
        self, tracks: ObjectSet, detections: ObjectSet, *, normalize: bool = True
    ) -> np.ndarray:
        """Return the ``(N, M)`` similarity of N tracks and M detections."""
        ...


def box_location_features(pooled: torch.Tensor) -> torch.Tensor:
    """Turn RoIAlign output ``(n, C, PH, PW)`` into row-major location sets ``(n, PH * PW, C)``."""
    if pooled.ndim != 4:
        raise ValueError(f"expected (n, C, PH, PW) pooled features, got {tuple(pooled.shape)}")
    return pooled.flatten(2).transpose(1, 2)


def grid_positions(rows: int, cols: int) -> torch.Tensor:
    """``(rows * cols, 2)`` (row, column) positions of a row-major grid."""
    r, c = torch.meshgrid(torch.arange(rows), torch.arange(cols), indexing="ij")
    return torch.stack([r.flatten(), c.flatten()], dim=1).to(torch.float64)


def _unpack(objects: ObjectSet) -> tuple[list[torch.Tensor], list[torch.Tensor | None]]:
    if isinstance(objects, (torch.Tensor, np.ndarray)):
        t = torch.as_tensor(objects)
        if t.ndim != 3:
            raise ValueError(f"a uniform object set must be (N, s, C); got {tuple(t.shape)}")
        return list(t.unbind(0)), [None] * t.shape[0]
    feats: list[torch.Tensor] = []
    positions: list[torch.Tensor | None] = []
    for i, obj in enumerate(objects):
        if isinstance(obj, ObjectFeatures):
            f, p = torch.as_tensor(obj.features), obj.positions
            if p is not None:
                p = torch.as_tensor(p, dtype=torch.float64)
                if p.shape != (f.shape[0], 2):
                    raise ValueError(
                        f"object {i}: positions {tuple(p.shape)} do not fit features "
                        f"{tuple(f.shape)}; expected ({f.shape[0]}, 2)"
                    )
        else:
            f, p = torch.as_tensor(obj), None
        if f.ndim != 2:
            raise ValueError(
                f"object {i}: location features must be (s, C); got {tuple(f.shape)}"
            )
        feats.append(f)
        positions.append(p)
    return feats, positions


_Prepared = tuple[
    list[torch.Tensor], list[torch.Tensor], list["torch.Tensor | None"], list["torch.Tensor | None"]
]


def _prepare(tracks: ObjectSet, detections: ObjectSet, normalize: bool) -> _Prepared:
    t_feats, t_pos = _unpack(tracks)
    d_feats, d_pos = _unpack(detections)
    channels = {f.shape[1] for f in t_feats + d_feats}
    if len(channels) > 1:
        raise ValueError(f"all objects must have the same channel count; got {sorted(channels)}")
    wide = any(f.dtype == torch.float64 for f in t_feats + d_feats)
    dtype = torch.float64 if wide else torch.float32

    def prep(f: torch.Tensor) -> torch.Tensor:
        f = f.to(dtype)
        return F.normalize(f, dim=1, eps=NORM_EPS) if normalize else f

    return [prep(f) for f in t_feats], [prep(f) for f in d_feats], t_pos, d_pos


def _cosine_matrix(a: torch.Tensor, b: torch.Tensor) -> np.ndarray:
    """Row-wise cosine similarity of ``(N, K)`` and ``(M, K)``."""
    a = F.normalize(a, dim=1, eps=NORM_EPS)
    b = F.normalize(b, dim=1, eps=NORM_EPS)
    return (a @ b.T).to(torch.float64).cpu().numpy()


def _empty(n: int, m: int) -> np.ndarray | None:
    return np.zeros((n, m), dtype=np.float64) if n == 0 or m == 0 else None


def _pad(objects: list[torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Stack ``(s_i, C)`` sets into ``(K, s_max, C)`` plus the flat padded index of each row."""
    sizes = [o.shape[0] for o in objects]
    s_max = max(max(sizes), 1)
    padded = objects[0].new_zeros((len(objects), s_max, objects[0].shape[1]))
    flat_index = []
    for k, o in enumerate(objects):
        padded[k, : o.shape[0]] = o
        flat_index.append(torch.arange(o.shape[0], device=o.device) + k * s_max)
    return padded, torch.cat(flat_index)


def _owners(objects: list[torch.Tensor]) -> torch.Tensor:
    """Index of the object that owns each concatenated location."""
    device = objects[0].device
    sizes = torch.tensor([o.shape[0] for o in objects], device=device)
    return torch.repeat_interleave(torch.arange(len(objects), device=device), sizes)


def _segment_sum(values: torch.Tensor, owners: torch.Tensor, count: int) -> torch.Tensor:
    """Sum the rows of ``values`` that belong to the same object: ``(count, ...)``."""
    out = values.new_zeros((count, *values.shape[1:]))
    return out.index_add_(0, owners, values)


def _reconstruction_cosine(
    queries: list[torch.Tensor],
    keys: list[torch.Tensor],
    affinity: torch.Tensor,
    attention: torch.Tensor,
) -> torch.Tensor:
    """cos(q_i, R_{i<-j} k_j) for all pairs, with R the (i, j) block of ``attention``.

    ``attention`` is the softmax of ``affinity`` over ALL key locations (no per-block
    renormalisation). The reconstruction norm is computed directly or through the key Gram
    matrices, whichever is cheaper.
    """
    n, m = len(queries), len(keys)
    q_owner, k_owner = _owners(queries), _owners(keys)
    weighted = _segment_sum(attention * affinity, q_owner, n)  # (N, sum s_j)
    inner = _segment_sum(weighted.T, k_owner, m).T  # (N, M)
    padded_keys, flat_index = _pad(keys)  # (M, s_max, C)
    s_max, channels = padded_keys.shape[1:]
    rows = attention.shape[0]
    if flat_index.numel() == m * s_max:  # all keys have s_max locations: no copy needed
        att = attention.reshape(rows, m, s_max)
    else:
        att = attention.new_zeros((rows, m * s_max))
        att[:, flat_index] = attention
        att = att.view(rows, m, s_max)
    if s_max < channels:
        gram = padded_keys @ padded_keys.transpose(1, 2)  # (M, s_max, s_max)
        recon_sq = (torch.einsum("rjk,jkl->rjl", att, gram) * att).sum(-1)
    else:
        recon_sq = torch.einsum("rjk,jkc->rjc", att, padded_keys).pow(2).sum(-1)
    recon_norm = _segment_sum(recon_sq.clamp(min=0), q_owner, n).sqrt()  # (N, M)
    query_norm = torch.stack([q.pow(2).sum() for q in queries]).sqrt().view(-1, 1)
    return inner / (query_norm.clamp(min=COSINE_EPS) * recon_norm.clamp(min=COSINE_EPS))


def rsm(
    tracks: ObjectSet,
    detections: ObjectSet,
    *,
    temperature: float = RSM_TEMPERATURE,
    normalize: bool = True,
) -> np.ndarray:
    """Reconstruction Similarity Metric (UniTrack, section 2.4, eq. "rsm").

    ``RSM(i, j) = (cos(t_i, t_hat_{i<-j}) + cos(d_j, d_hat_{j<-i})) / 2``, reconstructing each
    object from the other's locations with ``softmax(T D^T / temperature)`` taken over ALL
    locations of the other side, so a detection another detection explains better reconstructs
    a track poorly. Norms are floored at :data:`COSINE_EPS`. Symmetric; returns ``(N, M)``.
    """
    if temperature <= 0:
        raise ValueError(f"temperature must be > 0, got {temperature}")
    t_feats, d_feats, _, _ = _prepare(tracks, detections, normalize)
    empty = _empty(len(t_feats), len(d_feats))
    if empty is not None:
        return empty
    with torch.inference_mode():
        t_all = torch.cat(t_feats)
        d_all = torch.cat(d_feats)
        affinity = t_all @ d_all.T  # (St, Sd)
        if affinity.numel() == 0:  # objects without locations: nothing to compare
            return np.zeros((len(t_feats), len(d_feats)))
        logits = affinity / temperature
        forward = _reconstruction_cosine(t_feats, d_feats, affinity, logits.softmax(dim=1))
        backward = _reconstruction_cosine(
            d_feats, t_feats, affinity.T, logits.softmax(dim=0).T
        ).T
        return (0.5 * (forward + backward)).to(torch.float64).cpu().numpy()


def _centre_feature(
    features: torch.Tensor, positions: torch.Tensor | None, index: int,
    grid_shape: tuple[int, int],
) -> torch.Tensor:
    if features.shape[0] == 0:
        return features.new_zeros(features.shape[1])
    if positions is None:
        rows, cols = grid_shape
        if features.shape[0] != rows * cols:
            raise ValueError(
                f"object {index} has {features.shape[0]} locations and no positions; CF needs "
                f"positions (ObjectFeatures(features, positions)) unless the object is a "
                f"row-major {rows}x{cols} grid (grid_shape=)"
            )
        positions = grid_positions(rows, cols)
    centre = positions.mean(dim=0)
    dist = (positions - centre).norm(dim=1)
    nearest = dist <= dist.min() + CENTRE_TIE_TOLERANCE
    return features[nearest].mean(dim=0)


def center_feature_similarity(
    tracks: ObjectSet,
    detections: ObjectSet,
    *,
    normalize: bool = True,
    grid_shape: tuple[int, int] = DEFAULT_GRID_SHAPE,
) -> np.ndarray:
    """Center Feature (CF) baseline (UniTrack, appendix D): cosine of the centre-of-mass features.

    Locations tied for nearest to the centre are averaged (the bilinear centre of an even grid).
    Masks need :class:`ObjectFeatures` with positions; ``grid_shape`` is assumed otherwise.
    """
    t_feats, d_feats, t_pos, d_pos = _prepare(tracks, detections, normalize)
    empty = _empty(len(t_feats), len(d_feats))
    if empty is not None:
        return empty
    def centres(feats: list[torch.Tensor], pos: list[torch.Tensor | None]) -> torch.Tensor:
        return torch.stack([
            _centre_feature(f, p, i, grid_shape)
            for i, (f, p) in enumerate(zip(feats, pos, strict=True))
        ])

    return _cosine_matrix(centres(t_feats, t_pos), centres(d_feats, d_pos))


def global_feature_similarity(
    tracks: ObjectSet, detections: ObjectSet, *, normalize: bool = True
) -> np.ndarray:
    """Global Feature (GF) baseline (UniTrack, appendix D): cosine of the concatenated features.

    Defined only for observations of equal size (boxes on a fixed grid); raises ValueError else.
    """
    t_feats, d_feats, _, _ = _prepare(tracks, detections, normalize)
    empty = _empty(len(t_feats), len(d_feats))
    if empty is not None:
        return empty
    sizes = {f.shape[0] for f in t_feats + d_feats}
    if len(sizes) != 1:
        raise ValueError(
            f"GF needs observations of one fixed size (e.g. RoIAlign boxes); got sizes "
            f"{sorted(sizes)}. Use 'rsm', 'cf' or 'gpf' for masks."
        )
    return _cosine_matrix(
        torch.stack([f.flatten() for f in t_feats]), torch.stack([f.flatten() for f in d_feats])
    )


def global_pooled_feature_similarity(
    tracks: ObjectSet, detections: ObjectSet, *, normalize: bool = True
) -> np.ndarray:
    """Global-Pooled Feature (GPF) baseline (UniTrack, appendix D): cosine of mean features."""
    t_feats, d_feats, _, _ = _prepare(tracks, detections, normalize)
    empty = _empty(len(t_feats), len(d_feats))
    if empty is not None:
        return empty

    def pool(f: torch.Tensor) -> torch.Tensor:
        return f.mean(dim=0) if f.shape[0] else f.new_zeros(f.shape[1])

    return _cosine_matrix(
        torch.stack([pool(f) for f in t_feats]), torch.stack([pool(f) for f in d_feats])
    )


class _NamedTable(Mapping[str, Callable[..., np.ndarray]]):
    """A read-only name -> implementation table whose KeyError lists the valid names."""

    def __init__(self, kind: str, entries: Mapping[str, Callable[..., np.ndarray]]) -> None:
        self._kind = kind
        self._entries = dict(entries)

    def __getitem__(self, name: str) -> Callable[..., np.ndarray]:
        try:
            return self._entries[name]
        except KeyError:
            raise KeyError(
                f"unknown {self._kind} {name!r}; valid names: {', '.join(sorted(self._entries))}"
            ) from None

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)


SIMILARITIES: Mapping[str, Callable[..., np.ndarray]] = _NamedTable("similarity", {
    "rsm": rsm,
    "cf": center_feature_similarity,
    "gf": global_feature_similarity,
    "gpf": global_pooled_feature_similarity,
})
"""Name -> similarity function, each ``fn(tracks, detections, **options) -> (N, M) array``.
Read-only; to use another metric, pass the callable itself where a name is accepted."""
