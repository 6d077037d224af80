"""The k-NN searches of label propagation: dense over a frame, local over a padded ring.

Both return, per query location, the ``k`` largest affinities and the labels of those
memory locations; :func:`merge_topk` merges the candidate groups exactly (the top-k of a
union is the top-k of the union of each group's top-k). The layout of the local search (tiles,
their radius windows and the exclusion mask) is :class:`LocalGeometry`. Described in
:mod:`unitrack_env.agents.primitives.label_propagation`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F


def grid_positions(h: int, w: int, device: torch.device) -> torch.Tensor:
    """``(h*w, 2)`` float (row, column) of every location, row-major."""
    rows, cols = torch.meshgrid(
        torch.arange(h, device=device, dtype=torch.float32),
        torch.arange(w, device=device, dtype=torch.float32), indexing="ij",
    )
    return torch.stack([rows.reshape(-1), cols.reshape(-1)], dim=1)


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
    value = torch.cat(values, dim=1)
    label = torch.cat(labels, dim=1)
    k = min(topk, value.shape[1])
    best, index = value.topk(k, dim=1)
    kept = torch.gather(label, 1, index.unsqueeze(-1).expand(-1, -1, label.shape[2]))
    weights = torch.softmax(best / temperature, dim=1)  # -inf entries get weight 0
    return torch.einsum("qk,qkc->qc", weights, kept)



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
    flat_labels = lbl.reshape(lbl.shape[0], -1).t()  # (S, K)
    k = min(topk, size)
    chunk = max(1, max_elements // size)
    grid = grid_positions(h, w, q.device) if radius is not None else None
    out_v = torch.empty(q.shape[0], k, device=q.device)
    out_i = torch.empty(q.shape[0], k, dtype=torch.long, device=q.device)
    aff = torch.empty(min(chunk, q.shape[0]), size, dtype=q.dtype, device=q.device)
    for start in range(0, q.shape[0], chunk):
        stop = min(q.shape[0], start + chunk)
        block_aff = aff[:stop - start]
        torch.mm(q[start:stop], keys, out=block_aff)
        if grid is not None:
            block_aff.masked_fill_(torch.cdist(grid[start:stop], grid) > radius,
                                   float("-inf"))
        best, index = block_aff.topk(k, dim=1)
        out_v[start:stop] = best
        out_i[start:stop] = index
    return out_v, flat_labels[out_i]


def search_local(
    query: torch.Tensor, geo: LocalGeometry, ring_keys: torch.Tensor,
    ring_labels: torch.Tensor, slots: Sequence[int], topk: int, max_elements: int,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Top-k of every query over the radius windows of all recent frames.

    Args:
        query: ``(C, h, w)`` query features.
        geo: The local search's layout for this map size.
        ring_keys: ``(slots, Hp * Wp, C)`` zero-padded memory features.
        ring_labels: ``(slots, Hp * Wp, K)`` zero-padded memory labels.
        slots: Ring slots in use, oldest first.
        topk: Kept affinities per query.
        max_elements: Most affinities held at once.

    Returns:
        ``(h * w, k)`` affinities and ``(h * w, k, K)`` labels.
    """
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
        keys = flat_keys.index_select(0, block_rows.reshape(-1)).view(n, candidates, c)
        aff = torch.bmm(q_tiles[start:stop], keys.transpose(1, 2))  # (n, t^2, R * L)
        aff.view(n, t2, frames, window).masked_fill_(
            geo.excluded[start:stop].unsqueeze(2), float("-inf"))
        best, index = aff.topk(k, dim=2)  # (n, t^2, k)
        chosen = torch.gather(block_rows.unsqueeze(1).expand(n, t2, candidates), 2, index)
        out_v[start:stop] = best
        out_l[start:stop] = flat_labels[chosen]
    return geo.untile(out_v, h, w), geo.untile(out_l, h, w)


@dataclass(frozen=True)
class LocalGeometry:
    """Layout of the local search for one map size (see the module docstring).

    Attributes:
        key: What it was built for ``(h, w, tile, radius, device)``.
        tile: Tile side.
        pad: Zero padding of the ring's maps (``floor(radius)``) on every side.
        tiles_y: Tile rows.
        tiles_x: Tile columns.
        padded_h: Rows of a padded ring map (``tiles_y * tile + 2 pad``).
        padded_w: Columns of a padded ring map.
        key_index: ``(T, L)`` long: per tile, the flat positions (in a padded map) of the keys
            within the radius of at least one of its queries.
        excluded: ``(T, t^2, L)`` bool: key out of the query's radius or off the map.
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
