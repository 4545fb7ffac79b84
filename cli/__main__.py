"""``python -m foosball_gym.cli``: the ``foosball`` command without its console script."""

import sys

from . import main

sys.exit(main())
