"""``python -m pipeline.cli``: the same command line as ``uavpipe`` and ``python -m pipeline``."""

import sys

from pipeline.cli import main

sys.exit(main())
