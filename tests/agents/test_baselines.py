from __future__ import annotations

import numpy as np
import pytest

from unitrack_env.agents import available_agents, make_agent
from unitrack_env.agents.base import AGENTS, Agent
from unitrack_env.spaces import unpack_tracks


def observation(boxes, scores=None, capacity=16):
    boxes = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
    padded = np.zeros((capacity, 4), np.float32)
    padded[: len(boxes)] = boxes
    s = np.zeros(capacity, np.float32)
    s[: len(boxes)] = 1.0 if scores is None else scores
    return {"frame": np.zeros((4, 4, 3), np.uint8), "boxes": padded, "scores": s,
            "num_detections": len(boxes)}


def tracks(action):
    ids, boxes = unpack_tracks(action)
    return dict(zip(ids.tolist(), boxes.tolist(), strict=True))


def test_registry_lists_builtins_and_explains_unknown_names():
    assert {"iou", "fresh-ids", "unitrack"} <= set(available_agents())
    with pytest.raises(KeyError, match="unknown agent 'nope'; available: .*iou"):
        make_agent("nope")


def test_a_new_tracker_is_one_class():
    class Echo(Agent, name="test-echo", tasks=("mot",)):
        def reset(self, observation, info):
            self.calls = 0

        def act(self, observation):
            self.calls += 1
            return {"ids": np.array([1]), "boxes": observation["boxes"][:1]}

    try:
        agent = make_agent("test-echo")
        agent.reset(None, {})
        assert tracks(agent.act(observation([[1, 2, 3, 4]]))) == {1: [1, 2, 3, 4]}
        with pytest.raises(ValueError, match="already taken"):
            type("Other", (Agent,), {"reset": None, "act": None}, name="test-echo")
    finally:
        AGENTS.pop("test-echo", None)


def test_iou_keeps_id_of_a_moving_box_and_starts_new_ones():
    agent = make_agent("iou", min_hits=1)
    agent.reset(None, {"frame_rate": 10})
    first = tracks(agent.act(observation([[0, 0, 10, 20]])))
    second = tracks(agent.act(observation([[2, 0, 10, 20], [50, 50, 10, 20]])))
    (old_id,) = first
    assert old_id in second and second[old_id] == [2, 0, 10, 20]
    assert len(second) == 2


def test_iou_min_hits_and_lost_age_follow_the_frame_rate():
    agent = make_agent("iou", min_hits=2, max_lost_seconds=0.2)  # 2 frames at 10 fps
    agent.reset(None, {"frame_rate": 10})
    box = [[0, 0, 10, 20]]
    assert len(tracks(agent.act(observation(box)))) == 1  # opening frames are reported
    assert len(tracks(agent.act(observation(box)))) == 1
    (track_id,) = tracks(agent.act(observation(box)))
    for _ in range(2):  # lost for 2 frames: kept
        assert tracks(agent.act(observation([]))) == {}
    assert list(tracks(agent.act(observation(box)))) == [track_id]
    for _ in range(3):  # lost for 3 frames: dropped, the box comes back with a new id
        agent.act(observation([]))
    agent.act(observation(box))
    (new_id,) = tracks(agent.act(observation(box)))
    assert new_id != track_id


def test_iou_reset_restarts_ids_and_drops_duplicates():
    agent = make_agent("iou", min_hits=1)
    agent.reset(None, {"frame_rate": 30})
    agent.act(observation([[0, 0, 10, 20]]))
    out = tracks(agent.act(observation([[0, 0, 10, 20], [1, 0, 10, 20]])))
    assert len(out) == 1  # the overlapping second box is a duplicate detection
    agent.reset(None, {"frame_rate": 30})
    assert list(tracks(agent.act(observation([[5, 5, 5, 5]])))) == [1]


def test_fresh_ids_never_reuses_an_id():
    agent = make_agent("fresh-ids")
    agent.reset(None, {})
    a = tracks(agent.act(observation([[0, 0, 1, 1], [5, 5, 1, 1]])))
    b = tracks(agent.act(observation([[0, 0, 1, 1]])))
    assert list(a) == [1, 2] and list(b) == [3]
