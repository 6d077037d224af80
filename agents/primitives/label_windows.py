"""The default label-propagation search: a ring of im2col windows, grouped top-k, a floor.

The query grid is cut into ``t x t`` tiles; a tile's keys are the locations within the
radius of any of its queries. When a frame enters the memory, every tile's keys are copied
out once (im2col) into the ring ``(T, R, slots, g, C)``, so a tile's keys in all recent
frames form one contiguous matrix: no gather at search time. More in docs/module-notes.md.
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
    Workspace,
    kth_best,
    search_above,
    search_dense,
    stage,
)

if TYPE_CHECKING:
    from .label_propagation import LabelPropagationConfig


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
        win = tile + 2 * pad
        oy, ox = torch.meshgrid(torch.arange(win), torch.arange(win), indexing="ij")
        oy, ox = oy.reshape(-1), ox.reshape(-1)
        gap_y = torch.clamp(torch.maximum(pad - oy, oy - (pad + tile - 1)), min=0)
        gap_x = torch.clamp(torch.maximum(pad - ox, ox - (pad + tile - 1)), min=0)
        keep = (gap_y * gap_y + gap_x * gap_x).double() <= radius * radius
        oy, ox = oy[keep], ox[keep]  # (L,) offsets from the tile's corner, plus pad
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
