"""Cost of the reset-time image checks (limits at the door) against decoding the same files.

Every frame and annotation is checked when a sequence is opened: its header (PNG ``IHDR`` /
JPEG start-of-frame: format and size, refused above 8192 x 8192 before decoding) and its
tail (end marker: a truncated file). Prints, over every JPEG/PNG of the real fixtures, the
check's cost per file, a plain header-free tail read (the check before issue 22) and a full
``cv2.imread``, and the ratios. A 3,315-frame sequence (MOT20-05) pays the check once per
frame at reset.

Usage: python benchmarks/door_checks.py [--data ../shared/data] [--repeats 5]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import cv2

from unitrack_env.frames import check_complete

REPO = Path(__file__).resolve().parents[1]


def tail_only(path: Path) -> bytes:
    """Read the last 64 bytes of a file (what the check did before the header was read)."""
    with path.open("rb") as handle:
        size = handle.seek(0, 2)
        handle.seek(max(0, size - 64))
        return handle.read()


def best_seconds(fn: Callable[[Path], object], files: list[Path], repeats: int) -> float:
    """Best total wall time of ``fn`` over ``files`` in ``repeats`` passes."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for path in files:
            fn(path)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    files = sorted(p for p in args.data.rglob("*") if p.suffix.lower() in (".jpg", ".png"))
    if not files:
        raise SystemExit(f"no .jpg/.png files under {args.data}")
    check = best_seconds(check_complete, files, args.repeats)
    tail = best_seconds(tail_only, files, args.repeats)
    decode = best_seconds(lambda p: cv2.imread(str(p)), files, max(1, args.repeats // 2))
    per = 1e6 / len(files)
    print(f"{len(files)} images under {args.data}")
    print(f"  check at reset (header + tail): {check * per:8.1f} us/file")
    print(f"  tail read only (before)       : {tail * per:8.1f} us/file  "
          f"check/tail = {check / tail:.2f}")
    print(f"  cv2.imread (decode)           : {decode * per:8.1f} us/file  "
          f"check/decode = {check / decode:.4f}")
    print(f"  MOT20-05 (3,315 frames) at this rate: {check * per * 3315 / 1e6:.2f} s at reset")


if __name__ == "__main__":
    main()
