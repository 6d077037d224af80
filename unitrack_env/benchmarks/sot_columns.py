"""The scorecard columns of the SOT benchmarks: OTB (the default), LaSOT and GOT-10k val (opt-in).

The paper's Table 2 reports SOT on OTB-2015, so the default card keeps that column alone.
LaSOT and GOT-10k val are opt-in columns of their own (``--tasks sot,sot-lasot,sot-got10k``),
each titled with its benchmark: with ``--data``, ``<data>/LaSOT`` and ``<data>/GOT-10k`` (the
environments' folders) are played when present, else the environments' synthetic defaults
(marked † in the table, as every column on synthetic data).
"""

from __future__ import annotations

from unitrack_env.benchmarks.views import Head, ScorecardColumn

#: How far a SOT cell moves: the ranges measured by ``benchmarks/sot_stability.py`` on the
#: fixture clips (docs/envs/sot-protocols.md, "How reproducible a SOT number is").
SPREAD = ("SOT heads: across runtimes and thread counts a clip's AUC moved by at most 0.2 "
          "points; with one grey level changed on 64 pixels a frame, by up to 4.0 "
          "(benchmarks/sot_stability.py, docs/envs/sot-protocols.md).")
#: The box heads on an OTB-sized search area, as the default SOT column measures them.
_SOT = {"input_size": (3, 520, 520), "head_seconds": 0.02, "note": SPREAD}


def _sot_column(title: str, env_id: str, metrics: tuple[str, ...], order: float,
                **options: object) -> ScorecardColumn:
    """A SOT column: the XCorr and DCF heads and the repeat-box baseline, on ``metrics``."""
    return ScorecardColumn(
        title, (env_id,),
        (Head("unitrack-xcorr", "XCorr", metrics), Head("unitrack-dcf", "DCF", metrics)),
        Head("repeat-box", "repeat-box", metrics, appearance=False),
        ("XCorr", metrics[0]), order=order, **_SOT, **options)


#: OTB-2015: the paper's SOT column (success AUC, precision at 20 px).
OTB_COLUMN = _sot_column("SOT", "UniTrack/OTB-v0", ("AUC", "Precision@20px"), 1)
#: LaSOT (its test split when the root has ``testing_set.txt``), opt-in.
LASOT_COLUMN = _sot_column("SOT (LaSOT)", "UniTrack/LaSOT-v0",
                           ("AUC", "Precision@20px", "NormPrecision"), 1.1, opt_in=True,
                           task="sot-lasot")
#: GOT-10k's val split (the environment's default split), opt-in: AO and SR0.5.
GOT10K_COLUMN = _sot_column("SOT (GOT-10k val)", "UniTrack/GOT10k-v0", ("AO", "SR0.5"), 1.2,
                            opt_in=True, task="sot-got10k")
