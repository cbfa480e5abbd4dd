"""Issue 24, item 6: a measurement folder that cannot reach out.

Every result write goes through one atomic writer (temporary file, fsync, rename)
that replaces a link planted at the target instead of writing through it; reads of
files named in a configuration stay in its folder; no error echoes a file's
content; a scheduler address in a file needs the command line's confirmation; a
full disk is one line naming the right folder, with nothing truncated left.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

import numpy as np
import pytest

from tests.helpers import without_progress
from tunespec.app.cli import EXIT_DISK_FULL, main
from tunespec.core.atomic import atomic_open, atomic_write_text
from tunespec.core.datasets import load_colorchecker_sg
from tunespec.core.errors import DiskFullError
from tunespec.core.io.cgats import ti3_table, write_cgats
from tunespec.core.io.responses_csv import read_responses_csv, write_responses_csv
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.responses import Responses

VICTIM_TEXT = "the user's own file\n"


def _victim(tmp_path: Path) -> Path:
    victim = tmp_path / "elsewhere" / "victim.txt"
    victim.parent.mkdir()
    victim.write_text(VICTIM_TEXT)
    return victim


def _plant(link: Path, victim: Path) -> None:
    link.parent.mkdir(parents=True, exist_ok=True)
    link.symlink_to(victim)


def _one_line(capsys, rc: int, code: int) -> str:
    err = without_progress(capsys.readouterr().err)
    assert rc == code, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


# -- the one atomic writer ---------------------------------------------------------
def test_the_writers_replace_a_planted_link_and_leave_its_target_alone(
    tmp_path,
) -> None:
    victim = _victim(tmp_path)
    sg = load_colorchecker_sg()
    out = tmp_path / "run" / "export"
    writers = {
        "reflectances.csv": lambda p: write_spectra_csv(sg, p),
        "reflectances.ti3": lambda p: write_cgats(
            ti3_table(sg.names, reflectance=sg), p
        ),
        "summary.json": lambda p: atomic_write_text(p, "{}\n"),
    }
    for name, write in writers.items():
        _plant(out / name, victim)
        write(out / name)
        assert not (out / name).is_symlink() and (out / name).stat().st_size > 0
    assert victim.read_text() == VICTIM_TEXT
    assert read_spectra_csv(out / "reflectances.csv").values.shape == sg.values.shape
    assert sorted(os.listdir(out)) == sorted(writers)  # no temporary file left


def test_responses_writer_replaces_a_link(tmp_path) -> None:
    victim = _victim(tmp_path)
    link = tmp_path / "responses.csv"
    _plant(link, victim)
    rgb = np.arange(18.0).reshape(3, 2, 3) / 20
    responses = Responses(("A", "B", "C"), ("L1", "L2"), rgb)
    write_responses_csv(responses, link)
    assert victim.read_text() == VICTIM_TEXT
    assert read_responses_csv(link).rgb.shape == responses.rgb.shape


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path) -> None:
    path = tmp_path / "a.csv"
    path.write_text("old\n")
    with pytest.raises(RuntimeError), atomic_open(path, newline="") as fh:
        fh.write("half of the new\n")
        raise RuntimeError("stopped")
    assert path.read_text() == "old\n"
    assert os.listdir(tmp_path) == ["a.csv"]


def test_a_full_disk_names_the_folder_and_keeps_the_old_file(
    tmp_path, monkeypatch
) -> None:
    path = tmp_path / "out" / "a.csv"
    path.parent.mkdir()
    path.write_text("old\n")
    real_fsync = os.fsync

    def full(fd: int) -> None:
        real_fsync(fd)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)
    with pytest.raises(DiskFullError) as info:
        write_spectra_csv(load_colorchecker_sg(), path)
    assert info.value.folder == str(path.parent)
    assert "--resume" not in str(info.value)
    assert path.read_text() == "old\n"
    assert os.listdir(path.parent) == ["a.csv"]


def test_disk_full_on_an_output_option_is_exit_4_and_leaves_no_truncated_file(
    tmp_path, monkeypatch, capsys
) -> None:
    import tunespec.core.atomic as atomic

    sg = tmp_path / "sg.csv"
    write_spectra_csv(load_colorchecker_sg(), sg)
    out = tmp_path / "o" / "stats.json"
    real = atomic._commit

    def full(tmp: Path, path: Path) -> None:
        raise OSError(errno.ENOSPC, "No space left on device", str(tmp))

    monkeypatch.setattr(atomic, "_commit", full)
    args = ["evaluate", "--estimated", str(sg), "--reference", str(sg)]
    rc = main([*args, "--stats", str(out)])
    err = _one_line(capsys, rc, EXIT_DISK_FULL)
    assert f"{out.parent}: no space left" in err and "--resume" not in err
    assert not out.exists() and os.listdir(out.parent) == []
    monkeypatch.setattr(atomic, "_commit", real)


@pytest.mark.slow
def test_run_again_does_not_write_through_links_planted_in_the_folder(
    tmp_path, capsys
) -> None:
    """``ln -sf VICTIM run/export/reflectances.csv`` (and three more), then
    ``tunespec run run.toml`` again: VICTIM is untouched."""
    cfg = tmp_path / "run.toml"
    cfg.write_text(
        'out = "run"\n[bench]\nresolution = "384x256"\n[export]\nreport = false\n'
    )
    assert main(["run", str(cfg)]) == 0
    victim = _victim(tmp_path)
    run = tmp_path / "run"
    planted = [
        run / "export" / "reflectances.csv",
        run / "calibration" / "sensitivity.csv",
        run / "estimate" / "reflectance.csv",
        run / "export" / "chart_camera.ti3",
    ]
    for link in planted:
        link.unlink()
        _plant(link, victim)
    capsys.readouterr()
    assert main(["run", str(cfg)]) == 0
    assert victim.read_text() == VICTIM_TEXT
    assert not any(p.is_symlink() for p in planted)
    assert read_spectra_csv(planted[0]).values.shape[0] > 0


# -- reads stay inside the configuration's folder -----------------------------------
SECRET = "root:*:19000:0:99999:7:::"
CONFIG_FILE_KEYS = [
    ("sample", "reference"),
    ("sample", "reflectances"),
    ("chart", "reflectances"),
    ("chart", "layout"),
    ("estimate", "prior"),
]


def _secret_file(tmp_path: Path) -> Path:
    secret = tmp_path / "outside" / "shadow"
    secret.parent.mkdir()
    secret.write_text(f"{SECRET}\ndaemon:*:19000:0:99999:7:::\n")
    return secret


@pytest.mark.parametrize(("section", "key"), CONFIG_FILE_KEYS)
@pytest.mark.parametrize("how", ["absolute", "dotdot", "link"])
def test_a_config_cannot_read_outside_its_folder(
    tmp_path, capsys, section, key, how
) -> None:
    secret = _secret_file(tmp_path)
    proj = tmp_path / "proj"
    proj.mkdir()
    if how == "absolute":
        value = str(secret)
    elif how == "dotdot":
        value = "../outside/shadow"
    else:
        (proj / "inside.csv").symlink_to(secret)
        value = "inside.csv"
    cfg = proj / "run.toml"
    cfg.write_text(f'out = "m"\n[{section}]\n{key} = "{value}"\n')
    rc = main(["run", str(cfg)])
    err = _one_line(capsys, rc, 2)
    assert f"{section}.{key}:" in err and "outside the configuration's folder" in err
    assert "root:" not in err and "daemon" not in err
    assert not (proj / "m").exists()  # refused before anything ran


def test_files_beside_the_config_and_shipped_resources_are_read(tmp_path) -> None:
    from tunespec.app.pipeline.plan import load_config, plan_from_config

    proj = tmp_path / "proj"
    (proj / "data").mkdir(parents=True)
    write_spectra_csv(load_colorchecker_sg(), proj / "data" / "prior.csv")
    cfg = proj / "run.toml"
    cfg.write_text(
        '[estimate]\nprior = "data/prior.csv"\n'
        '[chart]\nlayout = "layouts/colorchecker_sg.json"\n'
    )
    plan = plan_from_config(load_config(cfg))
    assert plan.prior is not None and len(plan.prior.names) == 140
    assert plan.chart_layout.rows * plan.chart_layout.cols == 140
    assert plan.out_dir == proj / "run"


def test_a_file_that_is_no_spectral_csv_is_not_echoed(tmp_path) -> None:
    from tunespec.core.errors import InputError

    secret = _secret_file(tmp_path)
    env = tmp_path / "environ"
    env.write_bytes(b"HOME=/root\x00SECRET=hunter2\x00")
    for path in (secret, env):
        with pytest.raises(InputError) as info:
            read_spectra_csv(path)
        text = str(info.value)
        assert "not a spectral CSV header" in text and "wavelength_nm" in text
        assert "root" not in text.replace(str(tmp_path), "")
        assert "hunter2" not in text


@pytest.mark.parametrize("out", ["../elsewhere", "/tmp/x-tunespec-out"])
def test_a_config_out_outside_its_folder_is_refused(tmp_path, capsys, out) -> None:
    proj = tmp_path / "proj"
    proj.mkdir()
    cfg = proj / "run.toml"
    cfg.write_text(f'out = "{out}"\n')
    rc = main(["run", str(cfg)])
    err = _one_line(capsys, rc, 2)
    assert "out:" in err and "--out" in err
    assert not (tmp_path / "elsewhere").exists()


def test_out_on_the_command_line_may_be_anywhere(tmp_path) -> None:
    from tunespec.app.pipeline.plan import load_config, plan_from_config

    proj = tmp_path / "proj"
    proj.mkdir()
    cfg = proj / "run.toml"
    cfg.write_text('out = "../elsewhere"\n')
    plan = plan_from_config(load_config(cfg), out=tmp_path / "chosen")
    assert plan.out_dir == tmp_path / "chosen"


# -- a scheduler address in a file needs the command line ---------------------------
def test_a_scheduler_address_in_a_config_needs_confirmation(tmp_path, capsys) -> None:
    from tunespec.app.pipeline.plan import load_config, plan_from_config

    cfg = tmp_path / "run.toml"
    cfg.write_text('out = "m"\nscheduler = "tcp://203.0.113.9:8786"\n')
    rc = main(["run", str(cfg)])
    err = _one_line(capsys, rc, 2)
    assert str(cfg) in err and "scheduler:" in err
    assert "--scheduler tcp://203.0.113.9:8786" in err
    assert not (tmp_path / "m").exists()  # nothing captured, nothing connected
    confirmed = plan_from_config(load_config(cfg), scheduler="tcp://203.0.113.9:8786")
    assert confirmed.scheduler == "tcp://203.0.113.9:8786"
    # the command line's choice replaces the file's
    local = plan_from_config(load_config(cfg), scheduler="threads")
    assert local.scheduler == "threads"


@pytest.mark.parametrize("value", ["threads", "sync", "processes"])
def test_a_local_scheduler_in_a_config_needs_nothing(tmp_path, value) -> None:
    from tunespec.app.pipeline.plan import load_config, plan_from_config

    cfg = tmp_path / "run.toml"
    cfg.write_text(f'scheduler = "{value}"\n')
    assert plan_from_config(load_config(cfg)).scheduler == value


# -- a session's files stay inside it; process checks them by default ----------------
SG_LAYOUT_PATH = "layouts/colorchecker_sg.json"


@pytest.fixture(scope="module")
def captured(tmp_path_factory) -> Path:
    from tunespec.core.datasets import resource_path

    out = tmp_path_factory.mktemp("cap") / "s"
    args = ["capture", "--layout", str(resource_path(SG_LAYOUT_PATH)), "--out"]
    args += [str(out), "--resolution", "384x256", "--channels", "LED450,LED540"]
    assert main([*args, "--exposure", "2", "-q"]) == 0
    return out


def _session_copy(captured: Path, tmp_path: Path) -> Path:
    import shutil

    dst = tmp_path / "s"
    shutil.copytree(captured, dst)
    return dst


def _process(session: Path, tmp_path: Path, *extra: str) -> int:
    return main(["process", str(session), "-o", str(tmp_path / "r.csv"), *extra])


def test_process_works_on_the_session_as_captured(captured, tmp_path) -> None:
    s = _session_copy(captured, tmp_path)
    assert _process(s, tmp_path, "-q") == 0
    assert read_responses_csv(tmp_path / "r.csv").rgb.shape[:2] == (140, 2)


def test_process_refuses_a_linked_spd_and_does_not_echo_it(
    captured, tmp_path, capsys
) -> None:
    s = _session_copy(captured, tmp_path)
    secret = _secret_file(tmp_path)
    spd = s / "frames" / "target_LED450.spd.csv"
    spd.unlink()
    spd.symlink_to(secret)
    for extra in ((), ("--no-verify",)):
        rc = _process(s, tmp_path, *extra)
        err = _one_line(capsys, rc, 2)
        assert "frames/target_LED450.spd.csv is a link" in err, err
        assert "root:" not in err
    assert not (tmp_path / "r.csv").exists()


def test_process_refuses_a_linked_frames_folder(captured, tmp_path, capsys) -> None:
    import shutil

    s = _session_copy(captured, tmp_path)
    moved = tmp_path / "elsewhere_frames"
    shutil.move(s / "frames", moved)
    (s / "frames").symlink_to(moved)
    rc = _process(s, tmp_path, "--no-verify")
    err = _one_line(capsys, rc, 2)
    assert "is a link" in err and "frames/" in err


def test_process_verifies_checksums_by_default(captured, tmp_path, capsys) -> None:
    s = _session_copy(captured, tmp_path)
    spd = s / "frames" / "target_LED540.spd.csv"
    lines = spd.read_text().splitlines()
    wl, value = lines[100].split(",")
    lines[100] = f"{wl},{float(value) * 1.01!r}"  # one value 1 % off
    spd.write_text("\n".join(lines) + "\n")
    rc = _process(s, tmp_path)
    err = _one_line(capsys, rc, 2)
    assert "target_LED540.spd.csv fails its checksum" in err
    assert _process(s, tmp_path, "--no-verify", "-q") == 0
    assert _process(s, tmp_path, "--verify") == 2  # the old flag: accepted, a no-op


def _rewrite_spd(path: Path, edit) -> None:
    lines = path.read_text().splitlines()
    path.write_text("\n".join(edit(lines)) + "\n")


@pytest.mark.parametrize(
    ("edit", "expected"),
    [
        (lambda ls: ls[: len(ls) // 2], "cut short"),  # cut at a line boundary
        (
            lambda ls: (
                [ls[0]]
                + [
                    f"{float(a) / 1000:g},{b}"
                    for a, b in (x.split(",") for x in ls[1:])
                ]
            ),
            "expected nm, not µm",
        ),
        (lambda ls: [ls[0]] + [x.split(",")[0] + ",0" for x in ls[1:]], "zero"),
    ],
    ids=["cut", "micrometres", "zeros"],
)
def test_process_refuses_an_implausible_spd(
    captured, tmp_path, capsys, edit, expected
) -> None:
    s = _session_copy(captured, tmp_path)
    spd = s / "frames" / "target_LED450.spd.csv"
    _rewrite_spd(spd, edit)
    rc = _process(s, tmp_path, "--no-verify")
    err = _one_line(capsys, rc, 2)
    assert str(spd) in err and expected in err
    assert not (tmp_path / "r.csv").exists()


def test_a_measurement_reference_path_stays_in_its_folder(tmp_path) -> None:
    from tunespec.app.pipeline.folder import MeasurementFolder, measurement_reference

    secret = _secret_file(tmp_path)
    folder = MeasurementFolder.at(tmp_path / "m")
    (folder.root / "refs").mkdir(parents=True)
    (folder.root / "refs" / "ref.csv").write_text("x")
    (folder.root / "link.csv").symlink_to(secret)
    inside = measurement_reference(folder, "refs/ref.csv")
    assert inside == (folder.root / "refs" / "ref.csv").resolve()
    for value in (str(secret), "../outside/shadow", "link.csv", 5, ""):
        assert measurement_reference(folder, value) is None, value
    # the operator's own choice on this computer (remembered in user settings)
    assert measurement_reference(folder, str(secret), allowed=str(secret)) == secret


# -- disk full: exit 4, the right folder, nothing truncated, nothing left ---------------
def _fsync_fills_the_disk(monkeypatch) -> None:
    """Every fsync (after the data went into a temporary file) finds the disk full."""
    real = os.fsync

    def full(fd: int) -> None:
        real(fd)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(os, "fsync", full)


def _disk_full_line(capsys, rc: int, folder: Path) -> None:
    err = _one_line(capsys, rc, EXIT_DISK_FULL)
    assert f"disk full: {folder}: no space left" in err, err
    assert "--resume" not in err


def test_disk_full_in_process_names_the_output_folder(
    captured, tmp_path, monkeypatch, capsys
) -> None:
    s = _session_copy(captured, tmp_path)
    out = tmp_path / "out"
    out.mkdir()
    _fsync_fills_the_disk(monkeypatch)
    rc = main(["process", str(s), "-o", str(out / "r.csv"), "--no-verify"])
    _disk_full_line(capsys, rc, out)
    assert os.listdir(out) == []


def test_disk_full_in_export_cgats_and_report(tmp_path, monkeypatch, capsys) -> None:
    sg = tmp_path / "sg.csv"
    write_spectra_csv(load_colorchecker_sg(), sg)
    out = tmp_path / "out"
    _fsync_fills_the_disk(monkeypatch)
    rc = main(["export-cgats", "--reflectances", str(sg), "-o", str(out / "x.ti3")])
    _disk_full_line(capsys, rc, out)
    rc = main(["report", "-o", str(out / "rep"), "--reflectances", str(sg)])
    _disk_full_line(capsys, rc, out / "rep")
    assert [p.name for p in out.rglob("*") if p.is_file()] == []


@pytest.mark.slow
def test_disk_full_in_estimate_image_leaves_no_work_folder(
    captured, tmp_path, monkeypatch, capsys
) -> None:
    import tunespec.core.io.image_formats as fmt
    from tunespec.core.datasets import load_camera

    s = _session_copy(captured, tmp_path)
    cam = tmp_path / "cam.csv"
    write_spectra_csv(load_camera(), cam)
    # its side file (no LED corrections): else estimate-image warns that it is missing
    (tmp_path / "cam.csv.meta.json").write_text('{"spd_shift_nm": 0.0}')
    out = tmp_path / "img"
    real = fmt.os.pwrite
    calls = {"n": 0}

    def full_after_some(fd: int, data, offset: int) -> int:
        calls["n"] += 1
        if calls["n"] > 2:  # the response stack partly written, then full
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(fd, data, offset)

    monkeypatch.setattr(fmt.os, "pwrite", full_after_some)
    rc = main(["estimate-image", str(s), "--sensitivities", str(cam), "--out",
               str(out), "-q"])  # fmt: skip
    _disk_full_line(capsys, rc, out)
    assert calls["n"] > 2
    assert not (out / ".work").exists()
    assert sorted(p.name for p in out.iterdir()) == []


def test_results_that_are_links_are_not_read(tmp_path) -> None:
    from tunespec.app.pipeline.folder import (
        read_exports_index,
        read_processed,
        write_exports_index,
    )
    from tunespec.core.datasets import resource_path
    from tunespec.core.layout import TargetLayout

    out = tmp_path / "export"
    out.mkdir()
    sg = out / "reflectances.csv"
    write_spectra_csv(load_colorchecker_sg(), sg)
    write_exports_index(out, {"reflectances_csv": sg})
    assert read_exports_index(out) == {"reflectances_csv": sg}
    secret = _secret_file(tmp_path)
    sg.unlink()
    sg.symlink_to(secret)
    assert read_exports_index(out) is None  # done again: the link is replaced
    sg.unlink()
    write_spectra_csv(load_colorchecker_sg(), sg)
    (out / "exports.json").write_text('{"x": "../outside/shadow"}')
    assert read_exports_index(out) is None
    layout = TargetLayout.load(resource_path(SG_LAYOUT_PATH))
    (out / "responses.csv").symlink_to(secret)
    (out / "illuminants.csv").write_text("x")
    assert read_processed(out, layout) is None
