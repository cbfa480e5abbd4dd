"""TuneSpec application layer: the CLI (no Qt) and the Qt workstation GUI.

Only modules under ``tunespec.app`` import PySide6 or pyqtgraph, and only the GUI
modules do; the CLI runs on a machine without Qt.
"""
