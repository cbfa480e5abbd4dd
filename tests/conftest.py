"""Test-wide settings.

BLAS threads are pinned to one before numpy loads: the core's problems are small
(tens of rows), where multi-threaded BLAS only adds contention on shared CI machines
(measured: the calibration tests take 10 s with one thread and 55 s with two busy ones).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
