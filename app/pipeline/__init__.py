"""The measurement, sequenced once for every front end (Qt-free).

Every front end runs :mod:`~tunespec.app.pipeline.jobs` (capture, process, calibrate,
estimate, export: frozen inputs, a progress/cancel handle): the CLI's single-step
commands, ``tunespec run``/``demo`` (:mod:`~tunespec.app.pipeline.run`, ``run(plan)``
for a :class:`~tunespec.app.pipeline.plan.Plan`) and the GUI wizard. The jobs run the
steps of :mod:`~tunespec.app.pipeline.steps` (each chain written once) and
:mod:`~tunespec.app.pipeline.capture` (the one place resume and retake are decided),
and write :mod:`~tunespec.app.pipeline.folder` (the one measurement folder layout).
Layers: ``app.cli``, ``app.gui -> app.pipeline -> devices -> core``; nothing here
imports Qt.
"""
