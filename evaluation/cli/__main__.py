"""``python -m unitrack_env.evaluation.cli``: the ``unitrack`` command."""

import sys

from . import main

sys.exit(main())
