import os
import warnings
from pathlib import Path

import numpy as np
import pytest
import torch

from unitrack_env.agents.appearance import (
    AppearanceModel,
    CachedAppearanceModel,
    CacheKey,
    FeatureCache,
    FeatureCacheWarning,
)

KEY = CacheKey(model="abc123", input_size=(16, 24), sequence="MOT17-02-FRCNN", frame=7)


class Counter:
    def __init__(self, value: np.ndarray) -> None:
        self.value = value
        self.calls = 0

    def __call__(self) -> np.ndarray:
        self.calls += 1
        return self.value


def _features(seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(4, 2, 3)).astype(np.float32)


def test_miss_then_hit(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    first = cache.get_or_compute(KEY, compute)
    second = cache.get_or_compute(KEY, compute)
    assert compute.calls == 1 and (cache.misses, cache.hits) == (1, 1)
    assert first.dtype == torch.float32 and first.shape == (4, 2, 3)
    torch.testing.assert_close(first, second)  # same values warm or cold
    np.testing.assert_allclose(first.numpy(), _features(), rtol=1e-3, atol=1e-3)  # float16
    path = cache.path(KEY)
    assert path == tmp_path / "abc123-16x24" / "MOT17-02-FRCNN" / "000007.npy"
    assert np.load(path).dtype == np.float16
    assert [p.name for p in path.parent.iterdir()] == ["000007.npy"]  # no temp files left


def test_other_keys_miss(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    cache.get_or_compute(KEY, compute)
    for other in (
        CacheKey("abc124", KEY.input_size, KEY.sequence, KEY.frame),
        CacheKey(KEY.model, (16, 32), KEY.sequence, KEY.frame),
        CacheKey(KEY.model, KEY.input_size, "other", KEY.frame),
        CacheKey(KEY.model, KEY.input_size, KEY.sequence, 8),
    ):
        cache.get_or_compute(other, compute)
    assert compute.calls == 5 and cache.hits == 0


def test_float32_storage_is_exact(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path, dtype=np.float32)
    out = cache.get_or_compute(KEY, Counter(_features()))
    np.testing.assert_array_equal(out.numpy(), _features())
    with pytest.raises(ValueError, match="float"):
        FeatureCache(tmp_path, dtype=np.int32)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty", "shape", "dtype"])
def test_corrupt_entries_are_reported_once_and_recomputed(tmp_path: Path, damage: str) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    cache.get_or_compute(KEY, compute, expected_shape=(4, 2, 3))
    path = cache.path(KEY)
    data = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(data[: len(data) - 10])
    elif damage == "garbage":
        path.write_bytes(b"\x93NUMPY garbage header" + data[30:])
    elif damage == "empty":
        path.write_bytes(b"")
    elif damage == "shape":
        np.save(path, np.zeros((4, 3, 2), np.float16))
    else:
        np.save(path, np.zeros((4, 2, 3), np.float64))
    with pytest.warns(FeatureCacheWarning, match=str(path.name)):
        again = cache.get_or_compute(KEY, compute, expected_shape=(4, 2, 3))
    assert compute.calls == 2 and cache.recomputed == 1
    np.testing.assert_allclose(again.numpy(), _features(), rtol=1e-3, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # repaired: no further warning
        cache.get_or_compute(KEY, compute, expected_shape=(4, 2, 3))
    assert compute.calls == 2


def test_interrupted_writes_leave_no_entry(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    cache = FeatureCache(tmp_path)

    def failing() -> np.ndarray:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        cache.get_or_compute(KEY, failing)
    assert not cache.path(KEY).exists()

    real_save = np.save

    def half_save(handle: object, array: np.ndarray) -> None:
        real_save(handle, array)
        handle.truncate(20)  # type: ignore[attr-defined]
        raise KeyboardInterrupt  # interrupted in the middle of writing

    monkeypatch.setattr(np, "save", half_save)
    with pytest.raises(KeyboardInterrupt):
        cache.get_or_compute(KEY, Counter(_features()))
    assert not cache.path(KEY).exists()
    assert not any(p.is_file() for p in tmp_path.rglob("*"))  # temp file removed too


def test_sequence_names_cannot_escape_the_cache(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path / "cache")
    for name in ("../evil", "a/b", "..", "with space"):
        path = cache.path(CacheKey("m", (8, 8), name, 1)).resolve()
        assert (tmp_path / "cache").resolve() in path.parents
    a = cache.path(CacheKey("m", (8, 8), "a/b", 1))
    b = cache.path(CacheKey("m", (8, 8), "a_b", 1))
    assert a != b  # sanitising does not merge different names


def test_model_identity_key_follows_the_weights() -> None:
    a = AppearanceModel("random", seed=0).identity
    assert a.key() == AppearanceModel("random", seed=0).identity.key()
    assert a.key() != AppearanceModel("random", seed=1).identity.key()
    assert a.key() != AppearanceModel("random", seed=0, layer="layer4").identity.key()
    assert a.key() != AppearanceModel("random", seed=0, arch="resnet50").identity.key()


def test_cached_model_runs_the_backbone_only_on_misses(tmp_path: Path) -> None:
    model = AppearanceModel("random", seed=0)
    batches: list[int] = []
    real = model.features

    def counting(images: np.ndarray) -> torch.Tensor:
        batches.append(len(images))
        return real(images)

    model.features = counting  # type: ignore[method-assign]
    cached = CachedAppearanceModel(model, tmp_path)
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 256, (3, 24, 32, 3), dtype=np.uint8)
    first = cached.features(frames[:2], sequence="seq", frames=[1, 2])
    assert batches == [2] and first.shape == (2, 256, 3, 4)
    np.testing.assert_allclose(first.numpy(), real(frames[:2]).numpy(), rtol=2e-3, atol=2e-3)
    both = cached.features(frames, sequence="seq", frames=[1, 2, 3])
    assert batches == [2, 1]  # only frame 3 was computed
    torch.testing.assert_close(both[:2], first)
    single = cached.features(frames[2], sequence="seq", frames=3)
    assert batches == [2, 1] and single.shape == (1, 256, 3, 4)
    folder = tmp_path / f"{model.identity.key()}-24x32"
    names = sorted(p.name for p in (folder / "seq").iterdir())
    assert [n.split("-")[0] for n in names] == ["000001", "000002", "000003"]
    assert all(n.endswith(".npy") and len(n.split("-")[1]) == 16 + 4 for n in names)
    assert (folder / "model.json").is_file()
    # Another model (different weights) does not see these entries.
    other = CachedAppearanceModel(AppearanceModel("random", seed=1), tmp_path)
    other.features(frames[:1], sequence="seq", frames=[1])
    assert other.cache.misses == 1 and other.cache.hits == 0
    with pytest.raises(ValueError, match="frame indices"):
        cached.features(frames, sequence="seq", frames=[1])
    assert cached.describe()["cache"] == str(tmp_path)
    assert os.listdir(tmp_path)  # sanity: something was written


def test_same_sequence_name_with_other_pixels_does_not_share_an_entry(tmp_path):
    from unitrack_env.agents.appearance import AppearanceModel, CachedAppearanceModel

    model = AppearanceModel("random", arch="resnet18")
    cached = CachedAppearanceModel(model, tmp_path)
    a = np.zeros((64, 64, 3), np.uint8)
    b = np.full((64, 64, 3), 200, np.uint8)
    first = cached.features(a, sequence="seq", frames=1)
    other = cached.features(b, sequence="seq", frames=1)  # another data set, same name
    assert cached.cache.misses == 2 and not torch.allclose(first, other)
    again = cached.features(a, sequence="seq", frames=1)
    assert cached.cache.hits == 1 and torch.equal(again, first)
