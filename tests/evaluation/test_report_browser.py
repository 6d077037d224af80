"""The HTML report as a person sees it: opened in headless Chromium, screenshot, DOM checked.

Chromium is driven through the DevTools protocol over a pipe (``--remote-debugging-pipe``:
NUL-terminated JSON on file descriptors 3 and 4), so neither websockets nor playwright are
needed. `.ci/run` installs Debian's ``chromium`` when it is missing; elsewhere the test skips
and says why.
"""

from __future__ import annotations

import base64
import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from unitrack_env.evaluation.report.build import build_report
from unitrack_env.evaluation.run.runner import run

CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--remote-debugging-pipe",
                  "--window-size=1280,1600"]


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    pytest.skip("no chromium on PATH (`apt-get install -y chromium`; .ci/run installs it)")


def _onto_3_and_4(read_end: int, write_end: int) -> None:
    """In the child: Chromium reads commands on fd 3 and writes replies on fd 4."""
    a, b = os.dup(read_end), os.dup(write_end)  # out of the way of 3 and 4 first
    os.dup2(a, 3)
    os.dup2(b, 4)


class Browser:
    """A minimal DevTools-protocol client over Chromium's debugging pipe."""

    def __init__(self, profile: Path) -> None:
        cmd_r, cmd_w = os.pipe()  # we write commands, chromium reads fd 3
        res_r, res_w = os.pipe()  # chromium writes fd 4, we read
        self.proc = subprocess.Popen(
            [chromium(), *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "about:blank"],
            pass_fds=(cmd_r, res_w, 3, 4), stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, preexec_fn=lambda: _onto_3_and_4(cmd_r, res_w))
        os.close(cmd_r)
        os.close(res_w)
        self.out, self.inp = os.fdopen(cmd_w, "wb"), os.fdopen(res_r, "rb")
        self.next_id, self.session = 0, None
        self.buffer = b""

    def _read(self) -> dict[str, Any]:
        while b"\0" not in self.buffer:
            chunk = os.read(self.inp.fileno(), 1 << 20)
            if not chunk:
                raise RuntimeError("chromium closed the debugging pipe")
            self.buffer += chunk
        message, self.buffer = self.buffer.split(b"\0", 1)
        return json.loads(message)

    def send(self, method: str, session: bool = True, **params: Any) -> dict[str, Any]:
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params}
        if session and self.session:
            message["sessionId"] = self.session
        self.out.write(json.dumps(message).encode() + b"\0")
        self.out.flush()
        while True:
            reply = self._read()
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply.get("result", {})

    def wait_event(self, method: str) -> None:
        while self._read().get("method") != method:
            pass

    def open(self, url: str) -> None:
        target = self.send("Target.createTarget", session=False, url="about:blank")
        self.session = self.send("Target.attachToTarget", session=False,
                                 targetId=target["targetId"], flatten=True)["sessionId"]
        self.send("Page.enable")
        self.send("Page.navigate", url=url)
        self.wait_event("Page.loadEventFired")

    def js(self, expression: str) -> Any:
        result = self.send("Runtime.evaluate", expression=expression, returnByValue=True,
                           awaitPromise=True)
        if "exceptionDetails" in result:
            raise RuntimeError(f"{expression}: {result['exceptionDetails']}")
        return result["result"].get("value")

    def screenshot(self, path: Path) -> None:
        data = self.send("Page.captureScreenshot", format="png")["data"]
        path.write_bytes(base64.b64decode(data))

    def close(self) -> None:
        try:
            self.send("Browser.close", session=False)
        except (RuntimeError, OSError):
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def colour_pixels(path: Path, colour: tuple[int, int, int], tolerance: int = 70) -> int:
    """How many pixels of an image are within ``tolerance`` of ``colour`` in each channel."""
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.int32)
    return int((np.abs(rgb - np.array(colour)).max(axis=2) <= tolerance).sum())


@pytest.mark.slow
def test_report_in_chromium(tmp_path: Path) -> None:
    from unitrack_env.evaluation.report.thumbs import GT_COLOUR, TRACK_COLOUR

    chromium()
    runs = tmp_path / "runs"
    run("UniTrack/MOT16-v0", "iou", out=runs / "iou", progress=False)
    run("UniTrack/MOT16-v0", "iou", out=runs / "iou-strict", progress=False,
        agent_kwargs={"iou_threshold": 0.7})
    index = build_report([runs / "iou", runs / "iou-strict"], tmp_path / "report",
                         resamples=100)
    sequences = json.loads((runs / "iou" / "metrics.json").read_text())["per_sequence"]

    browser = Browser(tmp_path / "profile")
    try:
        browser.open(index.resolve().as_uri())
        browser.screenshot(tmp_path / "report.png")
        rows = browser.js("Array.from(document.querySelectorAll('#metrics-table tbody tr'))"
                          ".map(r => r.dataset.sequence)")
        thumb = browser.js("(() => {const i = document.querySelector('img.thumb.idsw');"
                           "if (!i) return null; i.scrollIntoView();"
                           "return new Promise(ok => {const done = () => ok({src: "
                           "i.getAttribute('src'), w: i.naturalWidth});"
                           "i.complete ? done() : i.addEventListener('load', done)})})()")
        col = browser.js("Array.from(document.querySelectorAll('#metrics-table th'))"
                         ".findIndex(h => h.textContent.startsWith('HOTA'))")
        values = ("Array.from(document.querySelectorAll('#metrics-table tbody tr'))"
                  f".map(r => parseFloat(r.cells[{col}].dataset.value))")
        browser.js(f"document.querySelectorAll('#metrics-table th')[{col}].click()")
        ascending = browser.js(values)
        browser.js(f"document.querySelectorAll('#metrics-table th')[{col}].click()")
        descending = browser.js(values)
    finally:
        browser.close()

    width, height = Image.open(tmp_path / "report.png").size
    assert width == 1280 and height > 800, "the screenshot is not the page"
    shot = np.asarray(Image.open(tmp_path / "report.png").convert("L"))
    assert shot.std() > 10, "the screenshot is blank"
    for seq in [*sequences, "COMBINED"]:
        assert seq in rows, f"no metrics row for {seq}"
    assert thumb is not None, "the report shows no ID-switch thumbnail"
    assert thumb["w"] > 0, "the switch thumbnail did not load in the browser"
    picture = index.parent / thumb["src"]
    assert colour_pixels(picture, GT_COLOUR) > 50, "no ground-truth box on the thumbnail"
    assert colour_pixels(picture, TRACK_COLOUR) > 50, "no track box on the thumbnail"
    assert ascending == sorted(ascending) and descending == sorted(ascending, reverse=True)
    assert ascending != descending


def label_patch(path: Path, colour: tuple[int, int, int], side: int = 5,
                tolerance: int = 60) -> bool:
    """Whether an image holds a solid ``side`` x ``side`` block of ``colour``: an id's label
    patch (box lines are at most 3 pixels wide, so only a label fills such a block)."""
    rgb = np.asarray(Image.open(path).convert("RGB"), dtype=np.int32)
    hit = (np.abs(rgb - np.array(colour)).max(axis=2) <= tolerance).astype(np.int32)
    sums = np.pad(hit, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    block = (sums[side:, side:] - sums[:-side, side:] - sums[side:, :-side]
             + sums[:-side, :-side])
    return bool((block == side * side).any())


LOADED_IMAGES = ("Promise.all(Array.from(document.images).map(i => i.complete ? 0 : "
                 "new Promise(ok => {i.onload = i.onerror = ok}))).then(() => "
                 "Array.from(document.images).map(i => ({src: i.getAttribute('src'), "
                 "w: i.naturalWidth, cls: i.closest('figure') ? "
                 "i.closest('figure').className : '', id: i.id})))")

#: The runs of the page test: a box MOT pair, a MOTS, a SOT and a VOS run (synthetic data).
PAGE_RUNS = (("mot-a", "UniTrack/MOT16-v0", "iou", {}),
             ("mot-b", "UniTrack/MOT16-v0", "iou", {"iou_threshold": 0.7}),
             ("mots", "UniTrack/MOTS-v0", "iou", {}),
             ("sot", "UniTrack/OTB-v0", "repeat-box", {}),
             ("vos", "UniTrack/DAVIS-v0", "repeat-mask", {}))


def _shoot(browser: Browser, shots: Path | None, name: str) -> None:
    """With ``UNITRACK_REPORT_SHOTS`` set, keep a compact screenshot there (docs/images)."""
    if shots is None:
        return
    path = shots / f"{name}.png"
    browser.js("document.querySelectorAll('img').forEach(i => {i.loading = 'eager'}); "
               + LOADED_IMAGES)  # lazy thumbnails below the fold load too
    browser.screenshot(path)
    shot = Image.open(path).convert("RGB")
    rows = np.nonzero((np.asarray(shot.convert("L")) < 250).any(axis=1))[0]
    bottom = int(rows.max()) + 16 if len(rows) else shot.height
    shot = shot.crop((0, 0, shot.width, min(shot.height, bottom)))
    shot = shot.resize((shot.width * 3 // 4, shot.height * 3 // 4), Image.LANCZOS)
    shot.quantize(256).save(path, optimize=True)


def _event_page(browser: Browser, index: Path, link: str, shots: Path | None,
                name: str) -> dict:
    """Open a sequence page from the index, then its first event page; what each shows."""
    from unitrack_env.evaluation.report.thumbs import GT_COLOUR, TRACK_COLOUR

    browser.open((index.parent / link).resolve().as_uri())
    _shoot(browser, shots, f"{name}-sequence")
    sequence = browser.js("({h1: document.querySelector('h1').textContent, "
                          "thumbs: document.querySelectorAll('img.thumb').length, "
                          "listed: document.querySelectorAll('#event-list-table tbody tr')"
                          ".length, legend: document.querySelector('.legend').textContent, "
                          "event: (document.querySelector('.thumbs a') || {}).href})")
    assert sequence["thumbs"] > 0 and sequence["listed"] > 0, f"{name}: {sequence}"
    assert "other tracks (grey)" in sequence["legend"]
    browser.open(sequence["event"])
    images = browser.js(LOADED_IMAGES)
    _shoot(browser, shots, f"{name}-event")
    nav = browser.js("Array.from(document.querySelectorAll('nav a')).map(a => a.className)")
    assert "sequence-page" in nav, f"{name}: the event page does not link its sequence"
    shown = {i["cls"] or i["id"]: i for i in images}
    assert shown["full"]["w"] > 0, f"{name}: the event's frame did not load"
    assert {"prev", "next"} & set(shown) and all(i["w"] > 0 for i in images), images
    event_dir = Path(sequence["event"].removeprefix("file://")).parent
    full = event_dir / shown["full"]["src"]
    assert label_patch(full, TRACK_COLOUR) or label_patch(full, GT_COLOUR), \
        f"{name}: no id label drawn on {full.name}"
    return sequence


@pytest.mark.slow
def test_report_pages_in_chromium(tmp_path: Path) -> None:
    """Index -> sequence page -> event page for box MOT, MOTS, SOT and VOS runs (issue 42).

    ``UNITRACK_REPORT_SHOTS=docs/images`` keeps the screenshots there (docs/report.md).
    """
    chromium()
    runs = tmp_path / "runs"
    for name, env_id, agent, options in PAGE_RUNS:
        run(env_id, agent, out=runs / name, progress=False, agent_kwargs=options,
            env_kwargs={"decode_frames": False})
    index = build_report([runs / name for name, *_ in PAGE_RUNS], tmp_path / "report",
                         thumbnails=6, resamples=100)
    shots = Path(os.environ["UNITRACK_REPORT_SHOTS"]) if os.environ.get(
        "UNITRACK_REPORT_SHOTS") else None
    browser = Browser(tmp_path / "profile")
    try:
        browser.open(index.resolve().as_uri())
        links = browser.js("Array.from(document.querySelectorAll('a.sequence-link'))"
                           ".map(a => [a.getAttribute('href'), a.textContent])")
        browser.js("document.getElementById('compare').scrollIntoView()")
        _shoot(browser, shots, "report-compare")
        rows = browser.js("Array.from(document.querySelectorAll('svg.forest .forest-row'))"
                          ".map(g => g.dataset.metric)")
        axis = browser.js("document.querySelector('svg.forest').textContent")
        seen = {}
        for name, *_ in PAGE_RUNS[:1] + PAGE_RUNS[2:]:
            link = next(href for href, text in links if text.startswith(f"{name} ("))
            seen[name] = _event_page(browser, index, link, shots, f"report-{name}")
    finally:
        browser.close()
    assert sorted(rows) == ["AssA", "DetA", "HOTA", "IDF1", "MOTA"], rows  # a row each
    assert "A - B in percent points (0: no difference" in axis
    assert all(seen[name]["h1"].startswith(f"{name} (") for name in seen)
