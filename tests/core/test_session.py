"""Session folder and manifest: planning, atomic commits, resume bookkeeping."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from tunespec.core.errors import InputError
from tunespec.core.io.session import (
    MANIFEST_NAME,
    SESSION_VERSION,
    CaptureSettings,
    FrameSpec,
    Session,
    atomic_write_text,
    create_temp_file,
    find_darks,
    frames_by_channel,
    plan_frames,
    sha256_file,
    with_exposures,
)
from tunespec.core.layout import TargetLayout
from tunespec.core.spectra import Spectra

LAYOUT = TargetLayout("t", 2, 2, 40.0, 40.0, patch_names=("a", "b", "c", "d"))


def _settings(**kw) -> CaptureSettings:
    base = {
        "channels": ("L1", "L2"),
        "exposure_mode": "fixed",
        "exposures_s": {"L1": (0.5,), "L2": (2.0,)},
    }
    base.update(kw)
    return CaptureSettings(**base)


def _spd() -> Spectra:
    return Spectra(np.array([400.0, 500.0, 600.0]), [[0.1, 0.3, 0.2]], ("measured",))


def _commit(session: Session, spec: FrameSpec, payload: bytes = b"raw"):
    stem = session.temp_stem(spec.id)
    path = stem.with_suffix(".dng")
    path.write_bytes(payload + spec.id.encode())
    spd = None if spec.kind == "dark" else _spd()
    return session.commit_frame(spec, path, spd=spd)


def test_plan_darks_per_exposure_then_whites_then_targets() -> None:
    plan = plan_frames(
        _settings(
            n_darks=2,
            bracket_factors=(1.0, 0.25),
            exposures_s={"L1": (0.5, 0.125), "L2": (2.0, 0.5)},
        )
    )
    kinds = [f.kind for f in plan]
    assert kinds == sorted(kinds, key=["dark", "white", "target"].index)
    darks = [f for f in plan if f.kind == "dark"]
    # distinct exposures 2, 0.5, 0.125 (0.5 shared by L1 b0 and L2 b1), 2 each
    assert [f.exposure_s for f in darks] == [2.0, 2.0, 0.5, 0.5, 0.125, 0.125]
    assert len({f.id for f in plan}) == len(plan)
    assert [f.id for f in plan if f.kind == "target"] == [
        "target_L1",
        "target_L1_b1",
        "target_L2",
        "target_L2_b1",
    ]


def test_plan_needs_resolved_exposures() -> None:
    s = CaptureSettings(("L1", "L2"), exposures_s={"L1": (1.0,)})
    assert not s.resolved
    with pytest.raises(InputError, match="L2"):
        plan_frames(s)
    assert with_exposures(s, {"L2": [0.25]}).resolved


@pytest.mark.parametrize(
    "kw",
    [
        {"channels": ()},
        {"channels": ("A", "A")},
        {"exposure_mode": "magic"},
        {"bracket_factors": (0.5, 1.0)},
        {"n_darks": 0},
        {"exposures_s": {"L1": (-1.0,)}},
        {"target_level": 1.2},
    ],
)
def test_bad_settings_are_input_errors(kw) -> None:
    with pytest.raises(InputError):
        _settings(**kw)


def test_create_commit_reopen_round_trip(tmp_path) -> None:
    s = Session.create(
        tmp_path / "s",
        settings=_settings(),
        devices={"light": {"vendor": "Sim", "model": "CAL1", "serial": "1"}},
        layout=LAYOUT,
        meta={"operator": "test"},
    )
    assert len(s.missing()) == 6  # 2 exposures -> 2 darks, + 2 whites + 2 targets
    for spec in s.plan():
        rec = _commit(s, spec)
        assert rec.sha256 == sha256_file(s.path_of(rec))
        assert rec.file == f"frames/{spec.id}.dng"
    assert s.missing() == []
    again = Session.open(tmp_path / "s")
    assert again.frames == s.frames
    assert again.layout == LAYOUT
    assert again.settings == s.settings
    assert again.devices["light"]["model"] == "CAL1"
    assert again.meta == {"operator": "test"}
    rec = again.frame("target_L2")
    assert rec is not None and rec.exposure_s == 2.0 and rec.channel == "L2"
    np.testing.assert_array_equal(again.read_spd(rec).values, _spd().values)
    assert [f.id for f in frames_by_channel(again.frames, "white")["L1"]] == [
        "white_L1"
    ]
    assert [d.id for d in find_darks(again.frames, 2.0, 100)] == ["dark_2s_iso100_0"]
    # nothing left behind in tmp/
    assert not list((tmp_path / "s" / "tmp").iterdir())
    manifest = json.loads((tmp_path / "s" / MANIFEST_NAME).read_text())
    assert manifest["format"] == "tunespec-session"
    assert manifest["version"] == SESSION_VERSION


def test_missing_covers_bad_tampered_and_deleted_frames(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=_settings(), layout=LAYOUT)
    recs = {spec.id: _commit(s, spec) for spec in s.plan()}
    s.mark_bad("white_L2", "blurred")
    s.path_of(recs["target_L1"]).write_bytes(b"changed")
    s.path_of(recs["dark_2s_iso100_0"]).unlink()
    missing = {f.id for f in s.missing()}
    assert missing == {"white_L2", "target_L1", "dark_2s_iso100_0"}
    assert s.frame("white_L2").note == "blurred"
    # a cheap check without hashing still sees the bad and the deleted frame
    assert {f.id for f in s.missing(verify=False)} == {"white_L2", "dark_2s_iso100_0"}
    # retaking replaces the record in place
    rec = _commit(s, s.missing()[0], payload=b"new")
    assert rec.status == "ok" and sum(f.id == rec.id for f in s.frames) == 1


def test_changed_exposure_makes_a_frame_missing(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=_settings(), layout=LAYOUT)
    for spec in s.plan():
        _commit(s, spec)
    s.set_settings(with_exposures(s.settings, {"L1": (0.25,)}))
    ids = {f.id for f in s.missing()}
    assert ids == {"dark_0.25s_iso100_0", "white_L1", "target_L1"}


def test_mark_bad_rejects_unknown_ids(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=_settings())
    with pytest.raises(InputError, match="nope"):
        s.mark_bad(["nope"])


def test_create_refuses_an_existing_session_and_open_checks_format(tmp_path) -> None:
    Session.create(tmp_path / "s", settings=_settings())
    with pytest.raises(InputError, match="already exists"):
        Session.create(tmp_path / "s", settings=_settings())
    with pytest.raises(InputError, match="no manifest"):
        Session.open(tmp_path / "nothing")
    m = tmp_path / "s" / MANIFEST_NAME
    d = json.loads(m.read_text())
    d["version"] = SESSION_VERSION + 1
    m.write_text(json.dumps(d))
    with pytest.raises(InputError, match="newer"):
        Session.open(tmp_path / "s")
    m.write_text("{ broken")
    with pytest.raises(InputError, match="JSON"):
        Session.open(tmp_path / "s")


def test_a_failed_manifest_write_keeps_the_previous_manifest(
    tmp_path, monkeypatch
) -> None:
    s = Session.create(tmp_path / "s", settings=_settings(), layout=LAYOUT)
    first = s.plan()[0]
    _commit(s, first)
    before = (tmp_path / "s" / MANIFEST_NAME).read_bytes()

    real_replace = os.replace

    def crash(src, dst):
        if str(dst).endswith(MANIFEST_NAME):
            raise OSError(
                "disk full"
            )  # dies between writing the temp file and renaming
        real_replace(src, dst)

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        _commit(s, s.plan()[1])
    monkeypatch.undo()
    assert (tmp_path / "s" / MANIFEST_NAME).read_bytes() == before
    reopened = Session.open(tmp_path / "s")
    assert [f.id for f in reopened.frames] == [first.id]
    assert reopened.missing()[0].id == s.plan()[1].id
    # no temporary manifest left beside it
    assert sorted(p.name for p in (tmp_path / "s").iterdir()) == sorted(
        [MANIFEST_NAME, "frames", "tmp"]
    )
    # and the session object did not record what is not on disk
    assert [f.id for f in s.frames] == [first.id]


def test_atomic_write_text_replaces_whole_file(tmp_path) -> None:
    p = tmp_path / "f.txt"
    atomic_write_text(p, "one")
    atomic_write_text(p, "two")
    assert p.read_text() == "two" and [x.name for x in tmp_path.iterdir()] == ["f.txt"]


def test_clean_temp_removes_leftovers_and_the_empty_folder(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=_settings())
    s.temp_stem("x").with_suffix(".dng").write_bytes(b"half")
    s.clean_temp()
    assert not (tmp_path / "s" / "tmp").exists()
    s.clean_temp()  # nothing to clean: fine
    assert s.temp_stem("y").parent.is_dir()  # made again when needed


@pytest.fixture
def umask_027():
    """A stricter umask than the usual 022, restored afterwards."""
    old = os.umask(0o027)
    yield 0o027
    os.umask(old)


def test_atomic_writes_get_the_permissions_of_a_plain_write(tmp_path, umask_027):
    """mkstemp's 0600 made manifests and summary.json owner-only while every other
    output followed the umask (issue 13)."""
    plain = tmp_path / "plain.txt"
    plain.write_text("x")
    atomic = tmp_path / "atomic.txt"
    atomic_write_text(atomic, "one")
    atomic_write_text(atomic, "two")  # replacing keeps the rule
    temp = create_temp_file(tmp_path, ".t.")
    s = Session.create(tmp_path / "s", settings=_settings())
    want = 0o666 & ~umask_027
    for p in (plain, atomic, temp, s.manifest_path):
        assert os.stat(p).st_mode & 0o777 == want, p


def _damaged(tmp_path, edit) -> Session:
    """A committed session whose manifest ``edit(m)`` damaged on disk."""
    s = Session.create(tmp_path / "s", settings=_settings(), layout=LAYOUT)
    for spec in s.plan()[:2]:
        _commit(s, spec)
    m = json.loads(s.manifest_path.read_text())
    edit(m)
    s.manifest_path.write_text(json.dumps(m))
    return s


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda m: m.update(version="abc"), "bad session version"),
        (lambda m: m.update(frames={"a": 1}), "'frames' must be a list"),
        (lambda m: m.pop("frames"), "'frames' must be a list"),
        (lambda m: m["frames"].append(3), "expected an object"),
        (lambda m: m.update(settings=[1]), "expected an object"),
        (lambda m: m.pop("settings"), "no 'settings'"),
        # a string would silently become one channel per character
        (lambda m: m["settings"].update(channels="L1"), "list of names"),
        (lambda m: m["settings"].update(exposures_s=[1]), "exposures_s"),
        (lambda m: m["settings"].update(levels=[1]), "levels"),
        (lambda m: m.update(layout=5), "'layout' must be an object"),
        (lambda m: m.update(devices=[1]), "'devices' must be an object"),
        (lambda m: m["frames"][0].update(exposure_s="x"), "exposure_s"),
        (lambda m: m["frames"][0].update(exposure_s=-1.0), "exposure_s"),
        (lambda m: m["frames"][0].update(iso="100"), "iso"),
        (lambda m: m["frames"][1].update(file="../../etc/passwd"), "inside"),
        (lambda m: m["frames"][1].update(file="/etc/passwd"), "inside"),
        (lambda m: m["frames"][1].update(spd_file="C:/x.csv"), "inside"),
        (lambda m: m["frames"].append(m["frames"][0]), "listed twice"),
    ],
)
def test_a_damaged_manifest_fails_on_open_with_one_line(
    tmp_path, edit, message
) -> None:
    s = _damaged(tmp_path, edit)
    with pytest.raises(InputError, match=message) as info:
        Session.open(s.root)
    assert str(s.manifest_path) in str(info.value)


def test_an_intact_manifest_still_opens(tmp_path) -> None:
    s = _damaged(tmp_path, lambda m: None)
    assert [f.id for f in Session.open(s.root).frames] == [f.id for f in s.frames]


def test_fingerprint_changes_when_a_frame_is_retaken(tmp_path) -> None:
    s = Session.create(tmp_path / "s", settings=_settings(), layout=LAYOUT)
    for spec in s.plan():
        _commit(s, spec)
    before = s.fingerprint()
    assert Session.open(tmp_path / "s").fingerprint() == before  # stable on reopen
    s.mark_bad("white_L2", "blurred")
    assert s.fingerprint() != before
    _commit(s, s.missing()[0], payload=b"retaken")
    assert s.fingerprint() not in (before, "")
