import json
import multiprocessing
import os
import shutil
import warnings
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

from unitrack_env.agents import make_agent
from unitrack_env.agents.appearance import (
    AppearanceModel,
    CachedAppearanceModel,
    CacheKey,
    CacheStats,
    FeatureCache,
    FeatureCacheWarning,
    content_key,
    default_cache_dir,
    resolve_cache,
    track_cache_run,
)
from unitrack_env.agents.appearance import cache_config as cc
from unitrack_env.agents.appearance import feature_cache as fc

KEY = CacheKey(model="abc123", input_size=(16, 24), content=content_key(np.zeros(3, np.uint8)))
SHAPE = (4, 2, 3)


class Counter:
    def __init__(self, value: np.ndarray) -> None:
        self.value = value
        self.calls = 0

    def __call__(self) -> np.ndarray:
        self.calls += 1
        return self.value


def _features(seed: int = 0, shape: tuple[int, ...] = SHAPE) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=shape).astype(np.float32)


def _key(i: int, model: str = "abc123") -> CacheKey:
    return CacheKey(model, (16, 24), content_key(np.array([i], np.int64)))


def _entries(root: Path) -> list[Path]:
    return sorted(root.rglob("*.npy"))


# ---------------------------------------------------------------------------- entries
def test_miss_then_hit(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    first = cache.get_or_compute(KEY, compute)
    second = cache.get_or_compute(KEY, compute)
    assert compute.calls == 1 and (cache.stats.misses, cache.stats.hits) == (1, 1)
    assert (cache.stats.misses, cache.stats.hits, cache.stats.corrupt) == (1, 1, 0)
    assert first.dtype == torch.float32 and first.shape == SHAPE
    torch.testing.assert_close(first, second)  # same values warm or cold
    np.testing.assert_allclose(first.numpy(), _features(), rtol=1e-3, atol=1e-3)  # float16
    path = cache.path(KEY)
    assert path == (tmp_path / "v3" / "abc123-16x24-float16" / KEY.content[:2]
                    / f"{KEY.content}.npy")
    assert np.load(path).dtype == np.float16
    assert [p.name for p in path.parent.iterdir()] == [path.name]  # no temp files left
    assert (tmp_path / "CACHEDIR.TAG").read_text().startswith("Signature: 8a477f597d28d172")
    usage = json.loads((tmp_path / "usage.json").read_text())
    assert usage["entries"] == 1 and usage["bytes"] == path.stat().st_size
    info = json.loads((path.parents[1] / "model.json").read_text())
    assert info["model_key"] == "abc123" and info["input_size"] == [16, 24]


def test_other_keys_miss(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    cache.get_or_compute(KEY, compute)
    for other in (
        CacheKey("abc124", KEY.input_size, KEY.content),
        CacheKey(KEY.model, (16, 32), KEY.content),
        CacheKey(KEY.model, KEY.input_size, content_key(np.ones(3, np.uint8))),
    ):
        cache.get_or_compute(other, compute)
    assert compute.calls == 4 and cache.stats.hits == 0
    # Another dtype is another entry folder, never a corrupt entry.
    exact = FeatureCache(tmp_path, dtype=np.float32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        exact.get_or_compute(KEY, compute)
    assert compute.calls == 5 and exact.path(KEY) != cache.path(KEY)


def test_keys_cannot_escape_the_cache(tmp_path: Path) -> None:
    for model in ("../evil", "a/b", ""):
        with pytest.raises(ValueError, match="model key"):
            CacheKey(model, (8, 8), KEY.content)
    for content in ("../x", "XYZ", ""):
        with pytest.raises(ValueError, match="hex digest"):
            CacheKey("m", (8, 8), content)


def test_float32_storage_is_exact(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path, dtype=np.float32)
    out = cache.get_or_compute(KEY, Counter(_features()))
    np.testing.assert_array_equal(out.numpy(), _features())
    with pytest.raises(ValueError, match="float"):
        FeatureCache(tmp_path, dtype=np.int32)


@pytest.mark.parametrize("damage", ["truncate", "garbage", "empty", "shape", "dtype", "pickle"])
def test_corrupt_entries_are_reported_once_and_recomputed(tmp_path: Path, damage: str) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    cache.get_or_compute(KEY, compute, expected_shape=SHAPE)
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
    elif damage == "dtype":
        np.save(path, np.zeros(SHAPE, np.float64))
    else:
        np.save(path, np.array([{"a": 1}], dtype=object), allow_pickle=True)
    with pytest.warns(FeatureCacheWarning, match=path.name):
        again = cache.get_or_compute(KEY, compute, expected_shape=SHAPE)
    assert compute.calls == 2 and cache.stats.corrupt == 1
    np.testing.assert_allclose(again.numpy(), _features(), rtol=1e-3, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # repaired in place: no further warning
        fresh = FeatureCache(tmp_path)
        torch.testing.assert_close(fresh.get_or_compute(KEY, compute, expected_shape=SHAPE), again)
    assert compute.calls == 2
    # The damage happened behind the cache's back; a scan (eviction, `unitrack cache info`)
    # makes the accounting exact again.
    assert (cache.usage().entries, cache.usage().bytes) == (1, path.stat().st_size)
    usage = json.loads((tmp_path / "usage.json").read_text())
    assert (usage["entries"], usage["bytes"]) == (1, path.stat().st_size)


@pytest.mark.parametrize("damage", ["swap", "bitflip", "nan", "old-format", "trailer"])
def test_swapped_damaged_and_nan_entries_are_never_served(tmp_path: Path, damage: str) -> None:
    cache = FeatureCache(tmp_path)
    compute = Counter(_features())
    cache.get_or_compute(KEY, compute, expected_shape=SHAPE)
    other = _key(7)
    cache.get_or_compute(other, Counter(_features(1)), expected_shape=SHAPE)
    path = cache.path(KEY)
    data = bytearray(path.read_bytes())
    if damage == "swap":  # a valid entry of the right shape, but of another key
        shutil.copyfile(cache.path(other), path)
    elif damage == "bitflip":
        data[len(data) // 2] ^= 0x01
        path.write_bytes(bytes(data))
    elif damage == "nan":  # NaN values in a well-formed entry (written through the format)
        from unitrack_env.agents.appearance.cache_files import _write_entry, key_digest

        with open(path, "wb") as handle:
            _write_entry(handle, np.full(SHAPE, np.nan, np.float16),
                         key_digest(cache.namespace(KEY), KEY.content))
    elif damage == "old-format":  # a plain .npy (the layout before entries had a trailer)
        np.save(path, np.full(SHAPE, np.nan, np.float16))
    else:
        path.write_bytes(bytes(data[:-4]) + b"\0\0\0\0")
    with pytest.warns(FeatureCacheWarning) as caught:
        again = cache.get_or_compute(KEY, compute, expected_shape=SHAPE)
    assert len(caught) == 1 and str(path) in str(caught[0].message), caught
    assert "not used" in str(caught[0].message)
    assert compute.calls == 2 and cache.stats.corrupt == 1
    np.testing.assert_allclose(again.numpy(), _features(), rtol=1e-3, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # replaced: the next read is a plain hit
        assert FeatureCache(tmp_path).get(KEY, SHAPE) is not None


def test_entries_of_the_previous_layout_are_misses(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    old = tmp_path / "v2" / cache.namespace(KEY) / KEY.content[:2] / f"{KEY.content}.npy"
    old.parent.mkdir(parents=True)
    np.save(old, _features().astype(np.float16))
    compute = Counter(_features(3))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = cache.get_or_compute(KEY, compute, expected_shape=SHAPE)
    assert compute.calls == 1 and cache.stats.misses == 1
    np.testing.assert_allclose(out.numpy(), _features(3), rtol=1e-3, atol=1e-3)


def test_non_finite_features_are_returned_but_not_stored(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    values = _features()
    values[0, 0, 0] = np.inf
    out = cache.get_or_compute(KEY, Counter(values), expected_shape=SHAPE)
    assert torch.isinf(out[0, 0, 0]) and not cache.path(KEY).exists()


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
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith(".tmp")]  # temp file removed


def test_an_unwritable_cache_warns_once_and_still_returns_features(tmp_path: Path) -> None:
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("x")
    cache = FeatureCache(blocker / "cache")
    compute = Counter(_features())
    with pytest.warns(FeatureCacheWarning, match="cannot be written"):
        out = cache.get_or_compute(KEY, compute)
    np.testing.assert_allclose(out.numpy(), _features(), rtol=1e-3, atol=1e-3)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cache.get_or_compute(_key(1), compute)  # no second warning
        cache.flush_stats()  # (statistics cannot be written either; warned once)
    assert compute.calls == 2


# ---------------------------------------------------------------------------- content keys
def test_content_key_hashes_every_byte() -> None:
    frame = np.random.default_rng(0).integers(0, 256, (1080, 1920, 3), dtype=np.uint8)
    base = content_key(frame)
    assert base == content_key(frame.copy()) and len(base) == 32
    for index in (0, 61, 62, 1234567, frame.size - 1):  # the old fingerprint read every 61st
        changed = frame.copy()
        changed.reshape(-1)[index] ^= 1
        assert content_key(changed) != base, index
    assert content_key(frame, "letterbox 1088x608 pad 128") != base
    assert content_key(frame.reshape(1920, 1080, 3)) != base  # same bytes, other shape
    assert content_key(frame.view(np.int8)) != base  # same bytes, other dtype
    strided = frame[:, ::2]
    assert content_key(strided) == content_key(np.ascontiguousarray(strided))


def test_model_identity_key_follows_the_weights() -> None:
    a = AppearanceModel("random", seed=0).identity
    assert a.key() == AppearanceModel("random", seed=0).identity.key()
    assert a.key() != AppearanceModel("random", seed=1).identity.key()
    assert a.key() != AppearanceModel("random", seed=0, layer="layer4").identity.key()
    assert a.key() != AppearanceModel("random", seed=0, arch="resnet50").identity.key()


# ---------------------------------------------------------------------------- configuration
def test_default_folder_and_switches(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(fc.CACHE_DIR_ENV, str(tmp_path / "feats"))
    assert default_cache_dir() == tmp_path / "feats"
    cache = resolve_cache(True)
    assert cache is not None and cache.root == tmp_path / "feats"
    assert cache.max_size == cc.DEFAULT_MAX_SIZE == 10 * 2**30
    assert resolve_cache(False) is None and resolve_cache(None) is None
    assert resolve_cache("off") is None
    assert resolve_cache(tmp_path / "x", max_size="1MiB").max_size == 2**20
    assert resolve_cache(cache) is cache
    for off in ("off", "0", "false", "None"):
        monkeypatch.setenv(fc.CACHE_DIR_ENV, off)
        assert default_cache_dir() is None and resolve_cache(True) is None
    monkeypatch.delenv(fc.CACHE_DIR_ENV)
    monkeypatch.setenv("UNITRACK_CACHE", str(tmp_path / "unitrack"))
    assert default_cache_dir() == tmp_path / "unitrack" / "features"
    monkeypatch.delenv("UNITRACK_CACHE")
    import platformdirs

    assert default_cache_dir() == Path(platformdirs.user_cache_dir("unitrack-env")) / "features"
    assert not list(tmp_path.iterdir())  # resolving creates nothing


def test_sizes(monkeypatch: pytest.MonkeyPatch) -> None:
    assert cc.parse_size("10GiB") == 10 * 2**30 == cc.parse_size("10G") == cc.parse_size("10 gib")
    assert cc.parse_size("500MB") == 500 * 10**6
    assert cc.parse_size("1.5k") == 1536 and cc.parse_size(123) == 123 == cc.parse_size("123")
    for bad in ("ten", "5 parsecs", "-1", "1e3"):
        with pytest.raises(ValueError, match="size"):
            cc.parse_size(bad)
    assert cc.format_size(512) == "512 B" and cc.format_size(1536) == "1.5 KiB"
    assert cc.format_size(3 * 2**30) == "3.0 GiB"
    monkeypatch.setenv(cc.CACHE_MAX_ENV, "2MiB")
    assert cc.default_max_size() == 2 * 2**20
    monkeypatch.setenv(cc.CACHE_MAX_ENV, "lots")
    with pytest.raises(ValueError, match=cc.CACHE_MAX_ENV):
        cc.default_max_size()


def test_the_test_suite_never_writes_to_the_user_cache() -> None:
    import platformdirs

    root = default_cache_dir()
    assert root is not None
    assert Path(platformdirs.user_cache_dir("unitrack-env")) not in [root, *root.parents]


# ---------------------------------------------------------------------------- eviction
def test_tiny_cap_evicts_least_recently_used_first_with_unchanged_results(tmp_path: Path) -> None:
    probe = FeatureCache(tmp_path / "probe")
    probe.get_or_compute(_key(0), lambda: _features(0))
    entry = probe.path(_key(0)).stat().st_size
    cache = FeatureCache(tmp_path / "cache", max_size=int(3.5 * entry))  # room for 3 entries
    first = {i: cache.get_or_compute(_key(i), lambda i=i: _features(i)) for i in range(3)}
    assert len(_entries(cache.root)) == 3 and cache.stats.evicted == 0
    cache.get_or_compute(_key(0), lambda: _features(0))  # a hit: 0 is now the most recent
    first[3] = cache.get_or_compute(_key(3), lambda: _features(3))  # over the cap: evict 1
    assert cache.stats.evicted == 1
    assert not cache.path(_key(1)).exists()
    assert all(cache.path(_key(i)).exists() for i in (0, 2, 3))
    first[4] = cache.get_or_compute(_key(4), lambda: _features(4))  # next oldest: 2
    assert not cache.path(_key(2)).exists()
    assert all(cache.path(_key(i)).exists() for i in (0, 3, 4))
    usage = json.loads((cache.root / "usage.json").read_text())
    assert usage["entries"] == 3 and usage["bytes"] == 3 * entry <= cache.max_size
    # Evicted entries are recomputed to the same values; kept ones are read back unchanged.
    compute = Counter(None)  # type: ignore[arg-type]
    for i in (0, 3, 4, 1, 2):  # hits, then misses that evict the least recent again (0, 3)
        compute.value = _features(i)
        torch.testing.assert_close(cache.get_or_compute(_key(i), compute), first[i],
                                   rtol=0, atol=0)
    assert compute.calls == 2  # 1 and 2


def test_prune_and_clear(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    for i in range(4):
        cache.get_or_compute(_key(i), lambda i=i: _features(i))
    entry = cache.path(_key(0)).stat().st_size
    stale = cache.path(_key(0)).parent / ".leftover.npy.tmp"
    stale.write_bytes(b"half")
    os.utime(stale, (1, 1))  # a writer killed long ago
    usage = cache.usage()
    assert (usage.entries, usage.bytes, usage.temp_files) == (4, 4 * entry, 1)
    assert [n.entries for n in usage.namespaces] == [4]
    assert usage.namespaces[0].model["model_key"] == "abc123"
    assert cache.prune(2 * entry) == (2, 2 * entry)
    assert not stale.exists()
    assert [p for p in _entries(tmp_path)] == sorted(cache.path(_key(i)) for i in (2, 3))
    assert cache.prune() == (0, 0)  # under the cap already
    cache.flush_stats()
    assert cache.clear() == (2, 2 * entry)
    assert _entries(tmp_path) == [] and not (tmp_path / "runs").exists()
    assert json.loads((tmp_path / "usage.json").read_text())["bytes"] == 0
    cache.get_or_compute(_key(0), lambda: _features(0))  # usable after clearing
    assert len(_entries(tmp_path)) == 1
    assert FeatureCache(tmp_path / "missing").clear() == (0, 0)


# ---------------------------------------------------------------------------- many writers
WRITER_SHAPE = (16, 48, 64)  # 96 KiB per float16 entry: writes take long enough to interleave


def _writer_value(i: int) -> np.ndarray:
    return _features(1000 + i, WRITER_SHAPE)


def _writer(root: str, worker: int, n_keys: int, rounds: int, max_size: int,
            barrier: object, results: object) -> None:
    with warnings.catch_warnings(record=True) as log:
        warnings.simplefilter("always")
        cache = FeatureCache(root, max_size=max_size)
        barrier.wait()  # type: ignore[attr-defined]
        wrong = 0
        order = np.random.default_rng(worker).permutation(n_keys)
        for _ in range(rounds):
            for i in order:
                i = int(i)
                got = cache.get_or_compute(_key(i, "writers"), lambda i=i: _writer_value(i),
                                           expected_shape=WRITER_SHAPE)
                expected = _writer_value(i).astype(np.float16).astype(np.float32)
                wrong += int(not np.array_equal(got.numpy(), expected))
        caught = [str(w.message) for w in log]
    results.put({"worker": worker, "wrong": wrong, "warnings": caught,  # type: ignore[attr-defined]
                 **asdict(cache.stats)})


def _run_writers(root: Path, n_keys: int, rounds: int, max_size: int) -> list[dict]:
    context = multiprocessing.get_context("spawn")
    barrier = context.Barrier(4)
    results = context.Queue()
    workers = [context.Process(target=_writer,
                               args=(str(root), w, n_keys, rounds, max_size, barrier, results))
               for w in range(4)]
    for process in workers:
        process.start()
    out = [results.get(timeout=300) for _ in workers]
    for process in workers:
        process.join(timeout=60)
        assert process.exitcode == 0
    return out


@pytest.mark.parametrize("capped", [False, True])
def test_four_writer_processes_on_the_same_frames(tmp_path: Path, capped: bool) -> None:
    n_keys, rounds = 24, 3
    entry = FeatureCache(tmp_path / "probe").put(_key(0), _writer_value(0))
    entry_bytes = FeatureCache(tmp_path / "probe").path(_key(0)).stat().st_size
    assert entry.nbytes < entry_bytes
    max_size = 10 * entry_bytes if capped else cc.DEFAULT_MAX_SIZE
    root = tmp_path / "shared"
    results = _run_writers(root, n_keys, rounds, max_size)
    assert [r["wrong"] for r in results] == [0, 0, 0, 0]  # never a partial or foreign entry
    assert [r["warnings"] for r in results] == [[], [], [], []]  # never a corrupt entry
    assert sum(r["hits"] + r["misses"] for r in results) == 4 * n_keys * rounds
    assert all(r["corrupt"] == 0 for r in results)
    files = _entries(root)
    usage = json.loads((root / "usage.json").read_text())
    assert usage["bytes"] == sum(p.stat().st_size for p in files)  # exact accounting
    assert usage["entries"] == len(files)
    assert not [p for p in root.rglob("*.tmp")]
    if capped:
        assert usage["bytes"] <= max_size  # the cap holds
        assert sum(r["evicted"] for r in results) > 0
        stored = sum(r["stored"] for r in results)
        assert stored - sum(r["evicted"] for r in results) == len(files)
    else:
        assert len(files) == n_keys
        assert sum(r["stored"] for r in results) == n_keys  # each frame stored exactly once
        assert sum(r["misses"] for r in results) >= n_keys


# ---------------------------------------------------------------------------- statistics
def test_run_statistics_are_recorded_per_run(tmp_path: Path) -> None:
    cache = FeatureCache(tmp_path)
    with track_cache_run() as run:
        assert os.environ[fc.RUN_ENV] == run.run
        for i in range(3):
            cache.get_or_compute(_key(i), lambda i=i: _features(i))
        cache.flush_stats()
        other = FeatureCache(tmp_path)  # a second process of the same run
        other.get_or_compute(_key(0), lambda: _features(0))
        other.flush_stats()
    assert fc.RUN_ENV not in os.environ
    stats = run.stats(tmp_path)
    assert stats is not None and (stats.hits, stats.misses, stats.stored) == (1, 3, 3)
    assert run.summary(tmp_path) == ("feature cache: 1/4 frames read from the cache (25%), "
                                     "3 computed")
    with track_cache_run(tmp_path) as second:
        for i in range(3):
            cache.get_or_compute(_key(i), lambda i=i: _features(i))
        cache.flush_stats()
    assert second.stats() == CacheStats(hits=3)  # counted from the new run on
    assert run.stats(tmp_path).lookups == 4  # the earlier run is unchanged
    records = cache.runs()
    assert [r.run for r in records] == [run.run, second.run]
    assert records[0].processes == 2 and records[1].processes == 1
    assert records[0].namespaces == ("abc123-16x24-float16",)
    assert track_cache_run().__enter__().stats(tmp_path / "none") is None


def test_run_statistics_keep_a_bounded_history(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fc, "MAX_RUN_FILES", 3)
    for i in range(5):
        cache = FeatureCache(tmp_path)
        cache.get_or_compute(_key(i), lambda i=i: _features(i))
        cache.flush_stats()
    assert len(list((tmp_path / "runs").iterdir())) == 3
    assert len(cache.runs()) == 3 and len(cache.runs(limit=2)) == 2


# ---------------------------------------------------------------------------- the model
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
    first = cached.features(frames[:2])
    assert batches == [2] and first.shape == (2, 256, 3, 4)
    np.testing.assert_allclose(first.numpy(), real(frames[:2]).numpy(), rtol=2e-3, atol=2e-3)
    both = cached.features(frames)
    assert batches == [2, 1]  # only the third frame was computed
    torch.testing.assert_close(both[:2], first)
    single = cached.features(frames[2])
    assert batches == [2, 1] and single.shape == (1, 256, 3, 4)
    folder = tmp_path / "v3" / f"{model.identity.key()}-24x32-float16"
    assert len(_entries(folder)) == 3
    assert json.loads((folder / "model.json").read_text())["model"]["arch"] == "resnet18"
    # Another model (different weights) does not see these entries.
    other = CachedAppearanceModel(AppearanceModel("random", seed=1), tmp_path)
    other.features(frames[:1])
    assert other.cache.stats.misses == 1 and other.cache.stats.hits == 0
    with pytest.raises(ValueError, match="keys"):
        cached.features(frames, keys=["ab"])
    assert cached.describe()["cache"] == str(tmp_path)
    with pytest.raises(ValueError, match="turns the cache off"):
        CachedAppearanceModel(model, False)


def test_the_same_frame_in_two_sequences_is_one_entry(tmp_path: Path) -> None:
    cached = CachedAppearanceModel(AppearanceModel("random", arch="resnet18"), tmp_path)
    a = np.zeros((64, 64, 3), np.uint8)
    b = np.full((64, 64, 3), 200, np.uint8)
    first = cached.features(a)
    other = cached.features(b)
    assert cached.cache.stats.misses == 2 and not torch.allclose(first, other)
    again = cached.features(a.copy())  # e.g. MOT17-02-DPM after MOT17-02-FRCNN
    assert cached.cache.stats.hits == 1 and torch.equal(again, first)
    assert len(_entries(tmp_path)) == 2


# ---------------------------------------------------------------------------- the head
def _episode(agent, env, sequence: str, steps: int) -> list[dict]:
    obs, info = env.reset(options={"sequence": sequence})
    agent.reset(obs, info)
    actions = []
    for _ in range(steps):
        action = agent.act(obs)
        actions.append(action)
        obs, _, terminated, _, _ = env.step(action)
        if terminated:
            break
    agent.close()
    return actions


def test_the_head_uses_the_default_cache_unless_turned_off(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(fc.CACHE_DIR_ENV, str(tmp_path / "default"))
    model = AppearanceModel("random", seed=3)
    agent = make_agent("unitrack", appearance_model=model, input_size=(136, 76))
    assert isinstance(agent.model, CachedAppearanceModel)
    assert agent.model.cache.root == tmp_path / "default"
    assert not isinstance(make_agent("unitrack", appearance_model=model, feature_cache=False,
                                     input_size=(136, 76)).model, CachedAppearanceModel)
    sized = make_agent("unitrack", appearance_model=model, feature_cache_size="1MiB")
    assert sized.model.cache.max_size == 2**20
    monkeypatch.setenv(fc.CACHE_DIR_ENV, "off")
    assert not isinstance(make_agent("unitrack", appearance_model=model).model,
                          CachedAppearanceModel)


def test_head_results_are_unchanged_under_a_tiny_cap(tmp_path: Path) -> None:
    env = gym.make("UniTrack/MOT16-v0")
    sequence = env.unwrapped.sequence_names[0]
    model = AppearanceModel("random", seed=0)
    options = {"appearance_model": model, "input_size": (136, 76), "num_threads": 1}
    big = make_agent("unitrack", feature_cache=tmp_path / "big", **options)
    reference = _episode(big, env, sequence, 8)
    entry = max(p.stat().st_size for p in _entries(tmp_path / "big"))
    tiny = make_agent("unitrack", feature_cache=tmp_path / "tiny",
                      feature_cache_size=int(2.5 * entry), **options)
    for _ in range(2):  # cold, then mostly evicted again
        actions = _episode(tiny, env, sequence, 8)
        for a, b in zip(reference, actions, strict=True):
            np.testing.assert_array_equal(a["ids"], b["ids"])
            np.testing.assert_array_equal(a["boxes"], b["boxes"])
    assert tiny.model.cache.stats.evicted >= 8
    assert len(_entries(tmp_path / "tiny")) <= 2


def _mot17_copy(mot17_root: Path, tmp_path: Path) -> Path:
    """A MOT17 root with MOT17-02-FRCNN and a copy of it named MOT17-02-DPM."""
    root = tmp_path / "MOT17"
    source = mot17_root / "train" / "MOT17-02-FRCNN"
    shutil.copytree(source, root / "train" / "MOT17-02-FRCNN")
    dpm = root / "train" / "MOT17-02-DPM"
    shutil.copytree(source, dpm)
    info = dpm / "seqinfo.ini"
    info.write_text(info.read_text().replace("MOT17-02-FRCNN", "MOT17-02-DPM"))
    return root


def test_a_renamed_copy_of_a_sequence_hits_the_cache_on_every_frame(
        mot17_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from unitrack_env.evaluation.run.runner import run

    root = _mot17_copy(mot17_root, tmp_path)
    monkeypatch.setenv(fc.CACHE_DIR_ENV, str(tmp_path / "features"))
    reports = {}
    stats = {}
    for name in ("MOT17-02-FRCNN", "MOT17-02-DPM"):
        with track_cache_run() as cache_run:
            reports[name] = run("UniTrack/MOT17-v0", "unitrack", out=tmp_path / name,
                                env_kwargs={"root": str(root)}, sequences=[name],
                                agent_kwargs={"num_threads": 1}, progress=False)
        stats[name] = cache_run.stats()
    frames = reports["MOT17-02-DPM"].records["MOT17-02-DPM"].frames
    assert frames == 4
    assert (stats["MOT17-02-FRCNN"].hits, stats["MOT17-02-FRCNN"].misses) == (0, frames)
    assert (stats["MOT17-02-DPM"].hits, stats["MOT17-02-DPM"].misses) == (frames, 0)
    assert stats["MOT17-02-DPM"].summary().startswith(
        "feature cache: 4/4 frames read from the cache (100%), 0 computed")
    a = reports["MOT17-02-FRCNN"].scores.per_sequence["MOT17-02-FRCNN"]
    b = reports["MOT17-02-DPM"].scores.per_sequence["MOT17-02-DPM"]
    assert a == b  # same frames, same detections, same features: same metrics
    assert len(_entries(tmp_path / "features")) == frames


def test_engines_that_round_differently_never_share_entries(tmp_path: Path) -> None:
    from dataclasses import replace

    model = AppearanceModel("random", seed=0)
    torch_key = CachedAppearanceModel(model, tmp_path).key((8, 8), KEY.content)
    model.identity = replace(model.identity, runtime="onnxruntime")
    other_key = CachedAppearanceModel(model, tmp_path).key((8, 8), KEY.content)
    cache = FeatureCache(tmp_path)
    assert cache.path(torch_key) != cache.path(other_key)


def test_an_injected_model_without_identity_runs_uncached() -> None:
    class Plain:  # duck-typed: features() and stride, nothing to key a cache by
        stride = 8

        def features(self, images):
            return torch.zeros((1, 4, 8, 8))

    plain = Plain()
    assert make_agent("unitrack", appearance_model=plain).model is plain


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_all_finite_finds_any_nan_or_infinity(dtype: type) -> None:
    from unitrack_env.agents.appearance.cache_files import all_finite

    values = np.full((3, 5), np.finfo(dtype).max, dtype)  # a float32 sum overflows: still finite
    assert all_finite(values) and all_finite(values[:0])
    for bad in (np.nan, np.inf, -np.inf):
        changed = values.copy()
        changed[2, 4] = bad
        assert not all_finite(changed), bad
