"""``python -m zmap.cli``: the ``zmap`` command."""

import sys

from .app import main

sys.exit(main())
