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

from tunespec.app.cli import EXIT_DISK_FULL, main
from tunespec.core.atomic import atomic_open, atomic_write_text
from tunespec.core.datasets import load_colorchecker_sg
from tunespec.core.errors import DiskFullError
from tunespec.core.io.cgats import ti3_table, write_cgats
from tunespec.core.responses import Responses, read_responses_csv, write_responses_csv
from tunespec.core.spectra import read_spectra_csv, write_spectra_csv

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
    err = capsys.readouterr().err.strip()
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
