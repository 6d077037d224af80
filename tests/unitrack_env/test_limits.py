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


def _tiff_header(width: int, height: int, order: str = "II", kind: int = 4) -> bytes:
    """A classic TIFF whose first directory states ``width`` x ``height`` (no pixels)."""
    end = "<" if order == "II" else ">"
    fmt = "HH" if kind == 3 else "I"
    entries = b"".join(struct.pack(f"{end}HHI", tag, kind, 1)
                       + struct.pack(f"{end}{fmt}", value, *([0] if kind == 3 else []))
                       for tag, value in ((256, width), (257, height)))
    magic = b"II*\x00" if order == "II" else b"MM\x00*"
    return magic + struct.pack(f"{end}I", 8) + struct.pack(f"{end}H", 2) + entries + b"\0" * 4


@pytest.mark.parametrize("ext,params", [(".tif", []), (".bmp", []), (".webp", []),
                                        (".webp", [cv2.IMWRITE_WEBP_QUALITY, 101]),
                                        (".ppm", []), (".pgm", [])])
def test_other_formats_are_measured_from_their_headers(tmp_path: Path, ext, params):
    channels = 1 if ext == ".pgm" else 3
    image = np.random.default_rng(0).integers(0, 255, (37, 53, channels), dtype=np.uint8)
    path = tmp_path / f"frame{ext}"
    assert cv2.imwrite(str(path), image, params)
    assert image_size(path)[1] == (53, 37)
    check_complete(path)  # accepted: measured, small
    assert read_rgb(path).shape[:2] == (37, 53)


@pytest.mark.parametrize("order,kind", [("II", 4), ("MM", 4), ("II", 3)])
def test_a_tiff_bomb_is_refused_before_decoding(tmp_path: Path, order: str, kind: int):
    path = tmp_path / "000001.tif"
    path.write_bytes(_tiff_header(20000, 20000, order, kind))
    assert image_size(path) == ("TIFF", (20000, 20000))
    with pytest.raises(DataFormatError, match=r"header says 20000x20000 pixels.*refused before "
                                              "decoding"):
        read_rgb(path)


def test_frames_in_a_format_without_a_measurable_header_are_refused(tmp_path: Path):
    path = tmp_path / "000001.jp2"
    path.write_bytes(b"\x00\x00\x00\x0cjP  \r\n\x87\n" + b"\0" * 64)  # JPEG 2000 signature
    with pytest.raises(DataFormatError, match="not an image format whose size can be checked "
                                              "before decoding"):
        read_rgb(path)


def test_annotation_files_over_their_byte_limit_are_refused_before_reading(tmp_path: Path,
                                                                          monkeypatch):
    import unitrack_env.datasets.motchallenge_tables as tables
    import unitrack_env.datasets.posetrack_json as pj
    from unitrack_env.datasets.motchallenge_tables import parse_table
    from unitrack_env.datasets.posetrack_json import read_posetrack_json

    monkeypatch.setattr(tables, "MAX_TEXT_BYTES", 1000)
    big = tmp_path / "gt.txt"
    big.write_text("1,1,0,0,10,10,1,1,1\n" * 100)  # 2,000 bytes
    with pytest.raises(DataFormatError, match=r"gt.txt: 2,000 bytes, more than the 1,000 bytes "
                                              "a MOTChallenge table may hold"):
        parse_table(big, 9, tuple("abcdefghi"))
    monkeypatch.setattr(pj, "MAX_VIDEO_JSON_BYTES", 100)
    video = tmp_path / "video.json"
    video.write_text('{"images": [], "annotations": [], "pad": "' + "x" * 200 + '"}')
    with pytest.raises(DataFormatError, match="video.json: 2.. bytes, more than"):
        read_posetrack_json(video)


def test_deep_json_is_one_error_naming_the_file(tmp_path: Path):
    from unitrack_env.datasets.posetrack_json import read_posetrack_json
    from unitrack_env.datasets.youtube_vis import parse_vis_json

    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    for reader in (read_posetrack_json, parse_vis_json):
        with pytest.raises(DataFormatError) as info:
            reader(path)
        assert str(info.value).startswith(f"{path}: JSON nested") and "\n" not in str(info.value)
