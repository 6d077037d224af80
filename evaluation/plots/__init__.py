"""``unitrack plot``: figures and tables of run folders (also drawn by ``unitrack report``).

* :mod:`.curves` - success and precision plots (each run's benchmark gives its curves);
* :mod:`.attributes` - per-attribute scores of runs: a table (Markdown, CSV) and a radar chart;
* :mod:`.figures` - matplotlib on demand and one way to save a figure (the scorecard's too).
"""
