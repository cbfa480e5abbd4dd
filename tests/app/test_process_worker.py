"""ProcessWorker: the GUI's numerics in a process of their own (no shared GIL)."""

from __future__ import annotations

import logging
import os
import time

from tests.app.helpers import caught
from tunespec.app.gui.processes import BACKGROUND_NICE, ProcessWorker
from tunespec.app.gui.workers import Worker
from tunespec.core.errors import InputError
from tunespec.core.progress import Cancelled, check_stop


def pid_and_sum(values, *, progress, should_stop):
    """Report progress, log a warning, return (pid, niceness, sum)."""
    for i, _ in enumerate(values):
        progress((i + 1) / len(values))
    logging.getLogger("tunespec.test_process").warning("LED700: weak (%d)", 7)
    return os.getpid(), os.getpriority(os.PRIO_PROCESS, 0), sum(values)


def fails(*, progress, should_stop):
    raise InputError("chart.json, key 'rows': expected an integer >= 1")


class _Unpicklable(Exception):
    def __init__(self, a, b):
        super().__init__(f"{a}{b}")


def fails_unpicklably(*, progress, should_stop):
    raise _Unpicklable("half", "way")


def runs_until_stopped(*, progress, should_stop):
    progress(0.1)
    while True:
        check_stop(should_stop)
        time.sleep(0.005)


def dies(*, progress, should_stop):
    os._exit(3)


def _run(qtbot, worker, signal):
    with caught(qtbot, signal, timeout=60_000) as blocker:
        worker.start()
    qtbot.waitUntil(lambda: Worker.active_count() == 0, timeout=20_000)
    return blocker.args[0]


def test_result_progress_and_log_come_back_from_another_process(qtbot, caplog):
    worker = ProcessWorker(pid_and_sum, [1, 2, 3, 4])
    seen: list[float] = []
    worker.signals.progressed.connect(seen.append)
    with caplog.at_level(logging.INFO):
        pid, nice, total = _run(qtbot, worker, worker.signals.returned)
    assert total == 10
    assert pid != os.getpid()
    # the numerics yield the cores to the GUI's process
    assert nice >= max(BACKGROUND_NICE, os.getpriority(os.PRIO_PROCESS, 0))
    qtbot.waitUntil(lambda: seen == [0.25, 0.5, 0.75, 1.0])
    records = [r for r in caplog.records if r.name == "tunespec.test_process"]
    assert [r.getMessage() for r in records] == ["LED700: weak (7)"]
    assert records[0].levelno == logging.WARNING


def test_errors_come_back_as_they_were_raised(qtbot):
    worker = ProcessWorker(fails)
    exc = _run(qtbot, worker, worker.signals.errored)
    assert isinstance(exc, InputError)
    assert "key 'rows'" in str(exc)
    worker = ProcessWorker(fails_unpicklably)
    exc = _run(qtbot, worker, worker.signals.errored)
    assert isinstance(exc, RuntimeError)
    assert str(exc) == "_Unpicklable: halfway"


def test_abort_stops_the_process(qtbot):
    worker = ProcessWorker(runs_until_stopped)
    worker.signals.progressed.connect(lambda f: worker.abort())
    exc = _run(qtbot, worker, worker.signals.errored)
    assert isinstance(exc, Cancelled)


def test_a_process_that_dies_is_an_error_not_a_hang(qtbot):
    worker = ProcessWorker(dies)
    exc = _run(qtbot, worker, worker.signals.errored)
    assert isinstance(exc, RuntimeError)
    assert "exit code 3" in str(exc)
