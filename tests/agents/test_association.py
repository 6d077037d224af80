"""Tests of the assignment helpers and the two-stage association engine on hand-built cases."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from unitrack_env.agents.primitives.association import Associator
from unitrack_env.agents.primitives.association_config import AssociationConfig
from unitrack_env.agents.primitives.kalman import CHI2_95_4DOF
from unitrack_env.agents.primitives.matching import fuse_motion, iou_cost, linear_assignment
from unitrack_env.agents.primitives.tracks import TrackState

RED = np.array([1.0, 0.0, 0.0])
GREEN = np.array([0.0, 1.0, 0.0])
BLUE = np.array([0.0, 0.0, 1.0])


def dot_similarity(tracks: list[np.ndarray], dets: list[np.ndarray]) -> np.ndarray:
    """Cosine similarity of unit payload vectors."""
    return np.array(tracks).reshape(len(tracks), -1) @ np.array(dets).reshape(len(dets), -1).T


def box(x: float, y: float = 100.0, w: float = 20.0, h: float = 40.0) -> list[float]:
    return [x, y, w, h]


def step(assoc: Associator, boxes: list[list[float]], payloads: list[np.ndarray],
         scores: list[float] | None = None) -> dict[int, int]:
    """Run one frame; return {detection index: reported id}."""
    scores = [0.9] * len(boxes) if scores is None else scores
    out = assoc.step(np.array(boxes, dtype=float).reshape(-1, 4), np.array(scores), payloads)
    return {o.detection_index: o.track_id for o in out}


# ---------------------------------------------------------------------- linear_assignment
def test_linear_assignment_threshold_and_optimum() -> None:
    cost = np.array([[0.1, 0.2], [0.15, 0.9]])
    a = linear_assignment(cost, 0.5)
    # Greedy would take (0, 0) = 0.1 and leave row 1 unmatched; the optimum matches both.
    assert a.matches.tolist() == [[0, 1], [1, 0]]
    assert a.unmatched_rows.tolist() == [] and a.unmatched_cols.tolist() == []
    # Strict threshold: a cost equal to the threshold is rejected.
    b = linear_assignment(np.array([[0.5, 0.6]]), 0.5)
    assert b.matches.shape == (0, 2) and b.unmatched_cols.tolist() == [0, 1]


def test_linear_assignment_prefers_more_gain_over_more_matches() -> None:
    # Threshold 1: matching {(0,0),(1,1)} gains (1-0.05)+(1-0.95) = 1.0 > (0,1) alone: 0.99.
    cost = np.array([[0.05, 0.01], [np.inf, 0.95]])
    a = linear_assignment(cost, 1.0)
    assert a.matches.tolist() == [[0, 0], [1, 1]]
    # Raise row 1's cost above the threshold: only the best single pair remains.
    a = linear_assignment(np.array([[0.05, 0.01], [np.inf, 1.5]]), 1.0)
    assert a.matches.tolist() == [[0, 1]]


def test_linear_assignment_empty_and_nan() -> None:
    a = linear_assignment(np.zeros((0, 3)), 0.5)
    assert a.matches.shape == (0, 2) and a.unmatched_cols.tolist() == [0, 1, 2]
    with pytest.raises(ValueError, match="NaN"):
        linear_assignment(np.array([[np.nan]]), 0.5)


def test_iou_cost_and_fusion() -> None:
    c = iou_cost(np.array([box(0)]), np.array([box(0), box(10), box(100)]))
    # Overlap of box(10) with box(0): 10 x 40 = 400 over 800 + 800 - 400 -> IoU 1/3.
    np.testing.assert_allclose(c, [[0.0, 2.0 / 3.0, 1.0]])
    fused = fuse_motion(np.array([[0.2, 0.2]]), np.array([[1.0, 10.0]]), 0.99)
    assert fused[0, 0] == pytest.approx(0.99 * 0.2 + 0.01 * 1.0)
    assert fused[0, 1] == np.inf  # 10 > 9.4877
    ungated = fuse_motion(np.array([[0.2]]), np.array([[10.0]]), 0.98, gate_threshold=None)
    assert ungated[0, 0] == pytest.approx(0.98 * 0.2 + 0.02 * 10.0)


# ---------------------------------------------------------------------- life cycle
def test_first_frame_confirms_and_ids_count_from_one() -> None:
    assoc = Associator(dot_similarity)
    assert step(assoc, [box(0), box(200)], [RED, GREEN]) == {0: 1, 1: 2}


def test_tentative_track_confirmed_on_second_frame() -> None:
    assoc = Associator(dot_similarity, AssociationConfig(confirm_on_first_frame=False))
    assert step(assoc, [box(0)], [RED]) == {}
    assert [t.state for t in assoc.tracks] == [TrackState.TENTATIVE]
    assert assoc.tracks[0].track_id is None
    assert step(assoc, [box(1)], [RED]) == {0: 1}


def test_tentative_track_needs_overlap_and_is_removed_when_unmatched() -> None:
    assoc = Associator(dot_similarity, AssociationConfig(confirm_on_first_frame=False))
    step(assoc, [box(0)], [RED])
    # IoU(box(0), box(8)) = 12/28 = 0.43 < confirm_iou_threshold 0.7: not confirmed.
    assert step(assoc, [box(8)], [RED]) == {}
    states = [t.state for t in assoc.tracks]
    assert states == [TrackState.TENTATIVE]  # the old one removed, a new one born at x=8
    assert assoc.tracks[0].start_frame == 2


def test_new_track_score_threshold() -> None:
    assoc = Associator(dot_similarity, AssociationConfig(new_track_raw_score=0.5))
    assert step(assoc, [box(0), box(200)], [RED, GREEN], scores=[0.49, 0.5]) == {1: 1}


def test_lost_track_is_refound_by_appearance_within_lost_age() -> None:
    assoc = Associator(dot_similarity, frame_rate=5.0)  # 1 s = 5 frames
    assert step(assoc, [box(0)], [RED]) == {0: 1}
    for _ in range(3):
        assert step(assoc, [], []) == {}
    assert [t.state for t in assoc.tracks] == [TrackState.LOST]
    # Same appearance, same place: re-found with the same id.
    assert step(assoc, [box(0)], [RED]) == {0: 1}
    assert assoc.tracks[0].state is TrackState.CONFIRMED


def test_lost_track_removed_after_lost_age() -> None:
    assoc = Associator(dot_similarity, frame_rate=5.0)
    assert assoc.max_lost_frames == 5
    step(assoc, [box(0)], [RED])  # frame 1
    for _ in range(5):  # frames 2..6: 6 - 1 = 5 frames since the match, still kept
        step(assoc, [], [])
    assert [t.state for t in assoc.tracks] == [TrackState.LOST]
    step(assoc, [], [])  # frame 7: 6 > 5 -> removed
    assert assoc.tracks == []
    # The object comes back: a new identity (confirmed on its second frame).
    assert step(assoc, [box(0)], [RED]) == {}
    assert step(assoc, [box(0)], [RED]) == {0: 2}


def test_lost_age_follows_frame_rate_and_seconds() -> None:
    assoc = Associator(dot_similarity, AssociationConfig(lost_seconds=2.0), frame_rate=14.0)
    assert assoc.max_lost_frames == 28
    assoc.reset(frame_rate=25.0)
    assert assoc.max_lost_frames == 50


def test_reset_clears_tracks_and_id_counter() -> None:
    assoc = Associator(dot_similarity)
    step(assoc, [box(0), box(200)], [RED, GREEN])
    step(assoc, [box(0), box(200)], [RED, GREEN])
    assoc.reset()
    assert assoc.tracks == [] and assoc.frame_index == 0
    assert step(assoc, [box(400)], [BLUE]) == {0: 1}


def test_two_instances_do_not_share_ids() -> None:
    a, b = Associator(dot_similarity), Associator(dot_similarity)
    assert step(a, [box(0)], [RED]) == {0: 1}
    assert step(b, [box(0)], [RED]) == {0: 1}


def test_empty_frames_and_bad_inputs() -> None:
    assoc = Associator(dot_similarity)
    assert assoc.step(np.zeros((0, 4)), np.zeros(0), []) == []
    with pytest.raises(ValueError, match="same length"):
        assoc.step(np.array([box(0)]), np.array([0.9, 0.8]), [RED])
    with pytest.raises(ValueError, match="non-positive width"):
        assoc.step(np.array([[0.0, 0.0, 0.0, 10.0]]), np.array([0.9]), [RED])


# ---------------------------------------------------------------------- two stages
def test_stage_one_threshold_on_appearance_cost() -> None:
    cfg = AssociationConfig(use_motion=False)
    near = np.array([np.sqrt(0.31), np.sqrt(1 - 0.31), 0.0])  # cos with RED = sqrt(0.31)
    for sim, expect_same in ((0.31, True), (0.29, False)):
        assoc = Associator(lambda t, d, s=sim: np.full((len(t), len(d)), s), cfg)
        step(assoc, [box(0)], [RED])
        # Far away (no overlap, so stage 2 cannot help): only stage 1 can match.
        out = step(assoc, [box(500)], [near])
        assert (out == {0: 1}) is expect_same, sim


def test_stage_two_iou_rescues_appearance_miss() -> None:
    # Appearance says "different" (cost 1), but the box barely moved: IoU stage matches.
    assoc = Associator(lambda t, d: np.zeros((len(t), len(d))))
    step(assoc, [box(0)], [RED])
    assert step(assoc, [box(2)], [GREEN]) == {0: 1}  # IoU 18/22 = 0.82 > 0.5
    # IoU below 0.5 -> no match, the track is lost and a new tentative one starts.
    assert step(assoc, [box(12)], [GREEN]) == {}  # IoU(x=2-ish, x=12) < 0.5
    states = sorted(t.state.value for t in assoc.tracks)
    assert states == ["lost", "tentative"]


def test_lost_tracks_are_not_offered_to_the_iou_stage() -> None:
    never_similar = AssociationConfig(confirm_on_first_frame=True)
    assoc = Associator(lambda t, d: np.zeros((len(t), len(d))), never_similar)
    step(assoc, [box(0)], [RED])
    step(assoc, [], [])  # lost
    assert step(assoc, [box(0)], [GREEN]) == {}  # overlapping, but lost -> appearance only
    included = Associator(
        lambda t, d: np.zeros((len(t), len(d))),
        AssociationConfig(iou_stage_includes_lost=True),
    )
    step(included, [box(0)], [RED])
    step(included, [], [])
    assert step(included, [box(0)], [GREEN]) == {0: 1}


def test_motion_gate_blocks_implausible_jumps() -> None:
    with_motion = Associator(dot_similarity)
    without = Associator(dot_similarity, AssociationConfig(use_motion=False))
    for assoc in (with_motion, without):
        step(assoc, [box(0)], [RED])
        step(assoc, [box(0)], [RED])
    # Identical appearance 300 px away: gated out with motion, accepted without.
    assert step(with_motion, [box(300)], [RED]) == {}
    assert step(without, [box(300)], [RED]) == {0: 1}
    # The gate is the chi-square 95% quantile.
    assert with_motion.config.gate_threshold == CHI2_95_4DOF


def test_motion_cost_breaks_appearance_ties() -> None:
    # Two identical-looking detections; the one nearer the prediction wins with motion.
    assoc = Associator(dot_similarity)
    step(assoc, [box(100)], [RED])
    assert step(assoc, [box(90), box(101)], [RED, RED]) == {1: 1}


def test_duplicate_of_a_lost_track_is_suppressed() -> None:
    # Track 1 lives 3 frames, disappears; a dissimilar detection shows up on top of its
    # predicted box. The newborn is the younger duplicate of the lost track: removed.
    assoc = Associator(lambda t, d: np.zeros((len(t), len(d))))
    for _ in range(3):
        step(assoc, [box(0)], [RED])
    step(assoc, [], [])
    assert step(assoc, [box(0)], [GREEN]) == {}
    assert [t.state for t in assoc.tracks] == [TrackState.LOST]
    # With the duplicate test disabled (IoU must exceed 1), the newborn survives.
    keep = Associator(
        lambda t, d: np.zeros((len(t), len(d))), AssociationConfig(duplicate_iou=1.0)
    )
    for _ in range(3):
        step(keep, [box(0)], [RED])
    step(keep, [], [])
    step(keep, [box(0)], [GREEN])
    assert sorted(t.state.value for t in keep.tracks) == ["lost", "tentative"]


def test_payload_is_the_last_matched_observation() -> None:
    assoc = Associator(dot_similarity, AssociationConfig(use_motion=False))
    step(assoc, [box(0)], [RED])
    mixed = np.array([0.8, 0.6, 0.0])
    step(assoc, [box(1)], [mixed])
    np.testing.assert_array_equal(assoc.tracks[0].payload, mixed)


def test_output_filter_and_reported_box() -> None:
    cfg = AssociationConfig(output_min_area=200.0, output_max_aspect=1.6,
                            report_filtered_box=False)
    assoc = Associator(dot_similarity, cfg)
    out = assoc.step(
        np.array([box(0, w=10, h=20), box(100, w=20, h=40), box(200, w=70, h=40)]),
        np.ones(3), [RED, GREEN, BLUE],
    )
    # 10x20 = 200 is not > 200; 70/40 = 1.75 > 1.6; only the middle box is reported.
    assert [(o.detection_index, o.box.tolist()) for o in out] == [(1, box(100, w=20, h=40))]


# ---------------------------------------------------------------------- crossing
def bounce(speed: float = 4.0, half: int = 10) -> list[np.ndarray]:
    """Two boxes approach, coincide, and go back where they came from."""
    frames = []
    for t in range(2 * half + 1):
        offset = speed * (t if t <= half else 2 * half - t)
        frames.append(np.array([box(offset), box(2 * speed * half - offset)]))
    return frames


@pytest.mark.parametrize("use_motion", [True, False])
def test_appearance_keeps_ids_where_iou_only_swaps(use_motion: bool) -> None:
    frames = bounce()
    payloads = [RED, GREEN]
    with_app = Associator(dot_similarity, AssociationConfig(use_motion=use_motion))
    iou_only = Associator(None)
    app_ids, iou_ids = [], []
    for boxes in frames:
        app_ids.append(step(with_app, boxes.tolist(), payloads))
        iou_ids.append(step(iou_only, boxes.tolist(), payloads))
    assert all(ids == {0: 1, 1: 2} for ids in app_ids)
    # IoU-only follows the constant-velocity prediction through the bounce: ids swap.
    assert iou_ids[0] == {0: 1, 1: 2}
    assert iou_ids[-1] == {0: 2, 1: 1}


# ---------------------------------------------------------------------- issue 11 knobs
def test_reported_box_is_the_detection_by_default_in_mot_but_filtered_in_the_paper() -> None:
    from dataclasses import replace

    from unitrack_env.agents.heads.unitrack_config import UniTrackConfig

    paper = Associator(dot_similarity)
    assert paper.config.report_filtered_box  # authors' code: the Kalman state
    unfiltered = {"output_min_area": None, "output_max_aspect": None}
    mot = Associator(dot_similarity,
                     replace(UniTrackConfig().resolve("mot").association(), **unfiltered))
    for x in (0.0, 3.0, 7.0, 8.0):  # uneven motion: the filter lags the detections
        det = [box(x)]
        out_paper = paper.step(np.array(det), np.ones(1), [RED])
        out_mot = mot.step(np.array(det), np.ones(1), [RED])
    assert out_mot[0].box.tolist() == box(8.0)
    assert out_paper[0].box.tolist() != box(8.0)


def test_step_record_lists_stages_births_and_similarities() -> None:
    assoc = Associator(dot_similarity)
    step(assoc, [box(0), box(100)], [RED, GREEN])
    assert [b[1] for b in assoc.last_step.births] == [0, 1]
    step(assoc, [box(1), box(101)], [RED, GREEN])
    record = assoc.last_step
    assert sorted((m[1], m[2], m[3]) for m in record.matches) == [
        (0, "appearance", False), (1, "appearance", False)]
    assert len(record.similarities) == 2
    np.testing.assert_allclose(sorted(r.tolist() for r in record.similarities.values()),
                               [[0.0, 1.0], [1.0, 0.0]])


def test_reid_threshold_keeps_a_weakly_similar_lost_track_lost() -> None:
    half = np.array([np.sqrt(0.5), np.sqrt(0.5), 0.0])  # cosine 0.71 with RED: cost 0.29
    for threshold, refound in ((None, True), (0.2, False)):
        assoc = Associator(dot_similarity, AssociationConfig(reid_threshold=threshold),
                           frame_rate=10.0)
        step(assoc, [box(0)], [RED])
        step(assoc, [], [])  # lost
        ids = step(assoc, [box(0)], [half])
        assert (ids == {0: 1}) is refound, threshold


def test_ambiguity_margin_leaves_look_alikes_to_the_iou_stage() -> None:
    # Two identical-looking people: appearance cannot tell which is which, the IoU stage can.
    cfg = AssociationConfig(use_motion=False, ambiguity_margin=0.05)
    assoc = Associator(dot_similarity, cfg)
    step(assoc, [box(0), box(60)], [RED, RED])
    step(assoc, [box(2), box(58)], [RED, RED])
    stages = {m[2] for m in assoc.last_step.matches}
    assert stages == {"iou"}
    # Without the margin the appearance stage takes them (ties broken arbitrarily).
    plain = Associator(dot_similarity, AssociationConfig(use_motion=False))
    step(plain, [box(0), box(60)], [RED, RED])
    step(plain, [box(2), box(58)], [RED, RED])
    assert {m[2] for m in plain.last_step.matches} == {"appearance"}


def test_appearance_momentum_keeps_a_track_after_one_wrong_observation() -> None:
    # Frame 2 gives the track a detection that looks like someone else (matched by overlap);
    # frame 3 offers both looks far away, so appearance alone decides whom the track follows.
    red, green = torch.from_numpy(RED[None]), torch.from_numpy(GREEN[None])
    followed = {}
    for momentum in (0.0, 0.9):
        assoc = Associator(dot_similarity, AssociationConfig(use_motion=False,
                                                             appearance_momentum=momentum))
        step(assoc, [box(0)], [red])
        assert step(assoc, [box(0)], [green]) == {0: 1}
        ids = step(assoc, [box(300), box(600)], [red, green])
        followed[momentum] = [det for det, track_id in ids.items() if track_id == 1]
    assert followed == {0.0: [1], 0.9: [0]}  # last observation: the other look; memory: its own


def test_remember_averages_location_sets_of_one_shape_only() -> None:
    from unitrack_env.agents.primitives.appearance_memory import remember

    old = torch.tensor([[1.0, 0.0], [0.0, 2.0]])
    new = torch.tensor([[0.0, 1.0], [0.0, 1.0]], dtype=torch.float16)
    mixed = remember(old, new, 0.5)
    assert mixed.dtype == torch.float16 and mixed.shape == (2, 2)
    np.testing.assert_allclose(mixed.float().norm(dim=1).numpy(), 1.0, atol=1e-3)
    np.testing.assert_allclose(mixed[0].float().numpy(), [0.7071, 0.7071], atol=1e-3)
    np.testing.assert_allclose(mixed[1].float().numpy(), [0.0, 1.0], atol=1e-3)
    assert remember(old, new, 0.0) is new
    bigger = torch.ones(3, 2)
    assert remember(old, bigger, 0.9) is bigger  # a mask of another size: the newest
    assert remember(RED, GREEN, 0.9) is GREEN  # not tensors: the newest


@pytest.mark.parametrize("momentum", [-0.1, 1.0, float("nan")])
def test_appearance_momentum_must_be_below_one(momentum: float) -> None:
    with pytest.raises(ValueError, match="appearance_momentum"):
        AssociationConfig(appearance_momentum=momentum)
