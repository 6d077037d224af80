"""The k-NN searches of label propagation: over a whole frame, and above a floor.

Each search returns, per query location, its best affinities and the labels of those memory
locations; :func:`merge_topk` merges the candidate groups exactly (the top-k of a union is
the top-k of the union of each group's top-k) and weighs the kept labels. How a
:class:`~unitrack_env.agents.primitives.label_propagation.LabelPropagator` lays out and
searches its memory is a :class:`MemorySearch`: the default
:class:`~unitrack_env.agents.primitives.label_windows.WindowSearch` or the reference
:class:`~unitrack_env.agents.primitives.label_search_tiled.TiledSearch`. Stages are marked
with :func:`stage` for ``torch.profiler`` (``benchmarks/propagation.py`` reports them).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING

import torch

if TYPE_CHECKING:
    from unitrack_env.agents.primitives.label_propagation import LabelPropagationConfig

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
    """Scratch tensors reused from step to step.

    A fresh tensor of tens of MiB costs page faults on every step (measured here: 31 ms to
    gather the windows of a 480p frame into a new tensor, 4 ms into a reused one).
    """

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
    """Top-k over candidate groups, softmax over the kept ones, weighted labels.

    Args:
        values: Per group ``(Q, k_g)`` affinities (``-inf`` = not a candidate).
        labels: Per group ``(Q, k_g, K)`` labels of those candidates.
        topk: Candidates kept over all groups.
        temperature: Softmax temperature.

    Returns:
        ``(Q, K)`` propagated labels.
    """
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


def kth_best(values: list[torch.Tensor], k: int) -> torch.Tensor:
    """``(Q,)`` the ``k``-th largest of the candidate groups per query (``-inf``: fewer).

    Each group is sorted, largest first (as ``torch.topk`` returns it).
    """
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
    """Top-k of every query over one whole memory frame, by blocks of queries.

    Args:
        q: ``(Q, C)`` query features.
        feats: ``(C, h, w)`` memory features.
        lbl: ``(K, h, w)`` memory labels.
        h: Map rows.
        w: Map columns.
        radius: Euclidean radius a query may attend to (None: all).
        topk: Kept affinities per query.
        max_elements: Most affinities held at once.

    Returns:
        ``(Q, k)`` affinities and ``(Q, k, K)`` labels.
    """
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

GROUP_CAP: int = 8
"""Groups a query may reach the floor in before it falls back to a plain top-k of its row
(measured on DAVIS blackswan / dog at 480p: 7% / 15% of the queries reach it in more than 8
of the 321 groups, 14% / 23% in more than 4)."""


def search_above(
    q: torch.Tensor, feats: torch.Tensor, lbl: torch.Tensor, h: int, w: int,
    radius: float | None, floor: torch.Tensor, topk: int, max_elements: int,
    workspace: Workspace | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k of every query over one memory frame, where it can reach ``floor``.

    Exact for the merged top-k when ``floor`` is, per query, the ``topk``-th best affinity
    of other candidates: nothing below it can enter the merged top-k, so only the keys at or
    above the floor need to be found. The ``S`` keys form ``ceil(S / 20)`` strided groups of
    20 (key ``j`` in group ``j mod ceil(S / 20)``); one strided max per block of queries gives
    every group's best affinity; only the (typically one or two) groups whose best reaches
    the floor are read again, instead of a top-k over every key. A query reaching the floor
    in more than :data:`GROUP_CAP` groups, or with an infinite floor, gets a plain top-k of
    its row.

    Args:
        q: ``(Q, C)`` query features.
        feats: ``(C, h, w)`` memory features.
        lbl: ``(K, h, w)`` memory labels.
        h: Map rows.
        w: Map columns.
        radius: Euclidean radius a query may attend to (None: all).
        floor: ``(Q,)`` float32: least affinity worth finding per query (``-inf``: all).
        topk: Kept affinities per query.
        max_elements: Most affinities held at once.
        workspace: Where to keep the affinity buffer between calls (None: a new one).

    Returns:
        ``(Q, k)`` affinities (``-inf`` or below the floor: not needed) and ``(Q, k, K)``
        labels.
    """
    size = h * w
    keys = feats.reshape(feats.shape[0], -1)
    lanes = math.ceil(size / GROUP_SIZE)
    k = min(topk, size)
    chunk = max(1, max_elements // (lanes * GROUP_SIZE))
    grid = grid_positions(h, w, q.device) if radius is not None else None
    out_v = torch.empty(q.shape[0], k, device=q.device)
    out_i = torch.empty(q.shape[0], k, dtype=torch.long, device=q.device)
    shape = (min(chunk, q.shape[0]), lanes * GROUP_SIZE)
    aff = (workspace.get("first frame", shape, q.dtype, q.device) if workspace is not None
           else torch.empty(shape, dtype=q.dtype, device=q.device))
    aff[:, size:] = float("-inf")  # the tail past S (if any) stays -inf
    for start in range(0, q.shape[0], chunk):
        stop = min(q.shape[0], start + chunk)
        block = aff[:stop - start]
        _affinity_block(q[start:stop], keys, block[:, :size], grid, slice(start, stop), radius)
        with stage("top-k"):
            best, index = _select_above(block, lanes, floor[start:stop], k)
            out_v[start:stop] = best
            out_i[start:stop] = index
    with stage("labels"):
        return out_v, lbl.reshape(lbl.shape[0], -1).t()[out_i.clamp_(max=size - 1)]


def _select_above(block: torch.Tensor, lanes: int, floor: torch.Tensor,
                  k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k of each row of ``block`` among its groups reaching ``floor`` (or of all)."""
    n = block.shape[0]
    cap = min(lanes, max(GROUP_CAP, math.ceil(k / GROUP_SIZE)))
    grid = block.view(n, GROUP_SIZE, lanes)
    best_groups, group = grid.amax(1).topk(min(lanes, cap + 1), dim=1)
    group = group[:, :cap]
    picked = torch.gather(grid, 2, group.unsqueeze(1).expand(n, GROUP_SIZE, cap))
    best, pick = picked.view(n, -1).topk(k, dim=1)  # (n, 20 cap): member, group
    best, index = best.float(), (pick // cap) * lanes + group.gather(1, pick % cap)
    # The cap best groups hold every key at or above the floor unless one more group does.
    heavy = ~torch.isfinite(floor)
    if cap < lanes:
        heavy |= best_groups[:, cap] >= floor
    rows = heavy.nonzero().squeeze(1)
    if len(rows):  # the floor is reached in too many groups: a plain top-k of the row
        top_v, top_i = block[rows].topk(k, dim=1)
        best[rows] = top_v.float()
        index[rows] = top_i
    return best, index


class MemorySearch(ABC):
    """How a label propagator lays out its recent memory and finds each query's top-k.

    The propagator keeps the bookkeeping (the first frame, the recent frames and their
    ring slots); a search keeps its own copy of the recent frames in the layout it
    searches, written once per frame by :meth:`write`.

    Args:
        config: The propagator's hyper-parameters.
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
    def propagate(self, query: torch.Tensor, first: tuple[torch.Tensor, torch.Tensor],
                  recent: Sequence[tuple[torch.Tensor, torch.Tensor]],
                  slots: Sequence[int]) -> torch.Tensor:
        """``(h * w, K)`` labels of ``query`` ``(C, h, w)`` from the whole memory.

        Args:
            query: Prepared (normalised) query features.
            first: The first frame's features and labels.
            recent: The recent frames' features and labels, oldest first.
            slots: Their ring slots, oldest first.
        """
