import numpy as np
import pytest
import torch
import torch.nn.functional as F

from unitrack_env.agents.primitives.roi_align import roi_align
from unitrack_env.agents.primitives.similarity import (
    RSM_TEMPERATURE,
    SIMILARITIES,
    ObjectFeatures,
    box_location_features,
    center_feature_similarity,
    global_feature_similarity,
    global_pooled_feature_similarity,
    grid_positions,
    rsm,
)


def _rsm_by_the_equation(tracks: list, dets: list, temperature: float) -> np.ndarray:
    """UniTrack eq. (rsm) pair by pair, with explicit sub-block slicing (float64)."""
    tracks = [F.normalize(t.double(), dim=1) for t in tracks]
    dets = [F.normalize(d.double(), dim=1) for d in dets]
    big_t, big_d = torch.cat(tracks), torch.cat(dets)
    affinity = big_t @ big_d.T
    forward = (affinity / temperature).softmax(dim=1)   # over all detection locations
    backward = (affinity / temperature).softmax(dim=0)  # over all track locations
    t_start = np.cumsum([0] + [len(t) for t in tracks])
    d_start = np.cumsum([0] + [len(d) for d in dets])
    out = np.zeros((len(tracks), len(dets)))
    for i, t in enumerate(tracks):
        for j, d in enumerate(dets):
            rows = slice(t_start[i], t_start[i + 1])
            cols = slice(d_start[j], d_start[j + 1])
            t_hat = forward[rows, cols] @ d           # t_i reconstructed from d_j
            d_hat = backward[rows, cols].T @ t        # d_j reconstructed from t_i
            cos_f = F.cosine_similarity(t.flatten(), t_hat.flatten(), dim=0)
            cos_b = F.cosine_similarity(d.flatten(), d_hat.flatten(), dim=0)
            out[i, j] = 0.5 * (cos_f + cos_b).item()
    return out


@pytest.mark.parametrize("channels", [64, 8])  # Gram path (s_max < C) and direct path
@pytest.mark.parametrize("temperature", [RSM_TEMPERATURE, 0.5])
def test_rsm_matches_the_paper_equation(channels: int, temperature: float) -> None:
    g = torch.Generator().manual_seed(channels)
    tracks = [torch.randn(n, channels, generator=g) for n in (40, 3, 17, 1)]
    dets = [torch.randn(n, channels, generator=g) for n in (12, 40, 5)]
    dets[1] = tracks[0] + 0.3 * torch.randn(40, channels, generator=g)
    got = rsm(tracks, dets, temperature=temperature)
    want = _rsm_by_the_equation(tracks, dets, temperature)
    np.testing.assert_allclose(got, want, atol=2e-5)
    assert got.shape == (4, 3) and got.dtype == np.float64


def test_identical_observation_scores_one_and_unrelated_scores_low() -> None:
    g = torch.Generator().manual_seed(0)
    tracks = torch.randn(4, 40, 256, generator=g)
    dets = torch.randn(5, 40, 256, generator=g)
    dets[3] = tracks[1]
    sim = rsm(tracks, dets)
    assert sim[1, 3] > 0.99
    others = np.delete(sim.flatten(), 1 * 5 + 3)
    assert others.max() < 0.4
    # Every metric ranks the identical pair first in its row.
    for name, fn in SIMILARITIES.items():
        s = fn(tracks, dets)
        assert s[1, 3] == pytest.approx(1.0, abs=1e-5), name
        assert s[1].argmax() == 3, name


def test_rsm_tolerates_partial_observations() -> None:
    # An occluded detection (only the top half of the track's locations) still matches
    # its track far better than other objects do.
    g = torch.Generator().manual_seed(3)
    tracks = [torch.randn(40, 32, generator=g) for _ in range(3)]
    dets = [tracks[2][:20].clone(), torch.randn(40, 32, generator=g)]
    sim = rsm(tracks, dets)
    assert sim[2, 0] > 0.8
    assert sim[:, 0].argmax() == 2
    assert sim[[0, 1], 0].max() < 0.4


def test_rsm_is_symmetric() -> None:
    g = torch.Generator().manual_seed(1)
    tracks = [torch.randn(n, 16, generator=g) for n in (5, 40, 9)]
    dets = [torch.randn(n, 16, generator=g) for n in (40, 2)]
    np.testing.assert_allclose(rsm(tracks, dets), rsm(dets, tracks).T, atol=1e-6)
    for name in ("cf", "gpf"):
        fn = SIMILARITIES[name]
        positioned_t = [ObjectFeatures(t, grid_positions(len(t), 1)) for t in tracks]
        positioned_d = [ObjectFeatures(d, grid_positions(len(d), 1)) for d in dets]
        np.testing.assert_allclose(
            fn(positioned_t, positioned_d), fn(positioned_d, positioned_t).T, atol=1e-6
        )


@pytest.mark.parametrize("name", sorted(SIMILARITIES))
def test_empty_inputs(name: str) -> None:
    fn = SIMILARITIES[name]
    some = torch.randn(3, 40, 8)
    assert fn(some, []).shape == (3, 0)
    assert fn([], some[:2]).shape == (0, 2)
    assert fn(torch.zeros(0, 40, 8), torch.zeros(0, 40, 8)).shape == (0, 0)


def test_global_feature_known_answer() -> None:
    # With unit location features, the cosine of the concatenations is the mean of the
    # per-location cosines.
    g = torch.Generator().manual_seed(2)
    a = F.normalize(torch.randn(2, 6, 5, generator=g), dim=2)
    b = F.normalize(torch.randn(3, 6, 5, generator=g), dim=2)
    want = torch.einsum("isc,jsc->ijs", a, b).mean(-1).numpy()
    np.testing.assert_allclose(global_feature_similarity(a, b), want, atol=1e-6)
    with pytest.raises(ValueError, match="fixed size"):
        global_feature_similarity([torch.randn(4, 5)], [torch.randn(6, 5)])


def test_global_pooled_feature_known_answer() -> None:
    a = [torch.tensor([[1.0, 0.0], [0.0, 1.0]])]      # mean (0.5, 0.5)
    b = [torch.tensor([[1.0, 0.0]]), torch.tensor([[0.0, 1.0], [0.0, 1.0], [-1.0, 0.0]])]
    got = global_pooled_feature_similarity(a, b)
    # (0.5, 0.5) vs (1, 0): 1/sqrt(2); vs mean (-1/3, 2/3): (1/6) / (sqrt(.5) * sqrt(5/9))
    np.testing.assert_allclose(got, [[1 / np.sqrt(2), (1 / 6) / (np.sqrt(0.5) * np.sqrt(5 / 9))]])


def test_center_feature_uses_the_centre_of_mass() -> None:
    channels = 4
    base = torch.zeros(10, 4, channels)
    base[..., 0] = 1.0  # every location points along channel 0 ...
    centre = base.clone()
    centre[4:6, 1:3] = torch.tensor([0.0, 1.0, 0.0, 0.0])  # ... except the 4 central cells
    track = box_location_features(centre.permute(2, 0, 1)[None])  # (1, 40, C)
    probe_centre = torch.zeros(1, 40, channels)
    probe_centre[0, :, 1] = 1.0
    probe_edge = base.reshape(1, 40, channels)
    sim = center_feature_similarity(track, torch.cat([probe_centre, probe_edge]))
    np.testing.assert_allclose(sim, [[1.0, 0.0]], atol=1e-6)
    # A mask-like set with explicit positions: the location nearest its centroid counts.
    feats = torch.eye(3)
    positions = torch.tensor([[0.0, 0.0], [0.0, 1.0], [0.0, 5.0]])  # centroid (0, 2)
    mask = ObjectFeatures(feats, positions)
    np.testing.assert_allclose(
        center_feature_similarity([mask], [torch.eye(3)[[1]] * torch.ones(40, 1)]), [[1.0]]
    )
    with pytest.raises(ValueError, match="positions"):
        center_feature_similarity([torch.randn(7, 3)], [torch.randn(7, 3)])


def test_box_pipeline_from_roi_align() -> None:
    # Two objects in a feature map; the same boxes one step later match themselves.
    g = torch.Generator().manual_seed(4)
    fmap = torch.randn(32, 30, 40, generator=g)
    boxes = torch.tensor([[2.0, 2.0, 8.0, 20.0], [20.0, 5.0, 26.0, 25.0]])
    moved = torch.roll(fmap, shifts=(1, 2), dims=(1, 2))
    tracks = box_location_features(roi_align(fmap, boxes))
    dets = box_location_features(roi_align(moved, boxes[[1, 0]] + torch.tensor([2.0, 1, 2, 1])))
    assert tracks.shape == (2, 40, 32)
    for name, fn in SIMILARITIES.items():
        sim = fn(tracks, dets)
        assert sim[0, 1] > 0.95 and sim[1, 0] > 0.95, name
        assert sim[0, 0] < 0.5 and sim[1, 1] < 0.5, name


def test_registry_and_argument_errors() -> None:
    assert set(SIMILARITIES) == {"rsm", "cf", "gf", "gpf"}
    with pytest.raises(KeyError, match="cf, gf, gpf, rsm"):
        SIMILARITIES["cosine"]
    with pytest.raises(ValueError, match="temperature"):
        rsm(torch.randn(1, 2, 3), torch.randn(1, 2, 3), temperature=0)
    with pytest.raises(ValueError, match="channel"):
        rsm([torch.randn(2, 3)], [torch.randn(2, 4)])
    with pytest.raises(ValueError, match=r"\(s, C\)"):
        rsm([torch.randn(2, 3, 1)], [torch.randn(2, 3)])
    # numpy input works the same as torch input.
    a = np.random.default_rng(0).normal(size=(2, 5, 3)).astype(np.float32)
    np.testing.assert_allclose(rsm(a, a), rsm(torch.from_numpy(a), torch.from_numpy(a)))
