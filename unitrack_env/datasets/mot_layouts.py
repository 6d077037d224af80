"""How each MOTChallenge-layout benchmark lays out its files: one description per rule set.

MOT15/16/17/20, DanceTrack and SportsMOT share the sequence layout (``seqinfo.ini``,
``img1/``, ``gt/gt.txt``) and TrackEval's MOTChallenge scoring; they differ in where the
split folders are, which file lists a split's sequences, how frames are numbered, whether
public detections ship, and how the test server wants results. :class:`MOTLayout` states
those differences, so the one reader (:mod:`unitrack_env.datasets.motchallenge`), the one
environment and the one benchmark serve every rule set.

Sources of the facts below:

- DanceTrack (github.com/DanceTrack/DanceTrack, README "Dataset" and "Competition"):
  ``dancetrack/{train,val,test}/dancetrack0001/{img1/00000001.jpg, gt/gt.txt, seqinfo.ini}``
  and ``{train,val,test}_seqmap.txt``; gt rows ``frame, id, x, y, w, h, 1, 1, 1``; scored
  with TrackEval's ``run_mot_challenge.py``; no detections ship; test results go to the
  server as ``tracker.zip`` holding a folder named ``tracker`` with one
  ``dancetrack000x.txt`` per video ("archive tracker folder, instead of txt files").
- SportsMOT (github.com/MCG-NJU/SportsMOT, README "Data Format" and codes/README "How to
  eval"): ``dataset/{train,val,test}/<VIDEO>/{img1/000001.jpg, gt/gt.txt, seqinfo.ini}``
  and ``splits_txt/{train,val,test}.txt`` (videos ``v_-6Os86HzwCs_c001``, ...), "organized
  in the form of MOT Challenge 17", gt rows ``frame, id, x, y, w, h, 1, 1, 1`` (ids from 0);
  results one ``VIDEONAME.txt`` per video, scored with TrackEval; no detections ship.
- MOT15/16/17/20 (motchallenge.net): ``{train,test}/<SEQ>/``, frames ``000001.jpg``,
  public detections in ``det/det.txt``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from unitrack_env.errors import DataFormatError


@dataclass(frozen=True)
class MOTLayout:
    """Where one MOTChallenge-layout benchmark keeps its files.

    Attributes:
        name: the rule set, as TrackEval's ``BENCHMARK`` and score reports name it.
        splits: the split folders it has.
        splits_folder: folder of the split folders under the root ("": the root itself).
        seqmap: file listing a split's sequences, ``{split}`` filled in ("": none; every
            folder with a ``seqinfo.ini`` is a sequence).
        frame_digits: digits of the frame files' names (``000001.jpg``: 6).
        public_detections: whether ``<seq>/det/det.txt`` ship with the data.
        class_column: whether ``gt.txt`` has the class and visibility columns (8, 9).
        submission_folder: the test split's results are written in this sub-folder of the
            result folder ("": directly), the folder the test server wants zipped.
    """

    name: str
    splits: tuple[str, ...] = ("train", "test")
    splits_folder: str = ""
    seqmap: str = ""
    frame_digits: int = 6
    public_detections: bool = True
    class_column: bool = True
    submission_folder: str = ""

    def split_dir(self, root: Path, split: str) -> Path:
        """The folder of ``split``'s sequences under the benchmark's ``root``."""
        return root / self.splits_folder / split if self.splits_folder else root / split

    def seqmap_path(self, root: Path, split: str) -> Path | None:
        """The file listing ``split``'s sequences (None: the layout has none)."""
        return root / self.seqmap.format(split=split) if self.seqmap else None

    def result_dir(self, folder: Path, split: str) -> Path:
        """Where results of ``split`` go in a result folder (the test server's layout)."""
        return folder / self.submission_folder if split == "test" and \
            self.submission_folder else folder


LAYOUTS: MappingProxyType[str, MOTLayout] = MappingProxyType({
    "MOT15": MOTLayout("MOT15", class_column=False),
    "MOT16": MOTLayout("MOT16"),
    "MOT17": MOTLayout("MOT17"),
    "MOT20": MOTLayout("MOT20"),
    "DanceTrack": MOTLayout("DanceTrack", ("train", "val", "test"), seqmap="{split}_seqmap.txt",
                            frame_digits=8, public_detections=False,
                            submission_folder="tracker"),
    "SportsMOT": MOTLayout("SportsMOT", ("train", "val", "test"), splits_folder="dataset",
                           seqmap="splits_txt/{split}.txt", public_detections=False),
})
"""Rule set -> its layout (read-only)."""


def read_seqmap(path: Path) -> list[tuple[int, str]]:
    """The sequence names of a seqmap file with their 1-based lines.

    A first line ``name`` is TrackEval's header (DanceTrack's seqmaps have it, SportsMOT's
    ``splits_txt`` files do not); blank lines are skipped. Names must be plain folder names.
    """
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataFormatError(path, f"cannot be read as a list of sequence names ({exc})"
                              ) from None
    names: list[tuple[int, str]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        name = line.strip()
        if not name or (number == 1 and name == "name"):
            continue
        if "/" in name or "\\" in name or name in (".", ".."):
            raise DataFormatError(path, f"'{name}' is not a sequence folder name", line=number)
        names.append((number, name))
    if not names:
        raise DataFormatError(path, "lists no sequences")
    return names
