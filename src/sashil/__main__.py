"""``python -m sashil`` is the ``sashil`` command."""

import sys

from sashil.cli import main

sys.exit(main())
