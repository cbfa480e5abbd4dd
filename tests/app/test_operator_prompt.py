"""On hardware the stage is the operator: the wizard asks, the capture waits."""

from __future__ import annotations

from types import SimpleNamespace

from tests.app.helpers import caught
from tests.app.test_workers import _FakeCamera, _FakeLight
from tunespec.app.gui.settings import AppSettings
from tunespec.app.gui.wizard.measurement import Measurement
from tunespec.app.gui.wizard.wizard_panel import WizardPanel
from tunespec.app.gui.workers import DeviceController, DeviceJob
from tunespec.core.progress import Cancelled
from tunespec.devices.registry import OperatorStage


def _opener(light_spec, camera_spec, *, prompt, **options):
    return SimpleNamespace(
        light=_FakeLight(), camera=_FakeCamera(), stage=OperatorStage(prompt)
    )


def _present_white(context, *, progress, should_stop):
    context.bench.stage.present("white")
    return "white in place"


def _wizard_on_a_fake_bench(qtbot) -> tuple[DeviceController, WizardPanel]:
    """A wizard panel whose controller opened the scripted CAL1 and gphoto2."""
    controller = DeviceController(_opener)
    wizard = WizardPanel(Measurement(controller, AppSettings()))
    qtbot.addWidget(wizard)
    with caught(qtbot, controller.devices_opened):
        controller.open_devices("cal1:///dev/null", "gphoto2")
    return controller, wizard


def test_the_operator_is_asked_and_the_job_waits(qtbot, tmp_path):
    controller, wizard = _wizard_on_a_fake_bench(qtbot)
    wizard.show()
    job = DeviceJob(_present_white)
    done = []
    job.signals.returned.connect(done.append)
    controller.submit(job)
    qtbot.waitUntil(wizard.prompt_frame.isVisible)
    assert "white background" in wizard.prompt_label.text()
    assert not done  # waiting for the operator
    wizard.prompt_button.click()
    qtbot.waitUntil(lambda: done == ["white in place"])
    assert not wizard.prompt_frame.isVisible()
    controller.shutdown()


def test_aborting_while_the_operator_is_asked(qtbot):
    controller, wizard = _wizard_on_a_fake_bench(qtbot)
    job = DeviceJob(_present_white)
    errors = []
    job.signals.errored.connect(errors.append)
    controller.submit(job)
    qtbot.waitUntil(lambda: wizard.prompt_label.text() != "")
    job.abort()
    qtbot.waitUntil(lambda: bool(errors))
    assert isinstance(errors[0], Cancelled)
    controller.shutdown()
