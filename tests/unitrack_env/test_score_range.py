"""Detection score ranges are declared per benchmark, reported at reset, mapped to 0..1."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.score_range import DETECTION_SCORES, UNIT, ScoreRange, declared_range

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
PETS_ROOT = DATA / "MOT15"
MOT17_ROOT = DATA / "MOT17"


def test_range_maps_to_and_from_unit() -> None:
    mot15 = declared_range("MOT15")
    assert (mot15.low, mot15.high, mot15.bounded) == (0.0, 100.0, False)
    assert mot15.from_unit(0.5) == 50.0
    assert mot15.to_unit(np.array([-0.48, 55.955, 138.92])).tolist() == [0.0, 0.55955, 1.0]
    assert UNIT.to_unit(np.array([0.25, 1.5])).tolist() == [0.25, 1.0]
    assert UNIT.from_unit(0.5) == 0.5 and declared_range("custom") == UNIT
    assert ScoreRange.from_info(mot15.info()) == mot15 and ScoreRange.from_info(None) is None
    with pytest.raises(ValueError, match="finite low < high"):
        ScoreRange(1.0, 1.0, True, "")


def test_every_mot_benchmark_declares_a_range() -> None:
    assert {"MOT15", "MOT16", "MOT17", "MOT20"} <= set(DETECTION_SCORES)
    for name in ("MOT16", "MOT17", "MOT20"):
        assert DETECTION_SCORES[name].is_unit, name


def _scores(root: Path) -> np.ndarray:
    files = sorted(root.glob("train/*/det/det.txt"))
    if not files:
        pytest.skip(f"no fixtures under {root}")
    return np.concatenate([np.loadtxt(f, delimiter=",", ndmin=2)[:, 6] for f in files])


def test_declarations_match_the_fixtures() -> None:
    # MOT17 FRCNN: 0.051..1, inside its bounded 0..1; PETS09: -0.48..138.92, beyond 0..100.
    mot17 = _scores(MOT17_ROOT)
    assert mot17.min() >= 0.0 and mot17.max() <= 1.0
    pets = _scores(PETS_ROOT)
    assert pets.min() == pytest.approx(-0.47763) and pets.max() == pytest.approx(138.92)
    assert not DETECTION_SCORES["MOT15"].bounded


def _first(env_id: str, root: Path, **kwargs) -> tuple[dict, dict, gym.Env]:
    if not root.is_dir():
        pytest.skip(f"{root} not found")
    env = gym.make(env_id, root=str(root), decode_frames=False, **kwargs)
    obs, info = env.reset()
    return obs, info, env


def test_env_reports_the_range_and_maps_scores_on_request() -> None:
    obs, info, env = _first("UniTrack/MOT15-v0", PETS_ROOT)
    n = obs["num_detections"]
    assert info["detection_scores"]["high"] == 100.0 and not info["detection_scores"]["bounded"]
    raw = obs["scores"][:n].copy()
    env.close()
    obs, info, env = _first("UniTrack/MOT15-v0", PETS_ROOT, detection_scores="unit")
    assert (info["detection_scores"]["low"], info["detection_scores"]["high"]) == (0.0, 1.0)
    np.testing.assert_allclose(obs["scores"][: obs["num_detections"]], raw / 100, rtol=1e-6)
    env.close()
    # min_score is on the scale the agent sees: 0.6 of the unit scale keeps scores >= 60.
    obs, _, env = _first("UniTrack/MOT15-v0", PETS_ROOT, detection_scores="unit", min_score=0.6)
    assert obs["num_detections"] == int((raw >= 60).sum())
    env.close()
    obs, info, env = _first("UniTrack/MOT15-v0", PETS_ROOT, detection_scores="unit",
                            score_range=(0.0, 200.0))
    np.testing.assert_allclose(obs["scores"][: obs["num_detections"]], raw / 200, rtol=1e-6)
    assert "score_range=" in info["detection_scores"]["source"]
    env.close()
    with pytest.raises(ValueError, match="detection_scores must be one of raw, unit"):
        gym.make("UniTrack/MOT15-v0", root=str(PETS_ROOT), detection_scores="probability")


def test_mot17_range_is_unit_and_unit_mode_changes_nothing() -> None:
    raw, info, env = _first("UniTrack/MOT17-v0", MOT17_ROOT)
    env.close()
    unit, _, env = _first("UniTrack/MOT17-v0", MOT17_ROOT, detection_scores="unit")
    env.close()
    assert info["detection_scores"]["high"] == 1.0 and info["detection_scores"]["bounded"]
    np.testing.assert_array_equal(raw["scores"], unit["scores"])


def test_registry_rows_carry_their_declared_range() -> None:
    from unitrack_env.registration import variant

    assert variant("UniTrack/MOT15-v0").detection_scores == declared_range("MOT15")
    assert variant("UniTrack/MOT17-v0").detection_scores.is_unit
    assert variant("UniTrack/VIS-v0").detection_scores.is_unit
    assert variant("UniTrack/OTB-v0").detection_scores is None
