"""Issue 13, item 4: where measurements go is asked once and remembered, the last
measurement is offered on restart, recent ones are listed, and both "Open" commands
start in the same place."""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6.QtWidgets import QFileDialog

from tests.app.helpers import new_main_window
from tests.app.test_wizard import SIM, run_step
from tunespec.app.gui.main_window import MainWindow


class FakeDialog:
    """Stands in for ``QFileDialog.getExistingDirectory``: records where it starts."""

    def __init__(self, answer: str) -> None:
        self.answer = answer
        self.start_dirs: list[str] = []

    def __call__(self, _parent, _caption, start_dir="", *args) -> str:
        self.start_dirs.append(start_dir)
        return self.answer


@pytest.fixture
def make_window(qtbot, tmp_path):
    windows = []

    def make() -> MainWindow:
        w = new_main_window(qtbot, tmp_path, SIM)
        windows.append(w)
        return w

    yield make
    for w in windows:
        w.close()


def test_take_frames_asks_once_where_measurements_go(
    make_window, qtbot, tmp_path, monkeypatch
):
    root = tmp_path / "measurements"
    root.mkdir()
    dialog = FakeDialog(str(root))
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", dialog)
    window = make_window()
    wizard = window.wizard_panel
    assert not wizard.resume_button.isVisibleTo(wizard)  # nothing to resume yet
    run_step(qtbot, wizard, wizard.connect_page)
    # "Take frames" with no measurement open: asks where measurements go, once
    wizard.go_to(wizard.pages.index(wizard.dark_page))
    wizard.dark_page.start_button.click()
    wizard.dark_page.abort()
    qtbot.waitUntil(lambda: not wizard.dark_page.running, timeout=60_000)
    first = window.measurement.folder
    assert len(dialog.start_dirs) == 1 and first.parent == root
    assert not (Path.home() / "TuneSpec").exists() or first.parent != Path.home()
    window.close()

    # restart: the last measurement is offered, and opens
    window = make_window()
    wizard = window.wizard_panel
    assert wizard.resume_button.isVisibleTo(wizard)
    assert str(first.resolve()) in wizard.folder_label.text()
    wizard.resume_button.click()
    assert window.measurement.folder == first.resolve()
    assert wizard.current_page is wizard.connect_page
    assert not wizard.resume_button.isVisibleTo(wizard)

    # a second measurement goes to the same place without asking again
    window.measurement.folder = None
    second = window.measurement.require_folder()
    assert second.parent == root and second != first
    assert len(dialog.start_dirs) == 1
    wizard._fill_recent_menu()
    listed = [a.text() for a in wizard.recent_menu.actions()]
    assert listed == [str(second.resolve()), str(first.resolve())]


def test_cancelled_folder_question_refuses_with_one_line(
    make_window, qtbot, monkeypatch
):
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", FakeDialog(""))
    window = make_window()
    wizard = window.wizard_panel
    run_step(qtbot, wizard, wizard.connect_page)
    wizard.go_to(wizard.pages.index(wizard.dark_page))
    assert wizard.dark_page.start() is None
    assert "no measurement folder" in wizard.dark_page.result_label.text()
    assert window.measurement.folder is None


def test_file_open_and_open_resume_start_in_the_same_place(
    make_window, tmp_path, monkeypatch
):
    window = make_window()
    wizard = window.wizard_panel
    assert wizard.new_measurement(tmp_path / "runs" / "m1")
    dialog = FakeDialog("")  # cancelled: only where it started counts
    monkeypatch.setattr(QFileDialog, "getExistingDirectory", dialog)
    window.open_action.trigger()
    wizard.open_button.click()
    window.new_action.trigger()
    wizard.new_button.click()
    assert dialog.start_dirs == [str((tmp_path / "runs").resolve())] * 4
