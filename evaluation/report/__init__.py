"""The static HTML report of runs (``unitrack report``): see :mod:`.build`."""
