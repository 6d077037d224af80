"""Evaluation: runs, scorecard, analysis, report, plots, tuning and the CLI, a sub-package each."""
