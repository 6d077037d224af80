"""Every exception of the package survives pickling (worker processes send them home)."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest

from unitrack_env.errors import (
    CheckpointError,
    DataFormatError,
    InvalidActionError,
    UnknownSequenceError,
)
from unitrack_env.errors import CheckpointError as ReExported


@pytest.mark.parametrize("error", [
    DataFormatError(Path("/data/MOT17/train/S/gt/gt.txt"), "duplicate id 3 in frame 7",
                    line=12, field="id"),
    DataFormatError("seqinfo.ini", "missing", field="seqLength"),
    DataFormatError("a.txt", "plain"),
    CheckpointError("/ckpt/model.pth", "missing keys: layer1.0.conv1.weight"),
    CheckpointError(None, "partial load"),
    InvalidActionError("num_tracks=2.7 is not an integer"),
    UnknownSequenceError("no sequence 'X'; this environment has: A, B"),
], ids=lambda e: type(e).__name__)
def test_round_trip_keeps_type_message_and_fields(error: Exception) -> None:
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is type(error)
    assert str(back) == str(error)
    assert back.args == error.args
    assert getattr(back, "__dict__", {}) == getattr(error, "__dict__", {})


def test_checkpoint_error_is_the_same_class_everywhere() -> None:
    assert ReExported is CheckpointError


def test_subclass_round_trips() -> None:
    class Sub(DataFormatError):
        pass

    globals()["Sub"] = Sub  # picklable by reference
    Sub.__qualname__ = "Sub"
    error = Sub("f.txt", "bad", line=3)
    back = pickle.loads(pickle.dumps(error))
    assert type(back) is Sub and str(back) == "f.txt, line 3: bad" and back.line == 3
