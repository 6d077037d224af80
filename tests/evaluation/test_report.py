"""`unitrack report`: a self-contained HTML page built from run folders (no browser here;
tests/evaluation/test_report_browser.py opens it in Chromium)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from unitrack_env.evaluation.cli import main
from unitrack_env.evaluation.report.thumbs import miss_bursts, sample
from unitrack_env.evaluation.run.runner import run

ENV = "UniTrack/MOT16-v0"


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("report")
    run(ENV, "iou", out=root / "a", progress=False, env_kwargs={"decode_frames": False})
    run(ENV, "iou", out=root / "b", progress=False, env_kwargs={"decode_frames": False},
        agent_kwargs={"iou_threshold": 0.7})
    (root / "a" / "videos").mkdir()
    (root / "a" / "videos" / "SYN-01.mp4").write_bytes(b"not really a video")
    return root / "a", root / "b"


def test_report_is_self_contained_and_complete(runs, tmp_path, capsys) -> None:
    a, b = runs
    out = tmp_path / "report"
    assert main(["report", str(a), str(b), "--out", str(out), "--thumbnails", "3",
                 "--resamples", "50"]) == 0
    assert "report:" in capsys.readouterr().out
    page = (out / "index.html").read_text(encoding="utf-8")
    assert not re.search(r"(src|href)=\"(https?:)?//", page), "nothing may load from the web"
    assert "<script src" not in page and "<link" not in page
    for seq in json.loads((a / "metrics.json").read_text())["per_sequence"]:
        assert page.count(f'data-sequence="{seq}" data-run=') == 2  # one row per run
        assert f'<section class="sequence" data-sequence="{seq}">' in page
    assert 'id="compare-table"' in page and "95% interval" in page
    thumbs = re.findall(r'<img loading="lazy" class="thumb (\w+)"[^>]* src="([^"]+)"', page)
    assert thumbs and {kind for kind, _ in thumbs} <= {"idsw", "miss"}
    assert sum(kind == "idsw" for kind, _ in thumbs) <= 3 * 4  # sampled: 3 per sequence & run
    for _, src in thumbs:
        assert (out / src).is_file() and (out / src.replace(".jpg", "-full.jpg")).is_file()
    assert "SYN-01.mp4#t=" in page  # click-through to the clip `render` made
    assert len(page) < 400_000
    _check_pages(out, page)


def _check_pages(out: Path, index: str) -> None:
    """Issue 42: a page per sequence, linked from the index; a page per pictured event, with
    the frames before and after it and links back and on."""
    links = re.findall(r'<a class="sequence-link" href="([^"]+)"', index)
    assert len(links) == 4 and all((out / link).is_file() for link in links)
    sequence = (out / links[0]).read_text(encoding="utf-8")
    assert 'id="event-list-table"' in sequence and "other tracks (grey)" in sequence
    events = re.findall(r'<figure><a href="([^"]+\.html)"><img', sequence)
    assert events and all((out / e).is_file() for e in events)
    event = (out / events[1]).read_text(encoding="utf-8")
    assert f'href="../{links[0]}"' in event and 'class="prev-event"' in event
    for kind in ("full", "prev", "next"):
        src = re.search(rf'<figure class="{kind}"><img (?:id="event-frame" )?src="([^"]+)"',
                        event)
        assert src and (out / events[1]).with_name(src[1]).is_file(), kind
    assert max(len((out / link).read_text()) for link in links) < 200_000


def test_every_drawn_object_carries_its_id_and_the_event_stands_out() -> None:
    from PIL import Image

    from unitrack_env.evaluation.report.thumbs import (
        GT_COLOUR,
        OTHER_COLOUR,
        TRACK_COLOUR,
        draw_event,
    )

    frame = Image.new("RGB", (640, 360), (40, 40, 40))
    rows = pd.DataFrame({  # gt 9 switched to track 4; gt 2 with track 7 elsewhere
        "type": ["tp", "idsw", "tp"], "gt_id": [9, 9, 2], "track_id": [4, 4, 7],
        "x": [100.0, 100.0, 400.0], "y": [100.0, 100.0, 80.0], "w": [60.0, 60.0, 50.0],
        "h": [150.0, 150.0, 160.0], "tx": [104.0, 104.0, 402.0], "ty": [98.0, 98.0, 84.0],
        "tw": [58.0, 58.0, 50.0], "th": [150.0, 150.0, 150.0]})
    img, crop = draw_event(frame, rows, 9, 4, None)
    rgb = np.asarray(img, dtype=int)

    def solid(colour, region, side=5):  # a label patch: lines are at most 3 pixels wide
        x0, y0, x1, y1 = region
        hit = (np.abs(rgb[y0:y1, x0:x1] - colour).max(axis=2) <= 40).astype(int)
        sums = np.pad(hit, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
        block = (sums[side:, side:] - sums[:-side, side:] - sums[side:, :-side]
                 + sums[:-side, :-side])
        return bool((block == side * side).any())

    assert solid(TRACK_COLOUR, (90, 60, 200, 100))  # "track 4" above the event's track
    assert solid(GT_COLOUR, (90, 250, 200, 290))  # "gt 9" below the event's ground truth
    context = np.abs(rgb[84:234, 400:403] - OTHER_COLOUR).max(axis=2)  # track 7's left edge
    assert context.min() > 40, "other tracks are faded, not drawn at full strength"
    assert crop[0] <= 100 and crop[2] >= 164 and crop[2] < 400  # around the event only


def test_report_of_a_scorecard_folder(tmp_path) -> None:
    card = {"version": 1, "models": ["m"], "tasks": ["mot"],
            "sources": {"mot": {"kind": "synthetic", "root": None, "env_id": ENV}},
            "rows": [{"model": "m", "task": "mot", "head": "UniTrack", "combined":
                      {"IDF1": 0.5, "HOTA": 0.4}, "per_sequence": {}}]}
    folder = tmp_path / "sc"
    folder.mkdir()
    (folder / "scorecard.json").write_text(json.dumps(card))
    (folder / "scorecard.svg").write_text("<svg xmlns='http://www.w3.org/2000/svg'/>")
    (folder / "scorecard_ci.json").write_text(json.dumps([
        {"model": "m", "task": "mot", "head": "UniTrack", "metric": "IDF1", "value": 0.5,
         "low": 0.41, "high": 0.58}]))
    assert main(["report", str(folder), "--out", str(tmp_path / "r")]) == 0
    page = (tmp_path / "r" / "index.html").read_text()
    assert 'id="scorecard"' in page and 'data-sequence="m"' in page
    assert (tmp_path / "r" / "scorecard.svg").is_file()
    assert 'id="ci-table"' in page and "[41.0, 58.0]" in page


def test_bad_input_is_one_line(tmp_path, capsys) -> None:
    assert main(["report", str(tmp_path / "nothing"), "--out", str(tmp_path / "r")]) == 2
    assert "not a finished run" in capsys.readouterr().err


def test_miss_bursts_and_sampling() -> None:
    fn = pd.DataFrame({"gt_id": [1, 1, 1, 2, 1], "frame": [3, 4, 5, 4, 9]})
    assert sorted(miss_bursts(fn)) == [(1, 3, 3), (1, 9, 1), (2, 4, 1)]
    assert sample(list(range(10)), 3) == [0, 3, 6] and sample([1], 5) == [1]


def test_masks_are_drawn_under_the_boxes() -> None:
    from PIL import Image

    from unitrack_env.evaluation.report.thumbs import GT_COLOUR, overlay_masks

    frame = Image.new("RGB", (200, 100), (40, 40, 40))
    mine, other = np.zeros((100, 200), bool), np.zeros((100, 200), bool)
    mine[20:60, 20:60], other[20:60, 120:160] = True, True
    rgb = np.asarray(overlay_masks(frame, {9: mine}, {4: mine, 7: other}, 9, 4, None), int)
    assert rgb[40, 40, 0] > 120 and rgb[40, 40, 1] < 60  # the event's track: filled red
    assert rgb[40, 140].max() - rgb[40, 140].min() < 10 < rgb[40, 140, 0] - 40  # grey, faded
    assert tuple(rgb[20, 40]) == GT_COLOUR and tuple(rgb[40, 40]) != GT_COLOUR  # outline
