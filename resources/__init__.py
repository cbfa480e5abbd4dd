"""Package data: camera sensitivities, chart reflectances, LED spectra, layouts, icons.

Read through :mod:`importlib.resources` (see ``tunespec.core.datasets``), never by
``__file__`` paths, so frozen (PyInstaller) builds keep working.
"""
