"""The measurement record's options of ``run``, ``demo`` and ``report``.

One option per field of :data:`tunespec.app.pipeline.record.RECORD_FIELDS`
(``--operator``, ``--sample-id``, ``--chart-serial`` ...), checked as the
configuration's ``[provenance]`` is, with errors naming the option.
"""

from __future__ import annotations

import argparse
from typing import Any


def add_record_options(parser: argparse.ArgumentParser) -> None:
    """``--operator``, ``--sample-id`` ... in their own help group."""
    from tunespec.app.pipeline.record import RECORD_FIELDS

    group = parser.add_argument_group(
        "measurement record",
        "shown on the report's first page and in summary.json; kept in the "
        "measurement folder's record.json (these replace the fields they give)",
    )
    for key, (label, what) in RECORD_FIELDS.items():
        group.add_argument(
            f"--{key.replace('_', '-')}",
            dest=f"record_{key}",
            default=None,
            metavar="TEXT" if key not in ("temperature_c", "warm_up_min") else "N",
            help=f"{label}: {what}" if what else label,
        )


def record_from_args(args: argparse.Namespace) -> Any:
    """The :class:`~tunespec.app.pipeline.record.MeasurementRecord` of the options
    given (the others empty).

    Raises
    ------
    InputError
        A bad value, naming its option (``--light-source-calibration: expected a
        date YYYY-MM-DD``).
    """
    from tunespec.app.pipeline.record import RECORD_FIELDS, record_from_mapping

    values = {key: getattr(args, f"record_{key}", None) for key in RECORD_FIELDS}
    return record_from_mapping(values, option_names=True)
