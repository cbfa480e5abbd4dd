"""BlockWriter: writes in order on its own thread, bounded, errors raised back."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from tunespec.app.pipeline.block_writer import BlockWriter


def test_writes_run_in_order_off_the_calling_thread_and_buffers_are_reused() -> None:
    seen: list[tuple[int, float, bool]] = []
    caller = threading.get_ident()
    bases = set()
    with BlockWriter(depth=1, n_buffers=2) as w:
        for k in range(6):
            buf = w.buffer((4, 3))
            bases.add(id(buf.base))
            buf[:] = k

            def write(k: int = k, buf: np.ndarray = buf) -> None:
                seen.append((k, float(buf.sum()), threading.get_ident() != caller))

            w.put(write, buf)
        w.flush()
        assert [s[0] for s in seen] == list(range(6))
    assert [s[1] for s in seen] == [12.0 * k for k in range(6)]  # not overwritten
    assert all(s[2] for s in seen)
    assert len(bases) <= 2  # the pool, not a fresh array per block


def test_a_failed_write_is_raised_to_the_next_put_and_to_flush() -> None:
    w = BlockWriter()

    def full_disk() -> None:
        raise OSError(28, "No space left on device")

    w.put(full_disk)
    with pytest.raises(OSError, match="No space"):
        w.flush()
    with pytest.raises(OSError, match="No space"):
        w.put(lambda: None)
    w.close(raise_error=False)
