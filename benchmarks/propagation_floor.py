"""How fast can exact label propagation be on this CPU? The float32 floor and two pruning bounds.

Usage (from the repository root)::

    PYTHONPATH=. python benchmarks/propagation_floor.py --threads 2

On the real DAVIS frames at 854x480 (default model, features 112 x 60 x 107; M = 6: the
first frame without radius, 5 recent frames within radius 12; top-10) it prints:

* **floor**: the affinities every exact formulation computes (a query's inner products with
  the whole first frame and with the recent keys within its radius), in GFLOP, and the
  milliseconds they take at the float32 matrix-product rate measured here (one
  ``6420 x 112 x 6420`` product, best of 5). No exact float32 search of this memory is faster.
* **cluster bound**: can the first frame's keys be skipped without computing them? Keys are
  grouped by spherical k-means; a group whose keys all lie within angle ``theta`` of its
  centre direction holds no key above ``cos(max(0, phi - theta))`` for a query at angle
  ``phi`` from that direction, so groups whose bound is below the query's floor (its 10th
  best recent affinity, which the search already uses) could be skipped. Printed: the
  share of (query, group) pairs that cannot be skipped.
* **projection bound**: affinities split into the first ``d`` principal directions of the
  first frame's keys and the rest, ``q.k <= q_d.k_d + |q_r| |k_r|``. Printed: the share of
  (query, key) pairs above the floor (the true candidates), the share the bound cannot
  rule out, and the share of ``64 x 64`` blocks (queries in 8 x 8 tiles, keys ordered by
  k-means group) that hold at least one such pair: a block product can skip only the
  blocks without any.

Measured on 2 AVX-512 cores (stop 21 of issue 13): the cluster bound rules out almost
nothing (features of a location are spread too widely) and the projection bound leaves
candidates in most blocks, so neither makes an exact search cheaper than the floor.
"""

from __future__ import annotations

import argparse
import math
import time

import torch
from propagation import davis_features  # a sibling file (the script's folder)

from unitrack_env.agents.appearance import AppearanceModel
from unitrack_env.agents.primitives.label_propagation import (
    LabelPropagationConfig,
    WindowSearch,
    kth_best,
    normalize_features,
)


def floors(feats: list[torch.Tensor], config: LabelPropagationConfig
           ) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Per frame once the memory is full: ``(h w, C)`` queries and their floors ``(h w,)``."""
    search = WindowSearch(config)
    slots = config.memory_size - 1
    out = []
    for t, frame in enumerate(feats):
        query = normalize_features(frame)
        if t > slots:
            recent = [(t - 1 - i) % slots for i in range(slots)][::-1]
            values, _ = search.search_recent(query, recent)
            q = query.reshape(query.shape[0], -1).t().contiguous()
            out.append((q, kth_best([values], config.topk)))
        search.write(t % slots, query, torch.zeros(1, *query.shape[1:]))
    return out


def spherical_kmeans(x: torch.Tensor, groups: int, iters: int = 15) -> tuple[torch.Tensor,
                                                                             torch.Tensor]:
    """Unit centre directions ``(G, C)`` and each row's group ``(N,)`` (seeded, repeatable)."""
    gen = torch.Generator().manual_seed(0)
    centres = x[torch.randperm(len(x), generator=gen)[:groups]].clone()
    for _ in range(iters):
        member = (x @ centres.t()).argmax(1)
        sums = torch.zeros_like(centres).index_add_(0, member, x)
        empty = sums.norm(dim=1) == 0
        centres = torch.where(empty[:, None], centres, torch.nn.functional.normalize(sums, dim=1))
    return centres, (x @ centres.t()).argmax(1)


def gemm_rate(size: int, channels: int) -> float:
    """GFLOP/s of one ``size x channels x size`` float32 product (best of 5)."""
    a, b = torch.randn(size, channels), torch.randn(channels, size)
    out = torch.empty(size, size)
    best = math.inf
    for _ in range(6):
        start = time.perf_counter()
        torch.mm(a, b, out=out)
        best = min(best, time.perf_counter() - start)
    return 2 * size * channels * size / best / 1e9


def cluster_bound(keys: torch.Tensor, steps: list[tuple[torch.Tensor, torch.Tensor]],
                  groups: int) -> float:
    """Share of (query, group) pairs whose cone bound reaches the query's floor."""
    centres, member = spherical_kmeans(keys, groups)
    angle = torch.acos((keys * centres[member]).sum(1).clamp(-1, 1))
    theta = torch.zeros(groups).scatter_reduce_(0, member, angle, "amax")
    kept = [((torch.cos((torch.acos((q @ centres.t()).clamp(-1, 1)) - theta).clamp(min=0))
              >= floor[:, None]).float().mean().item()) for q, floor in steps]
    return sum(kept) / len(kept)


def projection_bound(keys: torch.Tensor, steps: list[tuple[torch.Tensor, torch.Tensor]],
                     dims: int, h: int, w: int) -> tuple[float, float, float]:
    """Shares of true candidates, of pairs the bound keeps, and of 64 x 64 blocks with one."""
    basis = torch.linalg.svd(keys, full_matrices=False).Vh
    _, member = spherical_kmeans(keys, 100)
    keys = keys[torch.argsort(member)]
    head, tail = basis[:dims], basis[dims:]
    k_head, k_tail = keys @ head.t(), (keys @ tail.t()).norm(dim=1)
    rows, cols = torch.meshgrid(torch.arange(h), torch.arange(w), indexing="ij")
    tiles = torch.argsort(((rows // 8) * math.ceil(w / 8) + cols // 8).reshape(-1), stable=True)
    true, kept, blocks = [], [], []
    for q, floor in steps:
        q, floor = q[tiles], floor[tiles]
        bound = (q @ head.t()) @ k_head.t() + (q @ tail.t()).norm(dim=1)[:, None] * k_tail
        keep = bound >= floor[:, None]
        true.append(((q @ keys.t()) >= floor[:, None]).float().mean().item())
        kept.append(keep.float().mean().item())
        nq, nk = len(q) // 64 * 64, len(keys) // 64 * 64
        blocks.append(keep[:nq, :nk].reshape(nq // 64, 64, nk // 64, 64).any(3).any(1)
                      .float().mean().item())
    return tuple(sum(v) / len(v) for v in (true, kept, blocks))  # type: ignore[return-value]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--sequences", default="blackswan,dog")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    config = LabelPropagationConfig()
    model = AppearanceModel(runtime="auto")
    for sequence in args.sequences.split(","):
        feats, _ = davis_features(model, sequence, args.frames)
        c, h, w = feats[0].shape
        steps = floors(feats, config)
        keys = normalize_features(feats[0]).reshape(c, -1).t().contiguous()
        radius = config.radius or 0.0
        near = sum(1 for y in range(-int(radius), int(radius) + 1)
                   for x in range(-int(radius), int(radius) + 1) if x * x + y * y <= radius ** 2)
        gflop = 2 * c * h * w * (h * w + (config.memory_size - 1) * near) / 1e9
        rate = gemm_rate(h * w, c)
        print(f"\n== DAVIS {sequence}: features {c} x {h} x {w}, M = {config.memory_size}, "
              f"radius {radius:g}, top-{config.topk}; {len(steps)} steps ==")
        print(f"floor: {gflop:.2f} GFLOP per step (first frame {2 * c * (h * w) ** 2 / 1e9:.2f}"
              f"); float32 product {rate:.0f} GFLOP/s here -> {gflop / rate * 1e3:.0f} ms")
        for groups in (64, 321, 642):
            print(f"cluster bound, {groups} groups: {cluster_bound(keys, steps, groups):.1%} "
                  f"of (query, group) pairs cannot be skipped")
        for dims in (32, 48, 64):
            true, kept, blocks = projection_bound(keys, steps, dims, h, w)
            print(f"projection bound, d = {dims}: candidates {true:.3%} of pairs, bound keeps "
                  f"{kept:.2%}, 64 x 64 blocks with a kept pair {blocks:.1%}")


if __name__ == "__main__":
    main()
