"""Per-sequence attributes of SOT benchmarks: OTB-2015's published list, LaSOT's and UAV123's files.

Each benchmark tags a sequence with challenge attributes (illumination variation, occlusion,
...) and reports its trackers' scores per attribute, over the sequences having it.
:class:`AttributeSource` says where a format's tags are and reads them for one sequence:

- OTB-2015 (11 attributes): the list published with the benchmark (the per-sequence table of
  its website, as ``data/tb_100.txt`` of the authors' Python toolkit, jwlim/tracker_benchmark
  @ 6633078b, holds it), kept below as :data:`OTB2015_TABLE` under the OTB reader's names.
- LaSOT (14): one line of 14 comma-separated 0/1 flags per sequence, ``annos/att/<seq>.txt``
  of the LaSOT evaluation toolkit (HengLan/LaSOT_Evaluation_Toolkit), in the order of its
  ``run_tracker_performance_evaluation.m``; the LaSOT release itself has none, so the files
  are read from ``<root>/att/<seq>.txt`` (the toolkit's ``annos/att`` copied there).
- UAV123 (12): ``anno/UAV123/att/<seq>.txt`` of the release, 12 flags in the column order of
  the dataset's annotation document (``SV ARC LR FM FOC POC OV BC IV VC CM SOB``, not
  alphabetical); the 10 fps copy reads ``anno/UAV123_10fps/att/`` when present, else the 30
  fps files (the same sequences).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from unitrack_env.datasets.limits import read_limited
from unitrack_env.datasets.otb import canonical_otb_name
from unitrack_env.errors import DataFormatError

#: The largest attribute file read (one line of flags).
MAX_ATTRIBUTE_BYTES = 4096
_SEPARATORS = re.compile(r"[,\s]+")


@dataclass(frozen=True)
class AttributeSource:
    """A benchmark's attributes: codes and names in its order, and how to read a sequence's.

    ``read(dataset, sequence)`` gives the codes of one sequence, or None when the benchmark's
    files say nothing about it (a sequence outside the published list, no attribute file).
    ``source`` says where the tags come from (shown under the tables).
    """

    codes: tuple[str, ...]
    names: tuple[str, ...]
    read: Callable[[Any, str], frozenset[str] | None]
    source: str


OTB2015_CODES = ("IV", "SV", "OCC", "DEF", "MB", "FM", "IPR", "OPR", "OV", "BC", "LR")
OTB2015_NAMES = ("Illumination Variation", "Scale Variation", "Occlusion", "Deformation",
                 "Motion Blur", "Fast Motion", "In-Plane Rotation", "Out-of-Plane Rotation",
                 "Out-of-View", "Background Clutters", "Low Resolution")

#: OTB-2015's attributes of its 100 sequences, as published (see the module docstring); the
#: names are the OTB reader's (``Jogging.1`` for the published ``Jogging-1``).
OTB2015_TABLE = """
Basketball IV OCC DEF OPR BC; Biker SV OCC MB FM OPR OV LR; Bird1 DEF FM OV; Bird2 OCC DEF FM
IPR OPR; BlurBody SV DEF MB FM IPR; BlurCar1 MB FM; BlurCar2 SV MB FM; BlurCar3 MB FM; BlurCar4
MB FM; BlurFace MB FM IPR; BlurOwl SV MB FM IPR; Board SV MB FM OPR OV BC; Bolt OCC DEF IPR
OPR; Bolt2 DEF BC; Box IV SV OCC MB IPR OPR OV BC LR; Boy SV MB FM IPR OPR; Car1 IV SV MB FM BC
LR; Car2 IV SV MB FM BC; Car24 IV SV BC; Car4 IV SV; CarDark IV BC; CarScale SV OCC FM IPR OPR;
ClifBar SV OCC MB FM IPR OV BC; Coke IV OCC FM IPR OPR BC; Couple SV DEF FM OPR BC; Coupon OCC
BC; Crossing SV DEF FM OPR BC; Crowds IV DEF BC; Dancer SV DEF IPR OPR; Dancer2 DEF; David IV
SV OCC DEF MB IPR OPR; David2 IPR OPR; David3 OCC DEF OPR BC; Deer MB FM IPR BC LR; Diving SV
DEF IPR; Dog SV DEF OPR; Dog1 SV IPR OPR; Doll IV SV OCC IPR OPR; DragonBaby SV OCC MB FM IPR
OPR OV; Dudek SV OCC DEF FM IPR OPR OV BC; FaceOcc1 OCC; FaceOcc2 IV OCC IPR OPR; Fish IV;
FleetFace SV DEF MB FM IPR OPR; Football OCC IPR OPR BC; Football1 IPR OPR BC; Freeman1 SV IPR
OPR; Freeman3 SV IPR OPR; Freeman4 SV OCC IPR OPR; Girl SV OCC IPR OPR; Girl2 SV OCC DEF MB
OPR; Gym SV DEF IPR OPR; Human2 IV SV MB OPR; Human3 SV OCC DEF OPR BC; Human4.2 IV SV OCC DEF;
Human5 SV OCC DEF; Human6 SV OCC DEF FM OPR OV; Human7 IV SV OCC DEF MB FM; Human8 IV SV DEF;
Human9 IV SV DEF MB FM; Ironman IV SV OCC MB FM IPR OPR OV BC LR; Jogging.1 OCC DEF OPR;
Jogging.2 OCC DEF OPR; Jump SV OCC DEF MB FM IPR OPR; Jumping MB FM; KiteSurf IV OCC IPR OPR;
Lemming IV SV OCC FM OPR OV; Liquor IV SV OCC MB FM OPR OV BC; Man IV; Matrix IV SV OCC FM IPR
OPR BC; Mhyang IV DEF OPR BC; MotorRolling IV SV MB FM IPR BC LR; MountainBike IPR OPR BC;
Panda SV OCC DEF IPR OPR OV LR; RedTeam SV OCC IPR OPR LR; Rubik SV OCC IPR OPR; Shaking IV SV
IPR OPR BC; Singer1 IV SV OCC OPR; Singer2 IV DEF IPR OPR BC; Skater SV DEF IPR OPR; Skater2 SV
DEF FM IPR OPR; Skating1 IV SV OCC DEF OPR BC; Skating2.1 SV OCC DEF FM OPR; Skating2.2 SV OCC
DEF FM OPR; Skiing IV SV DEF IPR OPR; Soccer IV SV OCC MB FM IPR OPR BC; Subway OCC DEF BC;
Surfer SV FM IPR OPR LR; Suv OCC IPR OV; Sylvester IV IPR OPR; Tiger1 IV OCC DEF MB FM IPR OPR;
Tiger2 IV OCC DEF MB FM IPR OPR OV; Toy SV FM IPR OPR; Trans IV SV OCC DEF; Trellis IV SV IPR
OPR BC; Twinnings SV OPR; Vase SV FM IPR; Walking SV OCC DEF; Walking2 SV OCC LR; Woman IV SV
OCC DEF MB FM OPR
"""


def parse_attribute_table(text: str) -> dict[str, frozenset[str]]:
    """``{sequence: codes}`` of a ``"Name CODE CODE; Name CODE"`` table."""
    table = {}
    for item in " ".join(text.split()).split(";"):
        name, *codes = item.split()
        table[name] = frozenset(codes)
    return table


#: :data:`OTB2015_TABLE` read: ``{sequence: codes}``.
OTB2015_ATTRIBUTES: Mapping[str, frozenset[str]] = parse_attribute_table(OTB2015_TABLE)


def _otb_attributes(dataset: Any, sequence: str) -> frozenset[str] | None:
    return OTB2015_ATTRIBUTES.get(canonical_otb_name(sequence))


def read_attribute_flags(path: Path, codes: tuple[str, ...]) -> frozenset[str]:
    """The codes flagged 1 in an attribute file of ``len(codes)`` 0/1 values (one line)."""
    try:
        text = read_limited(path, MAX_ATTRIBUTE_BYTES, "attribute file").decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DataFormatError(path, f"cannot read attribute file ({err})") from None
    tokens = [t for t in _SEPARATORS.split(text) if t]
    if len(tokens) != len(codes) or not set(tokens) <= {"0", "1"}:
        raise DataFormatError(path, f"expected {len(codes)} flags 0 or 1, one per attribute "
                                    f"({' '.join(codes)}); found {' '.join(tokens[:20])!r}",
                              line=1)
    return frozenset(code for code, flag in zip(codes, tokens, strict=True) if flag == "1")


@dataclass(frozen=True)
class AttributeFiles:
    """A ``read`` of :class:`AttributeSource`: ``<folder>/<sequence>.txt``, the first found.

    ``folders`` are templates formatted with the dataset's ``root`` (and ``folder``, the
    UAV123 variant's); ``codes``: the flags' order. A value, so environments still pickle.
    """

    folders: tuple[str, ...]
    codes: tuple[str, ...]

    def __call__(self, dataset: Any, sequence: str) -> frozenset[str] | None:
        """The codes of ``sequence`` from its file (None: no folder has one)."""
        for template in self.folders:
            folder = template.format(root=dataset.root, folder=getattr(dataset, "folder", ""))
            path = Path(folder) / f"{sequence}.txt"
            if path.is_file():
                return read_attribute_flags(path, self.codes)
        return None


OTB2015 = AttributeSource(
    OTB2015_CODES, OTB2015_NAMES, _otb_attributes,
    "OTB-2015's published per-sequence attributes (jwlim/tracker_benchmark data/tb_100.txt)")

LASOT_CODES = ("IV", "POC", "DEF", "MB", "CM", "ROT", "BC", "VC", "SV", "FOC", "FM", "OV",
               "LR", "ARC")
LASOT_NAMES = ("Illumination Variation", "Partial Occlusion", "Deformation", "Motion Blur",
               "Camera Motion", "Rotation", "Background Clutter", "Viewpoint Change",
               "Scale Variation", "Full Occlusion", "Fast Motion", "Out-of-View",
               "Low Resolution", "Aspect Ratio Change")
LASOT = AttributeSource(
    LASOT_CODES, LASOT_NAMES,
    AttributeFiles(("{root}/att",), LASOT_CODES),
    "LaSOT evaluation toolkit's annos/att/<seq>.txt, read from <root>/att/")

UAV123_CODES = ("SV", "ARC", "LR", "FM", "FOC", "POC", "OV", "BC", "IV", "VC", "CM", "SOB")
UAV123_NAMES = ("Scale Variation", "Aspect Ratio Change", "Low Resolution", "Fast Motion",
                "Full Occlusion", "Partial Occlusion", "Out-of-View", "Background Clutter",
                "Illumination Variation", "Viewpoint Change", "Camera Motion", "Similar Object")
UAV123 = AttributeSource(
    UAV123_CODES, UAV123_NAMES,
    AttributeFiles(("{root}/anno/{folder}/att", "{root}/anno/UAV123/att"), UAV123_CODES),
    "UAV123's anno/<UAV123 or UAV123_10fps>/att/<seq>.txt")

__all__ = ["LASOT", "OTB2015", "OTB2015_ATTRIBUTES", "UAV123", "AttributeFiles",
           "AttributeSource", "parse_attribute_table", "read_attribute_flags"]
