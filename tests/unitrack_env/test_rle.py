"""The RLE checker reads COCO compressed strings exactly as pycocotools writes them."""

from __future__ import annotations

import numpy as np

from unitrack_env.datasets.rle import check_rle, rle_runs
from unitrack_env.datasets.rle import mask_api as mask_utils


def reference_runs(mask: np.ndarray) -> list[int]:
    flat = mask.flatten(order="F")
    change = np.flatnonzero(np.diff(flat)) + 1
    bounds = np.concatenate([[0], change, [flat.size]])
    runs = np.diff(bounds).tolist()
    return runs if flat[0] == 0 else [0, *runs]


def test_runs_match_pycocotools_on_random_masks():
    rng = np.random.default_rng(0)
    for trial in range(200):
        h, w = (int(v) for v in rng.integers(1, 80, 2))
        mask = (rng.random((h, w)) < rng.random()).astype(np.uint8)
        if trial % 5 == 0:
            mask[:] = trial % 2
        counts = mask_utils.encode(np.asfortranarray(mask))["counts"]
        assert rle_runs(counts).tolist() == reference_runs(mask), trial
        assert check_rle(counts, h, w) is None


def test_bad_strings_are_explained():
    assert "sum to 15 pixels" in check_rle(b"0;4", 3, 3)
    assert "not RLE text" in check_rle(b"0 4", 3, 3)
    assert "cut short" in check_rle(b"0P", 3, 3)
