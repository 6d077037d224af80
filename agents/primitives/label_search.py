"""The k-NN searches of label propagation: over a whole frame, and above a floor.

:func:`merge_topk` merges candidate groups exactly (the top-k of a union is the top-k of
each group's top-k). A :class:`MemorySearch` lays out and searches a propagator's memory.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F

if TYPE_CHECKING:
    from .label_propagation import LabelPropagationConfig

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
