"""Frozen entry point of the ``tunespec`` command line (see ``packaging/tunespec.spec``)."""

import multiprocessing
import sys

from tunespec.app.cli import main

if __name__ == "__main__":
    multiprocessing.freeze_support()
    sys.exit(main())
