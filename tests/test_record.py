"""The measurement record (issue 27 item 5): the operator's fields, checked at every
way in (configuration, command line, record.json), kept in the folder, filled in
by the devices' serials, shown on the report's first page."""

from __future__ import annotations

from dataclasses import fields

import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.plan import load_config, plan_from_config
from tunespec.app.pipeline.record import (
    RECORD_FIELDS,
    RECORD_FILE,
    MeasurementRecord,
    chart_reference,
    instrument_rows,
    light_status_items,
    read_record,
    record_from_mapping,
    record_summary,
    update_record,
)
from tunespec.core.errors import InputError

DEVICES = {
    "light": {"model": "CAL1", "serial": "L-77", "firmware": "2.1"},
    "camera": {"model": "EOS 5D Mark III", "serial": "C-9"},
}


def test_every_field_has_a_label_and_a_place_in_the_record() -> None:
    assert tuple(RECORD_FIELDS) == tuple(f.name for f in fields(MeasurementRecord))


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"operator": 3}, "provenance.operator: expected text"),
        ({"light_source_calibration": "1/2/2026"}, "expected a date YYYY-MM-DD"),
        ({"spectroradiometer_calibration": "2026-02-30"}, "expected a date"),
        ({"temperature_c": 400}, "temperature_c: 400 is outside -40 to 80"),
        ({"warm_up_min": "half an hour"}, "warm_up_min: expected a number"),
        ({"operater": "x"}, "unknown key(s) 'operater'"),
        ({"notes": "x" * 501}, "at most 500 characters"),
    ],
)
def test_a_bad_field_is_one_line_naming_the_key(values, message) -> None:
    with pytest.raises(
        InputError, match=message.replace("(", r"\(").replace(")", r"\)")
    ):
        record_from_mapping(values)


def test_fields_are_one_line_and_numbers_normalised() -> None:
    rec = record_from_mapping(
        {"operator": " A.\tN.\nOperator ", "temperature_c": 23, "warm_up_min": "30.0"}
    )
    assert rec.operator == "A. N. Operator"
    assert (rec.temperature_c, rec.warm_up_min) == ("23", "30")


def test_the_configuration_provenance_reaches_the_plan(tmp_path) -> None:
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        '[provenance]\noperator = "Kim"\nsample_id = "S-1"\n'
        'light_source_calibration = "2026-10-01"\n',
        encoding="utf-8",
    )
    plan = plan_from_config(load_config(cfg))
    assert plan.record.operator == "Kim" and plan.record.sample_id == "S-1"
    assert plan.record.light_source_calibration == "2026-10-01"
    cfg.write_text('[provenance]\nlight_source_calibration = "soon"\n')
    with pytest.raises(InputError) as err:
        plan_from_config(load_config(cfg))
    assert "provenance.light_source_calibration" in str(err.value)
    assert "run.toml" in str(err.value)


def test_the_folder_keeps_fields_not_given_again(tmp_path) -> None:
    assert read_record(tmp_path) == MeasurementRecord()
    update_record(tmp_path, MeasurementRecord(operator="Kim", chart_serial="SG-1"))
    kept = update_record(tmp_path, MeasurementRecord(sample_id="S-2"))
    assert kept == MeasurementRecord(
        operator="Kim", chart_serial="SG-1", sample_id="S-2"
    )
    assert read_record(tmp_path) == kept
    (tmp_path / RECORD_FILE).write_text('{"operator": ["x"]}')
    with pytest.raises(InputError, match=r"record\.operator: expected text"):
        read_record(tmp_path)


def test_the_devices_serials_fill_what_the_operator_left_empty() -> None:
    rows = instrument_rows(MeasurementRecord(camera_serial="C-OWN"), DEVICES)
    light, meter, camera = rows
    assert (light["serial"], light["serial_source"]) == ("L-77", "device")
    assert light["firmware"] == "2.1" and light["calibration"] == "not recorded"
    # the CAL1's spectroradiometer is internal: the light's serial
    assert meter["model"].startswith("internal to the light source (CAL1")
    assert (meter["serial"], meter["serial_source"]) == ("L-77", "device")
    assert (camera["serial"], camera["serial_source"]) == ("C-OWN", "operator")
    own = MeasurementRecord(spectroradiometer="CS-2000", spectroradiometer_serial="M1")
    meter = instrument_rows(own, DEVICES)[1]
    assert (meter["model"], meter["serial"], meter["firmware"]) == (
        "CS-2000",
        "M1",
        "-",
    )
    assert instrument_rows(MeasurementRecord(), {})[0]["serial"] == "not recorded"


def test_the_summary_names_the_chart_reference_and_the_software() -> None:
    from tunespec.app.pipeline.plan import chart_layout

    doc = record_summary(
        MeasurementRecord(operator="Kim"), DEVICES, chart_layout=chart_layout()
    )
    assert doc["operator"] == "Kim" and doc["sample_id"] == ""
    assert doc["chart"] == "ColorChecker SG"
    assert doc["chart_reference"].startswith("charts/colorchecker_sg.csv")
    assert "not this chart's own" in doc["chart_reference"]
    assert doc["software"]["TuneSpec"] and len(doc["instruments"]) == 3
    own = MeasurementRecord(chart_reference="i1Pro 3, 2026-01-10")
    assert chart_reference(own, chart_layout()) == "i1Pro 3, 2026-01-10"


def test_report_command_takes_the_record_and_names_a_bad_option(
    tmp_path, capsys
) -> None:
    out = tmp_path / "r"
    args = ["report", "-o", str(out), "--operator", "Kim", "--sample-id", "S-7"]
    assert main([*args, "--warm-up-min", "45", "-q"]) == 0
    html = (out / "report.html").read_text(encoding="utf-8")
    record = html.split("<h2>Measurement record</h2>", 1)[1].split("<h2>", 1)[0]
    assert "<td>Operator</td><td>Kim</td>" in record
    assert "<td>Sample ID</td><td>S-7</td>" in record
    assert "not recorded, 45 min" in record  # temperature not given, warm-up given
    capsys.readouterr()
    bad = ["--light-source-calibration", "2026-13-01"]
    assert main(["report", "-o", str(tmp_path / "s"), *bad]) == 2
    err = capsys.readouterr().err.strip()
    assert "--light-source-calibration: expected a date YYYY-MM-DD" in err
    assert len(err.splitlines()) == 1


def test_the_report_shows_the_instruments_with_their_sources(tmp_path) -> None:
    from tunespec.app.report.report import ReportData, render_html

    html = render_html(
        ReportData(record=MeasurementRecord(operator="Kim"), devices=DEVICES)
    )
    assert "<td>Light source</td><td>CAL1</td><td>L-77 (device)</td>" in html
    assert "<td>Camera</td><td>EOS 5D Mark III</td><td>C-9 (device)</td>" in html
    # no record given (a caller of the library): no record section
    assert "Measurement record" not in render_html(ReportData())


def test_the_light_says_its_temperature_and_warm_up_if_it_can() -> None:
    from tunespec.devices.protocols import DeviceError, LightStatus

    class Light:
        def __init__(self, status):
            self._status = status

        def status(self):
            if isinstance(self._status, Exception):
                raise self._status
            return self._status

    items = light_status_items(Light(LightStatus(True, 31.25, 1800.0)))
    assert items == {
        "light source case temperature at the run's start (°C)": "31.2",
        "light source on for, at the run's start (min)": "30.0",
    }
    assert light_status_items(Light(DeviceError("no reply"))) == {}
    assert light_status_items(object()) == {}
