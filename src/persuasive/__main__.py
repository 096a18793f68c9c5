"""``python -m persuasive``: the same command line as the ``persuasive`` script."""

import sys

from .cli import main

sys.exit(main())
