"""Label propagation (level 2): the window search and the reference (tiled, gathered) search
against the dense definition and each other, their top-k pieces, and known answers for the
radius, the first frame, the memory bank and the soft labels."""

from __future__ import annotations

import pytest
import torch

from unitrack_env.agents.appearance.model import torch_threads
from unitrack_env.agents.primitives import label_propagation
from unitrack_env.agents.primitives.label_propagation import (
    NATIVE_BF16_FLAGS,
    LabelPropagationConfig,
    LabelPropagator,
    cpu_flags,
    grouped_topk,
    merge_topk,
    normalize_features,
    propagate_dense,
    search_above,
    search_dense,
)


def random_video(frames: int, c: int = 8, h: int = 13, w: int = 21, k: int = 3, seed: int = 0):
    gen = torch.Generator().manual_seed(seed)
    feats = [normalize_features(torch.randn(c, h, w, generator=gen)) for _ in range(frames)]
    labels = [torch.rand(k, h, w, generator=gen) for _ in range(frames)]
    return feats, labels


@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize("tile", [1, 5, 16, 64])
@pytest.mark.parametrize("radius", [0.0, 2.5, 12.0])
def test_searches_equal_the_dense_definition(tile, radius, reference):
    feats, labels = random_video(7)
    prop = LabelPropagator(LabelPropagationConfig(tile_size=tile, radius=radius,
                                                  max_affinity_elements=3000),
                           reference=reference)
    prop.reset(feats[0], labels[0])
    for t in range(1, 6):
        prop.push(feats[t], labels[t])
    assert prop.memory_length == 6
    ref = propagate_dense(feats[6], feats[:6], labels[:6], [None] + [radius] * 5)
    torch.testing.assert_close(prop.propagate(feats[6]), ref, atol=1e-5, rtol=0)


def test_first_frame_radius_and_no_radius_options():
    feats, labels = random_video(4, seed=1)
    prop = LabelPropagator(LabelPropagationConfig(radius=None, first_frame_radius=3.0))
    prop.reset(feats[0], labels[0])
    prop.push(feats[1], labels[1])
    prop.push(feats[2], labels[2])
    ref = propagate_dense(feats[3], feats[:3], labels[:3], [3.0, None, None])
    torch.testing.assert_close(prop.propagate(feats[3]), ref, atol=1e-5, rtol=0)


def one_hot_features(h: int, w: int, codes: dict[tuple[int, int], int], default: int,
                     c: int = 4) -> torch.Tensor:
    feats = torch.zeros(c, h, w)
    feats[default] = 1.0
    for (y, x), code in codes.items():
        feats[:, y, x] = 0.0
        feats[code, y, x] = 1.0
    return feats


def test_radius_limits_recent_frames_but_not_the_first():
    h, w = 3, 20
    query = one_hot_features(h, w, {}, default=0)  # every query looks like code 0
    background = torch.zeros(2, h, w)
    background[0] = 1.0
    # Recent frame: the only code-0 location is (1, 15), labelled object.
    recent = one_hot_features(h, w, {(1, 15): 0}, default=1)
    recent_labels = background.clone()
    recent_labels[:, 1, 15] = torch.tensor([0.0, 1.0])
    cfg = LabelPropagationConfig(topk=1, radius=12.0, memory_size=2)
    # First frame: nothing alike (code 2) -> background everywhere.
    prop = LabelPropagator(cfg)
    prop.reset(one_hot_features(h, w, {}, default=2), background)
    prop.push(recent, recent_labels)
    out = prop.propagate(query)
    assert out[1, 1, 10] == 1.0  # 5 px from the match: found
    assert out[1, 1, 0] == 0.0  # 15 px away: beyond the radius, background
    # The first frame has no radius: a far match there is found.
    first = one_hot_features(h, w, {(1, 19): 0}, default=2)
    first_labels = background.clone()
    first_labels[:, 1, 19] = torch.tensor([0.0, 1.0])
    prop.reset(first, first_labels)
    prop.push(recent, recent_labels)
    assert prop.propagate(query)[1, 1, 0] == 1.0


def test_translation_is_followed_exactly():
    gen = torch.Generator().manual_seed(3)
    big = normalize_features(torch.randn(16, 24, 30, generator=gen))
    first, moved = big[:, 2:22, 2:28], big[:, 4:24, 0:26]  # content shifts by (-2, +2)
    labels = torch.zeros(1, 20, 26)
    labels[0, 8:12, 10:14] = 1.0
    prop = LabelPropagator(LabelPropagationConfig(topk=1))
    prop.reset(first, labels)
    out = prop.step(moved)
    expected = torch.zeros(1, 20, 26)
    expected[0, 6:10, 12:16] = 1.0
    # Where the moved frame shows content of the first one, the labels move with it.
    torch.testing.assert_close(out[:, :18, 2:], expected[:, :18, 2:])
    assert prop.memory_length == 2


def test_memory_bank_keeps_the_first_and_latest_frames():
    feats, labels = random_video(10, seed=4)
    prop = LabelPropagator(LabelPropagationConfig(memory_size=3))
    prop.reset(feats[0], labels[0])
    for t in range(1, 9):
        prop.push(feats[t], labels[t])
    assert prop.memory_length == 3
    ref = propagate_dense(feats[9], [feats[0], feats[7], feats[8]],
                          [labels[0], labels[7], labels[8]], [None, 12.0, 12.0])
    torch.testing.assert_close(prop.propagate(feats[9]), ref, atol=1e-5, rtol=0)


def test_soft_labels_stay_convex_and_recurrent():
    feats, _ = random_video(8, seed=5, k=2)
    onehot = torch.zeros(2, 13, 21)
    onehot[0, :, :10] = 1.0
    onehot[1, :, 10:] = 1.0
    prop = LabelPropagator()
    prop.reset(feats[0], onehot)
    for t in range(1, 8):
        out = prop.step(feats[t])
        assert out.min() >= 0 and out.max() <= 1 + 1e-6
        torch.testing.assert_close(out.sum(0), torch.ones(13, 21))
    assert prop.memory_length == 6


NATIVE_BF16 = bool((cpu_flags() or set()) & set(NATIVE_BF16_FLAGS))


@pytest.mark.skipif(not NATIVE_BF16, reason="this CPU has no native bfloat16")
@pytest.mark.parametrize("reference", [False, True])
@pytest.mark.parametrize(("radius", "memory_size", "channels"), [
    (12.0, 6, 2),  # the heads' settings
    (3.0, 4, 15),  # pose-like: 15 belief maps
    (None, 3, 3),  # dense recent frames
    (2.0, 1, 3),  # the first frame alone
])
def test_bf16_candidates_rescored_give_float32s_labels(reference, radius, memory_size,
                                                         channels):
    # bfloat16 only picks the candidates; their float32 affinities decide, so the labels
    # are float32's to float rounding (pure bfloat16 affinities differ by ~1e-2 here).
    feats, labels = random_video(6, c=64, h=17, w=23, k=channels, seed=11)
    props = {precision: LabelPropagator(LabelPropagationConfig(
        radius=radius, memory_size=memory_size, max_affinity_elements=20000,
        propagation_precision=precision), reference=reference)
        for precision in ("float32", "bf16")}
    with torch_threads(1):  # tiny maps: threads only add overhead
        for prop in props.values():
            prop.reset(feats[0], labels[0])
        for t in range(1, 6):
            torch.testing.assert_close(props["bf16"].step(feats[t]),
                                       props["float32"].step(feats[t]), atol=1e-5, rtol=0)


@pytest.mark.parametrize("flags", [set(), {"avx512f", "avx512bw"}, None])
def test_bf16_is_refused_without_native_bf16(monkeypatch, flags):
    monkeypatch.setattr(label_propagation, "cpu_flags", lambda: flags)
    config = LabelPropagationConfig(propagation_precision="bf16")  # a value: allowed
    with pytest.raises(ValueError, match=r"propagation_precision='bf16'.*avx512_bf16 or "
                                         r"amx_bf16.*propagation_precision='float32'"):
        LabelPropagator(config)
    LabelPropagator()  # float32 needs nothing
    monkeypatch.setattr(label_propagation, "cpu_flags", lambda: {"avx512f", "amx_bf16"})
    assert LabelPropagator(config).bf16


def test_errors_name_what_to_fix():
    with pytest.raises(ValueError, match="memory_size"):
        LabelPropagationConfig(memory_size=0)
    with pytest.raises(ValueError, match="propagation_precision"):
        LabelPropagationConfig(propagation_precision="bfloat16")
    prop = LabelPropagator()
    with pytest.raises(RuntimeError, match="reset"):
        prop.step(torch.zeros(4, 5, 5))
    with pytest.raises(ValueError, match="downsample"):
        prop.reset(torch.zeros(4, 5, 5), torch.zeros(2, 10, 10))
    prop.reset(torch.randn(4, 5, 5), torch.zeros(2, 5, 5))
    with pytest.raises(ValueError, match="one size"):
        prop.step(torch.randn(4, 6, 5))


@pytest.mark.parametrize("tile", [3, 8])
def test_padded_ring_follows_the_memory_after_wrapping(tile):
    # More pushes than slots: the ring overwrites the oldest frame's slot; the local search
    # must still see exactly the first frame and the latest M - 1 frames.
    feats, labels = random_video(11, h=17, w=10, seed=3)
    cfg = LabelPropagationConfig(memory_size=4, radius=4.0, tile_size=tile,
                                 max_affinity_elements=5000)
    prop = LabelPropagator(cfg)
    prop.reset(feats[0], labels[0])
    for t in range(1, 10):
        prop.push(feats[t], labels[t])
    memory = [0, 7, 8, 9]
    ref = propagate_dense(feats[10], [feats[i] for i in memory], [labels[i] for i in memory],
                          [None, 4.0, 4.0, 4.0])
    torch.testing.assert_close(prop.propagate(feats[10]), ref, atol=1e-5, rtol=0)
    prop.reset(feats[1], labels[1])  # a new video empties the ring
    assert prop.memory_length == 1
    torch.testing.assert_close(
        prop.propagate(feats[2]), propagate_dense(feats[2], [feats[1]], [labels[1]], [None]),
        atol=1e-5, rtol=0)


@pytest.mark.parametrize(("tile", "radius", "memory_size", "channels", "max_elements"), [
    (8, 12.0, 6, 2, 1 << 23),  # the heads' settings, one block
    (3, 4.0, 4, 15, 4000),  # pose-like: 15 belief maps; many small blocks
    (5, 2.5, 2, 3, 20000),
    (4, 0.0, 6, 3, 1 << 23),  # radius 0: 5 recent candidates per query, fewer than k
])
def test_window_search_follows_the_reference_recurrently(tile, radius, memory_size, channels,
                                                          max_elements):
    # The heads' use: every prediction is written back; both searches must stay together.
    feats, labels = random_video(12, c=16, h=23, w=31, k=channels, seed=7)
    cfg = LabelPropagationConfig(tile_size=tile, radius=radius, memory_size=memory_size,
                                 max_affinity_elements=max_elements)
    new, old = LabelPropagator(cfg), LabelPropagator(cfg, reference=True)
    for prop in (new, old):
        prop.reset(feats[0], labels[0])
    for t in range(1, 12):
        torch.testing.assert_close(new.step(feats[t]), old.step(feats[t]), atol=1e-5, rtol=0)


def test_grouped_topk_is_the_topk():
    gen = torch.Generator().manual_seed(8)
    aff = torch.randn(300, 7 * 13, generator=gen)
    aff[aff < -1.0] = float("-inf")  # excluded candidates
    aff[:5] = float("-inf")  # rows with no candidate at all
    best, column = grouped_topk(aff, rows=7, k=10)
    expected = aff.topk(10, dim=1).values
    torch.testing.assert_close(best, expected, atol=0, rtol=0)
    torch.testing.assert_close(aff.gather(1, column), expected, atol=0, rtol=0)
    few, _ = grouped_topk(aff[:, :7 * 2], rows=7, k=10)  # 2 groups < k: still exact
    torch.testing.assert_close(few, aff[:, :14].topk(10, dim=1).values, atol=0, rtol=0)


@pytest.mark.parametrize(("radius", "h", "w"), [(None, 9, 13), (3.0, 9, 13), (None, 30, 41),
                                                (9.0, 30, 41)])
def test_search_above_keeps_what_can_beat_the_floor(radius, h, w):
    # Merged with k other candidates whose k-th best is the floor, the search above the
    # floor gives what the full search gives, whatever the floor: high (few keys), middling
    # (more keys than ABOVE_WIDTH, or more reached groups: plain top-k fallback), low (every
    # key) or infinite. 30 x 41 keys make 62 groups, more than ABOVE_WIDTH.
    gen = torch.Generator().manual_seed(9)
    c, k = 8, 10
    q = normalize_features(torch.randn(c, h, w, generator=gen)).reshape(c, -1).t()
    feats = normalize_features(torch.randn(c, h, w, generator=gen))
    lbl = torch.rand(3, h, w, generator=gen)
    full = search_dense(q, feats, lbl, h, w, radius, 300, 5000)
    # Floors at each query's 3rd best key (3 keys, at most 3 groups reach it), at its 25th,
    # 40th or 300th best (when there are that many) ...
    rank = torch.tensor([2, 24, 39, 299]).repeat(h * w // 4 + 1)[:h * w]
    finite = torch.isfinite(full[0]).sum(1)
    floor = full[0].gather(1, torch.minimum(rank, finite - 1).unsqueeze(1)).squeeze(1)
    full = (full[0][:, :k], full[1][:, :k])
    floor[:10] = -2.0  # ... low floors (every key reaches them) and no floor at all
    floor[10:15] = float("-inf")
    other_v = torch.rand(h * w, k, generator=gen).sort(dim=1, descending=True).values
    other_v[:, -1] = 0.0
    other_v = floor.unsqueeze(1) + other_v  # k candidates >= the floor
    other_v[10:15] = torch.linspace(0.9, -0.9, k)
    other_v[10:15, -1] = float("-inf")
    other_l = torch.rand(h * w, k, 3, generator=gen)
    above = search_above(q, feats, lbl, h, w, radius, floor, k, 500)
    expected = merge_topk([full[0], other_v], [full[1], other_l], k, 0.05)
    torch.testing.assert_close(merge_topk([above[0], other_v], [above[1], other_l], k, 0.05),
                               expected, atol=1e-6, rtol=0)
