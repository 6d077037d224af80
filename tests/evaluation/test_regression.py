"""Episode regression: the baselines replayed against golden files (synthetic and real)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from unitrack_env.evaluation.regression import (
    EpisodeRecord,
    GoldenMismatch,
    check_episode,
    compare_records,
)

GOLDENS = Path(__file__).resolve().parents[1] / "goldens"
#: Counts must not move at all; ratios only by float noise.
TOLERANCE = 1e-9


@pytest.mark.parametrize("agent", ["iou", "fresh-ids"])
@pytest.mark.parametrize("sequence", ["SYN-01", "SYN-02"])
def test_baselines_on_synthetic(episode_regression, agent, sequence):
    episode_regression.check(
        "UniTrack/MOT16-v0", agent=agent, sequence=sequence,
        golden=GOLDENS / f"{agent}-MOT16-{sequence}.json", tolerance=TOLERANCE,
        strict_actions=True,
    )


@pytest.mark.parametrize("agent", ["iou", "fresh-ids"])
@pytest.mark.parametrize("sequence", ["MOT17-02-FRCNN", "MOT17-04-FRCNN", "MOT17-05-FRCNN",
                                      "MOT17-11-FRCNN"])
def test_baselines_on_real_mot17(episode_regression, mot17_root, agent, sequence):
    episode_regression.check(
        "UniTrack/MOT17-v0", agent=agent, sequence=sequence,
        env_kwargs={"root": str(mot17_root)},
        golden=GOLDENS / f"{agent}-MOT17-{sequence}.json", tolerance=TOLERANCE,
        strict_actions=True,
    )


def test_iou_on_real_pets(episode_regression, mot15_root):
    episode_regression.check(
        "UniTrack/MOT15-v0", agent="iou", sequence="PETS09-S2L1",
        env_kwargs={"root": str(mot15_root), "decode_frames": False},
        golden=GOLDENS / "iou-MOT15-PETS09-S2L1.json", tolerance=TOLERANCE,
    )


def test_a_moved_metric_fails_with_a_readable_diff(tmp_path):
    golden = EpisodeRecord.load(GOLDENS / "iou-MOT16-SYN-01.json")
    changed = json.loads(golden.to_json())
    changed["metrics"]["MOTA"] += 0.01
    path = tmp_path / "golden.json"
    path.write_text(json.dumps(changed))
    with pytest.raises(GoldenMismatch) as info:
        check_episode("UniTrack/MOT16-v0", "iou", "SYN-01", path)
    text = str(info.value)
    assert "MOTA" in text and "change -0.010000" in text and "--update-goldens" in text
    assert "IDF1" not in text  # only what moved is listed


def test_a_diff_names_the_options_changed_since_the_recording(tmp_path):
    path = tmp_path / "golden.json"
    check_episode("UniTrack/MOT16-v0", "iou", "SYN-01", path, update=True)
    with pytest.raises(GoldenMismatch) as info:
        check_episode("UniTrack/MOT16-v0", "iou", "SYN-01", path,
                      agent_kwargs={"iou_threshold": 0.9})
    assert str(info.value).splitlines()[1] == "agent option iou_threshold: unset -> 0.9"


def test_missing_golden_and_update_flag(tmp_path):
    path = tmp_path / "new.json"
    with pytest.raises(GoldenMismatch, match="does not exist; run pytest with --update-goldens"):
        check_episode("UniTrack/MOT16-v0", "fresh-ids", "SYN-01", path)
    record = check_episode("UniTrack/MOT16-v0", "fresh-ids", "SYN-01", path, update=True)
    assert EpisodeRecord.load(path) == record
    check_episode("UniTrack/MOT16-v0", "fresh-ids", "SYN-01", path)  # now it matches


def test_compare_records_tolerance_and_digest():
    base = EpisodeRecord("e", "s", "a", {"MOTA": 0.5, "IDSW": 3.0}, "abc", 10)
    moved = EpisodeRecord("e", "s", "a", {"MOTA": 0.5004, "IDSW": 3.0}, "abd", 10)
    assert compare_records(base, moved, tolerance=1e-3) == []
    assert compare_records(base, moved, tolerance={"MOTA": 1e-4})[0].startswith("metrics moved")
    assert "action digest changed" in compare_records(base, moved, tolerance=1e-3,
                                                      strict_actions=True)[0]


def test_the_fixture_reports_a_missing_golden_once(tmp_path):
    """Through pytest itself: the user sees the message once, not chained twice.

    The short summary (``-rN`` turns it off) repeats the message when the terminal is wide
    enough, which depends on the machine; the failure report itself must hold it once.
    """
    import subprocess
    import sys

    (tmp_path / "test_user.py").write_text(
        "def test_mine(episode_regression):\n"
        "    episode_regression.check('UniTrack/MOT16-v0', agent='fresh-ids',\n"
        "                             sequence='SYN-01', golden='goldens/none.json')\n")
    result = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                             "-rN", str(tmp_path / "test_user.py")], cwd=tmp_path,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 1
    assert result.stdout.count("does not exist; run pytest with --update-goldens") == 1, (
        result.stdout)
    assert "During handling" not in result.stdout
