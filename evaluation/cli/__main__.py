"""``python -m unitrack_env.evaluation.cli``: the ``unitrack`` command."""

import sys

from . import main

if __name__ == "__main__":  # imported (by doctest collection, say), it runs nothing
    sys.exit(main())
