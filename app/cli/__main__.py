"""``python -m tunespec.app.cli``: the ``tunespec`` command line."""

import sys

from tunespec.app.cli import main

sys.exit(main())
