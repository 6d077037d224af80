import json
from pathlib import Path

import numpy as np
import pytest

from unitrack_env.agents.appearance import (
    AppearanceModel,
    CachedAppearanceModel,
    FeatureCache,
    track_cache_run,
)
from unitrack_env.evaluation.cli import main


@pytest.fixture
def filled(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A cache folder (the default one) with 3 entries of one model and one recorded run."""
    root = tmp_path / "features"
    monkeypatch.setenv("UNITRACK_FEATURE_CACHE", str(root))
    cached = CachedAppearanceModel(AppearanceModel("random", seed=0), True)
    with track_cache_run():
        for value in (0, 1, 2, 0):
            cached.features(np.full((32, 48, 3), value, np.uint8))
        cached.flush_stats()
    return root


def test_info_lists_location_models_entries_and_hit_rates(filled: Path, capsys) -> None:
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert str(filled) in out and "3 entries" in out and "cap 10.0 GiB" in out
    assert "resnet18" in out and "32x48" in out and "25%" in out
    assert main(["cache", "info", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["location"] == str(filled) and info["entries"] == 3
    assert [m["entries"] for m in info["models"]] == [3]
    assert info["models"][0]["model"]["arch"] == "resnet18"
    (run,) = info["runs"]
    assert (run["lookups"], run["hits"], run["misses"], run["hit_rate"]) == (4, 1, 3, 0.25)


def test_prune_and_clear(filled: Path, capsys) -> None:
    entry = max(p.stat().st_size for p in filled.rglob("*.npy"))
    assert main(["cache", "prune", "--max-size", str(2 * entry)]) == 0
    assert "pruned 1 entries" in capsys.readouterr().out
    assert len(list(filled.rglob("*.npy"))) == 2
    assert main(["cache", "prune"]) == 0  # default: the cap (10 GiB): nothing to do
    assert "pruned 0 entries" in capsys.readouterr().out
    assert main(["cache", "clear"]) == 0
    assert "removed 2 entries" in capsys.readouterr().out
    assert not list(filled.rglob("*.npy"))
    assert main(["cache", "info"]) == 0
    assert "nothing cached yet" in capsys.readouterr().out


def test_dir_option_and_a_cache_turned_off(tmp_path: Path, monkeypatch, capsys) -> None:
    other = tmp_path / "other"
    FeatureCache(other).put(CachedAppearanceModel(AppearanceModel("random"), other).key(
        (8, 8), "ab" * 16), np.zeros((2, 1, 1), np.float32))
    monkeypatch.setenv("UNITRACK_FEATURE_CACHE", "off")
    assert main(["cache", "info"]) == 2
    assert "turned off" in capsys.readouterr().err
    assert main(["cache", "info", "--dir", str(other)]) == 0
    assert "1 entries" in capsys.readouterr().out
    assert main(["cache", "prune", "--dir", str(other), "--max-size", "lots"]) == 2
    assert "not a size" in capsys.readouterr().err


def test_a_run_that_stored_features_says_where_they_are_and_how_much(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from unitrack_env.evaluation.cli.evaluate import feature_cache_report

    root = tmp_path / "features"  # issue 42: the cache grew by 883 MiB without a word
    monkeypatch.setenv("UNITRACK_FEATURE_CACHE", str(root))
    lines = []
    for frames in ((0, 1, 2), (0, 1)):  # the second run computes nothing: no place line
        with feature_cache_report("unitrack", {}) as summary:
            cached = CachedAppearanceModel(AppearanceModel("random", seed=0), True)
            for value in frames:
                cached.features(np.full((32, 48, 3), value, np.uint8))
            cached.flush_stats()
        lines.append(summary().splitlines())
    assert lines[0][0].startswith("feature cache: 0/3 frames read from the cache")
    assert lines[0][1].startswith(f"feature cache: {root} now holds ")
    assert "in 3 entries (cap 10.0 GiB)" in lines[0][1]
    assert "`unitrack cache prune --max-size 2GiB` trims them" in lines[0][1]
    assert lines[1] == ["feature cache: 2/2 frames read from the cache (100%), 0 computed"]
    with feature_cache_report("iou", {}) as summary:
        pass
    assert summary() is None
