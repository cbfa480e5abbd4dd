"""panels package (importing it applies the Qt binding work-arounds)."""

import tunespec.app.gui.qt_compat  # noqa: F401
