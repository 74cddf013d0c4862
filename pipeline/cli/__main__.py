"""``python -m pipeline.cli``: the ``recap`` command run as a module."""

import sys

from pipeline.cli import main

sys.exit(main())
