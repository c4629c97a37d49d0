"""``python -m anisosample``: the command line (:mod:`anisosample.cli`)."""

import sys

from .cli import main

sys.exit(main())
