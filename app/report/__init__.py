"""The measurement report (HTML and PDF, matplotlib figures): presentation, not
numerics, so it lives in ``app`` beside the other front-end code.

:func:`~tunespec.app.report.report.write_report` with
:class:`~tunespec.app.report.report.ReportData`.
"""
