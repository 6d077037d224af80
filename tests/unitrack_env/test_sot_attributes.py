"""SOT attributes from the benchmarks' own files or published lists (OTB-2015, LaSOT, UAV123)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from unitrack_env.benchmarks import benchmark_for
from unitrack_env.datasets.otb import OTB100_SEQUENCES
from unitrack_env.datasets.sot_attributes import (
    OTB2015_ATTRIBUTES,
    OTB2015_CODES,
    UAV123_CODES,
    read_attribute_flags,
)
from unitrack_env.errors import DataFormatError

#: airplane-1's line in the LaSOT toolkit's annos/att/airplane-1.txt
#: (HengLan/LaSOT_Evaluation_Toolkit @ df5bfb98).
AIRPLANE_1 = "0,1,0,0,0,1,0,0,1,0,0,0,1,0\n"


def test_the_otb_list_covers_the_100_sequences_with_the_11_attributes() -> None:
    assert set(OTB2015_ATTRIBUTES) == {spec.name for spec in OTB100_SEQUENCES}
    assert len(OTB2015_ATTRIBUTES) == 100
    counts = Counter(code for codes in OTB2015_ATTRIBUTES.values() for code in codes)
    assert set(counts) == set(OTB2015_CODES)
    # the list's own counts (docs/envs/sot-attributes.md states them)
    assert dict(counts) == {"IV": 38, "SV": 65, "OCC": 49, "DEF": 44, "MB": 31, "FM": 43,
                            "IPR": 51, "OPR": 64, "OV": 14, "BC": 32, "LR": 10}
    assert OTB2015_ATTRIBUTES["Crossing"] == {"SV", "DEF", "FM", "OPR", "BC"}
    assert OTB2015_ATTRIBUTES["Human3"] == {"SV", "OCC", "DEF", "OPR", "BC"}
    assert OTB2015_ATTRIBUTES["Jogging.2"] == {"OCC", "DEF", "OPR"}


def test_otb_fixture_sequences_get_their_published_attributes(shared_data) -> None:
    bench = benchmark_for("UniTrack/OTB-v0", root=shared_data / "OTB")
    attributes = bench.sequence_attributes(["Crossing", "Human3"])
    assert attributes.codes == OTB2015_CODES and len(attributes.names) == 11
    assert dict(attributes.of) == {"Crossing": {"SV", "DEF", "FM", "OPR", "BC"},
                                   "Human3": {"SV", "OCC", "DEF", "OPR", "BC"}}
    assert attributes.metrics == ("AUC", "Precision@20px")


def _linked_lasot(shared_data: Path, root: Path) -> Path:
    (root / "airplane").mkdir(parents=True)
    (root / "airplane" / "airplane-1").symlink_to(shared_data / "LaSOT/airplane/airplane-1")
    (root / "testing_set.txt").write_text("airplane-1\n")
    return root


def test_lasot_reads_the_toolkits_attribute_files_from_root_att(shared_data, tmp_path) -> None:
    root = _linked_lasot(shared_data, tmp_path / "LaSOT")
    bench = benchmark_for("UniTrack/LaSOT-v0", root=root)
    assert bench.sequence_attributes(["airplane-1"]) is None  # the release has no att/
    (root / "att").mkdir()
    (root / "att" / "airplane-1.txt").write_text(AIRPLANE_1)
    attributes = benchmark_for("UniTrack/LaSOT-v0", root=root).sequence_attributes(
        ["airplane-1"])
    assert dict(attributes.of) == {"airplane-1": {"POC", "ROT", "SV", "LR"}}
    assert len(attributes.codes) == 14
    assert attributes.metrics == ("AUC", "Precision@20px", "NormPrecision")


def _linked_uav(shared_data: Path, root: Path) -> Path:
    for part in ("data_seq/UAV123_10fps/wakeboard7", "anno/UAV123_10fps/wakeboard7.txt"):
        (root / part).parent.mkdir(parents=True, exist_ok=True)
        (root / part).symlink_to(shared_data / "UAV123" / part)
    return root


def test_uav123_reads_its_att_files_the_10fps_copy_falling_back_to_30fps(shared_data,
                                                                        tmp_path) -> None:
    root = _linked_uav(shared_data, tmp_path / "UAV123")
    assert benchmark_for("UniTrack/UAV123-v0", root=root).sequence_attributes(
        ["wakeboard7"]) is None
    (root / "anno/UAV123/att").mkdir(parents=True)  # with anno/UAV123: name the variant
    (root / "anno/UAV123/att/wakeboard7.txt").write_text("1,0,1,0,0,0,0,0,0,0,1,0\n")
    of = benchmark_for("UniTrack/UAV123-v0", root=root, variant="10fps").sequence_attributes(
        ["wakeboard7"]).of
    assert dict(of) == {"wakeboard7": {"SV", "LR", "CM"}}
    (root / "anno/UAV123_10fps/att").mkdir()
    (root / "anno/UAV123_10fps/att/wakeboard7.txt").write_text("0,1,0,0,0,0,0,0,0,0,0,1\n")
    of = benchmark_for("UniTrack/UAV123-v0", root=root, variant="10fps").sequence_attributes(
        ["wakeboard7"]).of
    assert dict(of) == {"wakeboard7": {"ARC", "SOB"}}


@pytest.mark.parametrize(("text", "found"), [("1,0,1\n", "'1 0 1'"),
                                            ("1,0,1,0,0,0,0,0,0,0,1,2\n", "2'")])
def test_a_bad_attribute_file_is_named_with_what_it_holds(tmp_path, text, found) -> None:
    path = tmp_path / "seq.txt"
    path.write_text(text)
    with pytest.raises(DataFormatError, match="expected 12 flags 0 or 1, one per attribute") \
            as err:
        read_attribute_flags(path, UAV123_CODES)
    assert str(path) in str(err.value) and found in str(err.value)


@pytest.mark.parametrize("env_id", ["UniTrack/GOT10k-v0", "UniTrack/TrackingNet-v0",
                                    "UniTrack/DAVIS-v0"])
def test_benchmarks_without_attributes_say_none(env_id) -> None:
    bench = benchmark_for(env_id)
    assert bench.sequence_attributes(bench.sequence_names) is None


def test_synthetic_otb_sequences_are_in_no_published_list() -> None:
    bench = benchmark_for("UniTrack/OTB-v0")
    assert bench.synthetic and bench.sequence_attributes(bench.sequence_names) is None


def test_attribute_sources_pickle_with_their_format() -> None:
    import pickle

    from unitrack_env.benchmarks.otb import SOT_FORMATS

    for key in ("otb", "lasot", "uav123"):
        assert pickle.loads(pickle.dumps(SOT_FORMATS[key])) == SOT_FORMATS[key]
