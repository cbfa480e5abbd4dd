"""The wizard pages: each keeps its description right under its title (the Connect
page, which has no widgets of its own, spread them over the page); a measurement
saved unchanged is not written again (fsyncs on the GUI thread)."""

from __future__ import annotations

from tests.app.test_wizard import window as window  # the fixture


def test_description_sits_under_the_title_on_every_page(window, qtbot):
    window.resize(1500, 950)
    wizard = window.wizard_panel
    for i, page in enumerate(wizard.pages):
        wizard.go_to(i)
        qtbot.waitUntil(page.isVisible)
        page.layout().activate()
        title, text = page.title_label, page.description_label
        # neither label is stretched (its text would float in the middle of it)
        for label in (title, text):
            extra = label.height() - label.heightForWidth(label.width())
            assert extra <= 12, (page.title, label.text()[:20], extra)
        assert 0 <= text.geometry().top() - title.geometry().bottom() <= 20
        # and the buttons are at the bottom of the page, not under the text
        assert page.start_button.geometry().top() > page.height() * 0.8, page.title


def test_an_unchanged_measurement_is_not_written_again(window, tmp_path):
    m = window.measurement
    assert window.wizard_panel.new_measurement(tmp_path / "m")
    path = tmp_path / "m" / "measurement.json"
    m.save()
    first = path.stat().st_mtime_ns, path.stat().st_ino
    m.save()  # nothing changed: the file is the same one
    assert (path.stat().st_mtime_ns, path.stat().st_ino) == first
    m.threshold = 0.002
    m.save()
    assert path.stat().st_ino != first[1]
    assert '"threshold_rgb_mean": 0.002' in path.read_text()
    path.unlink()  # gone: written again
    m.save()
    assert path.is_file()
