"""``unitrack cache``: inspect, prune and clear the feature cache.

Commands::

    unitrack cache info  [--dir DIR] [--runs N] [--json]   location, cap, size per model
                                                          identity, entries, recent hit rates
    unitrack cache prune [--dir DIR] [--max-size SIZE]    evict least recently used entries
                                                          down to SIZE (default: the cap)
    unitrack cache clear [--dir DIR]                      remove every entry and statistic

The folder is ``--dir``, else ``$UNITRACK_FEATURE_CACHE``, else the user cache folder (see
:func:`unitrack_env.agents.appearance.feature_cache.default_cache_dir`); the cap is
``$UNITRACK_FEATURE_CACHE_MAX`` or 10 GiB.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

#: ``unitrack cache --help`` opens with this (``unitrack --help`` shows the command's summary).
DESCRIPTION = "The on-disk feature cache of the UniTrack heads (on by default)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The actions of ``unitrack cache``: ``info``, ``prune``, ``clear``."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--dir", help="cache folder (default: $UNITRACK_FEATURE_CACHE, else "
                                      "$UNITRACK_CACHE/features, else the user cache "
                                      "folder; Linux: ~/.cache/unitrack-env/features)")
    sub = parser.add_subparsers(dest="cache_command", required=True, metavar="ACTION",
                                help="info, prune or clear")
    info = sub.add_parser("info", parents=[common],
                          help="location, cap, size per model, entries, recent hit rates")
    info.add_argument("--runs", type=int, default=10, help="recent runs to show (default 10)")
    info.add_argument("--json", action="store_true", help="print JSON instead of tables")
    prune = sub.add_parser("prune", parents=[common],
                           help="evict least recently used entries down to a size")
    prune.add_argument("--max-size", help="e.g. 5GiB or 500MB (default: the cap, "
                                          "$UNITRACK_FEATURE_CACHE_MAX or 10 GiB)")
    sub.add_parser("clear", parents=[common], help="remove every entry and statistic")


def run_summary(cache_run: Any, root: Path | None) -> str | None:
    """The feature cache's lines after a run (its hits; where stored features went)."""
    # lazy: start-up cost (torch via the appearance package: `cache --help` 0.22 s, else 2 s)
    from unitrack_env.agents.appearance.cache_config import default_cache_dir, format_size
    from unitrack_env.agents.appearance.feature_cache import FeatureCache

    stats = cache_run.stats()
    folder = root or default_cache_dir()
    if stats is None or folder is None:
        return None
    if not stats.stored:
        return stats.summary()
    cache = FeatureCache(folder)
    usage = cache.usage()
    where = f" --dir {folder}" if root else ""
    return (f"{stats.summary()}\nfeature cache: {folder} now holds {format_size(usage.bytes)} "
            f"in {usage.entries} entries (cap {format_size(cache.max_size)}); "
            f"`unitrack cache info{where}` shows them, "
            f"`unitrack cache prune{where} --max-size 2GiB` trims them")


def _cache(args: argparse.Namespace) -> Any:
    # lazy: start-up cost (torch, as in run_summary)
    from unitrack_env.agents.appearance.cache_config import CACHE_DIR_ENV, default_cache_dir
    from unitrack_env.agents.appearance.feature_cache import FeatureCache

    root = Path(args.dir).expanduser() if args.dir else default_cache_dir()
    if root is None:
        raise ValueError(f"the feature cache is turned off (${CACHE_DIR_ENV}="
                         f"{os.environ.get(CACHE_DIR_ENV)}); pass --dir to manage a folder")
    return FeatureCache(root)


def _when(timestamp: float) -> str:
    if not timestamp:
        return "-"
    return datetime.datetime.fromtimestamp(timestamp).strftime("%Y-%m-%d %H:%M:%S")


def _model_label(model: dict[str, Any]) -> tuple[str, str]:
    described = model.get("model", {}) if isinstance(model.get("model"), dict) else {}
    parts = [str(described[k]) for k in ("arch", "layer") if described.get(k)]
    if described.get("runtime"):
        parts.append(str(described["runtime"]))
    weights = str(described.get("weights", "?"))
    if described.get("digest"):
        weights += f" ({str(described['digest'])[:8]})"
    return " ".join(parts) or "?", weights


def cache_info(cache: Any, runs: int = 10) -> dict[str, Any]:
    """What ``unitrack cache info --json`` prints: a JSON-friendly summary of ``cache``."""
    usage = cache.usage()
    records = cache.runs(limit=runs)
    return {
        "location": str(cache.root),
        "max_size": cache.max_size,
        "bytes": usage.bytes,
        "entries": usage.entries,
        "temp_files": usage.temp_files,
        "models": [
            {"folder": ns.name, "entries": ns.entries, "bytes": ns.bytes,
             "last_used": ns.last_used, "model_key": ns.model.get("model_key"),
             "input_size": ns.model.get("input_size"), "dtype": ns.model.get("dtype"),
             "model": ns.model.get("model", {})}
            for ns in usage.namespaces
        ],
        "runs": [
            {"run": r.run, "started": r.started, "updated": r.updated,
             "processes": r.processes, "lookups": r.stats.lookups, "hits": r.stats.hits,
             "hit_rate": None if math.isnan(r.stats.hit_rate) else r.stats.hit_rate,
             **{k: getattr(r.stats, k) for k in ("misses", "corrupt", "stored", "evicted")}}
            for r in records
        ],
    }


def _print_info(cache: Any, console: Console, runs: int) -> None:
    # lazy: start-up cost (torch, as in run_summary)
    from unitrack_env.agents.appearance.cache_config import format_size

    info = cache_info(cache, runs)
    share = info["bytes"] / info["max_size"] if info["max_size"] else float("inf")
    console.print(f"feature cache: {info['location']}", highlight=False)
    console.print(f"  {format_size(info['bytes'])} in {info['entries']} entries, "
                  f"cap {format_size(info['max_size'])} ({100 * share:.0f}% used)",
                  highlight=False)
    if info["temp_files"]:
        console.print(f"  {info['temp_files']} temporary files (writers at work, or killed; "
                      "`unitrack cache prune` removes old ones)")
    if info["models"]:
        table = Table(title="entries per model identity")
        for column in ("model", "weights", "input HxW", "entries", "size", "last used"):
            table.add_column(column, justify="right" if column in ("entries", "size") else "left")
        for ns in info["models"]:
            arch, weights = _model_label(ns)
            size = ns["input_size"]
            geometry = f"{size[0]}x{size[1]} {ns['dtype'] or ''}" if size else ns["folder"]
            table.add_row(arch, weights, geometry, str(ns["entries"]), format_size(ns["bytes"]),
                          _when(ns["last_used"]))
        console.print(table)
    if info["runs"]:
        table = Table(title=f"last {len(info['runs'])} runs")
        for column in ("started", "processes", "frames", "hits", "hit rate", "computed",
                       "evicted"):
            table.add_column(column, justify="left" if column == "started" else "right")
        for r in info["runs"]:
            rate = "-" if r["hit_rate"] is None else f"{100 * r['hit_rate']:.0f}%"
            table.add_row(_when(r["started"]), str(r["processes"]), str(r["lookups"]),
                          str(r["hits"]), rate, str(r["misses"] + r["corrupt"]),
                          str(r["evicted"]))
        console.print(table)
    elif not info["entries"]:
        console.print("  empty: nothing cached yet")


def run(args: argparse.Namespace, console: Console) -> int:
    """Run ``unitrack cache <info|prune|clear>``."""
    # lazy: start-up cost (torch, as in run_summary)
    from unitrack_env.agents.appearance.cache_config import format_size

    cache = _cache(args)
    if args.cache_command == "info":
        if args.json:
            print(json.dumps(cache_info(cache, args.runs), indent=2))
        else:
            _print_info(cache, console, args.runs)
    elif args.cache_command == "prune":
        entries, size = cache.prune(args.max_size)
        left = cache.usage()
        console.print(f"pruned {entries} entries ({format_size(size)}) from {cache.root}; "
                      f"{format_size(left.bytes)} in {left.entries} entries remain",
                      highlight=False)
    else:
        entries, size = cache.clear()
        console.print(f"removed {entries} entries ({format_size(size)}) from {cache.root}",
                      highlight=False)
        if cache.kept:  # what the cache did not write is not its to delete
            shown = ", ".join(os.path.relpath(p, cache.root) for p in cache.kept[:5])
            more = f" and {len(cache.kept) - 5} more" if len(cache.kept) > 5 else ""
            console.print(f"kept {len(cache.kept)} file(s) in {cache.root} that the cache did "
                          f"not write: {shown}{more}", highlight=False)
    return 0
