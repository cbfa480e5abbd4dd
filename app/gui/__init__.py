"""The Qt application: main window, wizard, panels, plots, editors and workers.

Everything under ``tunespec.app.gui`` needs the ``gui`` extra (PySide6 and
pyqtgraph); the CLI and the pipeline never import it (see the import contracts
in ``pyproject.toml``).
"""
