"""Label propagation with a memory bank (UniTrack level 2: mask and pose propagation).

UniTrack (Wang et al., NeurIPS 2021), section 2.3 and appendix B.2, propagates a label map
``z`` (one channel per object, or one Gaussian belief map per joint) from a memory of past
frames to the current one through the affinity of their stride-8 feature maps:

* ``K[i, j] = softmax_j(<x_t^i, x_m^j> / tau)`` over the ``k`` largest affinities of query
  ``i`` (top-k, as in CRW; the authors' code: top-10, then ``softmax(A / 0.05)``), on
  L2-normalised features (a cosine, the scale the temperature is meant for);
* ``z_t = K z_m``: each query receives a convex combination of its top-k memory labels;
* the memory holds the first frame (the ground truth) and the ``M - 1`` latest *soft*
  predictions (``M = 6``);
* local attention (MAST / CRW): a query sees the *recent* frames' locations within radius
  ``r = 12`` feature pixels only; the first frame has no radius limit
  (``OFFICIAL-CODE-FACTS.md``, "Mask and pose propagation").

:func:`propagate_dense` is that definition, plain (slow, memory-hungry: the tests'
reference); :class:`LabelPropagator` is the fast, stateful, memory-bounded version the heads
use. It relies on one fact: the top-k of a union of candidate sets is the top-k of each
set's top-k (:func:`merge_topk`), so the recent frames and the first frame are searched
apart and merged exactly.

* Recent frames (:class:`WindowSearch`, the default): the query grid is cut into ``t x t``
  tiles; a tile's keys are the locations within the radius of any of its queries (the tile
  grown by the radius, ``L ~ t^2 + 4 t r + pi r^2``). When a frame enters the memory, every
  tile's keys are copied out once (im2col) into the ring ``(T, R, slots, g, C)``, so a
  tile's keys in all recent frames are one contiguous matrix: no gather at search time.
  Per step, by blocks of tiles bounded by ``max_affinity_elements``: one batched matmul
  per tile, one masking pass (radius, border, dummy keys: a cached ``-inf`` bias, cheaper
  than ``masked_fill``), then a grouped top-k: a query's top-k lies in the ``k`` groups of
  largest maximum, so a strided max, a top-k over group maxima and one over the chosen
  groups replace a top-k over all candidates (:func:`grouped_topk`).
* First frame: a dense matmul by blocks of queries keeping only the keys at or above the
  query's ``k``-th best recent affinity (:func:`search_above`): nothing below can enter the
  merged top-k.
* ``reference=True`` (:class:`TiledSearch`): the formulation the window ring replaced (a
  dense first-frame top-k; each tile's keys gathered per step), kept for
  ``benchmarks/propagation.py`` and the equality tests. Both agree up to the order of
  equal affinities.

Precision: float32 (default) or, with ``propagation_precision="bf16"`` on CPUs with native
bfloat16, bfloat16 affinities choose ``CANDIDATE_FACTOR x k`` candidates per query, whose
float32 affinities are then rescored exactly (:func:`rescore`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, replace

import torch
import torch.nn.functional as F

STAGE_PREFIX: str = "label_propagation."
"""Prefix of the ``torch.profiler`` labels of :func:`stage`."""


def stage(name: str) -> torch.profiler.record_function:
    """A ``torch.profiler`` label for one stage (affinity, top-k, labels, weights, memory)."""
    return torch.profiler.record_function(STAGE_PREFIX + name)


def grid_positions(h: int, w: int, device: torch.device) -> torch.Tensor:
    """``(h*w, 2)`` float (row, column) of every location, row-major."""
    rows, cols = torch.meshgrid(
        torch.arange(h, device=device, dtype=torch.float32),
        torch.arange(w, device=device, dtype=torch.float32), indexing="ij",
    )
    return torch.stack([rows.reshape(-1), cols.reshape(-1)], dim=1)


class Workspace:
    """Scratch tensors reused from step to step (fresh large tensors page-fault each step)."""

    def __init__(self) -> None:
        self._tensors: dict[str, torch.Tensor] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: torch.dtype,
            device: torch.device) -> torch.Tensor:
        """A contiguous ``shape`` tensor of undefined content, reused under ``name``."""
        size = math.prod(shape)
        tensor = self._tensors.get(name)
        if (tensor is None or tensor.numel() < size or tensor.dtype != dtype
                or tensor.device != device):
            tensor = self._tensors[name] = torch.empty(size, dtype=dtype, device=device)
        return tensor[:size].view(shape)

    def clear(self) -> None:
        """Free every scratch tensor."""
        self._tensors.clear()


def merge_topk(
    values: list[torch.Tensor], labels: list[torch.Tensor], topk: int, temperature: float
) -> torch.Tensor:
    """Top-k over candidate groups (``-inf`` = none), softmax over the kept, weighted labels."""
    with stage("top-k"):
        value = torch.cat(values, dim=1).float()
        label = torch.cat(labels, dim=1)
        k = min(topk, value.shape[1])
        best, index = value.topk(k, dim=1)
    with stage("labels"):
        kept = torch.gather(label, 1, index.unsqueeze(-1).expand(-1, -1, label.shape[2]))
    with stage("weights"):
        weights = torch.softmax(best / temperature, dim=1)  # -inf entries get weight 0
        return torch.einsum("qk,qkc->qc", weights, kept)


def rescore(q: torch.Tensor, values: list[torch.Tensor], ids: list[torch.Tensor],
            keys: torch.Tensor, labels: torch.Tensor, width: int, topk: int,
            temperature: float, max_elements: int) -> torch.Tensor:
    """``(Q, K)`` labels from the exact float32 top-k of approximate candidates.

    The ``width`` best candidates by their approximate (bfloat16) affinities ``values``,
    whose rows of ``keys`` ``(N, C)`` / ``labels`` ``(N, K)`` are ``ids`` (per group ``(Q,
    k_g, 1)``, float), are scored again against ``q`` ``(Q, C)`` in float32; the usual top-k
    and softmax follow: float32's result wherever its top-k lies among those candidates.
    """
    with stage("top-k"):
        value = torch.cat(values, dim=1).float()
        best, pick = value.topk(min(width, value.shape[1]), dim=1)
        index = torch.cat(ids, dim=1)[..., 0].gather(1, pick).long()
    with stage("rescore"):
        exact = torch.empty_like(best)
        chunk = max(1, max_elements // (best.shape[1] * keys.shape[1]))
        for start in range(0, q.shape[0], chunk):
            stop = min(q.shape[0], start + chunk)
            gathered = keys.index_select(0, index[start:stop].reshape(-1)).view(
                stop - start, best.shape[1], -1)
            exact[start:stop] = torch.bmm(gathered, q[start:stop].unsqueeze(2)).squeeze(2)
        exact.masked_fill_(best == float("-inf"), float("-inf"))  # not a candidate
    with stage("labels"):
        kept = labels.index_select(0, index.view(-1)).view(*index.shape, labels.shape[1])
    return merge_topk([exact], [kept], topk, temperature)


def kth_best(values: list[torch.Tensor], k: int) -> torch.Tensor:
    """``(Q,)`` the ``k``-th largest of the sorted candidate groups per query (``-inf``: fewer)."""
    if len(values) == 1 and values[0].shape[1] == k:  # one group, sorted by its top-k
        return values[0][:, k - 1].float()
    value = torch.cat(values, dim=1)
    if value.shape[1] < k:
        return value.new_full((value.shape[0],), float("-inf"))
    return value.topk(k, dim=1).values[:, k - 1].float()


def _affinity_block(q: torch.Tensor, keys: torch.Tensor, out: torch.Tensor,
                    grid: torch.Tensor | None, rows: torch.Tensor | slice,
                    radius: float | None) -> None:
    """``out = q @ keys``; beyond ``radius`` of the query positions ``grid[rows]``: -inf."""
    with stage("affinity"):
        torch.mm(q, keys, out=out)
        if grid is not None:
            out.masked_fill_(torch.cdist(grid[rows], grid) > radius, float("-inf"))


def search_dense(
    q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int, w: int,
    radius: float | None, topk: int, max_elements: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k ``(Q, k)`` affinities and ``(Q, k, K)`` labels over one memory frame."""
    size = h * w
    keys = feats.reshape(feats.shape[0], -1)  # (C, S)
    k = min(topk, size)
    chunk = max(1, max_elements // size)
    grid = grid_positions(h, w, q.device) if radius is not None else None
    out_v = torch.empty(q.shape[0], k, device=q.device)
    out_i = torch.empty(q.shape[0], k, dtype=torch.long, device=q.device)
    aff = torch.empty(min(chunk, q.shape[0]), size, dtype=q.dtype, device=q.device)
    for start in range(0, q.shape[0], chunk):
        stop = min(q.shape[0], start + chunk)
        block_aff = aff[:stop - start]
        _affinity_block(q[start:stop], keys, block_aff, grid, slice(start, stop), radius)
        with stage("top-k"):
            best, index = block_aff.topk(k, dim=1)
            out_v[start:stop] = best
            out_i[start:stop] = index
    with stage("labels"):
        return out_v, lbl.reshape(lbl.shape[0], -1).t()[out_i]


GROUP_SIZE: int = 20
"""Keys per group of the first-frame search above a floor (see :func:`search_above`)."""

ABOVE_WIDTH: int = 32
"""Most first-frame keys at or above its floor a query keeps (unsorted: the merge sorts)
before it falls back to a plain top-k of its row. Measured on DAVIS blackswan / dog at 480p
(M = 6, top-10): a query's floor is reached in about 2 / 5 groups on average, and by more
than 32 keys for 0.1% / 4.5% of the queries. The old rule (a top-k over at most 8 reached
groups) sent 15% of the dog's queries to the plain top-k, which then cost as much as the rest
of the selection."""


def search_above(
    q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int, w: int,
    radius: float | None, floor: torch.Tensor, topk: int, max_elements: int,
    workspace: Workspace | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Every key of one memory frame at or above each query's ``floor`` (or its top-k).

    Exact for the merged top-k when ``floor`` is each query's ``topk``-th best other
    candidate. Keys form strided groups of 20; one strided max finds the groups whose best
    reaches the floor, and only those are re-read (up to :data:`ABOVE_WIDTH` keys kept; more,
    or an infinite floor, falls back to a plain top-k). Returns unsorted ``(Q, W)`` affinities
    (``-inf``: empty) and ``(Q, W, K)`` labels.
    """
    size = h * w
    keys = feats.reshape(feats.shape[0], -1)
    lanes = math.ceil(size / GROUP_SIZE)
    k = min(topk, size)
    width = max(k, ABOVE_WIDTH)
    chunk = max(1, max_elements // (lanes * GROUP_SIZE))
    grid = grid_positions(h, w, q.device) if radius is not None else None
    out_v = torch.empty(q.shape[0], width, device=q.device)
    out_i = torch.empty(q.shape[0], width, dtype=torch.long, device=q.device)
    shape = (min(chunk, q.shape[0]), lanes * GROUP_SIZE)
    aff = (workspace.get("first frame", shape, q.dtype, q.device) if workspace is not None
           else torch.empty(shape, dtype=q.dtype, device=q.device))
    aff[:, size:] = float("-inf")  # the tail past S (if any) stays -inf
    for start in range(0, q.shape[0], chunk):
        stop = min(q.shape[0], start + chunk)
        block = aff[:stop - start]
        _affinity_block(q[start:stop], keys, block[:, :size], grid, slice(start, stop), radius)
        with stage("top-k"):
            _select_above(block, lanes, floor[start:stop], k, out_v[start:stop],
                          out_i[start:stop])
    with stage("labels"):
        return out_v, lbl.reshape(lbl.shape[0], -1).t()[out_i.clamp_(max=size - 1)]


def _select_above(block: torch.Tensor, lanes: int, floor: torch.Tensor, k: int,
                  out_v: torch.Tensor, out_i: torch.Tensor) -> None:
    """Fill ``out_v``/``out_i`` ``(n, W)``: each row's keys at or above its floor, or its top-k."""
    n, width = out_v.shape
    grid = block.view(n, GROUP_SIZE, lanes)
    hit = grid.amax(1) >= floor.unsqueeze(1)  # (n, lanes): groups whose best reaches it
    light = hit.sum(1) <= width  # each hit group holds a key at or above the floor
    row, group = (hit & light.unsqueeze(1)).nonzero(as_tuple=True)  # rows ascending
    columns = group.unsqueeze(1) + torch.arange(GROUP_SIZE, device=block.device) * lanes
    # index_select, not tensor[index]: several times faster for these 1-D gathers on CPU.
    where = ((row * block.shape[1]).unsqueeze(1) + columns).view(-1)
    values = block.view(-1).index_select(0, where)  # the hit groups' keys, (P * 20,)
    least = floor.index_select(0, row).repeat_interleave(GROUP_SIZE)
    kept = (values >= least).nonzero().squeeze(1)  # in row order
    key_row = row.index_select(0, kept // GROUP_SIZE)
    count = torch.bincount(key_row, minlength=n)
    # A kept key's slot: its rank among its row's kept keys. Rows with more than W are
    # clamped into the last slot here and rewritten below.
    before = (count.cumsum(0) - count).index_select(0, key_row)
    slot = torch.arange(len(kept), device=block.device) - before
    flat = key_row * width + slot.clamp_(max=width - 1)
    out_v.fill_(float("-inf"))
    out_i.zero_()
    out_v.view(-1)[flat] = values.index_select(0, kept).to(out_v.dtype)
    out_i.view(-1)[flat] = columns.view(-1).index_select(0, kept)
    heavy = (~light | (count > width)).nonzero().squeeze(1)
    if len(heavy):  # the floor is reached by too many keys: a plain top-k of the row
        top_v, top_i = block[heavy].topk(k, dim=1)
        out_v[heavy] = F.pad(top_v.to(out_v.dtype), (0, width - k), value=float("-inf"))
        out_i[heavy] = F.pad(top_i, (0, width - k))


class MemorySearch(ABC):
    """How a label propagator lays out its recent memory and finds each query's top-k.

    The propagator keeps the bookkeeping; a search keeps its own copy of the recent frames in
    the layout it searches, written once per frame by :meth:`write`.
    """

    def __init__(self, config: LabelPropagationConfig) -> None:
        self.config = config

    @abstractmethod
    def clear(self) -> None:
        """Forget the recent memory (a new video)."""

    @abstractmethod
    def write(self, slot: int, feats: torch.Tensor, labels: torch.Tensor) -> None:
        """A recent frame ``(C, h, w)`` with labels ``(K, h, w)`` takes ring slot ``slot``."""

    @abstractmethod
    def search_recent(self, query: torch.Tensor, slots: Sequence[int]
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(h * w, k)`` affinities and ``(h * w, k, K)`` labels over the recent windows."""

    @abstractmethod
    def candidates(self, query: torch.Tensor, first: tuple[torch.Tensor, torch.Tensor],
                   recent: Sequence[tuple[torch.Tensor, torch.Tensor]],
                   slots: Sequence[int]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Candidate groups (affinities, labels) of the prepared ``query`` ``(C, h, w)``.

        Their merged top-k (:func:`merge_topk`, ``k = config.topk``) is the query's top-k
        over the whole memory.
        """

    def recent_candidates(self, query: torch.Tensor,
                          recent: Sequence[tuple[torch.Tensor, torch.Tensor]],
                          slots: Sequence[int]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Top-k groups of the recent frames: dense per frame without a radius, else windows."""
        cfg = self.config
        c, h, w = query.shape
        if recent and cfg.radius is None:
            q = query.reshape(c, -1).t().contiguous()
            found = [search_dense(q, feats, lbl, h, w, None, cfg.topk, cfg.max_affinity_elements)
                     for feats, lbl in recent]
            return [v for v, _ in found], [lab for _, lab in found]
        if recent:
            v, lab = self.search_recent(query, slots)
            return [v], [lab]
        return [], []


def window_offsets(tile: int, radius: float) -> tuple[torch.Tensor, torch.Tensor]:
    """The ``(L,)`` row and column offsets of a tile's search window, within ``radius``.

    Offsets are from the tile's top-left query minus ``floor(radius)`` (the padding), over
    the ``tile + 2 pad`` square, kept where the nearest query of the tile is within the
    radius: the tile square grown by the radius.
    """
    pad = int(math.floor(radius))
    win = tile + 2 * pad
    oy, ox = torch.meshgrid(torch.arange(win), torch.arange(win), indexing="ij")
    oy, ox = oy.reshape(-1), ox.reshape(-1)
    gap_y = torch.clamp(torch.maximum(pad - oy, oy - (pad + tile - 1)), min=0)
    gap_x = torch.clamp(torch.maximum(pad - ox, ox - (pad + tile - 1)), min=0)
    keep = (gap_y * gap_y + gap_x * gap_x).double() <= radius * radius
    return oy[keep], ox[keep]


@dataclass(frozen=True)
class LocalGeometry:
    """Layout of the tiled local search for one map size (``key``: what it was built for).

    ``key_index`` ``(T, L)``: per tile, the flat positions in a padded map of the keys within
    the radius of any of its queries; ``excluded`` ``(T, t^2, L)``: out of radius or off map.
    """

    key: tuple[object, ...]
    tile: int
    pad: int
    tiles_y: int
    tiles_x: int
    padded_h: int
    padded_w: int
    key_index: torch.Tensor
    excluded: torch.Tensor

    @classmethod
    def build(cls, h: int, w: int, tile: int, radius: float, device: torch.device,
              key: tuple[object, ...]) -> LocalGeometry:
        """Lay out the local search of an ``h x w`` map with ``tile`` tiles."""
        pad = int(math.floor(radius))
        tiles_y, tiles_x = math.ceil(h / tile), math.ceil(w / tile)
        padded_h, padded_w = tiles_y * tile + 2 * pad, tiles_x * tile + 2 * pad
        oy, ox = window_offsets(tile, radius)
        ty = torch.arange(tiles_y).repeat_interleave(tiles_x)  # (T,) row-major tiles
        tx = torch.arange(tiles_x).repeat(tiles_y)
        rows = ty.view(-1, 1) * tile + oy.view(1, -1)  # (T, L) padded-map rows
        cols = tx.view(-1, 1) * tile + ox.view(1, -1)
        key_index = rows * padded_w + cols
        qy, qx = torch.meshgrid(torch.arange(tile), torch.arange(tile), indexing="ij")
        dy = oy.view(1, -1) - pad - qy.reshape(-1, 1)  # (t^2, L)
        dx = ox.view(1, -1) - pad - qx.reshape(-1, 1)
        outside = (dy * dy + dx * dx).double() > radius * radius
        off_map = ((rows < pad) | (rows >= pad + h) | (cols < pad) | (cols >= pad + w))
        excluded = outside.unsqueeze(0) | off_map.unsqueeze(1)  # (T, t^2, L)
        return cls(key, tile, pad, tiles_y, tiles_x, padded_h, padded_w,
                   key_index.to(device), excluded.to(device))

    def untile(self, values: torch.Tensor, h: int, w: int) -> torch.Tensor:
        """Tiles back to the map: ``(T, t^2, k, ...)`` -> ``(h * w, k, ...)``."""
        tile, rest = self.tile, values.shape[2:]
        tiles_hw = (self.tiles_y, self.tiles_x, tile, tile)
        order = (0, 2, 1, 3) + tuple(range(4, 4 + len(rest)))
        return values.view(*tiles_hw, *rest).permute(*order).reshape(
            self.tiles_y * tile, self.tiles_x * tile, *rest)[:h, :w].reshape(h * w, *rest)


def search_local(
    query: torch.Tensor, geo: LocalGeometry, ring_keys: torch.Tensor,
    ring_labels: torch.Tensor, slots: Sequence[int], topk: int, max_elements: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k ``(h * w, k)`` affinities and labels of every query over all recent frames' windows."""
    c, h, w = query.shape
    tile, t2 = geo.tile, geo.tile * geo.tile
    num_tiles, window = geo.key_index.shape
    slot_index = torch.tensor(list(slots), device=query.device)
    frames = len(slot_index)
    candidates = frames * window
    k = min(topk, candidates)
    num_labels = ring_labels.shape[2]
    # Queries by tile: (T, t^2, C) (zero-padded to whole tiles).
    padded = F.pad(query, (0, geo.tiles_x * tile - w, 0, geo.tiles_y * tile - h))
    q_tiles = padded.view(c, geo.tiles_y, tile, geo.tiles_x, tile).permute(
        1, 3, 2, 4, 0).reshape(num_tiles, t2, c)
    # Every tile's keys in every recent frame, as rows of the flattened ring.
    ring_size = geo.padded_h * geo.padded_w
    rows = (slot_index.view(1, -1, 1) * ring_size + geo.key_index.unsqueeze(1)).reshape(
        num_tiles, candidates)  # (T, R * L), frame-major per tile
    flat_keys = ring_keys.view(-1, c)
    flat_labels = ring_labels.view(-1, num_labels)
    per_block = max(1, max_elements // (t2 * candidates))
    out_v = torch.empty(num_tiles, t2, k, device=query.device)
    out_l = torch.empty(num_tiles, t2, k, num_labels, device=query.device)
    for start in range(0, num_tiles, per_block):
        stop = min(num_tiles, start + per_block)
        n = stop - start
        block_rows = rows[start:stop]
        with stage("gather"):
            keys = flat_keys.index_select(0, block_rows.reshape(-1)).view(n, candidates, c)
        with stage("affinity"):
            aff = torch.bmm(q_tiles[start:stop], keys.transpose(1, 2))  # (n, t^2, R * L)
            aff.view(n, t2, frames, window).masked_fill_(
                geo.excluded[start:stop].unsqueeze(2), float("-inf"))
        with stage("top-k"):
            best, index = aff.topk(k, dim=2)  # (n, t^2, k)
        with stage("labels"):
            chosen = torch.gather(block_rows.unsqueeze(1).expand(n, t2, candidates), 2, index)
            out_v[start:stop] = best
            out_l[start:stop] = flat_labels[chosen]
    return geo.untile(out_v, h, w), geo.untile(out_l, h, w)


class TiledSearch(MemorySearch):
    """The reference search: plain top-k over the first frame, gathered tiles for the rest."""

    def __init__(self, config: LabelPropagationConfig) -> None:
        super().__init__(config)
        self._geometry: LocalGeometry | None = None
        self._ring_keys: torch.Tensor | None = None  # (slots, Hp * Wp, C), zero-padded
        self._ring_labels: torch.Tensor | None = None  # (slots, Hp * Wp, K)

    def clear(self) -> None:
        """Forget the ring (a new video)."""
        self._ring_keys = self._ring_labels = None

    def geometry(self, h: int, w: int, device: torch.device) -> LocalGeometry:
        """The local search's layout for an ``h x w`` map (cached: one video, one size)."""
        cfg = self.config
        tile = max(1, min(cfg.tile_size, max(h, w)))
        key = (h, w, tile, float(cfg.radius or 0.0), str(device))
        if self._geometry is None or self._geometry.key != key:
            self._geometry = LocalGeometry.build(h, w, tile, float(cfg.radius or 0.0), device,
                                                 key)
        return self._geometry

    def write(self, slot: int, feats: torch.Tensor, labels: torch.Tensor) -> None:
        """Copy a recent frame into its ring slot, zero-padded and channels-last."""
        cfg = self.config
        if cfg.radius is None:
            return
        c, h, w = feats.shape
        geo = self.geometry(h, w, feats.device)
        if self._ring_keys is None or self._ring_labels is None:
            size = geo.padded_h * geo.padded_w
            self._ring_keys = feats.new_zeros(cfg.memory_size - 1, size, c)
            self._ring_labels = labels.new_zeros(cfg.memory_size - 1, size, labels.shape[0])
        pad = geo.pad
        keys = self._ring_keys[slot].view(geo.padded_h, geo.padded_w, c)
        keys[pad:pad + h, pad:pad + w] = feats.permute(1, 2, 0)
        lbl = self._ring_labels[slot].view(geo.padded_h, geo.padded_w, -1)
        lbl[pad:pad + h, pad:pad + w] = labels.permute(1, 2, 0)

    def search_recent(self, query: torch.Tensor, slots: Sequence[int]
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """Top-k of every query over the radius windows of the recent frames."""
        if self._ring_keys is None or self._ring_labels is None:
            raise RuntimeError("the recent memory has no ring")  # never: write() made it
        cfg = self.config
        geo = self.geometry(query.shape[1], query.shape[2], query.device)
        return search_local(query, geo, self._ring_keys, self._ring_labels, slots, cfg.topk,
                            cfg.max_affinity_elements)

    def candidates(self, query: torch.Tensor, first: tuple[torch.Tensor, torch.Tensor],
                   recent: Sequence[tuple[torch.Tensor, torch.Tensor]],
                   slots: Sequence[int]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Candidates: the first frame and the recent frames, searched apart."""
        cfg = self.config
        c, h, w = query.shape
        q = query.reshape(c, -1).t().contiguous()
        v, lab = search_dense(q, *first, h, w, cfg.first_frame_radius, cfg.topk,
                              cfg.max_affinity_elements)
        values, labels = self.recent_candidates(query, recent, slots)
        return [v, *values], [lab, *labels]


@dataclass(frozen=True)
class WindowLayout:
    """The window ring's layout for one map size (``key``: what it was built for).

    ``R`` rows of ``g`` keys per tile (padded with dummy keys); ``key_index`` gives their flat
    positions in the zero-padded frame (the last, always zero, serves dummies),
    ``key_position`` in the ``h x w`` map; ``bias`` (the affinities' dtype: a bfloat16 sum
    with a float32 bias is ~50x slower) is ``-inf`` for keys beyond a query's radius, off the
    map or dummy, else 0.
    """

    key: tuple[object, ...]
    tile: int
    pad: int
    tiles_y: int
    tiles_x: int
    rows: int
    width: int
    key_index: torch.Tensor
    key_position: torch.Tensor
    bias: torch.Tensor

    @classmethod
    def build(cls, h: int, w: int, tile: int, radius: float, slots: int, topk: int,
              device: torch.device, dtype: torch.dtype, key: tuple[object, ...]
              ) -> WindowLayout:
        """Lay out the windows of an ``h x w`` map for ``slots`` recent frames."""
        pad = int(math.floor(radius))
        tiles_y, tiles_x = math.ceil(h / tile), math.ceil(w / tile)
        padded_w = tiles_x * tile + 2 * pad
        dummy = (tiles_y * tile + 2 * pad) * padded_w
        oy, ox = window_offsets(tile, radius)
        # R x g layout: R near sqrt(slots L / k) balances the two top-k passes.
        rows = max(1, min(len(oy), round(math.sqrt(slots * len(oy) / topk))))
        width = math.ceil(len(oy) / rows)
        real = torch.arange(rows * width) < len(oy)
        oy = F.pad(oy, (0, rows * width - len(oy)))
        ox = F.pad(ox, (0, rows * width - len(ox)))
        ty = torch.arange(tiles_y).repeat_interleave(tiles_x).view(-1, 1)  # row-major tiles
        tx = torch.arange(tiles_x).repeat(tiles_y).view(-1, 1)
        map_y, map_x = ty * tile + oy - pad, tx * tile + ox - pad  # (T, R g)
        on_map = (map_y >= 0) & (map_y < h) & (map_x >= 0) & (map_x < w) & real
        key_index = torch.where(real, (map_y + pad) * padded_w + map_x + pad, dummy)
        key_position = torch.where(on_map, map_y * w + map_x, 0)
        qy, qx = torch.meshgrid(torch.arange(tile), torch.arange(tile), indexing="ij")
        dy = oy.view(1, -1) - pad - qy.reshape(-1, 1)  # (t^2, R g)
        dx = ox.view(1, -1) - pad - qx.reshape(-1, 1)
        outside = (dy * dy + dx * dx).double() > radius * radius
        excluded = (outside.unsqueeze(0) | ~on_map.unsqueeze(1)).view(
            len(on_map), tile * tile, rows, 1, width)
        bias = torch.zeros(excluded.shape).masked_fill_(excluded, float("-inf"))
        return cls(key, tile, pad, tiles_y, tiles_x, rows, width, key_index.to(device),
                   key_position.to(device), bias.to(device, dtype))

    @property
    def num_tiles(self) -> int:
        """``T``: tiles of the map."""
        return self.tiles_y * self.tiles_x

    def windows(self, feats: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
        """im2col: one frame's ``(C, h, w)`` -> ``(T, R, g, C)`` tile keys (a view of ``out``)."""
        c, h, w = feats.shape
        t, pad = self.tile, self.pad
        padded = feats.new_zeros((self.tiles_y * t + 2 * pad) * (self.tiles_x * t + 2 * pad)
                                 + 1, c)
        padded[:-1].view(self.tiles_y * t + 2 * pad, -1, c)[pad:pad + h, pad:pad + w] = (
            feats.permute(1, 2, 0))
        torch.index_select(padded, 0, self.key_index.view(-1), out=out)
        return out.view(self.num_tiles, self.rows, self.width, c)

    def tiles(self, query: torch.Tensor) -> torch.Tensor:
        """``(C, h, w)`` -> ``(T, t^2, C)`` queries by tile (zero-padded to whole tiles)."""
        c, h, w = query.shape
        t = self.tile
        padded = F.pad(query, (0, self.tiles_x * t - w, 0, self.tiles_y * t - h))
        return padded.view(c, self.tiles_y, t, self.tiles_x, t).permute(1, 3, 2, 4, 0).reshape(
            self.num_tiles, t * t, c)

    def untile(self, values: torch.Tensor, h: int, w: int) -> torch.Tensor:
        """Tiles back to the map: ``(T, t^2, k)`` -> ``(h * w, k)``."""
        t, k = self.tile, values.shape[2]
        return values.view(self.tiles_y, self.tiles_x, t, t, k).permute(0, 2, 1, 3, 4).reshape(
            self.tiles_y * t, self.tiles_x * t, k)[:h, :w].reshape(h * w, k)


def grouped_topk(aff: torch.Tensor, rows: int, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Exact top-k of each row of ``aff`` ``(N, R * G)`` seen as ``G`` strided groups of ``R``.

    The top-k lies in the ``k`` groups of largest maximum. Returns the sorted values and their
    columns in ``aff``.
    """
    n, groups = aff.shape[0], aff.shape[1] // rows
    grid = aff.view(n, rows, groups)
    kg = min(k, groups)
    group = grid.amax(1).topk(kg, dim=1).indices  # (N, k_g)
    picked = torch.gather(grid, 2, group.unsqueeze(1).expand(n, rows, kg))  # (N, R, k_g)
    best, pick = picked.view(n, -1).topk(min(k, rows * kg), dim=1)
    return best, (pick // kg) * groups + group.gather(1, pick % kg)


def search_windows(query: torch.Tensor, layout: WindowLayout, ring: torch.Tensor,
                   ring_labels: torch.Tensor, used: int, topk: int, max_elements: int,
                   workspace: Workspace | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k ``(h * w, k)`` affinities and labels of every query over the ring's ``used`` slots."""
    c, h, w = query.shape
    workspace = workspace if workspace is not None else Workspace()
    num_tiles, rows, slots, width = ring.shape[:4]
    t2 = layout.tile * layout.tile
    candidates = rows * slots * width
    k = min(topk, candidates)
    q_tiles = layout.tiles(query)
    out_v = torch.empty(num_tiles, t2, k, device=query.device)
    out_i = torch.empty(num_tiles, t2, k, dtype=torch.long, device=query.device)
    per_block = min(num_tiles, max(1, max_elements // (t2 * candidates)))
    buffer = workspace.get("windows", (per_block, t2, candidates), ring.dtype, ring.device)
    for start in range(0, num_tiles, per_block):
        stop = min(num_tiles, start + per_block)
        n = stop - start
        with stage("affinity"):
            keys = ring[start:stop].view(n, candidates, c)
            aff = torch.bmm(q_tiles[start:stop], keys.transpose(1, 2), out=buffer[:n])
            grid = aff.view(n, t2, rows, slots, width)
            grid += layout.bias[start:stop]  # -inf: beyond the radius, off the map, dummy
            if used < slots:
                grid[:, :, :, used:] = float("-inf")
        with stage("top-k"):
            best, column = grouped_topk(aff.view(n * t2, candidates), rows, k)
        with stage("labels"):
            # Column (row, slot, lane) -> the tile's key (row, lane) -> its map position.
            row, group = column // (slots * width), column % (slots * width)
            key = (row * width + group % width).view(n, t2 * k)
            position = layout.key_position[start:stop].gather(1, key).view(n, t2, k)
            out_v[start:stop] = best.view(n, t2, k)
            out_i[start:stop] = (group // width).view(n, t2, k) * (h * w) + position
    with stage("labels"):
        index = layout.untile(out_i, h, w)
        return layout.untile(out_v, h, w), ring_labels.view(-1, ring_labels.shape[2])[index]


class WindowSearch(MemorySearch):
    """The default search: im2col window ring, grouped top-k, first frame above a floor."""

    def __init__(self, config: LabelPropagationConfig) -> None:
        super().__init__(config)
        self._layout: WindowLayout | None = None
        self._ring: torch.Tensor | None = None  # (T, R, slots, g, C)
        self._ring_labels: torch.Tensor | None = None  # (slots, h * w, K)
        self.workspace = Workspace()

    def clear(self) -> None:
        """Forget the ring (a new video)."""
        self._ring = self._ring_labels = None

    def layout(self, h: int, w: int, device: torch.device, dtype: torch.dtype) -> WindowLayout:
        """The window layout for an ``h x w`` map (cached: one video, one size)."""
        cfg = self.config
        tile = max(1, min(cfg.tile_size, max(h, w)))
        radius, slots = float(cfg.radius or 0.0), cfg.memory_size - 1
        key = (h, w, tile, radius, slots, cfg.topk, str(device), dtype)
        if self._layout is None or self._layout.key != key:
            self._layout = WindowLayout.build(h, w, tile, radius, slots, cfg.topk, device,
                                              dtype, key)
        return self._layout

    def write(self, slot: int, feats: torch.Tensor, labels: torch.Tensor) -> None:
        """Cut a recent frame's windows into its ring slot (once per frame)."""
        cfg = self.config
        if cfg.radius is None:
            return
        c, h, w = feats.shape
        with stage("memory"):
            layout = self.layout(h, w, feats.device, feats.dtype)
            if self._ring is None or self._ring_labels is None:
                slots = cfg.memory_size - 1
                self._ring = feats.new_zeros(layout.num_tiles, layout.rows, slots,
                                             layout.width, c)
                self._ring_labels = labels.new_zeros(slots, h * w, labels.shape[0])
            scratch = self.workspace.get("im2col", (layout.key_index.numel(), c),
                                         feats.dtype, feats.device)
            self._ring[:, :, slot] = layout.windows(feats, scratch)
            self._ring_labels[slot] = labels.reshape(labels.shape[0], -1).t()

    def search_recent(self, query: torch.Tensor, slots: Sequence[int]
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """Top-k of every query over the radius windows of the recent frames."""
        if self._ring is None or self._ring_labels is None:
            raise RuntimeError("the recent memory has no ring")  # never: write() made it
        cfg = self.config
        layout = self.layout(query.shape[1], query.shape[2], query.device, query.dtype)
        return search_windows(query, layout, self._ring, self._ring_labels, len(slots),
                              cfg.topk, cfg.max_affinity_elements, self.workspace)

    def candidates(self, query: torch.Tensor, first: tuple[torch.Tensor, torch.Tensor],
                   recent: Sequence[tuple[torch.Tensor, torch.Tensor]],
                   slots: Sequence[int]) -> tuple[list[torch.Tensor], list[torch.Tensor]]:
        """Candidates: recent windows first, then the first frame above their floor."""
        cfg = self.config
        c, h, w = query.shape
        q = query.reshape(c, -1).t().contiguous()
        values, labels = self.recent_candidates(query, recent, slots)
        if values:
            with stage("top-k"):
                floor = kth_best(values, cfg.topk)
            v, lab = search_above(q, *first, h, w, cfg.first_frame_radius, floor, cfg.topk,
                                  cfg.max_affinity_elements, self.workspace)
        else:  # the first frame alone: nothing to set a floor
            v, lab = search_dense(q, *first, h, w, cfg.first_frame_radius, cfg.topk,
                                  cfg.max_affinity_elements)
        return [v, *values], [lab, *labels]


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
    (:class:`TiledSearch`): same results, slower.
    ``"bf16"`` precision: the same searches see bfloat16 features, ``CANDIDATE_FACTOR *
    topk`` and, as labels, each location's row in a float32 memory bank, from which
    :func:`rescore` scores the candidates
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
