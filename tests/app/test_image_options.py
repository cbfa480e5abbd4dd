"""``estimate-image`` / ``batch`` options of the noise model and the bins: parsed
into :class:`tunespec.app.pipeline.image.ImageSettings`, bad values one line."""

from __future__ import annotations

import numpy as np
import pytest

from tunespec.app.cli import main
from tunespec.app.pipeline.image import ImageSettings
from tunespec.core.errors import InputError
from tunespec.core.image import NoiseModel, SensorFigures


def _parse(*extra: str) -> ImageSettings:
    import argparse

    from tunespec.app.cli.image_cmds import _settings, register

    parser = argparse.ArgumentParser()
    register(parser.add_subparsers())
    args = parser.parse_args(
        ["estimate-image", "S", "--sensitivities", "s.csv", "--out", "o", *extra]
    )
    return _settings(args)  # type: ignore[return-value]


def test_default_is_the_photon_transfer_fit() -> None:
    s = _parse()
    assert s.noise is None and (s.n_levels, s.n_phi) == (32, 4)
    assert _parse("--noise-model", "photon-transfer").noise is None


def test_camera_figures_with_the_sessions_darks() -> None:
    s = _parse("--noise-model", "camera:67000,30,2", "--level-bins", "48")
    assert s.noise == SensorFigures(67000.0, 30.0, 2.0) and s.n_levels == 48
    # the session's 4 averaged darks add a quarter of a frame's read noise
    m = s.noise.model(4)
    fs_e = 67000.0 / 2.0
    np.testing.assert_allclose(m.shot_gain, [1 / fs_e, 0.5 / fs_e, 1 / fs_e])
    np.testing.assert_allclose(m.read_var[0], (30.0 / fs_e) ** 2 * 1.25)
    assert m.source == "camera"


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--noise-model", "camera:67000", "FULL_WELL_E,READ_NOISE_E"),
        ("--noise-model", "sensor:1,2", "photon-transfer"),
        ("--noise-model", "camera:0,30", "full well 0 e- (> 0)"),
        ("--noise-model", "camera:67000,nan", "read noise nan"),
        ("--level-bins", "0", "level bins: expected an integer from 1 to 256"),
        ("--phi-bins", "99", "phi bins: expected an integer from 1 to 32"),
    ],
)
def test_bad_values_give_one_line(tmp_path, capsys, option, value, message) -> None:
    session = tmp_path / "s"
    session.mkdir()
    (session / "manifest.json").write_text("{}")
    with pytest.raises(SystemExit) if option == "--noise-model" else _no_raise():
        code = main([
            "estimate-image", str(session), "--sensitivities", str(tmp_path / "x.csv"),
            "--out", str(tmp_path / "o"), option, value,
        ])  # fmt: skip
        assert code != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert message in err[-1], err
    assert "Traceback" not in "\n".join(err)


class _no_raise:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return False


def test_settings_check_their_values() -> None:
    with pytest.raises(InputError, match="level bins"):
        ImageSettings(n_levels=1.5)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="NoiseModel or SensorFigures"):
        ImageSettings(noise="camera")
    ok = NoiseModel([1e-6] * 3, [1e-5] * 3)
    assert ImageSettings(noise=ok).noise is ok


def test_dark_option() -> None:
    assert _parse().dark == "pixel"
    assert _parse("--dark", "smooth").dark == "smooth"
    with pytest.raises(InputError, match="dark: expected one of pixel, smooth"):
        ImageSettings(dark="median")


def test_settings_doc_survives_json_and_tells_settings_apart() -> None:
    """A batch skips a session only when its provenance's settings are these."""
    import json

    from tunespec.app.pipeline.image import _settings_doc
    from tunespec.core.spectra import Grid

    grid = Grid(400.0, 700.0, 5.0)
    docs = [
        _settings_doc(s, grid)
        for s in (
            ImageSettings(),
            ImageSettings(dark="smooth"),
            ImageSettings(noise=SensorFigures(67000.0, 30.0)),
            ImageSettings(noise=NoiseModel([1e-6] * 3, [1e-5] * 3), n_levels=8),
        )
    ]
    for d in docs:
        assert json.loads(json.dumps(d)) == d
    assert len({json.dumps(d, sort_keys=True) for d in docs}) == len(docs)


def test_sensitivities_without_their_side_file_are_said_never_silently(
    tmp_path,
) -> None:
    """estimate-image and batch go on without the LED corrections only saying so,
    and repeat what the calibration found about itself."""
    from tunespec.app.pipeline.image import calibration_warnings
    from tunespec.core.io.export import read_sensitivity_meta

    sens = tmp_path / "S.csv"
    sens.write_text("wavelength,R,G,B\n")

    def said() -> list[str]:
        return calibration_warnings(sens, read_sensitivity_meta(sens))

    (line,) = said()
    assert line.startswith("no LED corrections next to S.csv (S.csv.meta.json)")
    (tmp_path / "S.csv.meta.json").write_text("{}")
    assert said() == []
    (tmp_path / "S.csv.meta.json").write_text(
        '{"warnings": ["Table 1 is poor", "self-check: chi-square 8"]}'
    )
    assert said() == [f"the calibration {sens} warned: Table 1 is poor (and 1 more)"]


def test_a_session_whose_board_bends_is_said() -> None:
    """The per-pixel images have no Eq. 1 check of their targets: the white board's
    channels say a session on a tone curve (``lighting.sample_board``), in the
    record the provenance keeps."""
    from tunespec.app.pipeline.lighting import sample_scale_record
    from tunespec.core.datasets import (
        DEFAULT_CAMERA,
        load_camera_database,
        load_colorchecker_sg,
        load_led_set,
    )
    from tunespec.core.plausibility import white_response
    from tunespec.core.simulate import scale_to_exposure
    from tunespec.core.spectra import CALIBRATION_GRID

    camera = load_camera_database(CALIBRATION_GRID)[DEFAULT_CAMERA]
    leds = scale_to_exposure(
        load_colorchecker_sg(CALIBRATION_GRID), load_led_set(CALIBRATION_GRID), camera
    )
    board = 0.9 * white_response(leds, camera)
    lights = list(leds.names)
    linear = sample_scale_record(board, lights, leds, camera, {})
    assert linear["warnings"] == [] and linear["forced"] == []
    toned = sample_scale_record(board ** (1 / 1.2), lights, leds, camera, {})
    assert len(toned["warnings"]) == 1, toned
    assert (
        "channels bend" in toned["warnings"][0] and "gamma -0.1" in toned["warnings"][0]
    )


def test_batch_tells_warn_each_sessions_warnings_under_its_path(
    tmp_path, monkeypatch
) -> None:
    """What a session's images warn of (``provenance.json``'s ``warnings``, e.g. its
    board's bend) reaches ``batch``'s warn callback once, named by the session;
    the per-session work itself is faked here (the bench's sessions run in
    ``tests/test_image_pipeline.py``)."""
    from types import SimpleNamespace

    from tunespec.app.pipeline import image

    root = tmp_path / "in"
    for name in ("a", "b", "c"):
        (root / name).mkdir(parents=True)
        (root / name / "manifest.json").write_text("{}")
    monkeypatch.setattr(
        image, "_load_calibration", lambda *_: SimpleNamespace(sha256="x")
    )
    monkeypatch.setattr(image, "session_graph", lambda s, *_: s.name)
    bent = {"b": ["the white background's channels bend"], "c": ["one", "two"]}
    monkeypatch.setattr(
        image,
        "compute",
        lambda graphs, *_: [{"warnings": bent.get(g, [])} for g in graphs],
    )
    said: list[str] = []
    result = image.batch_images(root, "S.csv", tmp_path / "out", warn=said.append)
    assert len(result["done"]) == 3
    assert said == [
        f"{root / 'b'}: the white background's channels bend",
        f"{root / 'c'}: one",
        f"{root / 'c'}: two",
    ]
    # without a callback the same batch says nothing and still finishes
    assert len(image.batch_images(root, "S.csv", tmp_path / "o2")["done"]) == 3
