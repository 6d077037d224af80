"""Multi-object tracking on BDD100K box tracking (8 classes), scored with TrackEval."""

from __future__ import annotations

from pathlib import Path

from unitrack_env.benchmarks.bdd100k import BDD100KBenchmark
from unitrack_env.datasets.bdd100k import CLASSES, BDDSequence
from unitrack_env.envs.classed_mot import ClassedMOTEnv, FrameDetections


class BDD100KEnv(ClassedMOTEnv[BDDSequence]):
    """Multi-object tracking by association on BDD100K box tracking (8 classes).

    ## Description
    Each episode is one video of BDD100K's MOT set (``images/track/<split>/<video>/
    <video>-%07d.jpg``, ``labels/box_track_20/<split>/<video>.json``). At every step the
    agent sees one frame and that frame's detections of the 8 classes, read from the user's
    detection files in BDD100K's result format (BDD100K ships none), and answers with its
    tracks as in the MOT envs. At the end, TrackEval's ``BDD100K`` dataset class scores the
    video per class, per super-category and combined: the distractor categories (other
    person, trailer, other vehicle) and ``crowd`` boxes of the ground truth are ignore
    regions, as TrackEval treats them.

    Without ``root`` (and ``$UNITRACK_DATA/BDD100K``) it plays a small synthetic split in the
    exact layout, with its own detections (see Data below).

    ## Observation space
    The MOT envs' ``Dict`` (``frame``, ``boxes`` ``(x, y, w, h)``, ``scores``,
    ``num_detections``) and ``classes``: ``(max_detections,) int64``, 1 pedestrian, 2 rider,
    3 car, 4 bus, 5 truck, 6 train, 7 motorcycle, 8 bicycle (TrackEval's order).

    ## Action space
    The MOT envs' tracks (``ids``, ``boxes`` ``(x, y, w, h)``, ``num_tracks``). Each track
    takes the class of the detection it overlaps most in the frame (IoU > 0), else the class
    it had last, else car.

    ## Rewards
    0 at every step: the ignore regions need the whole frame's matching; the video's metrics
    come at the end.

    ## Episode end
    ``terminated=True`` after the last frame; ``info["metrics"]`` holds TrackEval's metrics
    of the video: detection-averaged over the classes unprefixed (``HOTA``, ``MOTA``, ...),
    and ``car/HOTA``, ``pedestrian/HOTA``, ..., ``HUMAN/HOTA``, ``VEHICLE/HOTA``,
    ``BIKE/HOTA``, ``cls_comb_cls_av/HOTA``, ``cls_comb_det_av/HOTA``, ... . As in
    TrackEval's Evaluator, ``cls_comb_cls_av`` averages all 8 classes, one with neither
    ground truth nor results counting 0: the real sample's labels given back as results
    (``unitrack score --env UniTrack/BDD100K-v0 --root <shared>/data/BDD100K --results
    <a copy of its labels folder>``) score HOTA 100.0 and ``cls_comb_cls_av/HOTA`` 75.0
    (6 of its 8 classes occur).

    ## Data, results and commands
    The synthetic default is **not benchmark data**: two 640x360 videos of the project's
    synthetic scenes (textured figures that walk, cross and occlude) labelled with BDD100K's
    class names, a distractor (``other person``) and a ``crowd`` box, and simulated
    detections (``detections/box_track_20/val``). It exercises the reader, the environment
    and the scoring offline; its scores say nothing about BDD100K or about a tracker on it.
    For real numbers, download BDD100K's MOT 2020 images and labels
    (``images/track/<split>/``, ``labels/box_track_20/<split>/``) and put your detector's
    output in the result format beside them, in ``detections/box_track_20/<split>/`` (or
    pass ``--env-arg detections=<folder>``).

    Results are written as ``<out>/data/<video>.json`` in BDD100K's result format (a JSON list
    of frames with ``name``, ``videoName``, ``frameIndex`` and ``labels``, each with ``id``,
    ``category``, ``box2d`` and ``score``). Scoring reads only the labels and the result
    files, not the frames:

        unitrack evaluate --env UniTrack/BDD100K-v0 --agent iou --out runs/bdd-synthetic
        unitrack score --env UniTrack/BDD100K-v0 --results runs/bdd-synthetic/data
        unitrack evaluate --env UniTrack/BDD100K-v0 --root data/BDD100K --agent iou --out runs/b
        unitrack score --env UniTrack/BDD100K-v0 --root data/BDD100K --results my-results

    ``evaluate`` on a root without a video's frame folder is refused before the first frame,
    naming the folder (``images/track/<split>/<video>``); ``score`` needs no frames.

    ## Arguments
    - ``root``: BDD100K's folder (holding ``labels/box_track_20/`` and ``images/track/``);
      default the synthetic split. Playing needs the frames, scoring does not: a root
      without a video's frame folder is refused at construction, naming it.
    - ``split``: ``"val"`` (or ``"train"``; every video of the split has its labels).
    - ``detections``: a folder of ``<video>.json`` in BDD100K's result format (default
      ``<root>/detections/box_track_20/<split>``; refused at construction when there is
      none).
    - ``sequences``, ``max_detections``, ``max_tracks`` and the shared episode options.
    """

    requires = ("trackeval",)
    benchmark_class = BDD100KBenchmark
    default_split = "val"
    detections_advice = ("BDD100K ships none, "
                                        "pass detections=<a folder of <video>.json in "
                                        "BDD100K's result format>")
    num_classes = len(CLASSES)
    default_class = CLASSES.index("car") + 1

    def _check_sequences(self) -> None:
        """Refuse a video without its frame folder (scoring needs none, playing does)."""
        for name in self.sequence_names:
            self.dataset.check_images(name)

    def _frame_detections_of(self, sequence: BDDSequence) -> list[FrameDetections]:
        return [FrameDetections.from_corners(
            [label.box for label in labels], [label.score for label in labels],
            [CLASSES.index(label.category) + 1 for label in labels])
            for labels in sequence.detections]

    def sequence_inputs(self, name: str) -> list[Path]:
        """The frames, the label file and the detection file of ``name``."""
        frames = sorted(self.dataset.image_dir(name).glob("*.jpg"))
        return [*frames, self.dataset.ground_truth_path(name),
                self.dataset.detection_path(name)]
