"""Issue 12, items 4-8: disk full, the validation boundary, standard JSON out, paths
inside project files, output paths and config values checked before any work."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import pytest

from tests.helpers import without_progress
from tunespec.app.cli import EXIT_DISK_FULL, EXIT_INPUT, main
from tunespec.app.pipeline.plan import load_config
from tunespec.app.pipeline.run import run_config
from tunespec.core.datasets import load_colorchecker_sg, resource_path
from tunespec.core.errors import DiskFullError, InputError
from tunespec.core.io.responses_csv import read_responses_csv
from tunespec.core.io.session import Session
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import (
    MAX_DEPTH,
    dumps_json,
    loads_json,
    valid_number,
)
from tunespec.devices.registry import layout_reflectances

SG_LAYOUT = resource_path("layouts", "colorchecker_sg.json")
SMALL = "384x256"


def _one_line_error(capsys, code: int, rc: int) -> str:
    err = without_progress(capsys.readouterr().err)
    assert rc == code, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


def _layout_doc() -> dict:
    return json.loads(SG_LAYOUT.read_text())


# -- 4. disk full ----------------------------------------------------------------------
def test_disk_full_during_capture_is_one_line_with_its_own_exit_code(
    tmp_path, monkeypatch, capsys
) -> None:
    import tunespec.devices.dng as dng

    calls = {"n": 0}
    real = dng._write_atomic

    def full_after_three(path, data):
        calls["n"] += 1
        if calls["n"] > 3:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(dng, "_write_atomic", full_after_three)
    out = tmp_path / "s"
    args = ["capture", "--layout", str(SG_LAYOUT), "--out", str(out)]
    args += ["--resolution", SMALL, "--channels", "LED450,LED540", "--exposure", "2"]
    rc = main(args)
    err = _one_line_error(capsys, EXIT_DISK_FULL, rc)
    assert str(out) in err and "MB" in err and "needed" in err
    session = Session.open(out)
    assert len(session.frames) == 3
    assert all(session.verify(f) for f in session.frames)
    monkeypatch.setattr(dng, "_write_atomic", real)
    assert main([*args[:-4], "--resume"]) == 0
    assert Session.open(out).missing() == []


def test_disk_full_writing_an_output_file_is_one_line(
    tmp_path, monkeypatch, capsys
) -> None:
    import tunespec.app.cli.core_cmds as cmds

    stats = tmp_path / "out" / "stats.json"

    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(cmds, "_write_json", full)
    sg = _sg_files(tmp_path)
    rc = main(
        [
            "evaluate",
            "--estimated",
            str(sg),
            "--reference",
            str(sg),
            "--stats",
            str(stats),
        ]
    )
    err = _one_line_error(capsys, EXIT_DISK_FULL, rc)
    assert str(stats.parent) in err and "free" in err


def test_free_space_is_checked_before_the_capture(tmp_path, monkeypatch, capsys):
    import shutil

    import tunespec.devices.capture as cap

    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(
        cap.shutil, "disk_usage", lambda p: usage._replace(free=1_000_000)
    )
    out = tmp_path / "s"
    rc = main(
        [
            "capture",
            "--layout",
            str(SG_LAYOUT),
            "--out",
            str(out),
            "--resolution",
            SMALL,
            "--channels",
            "LED450",
            "--exposure",
            "2",
        ]
    )
    err = capsys.readouterr().err
    assert rc == 0
    assert "warning:" in err and "MB" in err and str(out) in err


def test_disk_full_error_names_folder_and_sizes(tmp_path) -> None:
    err = DiskFullError(tmp_path, needed_bytes=12_000_000, free_bytes=1_000_000)
    text = str(err)
    assert str(tmp_path) in text and "12.0 MB" in text and "1.0 MB free" in text


# -- 5. the validation boundary --------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("[" * 100_000 + "]" * 100_000, "nested"),
        ('{"a": ' + "1" * 5000 + "}", "digits"),
        ("[NaN]", "NaN"),
        ("[-Infinity]", "Infinity"),
        ('{"a": 1e400}', "non-finite"),
    ],
)
def test_json_limits(text, fragment) -> None:
    with pytest.raises(InputError, match=fragment):
        loads_json(text, path="x.json")


def test_layout_and_manifest_nested_too_deep_are_input_errors(tmp_path) -> None:
    p = tmp_path / "deep.json"
    p.write_text(
        '{"format": "tunespec-layout", "meta": ' + "[" * 5000 + "]" * 5000 + "}"
    )
    with pytest.raises(InputError, match=f"nested more than {MAX_DEPTH}"):
        TargetLayout.load(p)
    (tmp_path / "manifest.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(InputError, match="nested"):
        Session.open(tmp_path)


def test_huge_csv_field_non_utf8_and_long_names(tmp_path) -> None:
    p = tmp_path / "x.csv"
    p.write_text("wavelength_nm,a\n400," + "1" * 200_000 + "\n500,1\n")
    with pytest.raises(InputError, match="bad CSV"):
        read_spectra_csv(p)
    # not UTF-8: read as Latin-1 (instrument software on Windows), then the cell
    # is no number, on its line
    p.write_bytes(b"wavelength_nm,a\n400,1\n500,\xff\n")
    with pytest.raises(InputError, match="not a number") as info:
        read_spectra_csv(p)
    assert info.value.line == 3
    with pytest.raises(InputError, match="too long"):
        read_spectra_csv(tmp_path / ("x" * 5000 + ".csv"))
    q = tmp_path / "r.csv"
    q.write_text("patch,illuminant,R,G,B\n" + "p" * 1000 + ",L,1,1,1\n")
    with pytest.raises(InputError, match="patch"):
        read_responses_csv(q)


def test_non_utf8_and_deep_config(tmp_path) -> None:
    p = tmp_path / "c.toml"
    p.write_bytes(b'out = "r\xe9sultat"\n')
    with pytest.raises(InputError, match="UTF-8"):
        load_config(p)
    p.write_text("a = " + "[" * 50_000 + "]" * 50_000 + "\n")
    with pytest.raises(InputError, match="nested"):
        load_config(p)


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"version": 1e309}, "version"),
        ({"version": [1]}, "version"),
        ({"version": "1"}, "version"),
        ({"version": True}, "version"),
        ({"meta": []}, "meta"),
        ({"meta": {"reflectances": 3}}, "meta"),
        ({"patch_names": [1] * 140}, "patch_names"),
        ({"margin_mm": [0, 0, 0, float("-inf")]}, "margin_mm"),
        ({"rows": True}, "rows"),
        ({"rows": 10**15, "cols": 10**15}, "rows"),
        ({"width_mm": 1e400}, "width_mm"),
    ],
)
def test_layout_fields_are_checked(tmp_path, change, fragment) -> None:
    doc = {**_layout_doc(), **change}
    p = tmp_path / "l.json"
    # what a hand-edited file would hold: 1e400 (json.dumps would write Infinity)
    p.write_text(json.dumps(doc).replace("Infinity", "1e400"))
    with pytest.raises(InputError, match=fragment) as info:
        TargetLayout.load(p)
    assert info.value.path == str(p)


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"n_darks": 1e30}, "n_darks"),
        ({"n_darks": 10**18}, "n_darks"),
        ({"n_darks": True}, "n_darks"),
        ({"iso": 100.5}, "iso"),
        ({"bracket_factors": [1.0] * 10_000}, "bracket_factors"),
        ({"levels": {"LED450": "x"}}, "levels"),
    ],
)
def test_manifest_settings_are_bounded(tmp_path, change, fragment) -> None:
    out = tmp_path / "s"
    Session.create(out, settings=_settings())
    m = json.loads((out / "manifest.json").read_text())
    m["settings"].update(change)
    (out / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(InputError, match=fragment):
        Session.open(out)


def _settings():
    from tunespec.core.io.session import CaptureSettings

    return CaptureSettings(
        ("LED450",), exposure_mode="fixed", exposures_s={"LED450": (1.0,)}
    )


def test_negative_seeds_are_refused_in_one_line(tmp_path, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        main(["demo", "--out", str(tmp_path / "d"), "--seed", "-1"])
    assert info.value.code == 2
    assert "--seed" in capsys.readouterr().err
    cfg = tmp_path / "c.toml"
    cfg.write_text("[bench]\nseed = -1\n")
    with pytest.raises(InputError, match=r"bench\.seed") as err:
        run_config(cfg)
    assert str(cfg) in str(err.value)


# -- 6. non-finite, out of range, booleans; standard JSON out ---------------------------
def test_booleans_are_not_numbers_and_ranges_are_named() -> None:
    with pytest.raises(InputError, match=r"in \[0, 1\]"):
        valid_number(True, "x", lo=0, hi=1)
    with pytest.raises(InputError, match="x"):
        valid_number(float("nan"), "x")
    assert valid_number(0.5, "x", lo=0, hi=1) == 0.5


def test_absurd_reflectances_are_refused_with_file_and_line(tmp_path, capsys) -> None:
    sg = load_colorchecker_sg()
    bad = sg.with_values(sg.values * 1e200)
    p = tmp_path / "huge.csv"
    write_spectra_csv(bad, p)
    ok = tmp_path / "sg.csv"
    write_spectra_csv(sg, ok)
    stats = tmp_path / "stats.json"
    rc = main(
        [
            "evaluate",
            "--estimated",
            str(p),
            "--reference",
            str(ok),
            "--stats",
            str(stats),
        ]
    )
    err = _one_line_error(capsys, EXIT_INPUT, rc)
    assert f"{p}:2:" in err and "out of range" in err
    assert not stats.exists()


def test_outputs_are_standard_json() -> None:
    text = dumps_json({"a": float("nan"), "b": [float("inf"), 1.0]})
    assert json.loads(text, parse_constant=lambda c: pytest.fail(c)) == {
        "a": None,
        "b": [None, 1.0],
    }


def test_a_non_finite_margin_never_reaches_the_manifest() -> None:
    with pytest.raises(InputError, match="finite"):
        TargetLayout("t", 2, 2, 40.0, 40.0, margin_mm=(0, 0, 0, float("-inf")))


# -- 7. paths inside project files ----------------------------------------------------
@pytest.mark.parametrize(
    "ref", ["/etc/passwd", "../secret.csv", "sub/../../secret.csv"]
)
def test_layout_paths_stay_in_the_project(tmp_path, ref) -> None:
    secret = tmp_path / "secret.csv"
    secret.write_text("root:x:0:0:SECRET-LINE\n")
    proj = tmp_path / "proj"
    proj.mkdir()
    doc = _layout_doc()
    doc["meta"] = {"reflectances": ref}
    lp = proj / "l.json"
    lp.write_text(json.dumps(doc))
    layout = TargetLayout.load(lp)
    with pytest.raises(InputError, match=r"meta\.reflectances") as info:
        layout_reflectances(layout, lp)
    assert "SECRET" not in str(info.value) and "root:x" not in str(info.value)


def test_layout_paths_beside_the_file_and_in_resources_still_work(tmp_path) -> None:
    doc = _layout_doc()
    layout = TargetLayout.load(SG_LAYOUT)
    assert len(layout_reflectances(layout, SG_LAYOUT).names) == 140
    write_spectra_csv(load_colorchecker_sg(), tmp_path / "mine.csv")
    doc["meta"] = {"reflectances": "mine.csv"}
    (tmp_path / "l.json").write_text(json.dumps(doc))
    lay = TargetLayout.load(tmp_path / "l.json")
    assert len(layout_reflectances(lay, tmp_path / "l.json").names) == 140


def test_errors_do_not_echo_file_contents(tmp_path) -> None:
    p = tmp_path / "x.csv"
    p.write_text("SECRET-HEADER-" + "x" * 200 + ",a\n400,1\n500,1\n")
    with pytest.raises(InputError) as info:
        read_spectra_csv(p)
    assert "x" * 60 not in str(info.value)


# -- 8. output paths and config values before any work --------------------------------
def _sg_files(tmp_path: Path) -> Path:
    ok = tmp_path / "sg.csv"
    write_spectra_csv(load_colorchecker_sg(), ok)
    return ok


@pytest.mark.parametrize(
    "argv",
    [
        ["evaluate", "--estimated", "{sg}", "--reference", "{sg}", "--stats", "{dir}"],
        ["export-cgats", "--reflectances", "{sg}", "-o", "{dir}"],
        ["report", "--out", "{file}", "--reflectances", "{sg}"],
        ["demo", "--out", "{file}"],
        ["process", "{dir}", "-o", "{dir}"],
        ["capture", "--layout", str(SG_LAYOUT), "--out", "{file}"],
    ],
)
def test_output_paths_are_checked_first(tmp_path, capsys, argv) -> None:
    sg = _sg_files(tmp_path)
    d = tmp_path / "adir"
    d.mkdir()
    f = tmp_path / "afile"
    f.write_text("keep")
    argv = [a.format(sg=sg, dir=d, file=f) for a in argv]
    rc = main(argv)
    err = _one_line_error(capsys, EXIT_INPUT, rc)
    assert "folder" in err or "file" in err
    assert capsys.readouterr().out == ""  # nothing computed, no Table 2 printed
    assert f.read_text() == "keep"


@pytest.mark.parametrize(
    ("toml", "key"),
    [
        ('[calibrate]\nmethod = "foo"\n', "calibrate.method"),
        ('[calibrate]\ngrid = "700:400:5"\n', "calibrate.grid"),
        ('[capture]\nexposure = "fast"\n', "capture.exposure"),
        ("[capture]\nexposure = true\n", "capture.exposure"),
        ("[capture]\niso = -5\n", "capture.iso"),
        ("[capture]\nbrackets = [1.0, 2.0]\n", "capture.brackets"),
        ('[bench]\nresolution = "10x10"\n', "bench.resolution"),
        ('out = "afile"\n', "out"),
    ],
)
def test_config_values_are_checked_before_capture(tmp_path, toml, key) -> None:
    (tmp_path / "afile").write_text("keep")
    cfg = tmp_path / "c.toml"
    cfg.write_text(toml)
    with pytest.raises(InputError, match=key) as err:
        run_config(cfg)
    assert str(cfg) in str(err.value) or "afile" in str(err.value)
    assert not (tmp_path / "run").exists()  # nothing captured
