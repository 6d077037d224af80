"""What a finished run says beyond its metrics: error events, paired comparisons, tables.

* :mod:`.events` - per-frame error events of a run (``load_events``, ``event_counts``);
* :mod:`.intervals` - a run's per-metric intervals (``run_intervals``) and two runs compared
  with a paired interval (``compare_runs``);
* :mod:`.compare` - the paired jackknife and block bootstrap behind those intervals;
* :mod:`.crosscheck` - MOTChallenge scores cross-checked with py-motmetrics;
* :mod:`.tables` - metrics as a table fitted to the terminal, CSV or JSON.
"""
