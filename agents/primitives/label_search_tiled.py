"""The reference label-propagation search: keys gathered at every step.

The formulation the window ring (:mod:`~unitrack_env.agents.primitives.label_windows`)
replaced, kept as ``LabelPropagator(reference=True)`` for ``benchmarks/propagation.py`` and
the equality tests: a dense top-k over the first frame; for the recent frames, each tile's
radius keys gathered from a zero-padded ring with one ``index_select`` per step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import torch
import torch.nn.functional as F

from .label_search import (
    MemorySearch,
    search_dense,
    stage,
)

if TYPE_CHECKING:
    from .label_propagation import LabelPropagationConfig


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
        win = tile + 2 * pad
        # Window positions (relative to the tile's top-left query, minus pad) within the
        # radius of the nearest query of the tile: the tile square grown by the radius.
        oy, ox = torch.meshgrid(torch.arange(win), torch.arange(win), indexing="ij")
        oy, ox = oy.reshape(-1), ox.reshape(-1)
        gap_y = torch.clamp(torch.maximum(pad - oy, oy - (pad + tile - 1)), min=0)
        gap_x = torch.clamp(torch.maximum(pad - ox, ox - (pad + tile - 1)), min=0)
        keep = (gap_y * gap_y + gap_x * gap_x).double() <= radius * radius
        oy, ox = oy[keep], ox[keep]  # (L,)
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
