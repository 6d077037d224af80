"""Limits at the door: image headers read without decoding, id ranges and counts, and the
scorer's memory check (issue 22)."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from unitrack_env.datasets.davis import read_label_png
from unitrack_env.datasets.limits import (
    MAX_ID,
    MAX_IMAGE_PIXELS,
    MAX_TRACKS,
    check_id,
    check_track_count,
    image_size,
)
from unitrack_env.errors import DataFormatError
from unitrack_env.frames import check_complete, read_rgb
from unitrack_env.metrics.motchallenge import check_matrix_memory


def _png_header(width: int, height: int) -> bytes:
    def chunk(kind: bytes, body: bytes) -> bytes:
        return (struct.pack(">I", len(body)) + kind + body
                + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 3, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")


@pytest.mark.parametrize("suffix,params", [
    (".jpg", []),
    (".jpg", [cv2.IMWRITE_JPEG_PROGRESSIVE, 1]),  # SOF2
    (".png", []),
])
def test_header_size_is_the_decoded_size(tmp_path: Path, suffix, params):
    image = np.random.default_rng(0).integers(0, 255, (37, 53, 3), dtype=np.uint8)
    path = tmp_path / f"frame{suffix}"
    assert cv2.imwrite(str(path), image, params)
    assert image_size(path) == (("JPEG" if suffix == ".jpg" else "PNG"), (53, 37))


def test_jpeg_with_a_large_exif_segment_is_measured(tmp_path: Path):
    image = np.zeros((20, 30, 3), dtype=np.uint8)
    ok, jpeg = cv2.imencode(".jpg", image)
    app1 = b"\xff\xe1" + struct.pack(">H", 60002) + b"\0" * 60000  # before the frame header
    path = tmp_path / "exif.jpg"
    path.write_bytes(jpeg.tobytes()[:2] + app1 + jpeg.tobytes()[2:])
    assert image_size(path) == ("JPEG", (30, 20))
    assert read_rgb(path).shape == (20, 30, 3)


def test_every_real_fixture_image_passes_the_door(shared_data: Path):
    images = [p for p in shared_data.rglob("*") if p.suffix.lower() in (".jpg", ".png")]
    assert len(images) > 500
    for path in images:
        check_complete(path)  # raises on a bad or too large one
        kind, size = image_size(path)
        assert size is not None and size[0] * size[1] <= MAX_IMAGE_PIXELS, path
    # the largest frame of a supported benchmark (DAVIS full resolution) fits 8x over
    assert 3840 * 2160 * 8 <= MAX_IMAGE_PIXELS


def test_png_bomb_is_refused_before_pillow_opens_it(tmp_path: Path):
    path = tmp_path / "00000.png"
    path.write_bytes(_png_header(100_000, 100_000))
    with pytest.raises(DataFormatError, match="100000x100000.*decompression bomb"):
        read_label_png(path)
    with pytest.raises(DataFormatError, match="100000x100000"):
        check_complete(path)


@pytest.mark.parametrize("pillow_limit", [1000, 100])  # 1600 px: Pillow warns, then refuses
def test_pillow_bomb_check_becomes_a_data_error_not_an_escape(tmp_path: Path, monkeypatch,
                                                             pillow_limit):
    from PIL import Image

    path = tmp_path / "00000.png"
    Image.fromarray(np.zeros((40, 40), dtype=np.uint8)).save(path)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", pillow_limit)  # a user's stricter limit
    with pytest.raises(DataFormatError, match="too large to decode"):
        read_label_png(path)


def test_png_named_jpg_decodes_as_the_png_it_is(tmp_path: Path):
    image = np.full((8, 12, 3), 200, dtype=np.uint8)
    ok, png = cv2.imencode(".png", image)
    path = tmp_path / "000001.jpg"
    path.write_bytes(png.tobytes())
    assert read_rgb(path).shape == (8, 12, 3)
    path.write_bytes(png.tobytes()[:-20])
    with pytest.raises(DataFormatError, match=r"truncated image \(a PNG file named \.jpg\)"):
        check_complete(path)


def test_track_count_limit_is_inclusive():
    check_track_count(np.arange(MAX_TRACKS), "gt.txt")
    with pytest.raises(DataFormatError, match="10,001 distinct ground-truth ids"):
        check_track_count(np.arange(MAX_TRACKS + 1), "gt.txt", field="id")


def test_check_id_range_and_type():
    assert check_id(MAX_ID, "a.json", field="id") == MAX_ID
    assert check_id(7.0, "a.json", field="id") == 7
    with pytest.raises(DataFormatError, match="out of range"):
        check_id(2**70, "a.json", field="id")
    with pytest.raises(DataFormatError, match="must be an integer"):
        check_id(1.5, "a.json", field="id")
    with pytest.raises(DataFormatError, match="must be an integer"):
        check_id(True, "a.json", field="id")


def test_scoring_refuses_matrices_larger_than_the_machine():
    data = {"num_gt_ids": 10_000_000, "num_tracker_ids": 10_000_000}
    with pytest.raises(DataFormatError, match=r"SEQ: 10,000,000 distinct track ids .* GiB"):
        check_matrix_memory(data, Path("results/SEQ.txt"), "SEQ")
    check_matrix_memory({"num_gt_ids": 1200, "num_tracker_ids": 5000}, Path("r.txt"), "SEQ")


def test_score_sequence_names_the_results_file_when_the_matrices_cannot_fit(tmp_path, monkeypatch):
    from unitrack_env.datasets.synthetic import ensure_synthetic
    from unitrack_env.metrics import motchallenge

    seq = ensure_synthetic("MOT17", "motchallenge") / "train" / "SYN-01"
    rows = "".join(f"{1 + i % 50},{i + 1},10,10,20,40,1,-1,-1,-1\n" for i in range(400))
    results = tmp_path / "SYN-01.txt"
    results.write_text(rows)
    monkeypatch.setattr(motchallenge, "_memory_bytes", lambda: 1024)
    with pytest.raises(DataFormatError, match=r"SYN-01\.txt: SYN-01: 400 distinct track ids"):
        motchallenge.score_sequence(seq, results, benchmark="MOT17")


def test_action_ids_beyond_int64_are_out_of_range_and_object_ints_still_work():
    from unitrack_env.errors import InvalidActionError
    from unitrack_env.spaces.limits import checked_ids

    with pytest.raises(InvalidActionError, match="track id 1180591620717411303424 is out of"):
        checked_ids(np.array([3, 2**70], dtype=object), 2)
    assert checked_ids(np.array([3, 4], dtype=object), 2).tolist() == [3, 4]
    with pytest.raises(InvalidActionError, match="above"):
        checked_ids(np.array([3, 2**40], dtype=object), 2)
