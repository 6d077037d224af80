"""``unitrack evaluate --backend ray``: a run's sequences as Ray tasks.

Each sequence is one ``num_cpus=1`` task on the scorecard's Ray backend
(:func:`~unitrack_env.evaluation.run.backends.ray_backend`: a local Ray, or a cluster at
``address``). The task plays the sequence in a scratch folder on whichever machine runs it
and sends back its result files and record as bytes; this process writes them into the run
folder (results first, the record last: the record marks the sequence done), so workers need
no shared file system and the files are the bytes a local run writes. The runner keeps its
own rules around this: the folder's lock and manifest, resume, scoring. A sequence that fails
(or whose task dies) fails alone; the progress bar advances by each finished sequence's
frames.
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from unitrack_env.io import atomic_write_bytes

from .backends import ray_backend
from .episode import OutputError, SequenceRecord
from .workers import SequenceFailure, _play_one


def play_remote(item: tuple[Any, str, Any], threads: int) -> dict[str, Any]:
    """A Ray task: play one sequence in a scratch folder; its outcome and files as bytes."""
    spec, sequence, stamp = item
    if threads:
        import torch  # lazy: start-up cost (+1.4 s; agents without a network never load torch)

        torch.set_num_threads(threads)
    with tempfile.TemporaryDirectory(prefix="unitrack-ray-") as scratch:
        status, payload = _play_one(spec, scratch, sequence, stamp)
        root = Path(scratch)
        files = {str(p.relative_to(root)): p.read_bytes()
                 for sub in ("data", "sequences") for p in sorted((root / sub).rglob("*"))
                 if p.is_file()} if status == "ok" else {}
    return {"status": status, "payload": payload, "files": files}


def store(out: Path, files: dict[str, bytes]) -> None:
    """Write a played sequence's files into the run folder, its record last."""
    for relative in sorted(files, key=lambda name: name.startswith("sequences")):
        atomic_write_bytes(out / relative, files[relative])


def play_on_ray(spec: Any, out: Path, todo: list[str], stamps: dict[str, Any],
                lengths: dict[str, int], *, workers: int, address: str | None,
                bar: Any) -> tuple[dict[str, Any], dict[str, str]]:
    """Play ``todo`` as Ray tasks; return (records, failures) as the local workers do."""
    records: dict[str, SequenceRecord] = {}
    failures: dict[str, str] = {}
    items = [(spec, name, stamps[name]) for name in todo]
    with ray_backend(workers, address) as run_tasks:
        for (_, name, _), outcome in run_tasks(play_remote, items):
            bar.advance(lengths[name])
            if isinstance(outcome, BaseException):
                failures[name] = SequenceFailure.describe(outcome)
            elif outcome["status"] != "ok":
                failures[name] = outcome["payload"]
            else:
                try:
                    store(out, outcome["files"])
                except OSError as exc:
                    raise OutputError(exc.errno, f"cannot write the results of '{name}' to "
                                                 f"{out}: {exc.strerror or exc}") from exc
                records[name] = SequenceRecord.from_json(outcome["payload"])
    return records, failures
