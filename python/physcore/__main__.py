"""``python -m physcore``: the ``physcore`` command line (see :mod:`physcore.cli`)."""
from __future__ import annotations

import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
