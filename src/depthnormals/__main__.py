"""``python -m depthnormals``."""

import sys

from .cli import main

sys.exit(main())
