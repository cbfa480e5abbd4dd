"""reused_heap: a large block freed inside is reused, not faulted in again."""

from __future__ import annotations

import resource

import numpy as np
import pytest

from tunespec.app.pipeline import heap


def _faults_of_a_64mb_block() -> int:
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    block = np.ones(1 << 24, dtype=np.float32)  # 64 MB, every page touched
    del block
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


@pytest.mark.skipif(heap._libc() is None, reason="glibc's mallopt only")
def test_inside_freed_blocks_are_reused() -> None:
    with heap.reused_heap(), heap.reused_heap():  # nestable
        _faults_of_a_64mb_block()
        again = _faults_of_a_64mb_block()
    # a fresh 64 MB block is 16,384 pages (with transparent huge pages, 32 of
    # them and the kernel's zeroing: about 540 faults measured here)
    assert again < 50
    assert heap._DEPTH == 0
