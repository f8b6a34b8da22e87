"""``python -m partcal``."""

import sys

from .cli import main

sys.exit(main())
