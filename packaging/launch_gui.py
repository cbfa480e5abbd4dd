"""Frozen entry point of ``tunespec-gui`` (PyInstaller needs a script, not an entry point)."""

import multiprocessing
import sys

from tunespec.app.__main__ import main

if __name__ == "__main__":
    multiprocessing.freeze_support()
    sys.exit(main())
