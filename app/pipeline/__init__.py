"""The measurement, sequenced once for every front end (Qt-free).

``tunespec run``, ``tunespec demo`` and the GUI wizard go through this package:
:mod:`~tunespec.app.pipeline.plan` (what to measure: :class:`Plan`),
:mod:`~tunespec.app.pipeline.steps` (the step functions: frozen inputs, ``progress``
and ``should_stop``, frozen results), :mod:`~tunespec.app.pipeline.folder` (the one
measurement folder layout) and :mod:`~tunespec.app.pipeline.run` (``run(plan)``).
Layers: ``app.gui -> app.pipeline -> devices -> core``; nothing here imports Qt.
"""
