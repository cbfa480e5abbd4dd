"""Decoding the next raw frames on a thread of their own while this one works.

Processing a session reads its frames one after the other and takes each one's
statistics before the next (memory: one frame). LibRaw decodes with the GIL
released, so a :class:`ReadAhead` decodes the frames the plan says come next on a
thread while the caller gathers the previous frame's pixels: decode and statistics
overlap, and processing costs about the decode alone.

The plan is a prediction, not a contract: a frame asked for out of turn is read
at once on the caller's thread, and the read-ahead goes on after it in the plan.
At most ``depth`` frames are decoded ahead, so memory stays a few frames.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

__all__ = ["ReadAhead"]


class ReadAhead:
    """Frames ``load(path)`` decoded ahead along ``plan``, ``depth`` at most.

    Examples
    --------
    >>> seen = []
    >>> ahead = ReadAhead(lambda p: seen.append(p) or p.upper(), ["a", "b", "c"])
    >>> [ahead.get(p) for p in ["a", "b", "c"]]
    ['A', 'B', 'C']
    >>> ahead.close(); sorted(seen)
    ['a', 'b', 'c']
    """

    def __init__(
        self,
        load: Callable[[Any], Any],
        plan: Sequence[str | Path],
        depth: int = 2,
    ) -> None:
        self._load = load
        self._plan = [str(p) for p in plan]
        self._paths = {str(p): p for p in plan}
        self._index = {p: i for i, p in reversed(list(enumerate(self._plan)))}
        self._depth = max(1, depth)
        self._done: set[str] = set()
        self._pending: dict[str, Future[Any]] = {}
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="tunespec-read-ahead")
        self._schedule_after(-1)

    def get(self, path: str | Path) -> Any:
        """The frame at ``path``: the read-ahead's if it has it, else read now."""
        key = str(path)
        future = self._pending.pop(key, None)
        self._done.add(key)
        # the next frames start decoding before this one is handed over
        self._schedule_after(self._index.get(key, -1))
        if future is not None:
            return future.result()
        return self._load(path)

    def close(self) -> None:
        """Stop reading ahead (a frame being decoded is finished and dropped)."""
        for future in self._pending.values():
            future.cancel()
        self._pending.clear()
        self._pool.shutdown(wait=True)

    def _schedule_after(self, i: int) -> None:
        for p in self._plan[i + 1 :]:
            if len(self._pending) >= self._depth:
                return
            if p not in self._done and p not in self._pending:
                self._pending[p] = self._pool.submit(self._load, self._paths[p])
