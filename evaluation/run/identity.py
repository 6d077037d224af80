"""What makes a finished sequence reusable: fingerprints of a run's inputs and results.

A run's identity covers the environment id and arguments, the agent's import reference and
options, and the content of every file an option names (a checkpoint, a detections file);
a sequence's fingerprint adds its input files (:meth:`SequenceEnv.sequence_inputs
<unitrack_env.envs.base.SequenceEnv.sequence_inputs>`). The result digest covers every byte
of the result files a sequence wrote.

None of them depends on where things live: the data folder (``root``) is left out of the
identity and input files are named relative to it; files named by options (a checkpoint) and
the agent's code (:func:`~unitrack_env.evaluation.run.agent_code.agent_code`: its file and the
modules of ``unitrack_env.agents`` it imports) count by base name and content. A run folder
copied to another machine, or resumed with the data or the checkpoint moved elsewhere, reuses
its sequences; different data, weights or code replay them.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import unitrack_env
from unitrack_env.fingerprint import files_fingerprint, sequence_files

from .agent_code import code_manifest


def _named_file(value: Any) -> Path | None:
    """The existing file a string option value names, if it names one."""
    if not isinstance(value, str) or not value or len(value) >= 4096:
        return None
    path = Path(value).expanduser()
    try:
        return path if path.is_file() else None
    except OSError:
        return None


def _named_files(values: Iterable[Any]) -> list[Path]:
    """Existing files named by string option values (also inside lists)."""
    found: list[Path] = []
    for value in values:
        if isinstance(value, (list, tuple)):
            found += _named_files(value)
        elif (path := _named_file(value)) is not None:
            found.append(path)
    return found


def placeless(value: Any, like: Any = None) -> Any:
    """An option value with the folders of the files it names left out.

    A string naming an existing file becomes the file's base name (its content is in the
    identity). ``like`` is the same option of the run at hand when ``value`` comes from an
    older run, whose files may have moved since: ``value`` is then read as a file name where
    ``like`` names an existing file.
    """
    probe = value if like is None else like
    if isinstance(value, (list, tuple)):
        probes = probe if isinstance(probe, (list, tuple)) and len(probe) == len(value) \
            else value
        return [placeless(v, p) for v, p in zip(value, probes, strict=True)]
    if isinstance(value, str) and _named_file(probe) is not None:
        return Path(value).name
    return value


def placeless_options(options: dict[str, Any], like: dict[str, Any] | None = None
                      ) -> dict[str, Any]:
    """:func:`placeless` for every option (``like``: the options of the run at hand)."""
    return {k: placeless(v, (like or {}).get(k)) for k, v in options.items()}


def placeless_reference(reference: str | None) -> str | None:
    """``path/to/agent.py:Class`` as ``agent.py:Class``; module references are unchanged.

    The file's content is in the identity.
    """
    if reference is None:
        return None
    target, sep, name = reference.rpartition(":")
    if sep and (target.endswith(".py") or "/" in target or "\\" in target):
        return f"{Path(target).name}:{name}"
    return reference


def _shown(options: dict[str, Any], name: str) -> str:
    return repr(options[name]) if name in options else "unset"


def option_changes(old: dict[str, Any], new: dict[str, Any], label: str) -> list[str]:
    """``["<label> <name>: <old> -> <new>", ...]`` for every option that differs (sorted)."""
    return [f"{label} {name}: {_shown(old, name)} -> {_shown(new, name)}"
            for name in sorted(old.keys() | new.keys()) if _shown(old, name) != _shown(new, name)]


@dataclass(frozen=True)
class RunIdentity:
    """A digest of everything but the data that decides a sequence's results.

    ``code`` is the agent's code manifest (:func:`~.agent_code.code_manifest`), kept in each
    record so that a replay can say which file changed and :mod:`.restamp` can tell an edit
    of the code alone.
    """

    digest: str
    code: dict[str, str] = field(default_factory=dict, compare=False)

    @classmethod
    def of(cls, spec: Any, code: dict[str, str] | None = None) -> RunIdentity:
        """The identity of a :class:`~unitrack_env.evaluation.run.run_spec.RunSpec`.

        ``code``: the agent's code manifest to assume (default: the files as they are now).
        """
        env_kwargs = {k: v for k, v in spec.env_kwargs.items() if k != "root"}
        described = json.dumps(
            {"env": spec.env_id, "env_kwargs": placeless_options(env_kwargs),
             "agent": placeless_reference(spec.agent_ref or spec.agent),
             "agent_kwargs": placeless_options(spec.agent_kwargs),
             "version": unitrack_env.__version__},
            sort_keys=True, default=str,
        )
        if code is None:
            code = code_manifest(spec.agent_ref or spec.agent)
        files = _located_anywhere(_named_files([*spec.agent_kwargs.values(),
                                                *env_kwargs.values()]))
        text = f"{described}\n{files}\n{json.dumps(code, sort_keys=True)}"
        return cls(hashlib.blake2b(text.encode(), digest_size=16).hexdigest(), dict(code))

    def sequence_fingerprint(self, inputs: Iterable[Path], root: Path | None = None) -> str:
        """This identity combined with a sequence's input files.

        Files are named relative to ``root`` (the data folder); files outside it keep their
        full names.
        """
        return hashlib.blake2b(f"{self.digest}:{files_fingerprint(inputs, root)}".encode(),
                               digest_size=16).hexdigest()

    def stamp(self, inputs: Iterable[Path], root: Path | None = None, data: str = "") -> Stamp:
        """What a sequence's record keeps of this identity and its input files.

        ``data``: the fingerprint of its data files alone (:func:`.integrity.data_fingerprint`).
        """
        return Stamp(self.sequence_fingerprint(inputs, root), self.code, data)


@dataclass(frozen=True)
class Stamp:
    """A sequence's input fingerprint and the agent's code manifest, as its record keeps them."""

    inputs: str
    code: dict[str, str] = field(default_factory=dict, compare=False)
    data: str = field(default="", compare=False)

    def apply(self, record: Any) -> None:
        """Stamp a freshly played :class:`~.episode.SequenceRecord`."""
        record.inputs, record.code = self.inputs, dict(self.code)
        if self.data:
            record.data = self.data


def _located_anywhere(paths: Iterable[Path]) -> str:
    """A digest of files by base name and every byte, whatever folder holds them."""
    each = sorted(files_fingerprint([path], path.parent, content=True) for path in set(paths))
    return hashlib.blake2b("\n".join(each).encode(), digest_size=16).hexdigest()


def result_digest(folder: Path, sequence: str, all_sequences: Iterable[str]) -> str:
    """Digest of the result files of ``sequence`` in ``folder`` (every byte)."""
    folder = Path(folder)
    if not folder.is_dir():
        return files_fingerprint([])
    files = sequence_files(folder, sequence, all_sequences, shared=False)
    return files_fingerprint(files, folder, content=True)
