"""Evaluation: runners, official-format writers, scorers, reports and the CLI."""
