"""TAP-Vid: the restricted pickle reader, the synthetic ground truth and the environments."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import unitrack_env  # noqa: F401  (registers the ids)
from unitrack_env.datasets.synthetic import render_scene
from unitrack_env.datasets.synthetic.tapvid import SPECS, point_tracks
from unitrack_env.datasets.tapvid import RefusedGlobal, TAPVidDataset, restricted_load
from unitrack_env.errors import DataFormatError, InvalidActionError

IDS = ("UniTrack/TAPVid-DAVIS-v0", "UniTrack/TAPVid-RGBStacking-v0", "UniTrack/RoboTAP-v0")


def _video(frames=4, tracks=2):
    points = np.full((tracks, frames, 2), 0.5, np.float32)
    return {"video": np.zeros((frames, 8, 8, 3), np.uint8), "points": points,
            "occluded": np.zeros((tracks, frames), bool)}


class _Payload:
    """Unpickling this runs ``_touch(path)``: the code a crafted pickle would smuggle in."""

    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (_touch, (str(self.path),))


def _touch(path):
    with open(path, "w") as handle:
        handle.write("the pickle's code ran")


def test_a_crafted_pickle_is_refused_and_its_code_never_runs(tmp_path):
    marker = tmp_path / "ran.txt"
    path = tmp_path / "tapvid_davis.pkl"
    path.write_bytes(pickle.dumps({"a": _video(), "b": _Payload(marker)}, protocol=4))
    with pytest.raises(RefusedGlobal) as caught:
        TAPVidDataset(tmp_path)
    message = str(caught.value)
    assert str(path) in message and "test_tapvid._touch" in message
    assert not marker.exists()
    # a plain pickle.load would have run it: the test's payload is real
    pickle.loads(path.read_bytes())
    assert marker.exists()


def test_builtin_callables_are_refused_by_name(tmp_path):
    path = tmp_path / "evil.pkl"
    path.write_bytes(b"cbuiltins\neval\n(S'1+1'\ntR.")
    with pytest.raises(RefusedGlobal, match=r"builtins\.eval"):
        restricted_load(path)


def test_dict_and_list_layouts_and_validation(tmp_path):
    (tmp_path / "tapvid_rgb_stacking.pkl").write_bytes(pickle.dumps([_video(), _video(5)]))
    data = TAPVidDataset(tmp_path, "TAPVid-RGBStacking")
    assert data.sequence_names == ["0", "1"] and data.load("1").num_frames == 5
    bad = _video()
    bad["points"][1, 2] = [0.5, 1.7]
    (tmp_path / "tapvid_davis.pkl").write_bytes(pickle.dumps({"cat": bad, "dog": _video()}))
    davis = TAPVidDataset(tmp_path)
    assert davis.load("dog").points.shape == (2, 4, 2)
    with pytest.raises(DataFormatError, match=r"video 'cat': visible point 1 at frame 2"):
        davis.load("cat")
    shapes = _video()
    shapes["occluded"] = shapes["occluded"][:, :3]
    (tmp_path / "tapvid_davis.pkl").write_bytes(pickle.dumps({"cat": shapes}))
    with pytest.raises(DataFormatError, match=r"tapvid_davis.pkl.*'cat'.*occluded"):
        TAPVidDataset(tmp_path).load("cat")
    (tmp_path / "tapvid_davis.pkl").write_bytes(b"not a pickle")
    with pytest.raises(DataFormatError, match="not a readable pickle"):
        TAPVidDataset(tmp_path)


def test_synthetic_tracks_are_exact():
    """A visible point lies on its object's pixels, and its texture moves with it."""
    spec = SPECS["TAPVid-DAVIS"][0]
    video = render_scene(spec.scene)
    frames, xy, occluded = point_tracks(video, spec.scene.seed)
    assert occluded.any() and (~occluded).any()
    instance = np.stack([f.instance_map for f in video])
    n, t = np.nonzero(~occluded)
    cols, rows = np.floor(xy[n, t, 0]).astype(int), np.floor(xy[n, t, 1]).astype(int)
    labels = instance[t, rows, cols]
    # each track stays on one label where visible
    for track in range(len(xy)):
        assert len(set(labels[n == track].tolist())) <= 1
    # colour under a visible point on a moving object is the texel of its anchor
    moving = [k for k in range(len(xy)) if np.ptp(xy[k, :, 0]) > 5 and (~occluded[k]).sum() > 3]
    assert moving
    k = moving[0]
    seen = np.flatnonzero(~occluded[k])
    colours = frames[seen, np.floor(xy[k, seen, 1]).astype(int),
                     np.floor(xy[k, seen, 0]).astype(int)].astype(int)
    assert np.abs(colours - colours[0]).max() <= 40  # same texel (shading varies slightly)


@pytest.mark.parametrize("env_id", IDS)
def test_check_env_and_both_passes(env_id):
    from gymnasium.utils.env_checker import check_env

    env = gym.make(env_id, query_mode="strided", render_mode="rgb_array")
    check_env(env.unwrapped, skip_render_check=False)
    observation, info = env.reset(seed=0)
    assert info["task"] == "points" and info["raster_size"] == (256, 256)
    assert observation["frame"].shape == (256, 256, 3)
    passes, revealed = [], {False: set(), True: set()}
    terminated = False
    while not terminated:
        reverse = bool(observation["reverse"])
        passes.append(reverse)
        revealed[reverse].update(observation["query_ids"][:observation["num_new"]].tolist())
        action = {"tracks": np.zeros((info["capacities"]["max_queries"], 2), np.float32),
                  "occluded": np.zeros(info["capacities"]["max_queries"], np.int8)}
        observation, _, terminated, _, step_info = env.step(action)
        assert step_info["reverse"] == bool(observation["reverse"]) or terminated
    assert passes.index(True) == info["num_frames"] and passes[-1] is True
    assert revealed[False] == set(range(info["num_queries"]))
    frames = env.unwrapped.scoring.queries(info["sequence"]).query_frames
    assert revealed[True] == set(np.flatnonzero(frames > 0).tolist())
    assert env.render().shape == (256, 256, 3)


def test_an_oracle_scores_one_and_first_mode_has_no_reversed_pass():
    env = gym.make("UniTrack/TAPVid-DAVIS-v0").unwrapped
    observation, info = env.reset()
    truth = env.scoring.queries(info["sequence"])
    terminated, steps = False, 0
    while not terminated:
        frame = info["frame_index"]
        observation, reward, terminated, _, info = env.step(
            {"tracks": truth.tracks[:, frame], "occluded": truth.occluded[:, frame]})
        steps += 1
    assert steps == env.scoring.load(info["sequence"]).num_frames
    assert info["metrics"]["AJ"] == info["metrics"]["OA"] == 1.0


def test_bad_actions_name_the_query():
    env = gym.make("UniTrack/TAPVid-DAVIS-v0").unwrapped
    _, info = env.reset()
    rows = info["num_queries"]
    with pytest.raises(InvalidActionError, match="must be a dict"):
        env.step(np.zeros((rows, 2)))
    with pytest.raises(InvalidActionError, match="tracks must be"):
        env.step({"tracks": np.zeros((rows + 1, 2)), "occluded": np.zeros(rows + 1)})
    tracks = np.zeros((rows, 2))
    active = int(np.flatnonzero(env.scoring.queries(info["sequence"]).query_frames == 0)[0])
    tracks[active] = np.nan
    with pytest.raises(InvalidActionError, match=f"frame 0: query {active}:"):
        env.step({"tracks": tracks, "occluded": np.zeros(rows)})


def test_full_resolution_and_real_fixture(shared_data, tmp_path):
    root = shared_data / "TAPVid"
    env = gym.make("UniTrack/TAPVid-DAVIS-v0", root=root, resolution="full").unwrapped
    assert env.sequence_names == ["car-roundabout", "blackswan", "dog"]
    _, info = env.reset(options={"sequence": "car-roundabout"})
    assert info["raster_size"] == (256, 256) and info["num_queries"] == 19
    synthetic = gym.make("UniTrack/TAPVid-DAVIS-v0", resolution="full").unwrapped
    assert synthetic.reset()[1]["raster_size"] == (320, 180)


def test_cli_evaluate_then_score_the_folder_in_both_modes(tmp_path, capsys):
    import json

    from unitrack_env.evaluation.cli import main

    for mode in ("first", "strided"):
        out = tmp_path / mode
        assert main(["evaluate", "--env", "UniTrack/TAPVid-RGBStacking-v0", "--agent",
                     "lk-points", "--env-arg", f"query_mode={mode}", "--out", str(out),
                     "--quiet", "--format", "json"]) == 0
        played = json.loads(capsys.readouterr().out)
        assert sorted(p.name for p in (out / "data").iterdir()) == ["0.npz", "1.npz"]
        assert main(["score", "--env", "UniTrack/TAPVid-RGBStacking-v0", "--env-arg",
                     f"query_mode={mode}", "--results", str(out / "data"),
                     "--format", "json"]) == 0
        scored = json.loads(capsys.readouterr().out)
        assert scored["combined"] == pytest.approx(played["combined"])
        assert set(scored["combined"]) >= {"AJ", "delta_x_avg", "OA"}
    # the strided results are not the "first" queries: refused, naming the file
    assert main(["score", "--env", "UniTrack/TAPVid-RGBStacking-v0", "--results",
                 str(tmp_path / "strided" / "data")]) != 0
    assert "0.npz, field 'query_points'" in capsys.readouterr().err
