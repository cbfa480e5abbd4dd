"""A measurement session on disk: a folder with a versioned JSON manifest and raw files.

Layout of a session folder::

    SESSION/
      manifest.json          format "tunespec-session", version, devices, settings,
                             target layout, and one record per frame
      frames/<id>.<ext>      raw files as the camera wrote them (``.dng``, ``.cr2``)
      frames/<id>.spd.csv    the light source's measured SPD around that exposure
      tmp/                   files being written (never referenced by the manifest)
      session.lock           who is writing the session now (pid, host, start time)

Crash safety: a frame is written to ``tmp/``, flushed to disk, moved into ``frames/``
with :func:`os.replace` and only then entered into the manifest, which is itself
rewritten atomically (temporary file, ``fsync``, ``os.replace``, ``fsync`` of the
folder). A crash, a kill or a device error at any moment therefore leaves a manifest
that lists only complete, checksummed frames (the raw file and its SPD); what is not
listed, or fails its checksums, is taken again on resume (:meth:`Session.missing`).

One writer at a time: :class:`SessionLock` holds ``session.lock`` (an advisory
``flock``, released by the kernel when its process dies, so a lock left by a killed
capture is recognised as stale and taken over; :mod:`.session_lock`). Temp cleaning
never follows links: a ``tmp`` that is a symbolic link is removed (the link, not what
it points to).

The frames a session needs follow from its :class:`CaptureSettings`
(:func:`plan_frames`): dark frame(s) for each distinct exposure, then per LED channel
a white-background frame and a target frame (one per exposure bracket). The
manifest's content (settings, plan, frame records and their checks) is
:mod:`.session_format`; its names are importable from here too. This module is the
folder: create, open, verify, resume (:meth:`Session.missing`), commit frames.

References
----------
Trichromatic Reflectance Capture Using a Tunable Light Source (``shared/reference``),
section "Capturing and Processing": dark frame, white background ``A_B`` and target
``A`` under each of the 22 LEDs.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import os
from collections.abc import Iterable, Mapping
from os import PathLike
from pathlib import Path, PurePosixPath
from typing import Any

from tunespec.core.atomic import (
    atomic_write_bytes,
    atomic_write_text,
    create_temp_file,
    fsync_dir,
)
from tunespec.core.errors import InputError

# the manifest's content (session_format) and the lock (session_lock) are re-exported:
# their names stay importable from here
from tunespec.core.io.session_format import (
    EXPOSURE_MODES,
    EXPOSURE_RTOL,
    FRAME_KINDS,
    FRAMES_DIR,
    LOCK_NAME,
    MANIFEST_NAME,
    MAX_BRACKETS,
    MAX_CHANNELS,
    MAX_DARKS,
    MAX_FRAMES,
    MAX_ISO,
    SESSION_FORMAT,
    SESSION_VERSION,
    TMP_DIR,
    CaptureSettings,
    FrameRecord,
    FrameSpec,
    dark_id,
    find_darks,
    frames_by_channel,
    plan_frames,
    same_spec,
    with_exposures,
)
from tunespec.core.io.session_lock import SessionBusyError, SessionLock
from tunespec.core.io.session_lock import utc_now as _utc_now
from tunespec.core.io.spectral import read_spectra_csv
from tunespec.core.io.spectral_csv import write_spectra_csv
from tunespec.core.layout import TargetLayout
from tunespec.core.limits import (
    dumps_json,
    read_json,
    shown,
)
from tunespec.core.spectra import Spectra

__all__ = [
    "EXPOSURE_MODES",
    "EXPOSURE_RTOL",
    "FRAMES_DIR",
    "FRAME_KINDS",
    "LOCK_NAME",
    "MANIFEST_NAME",
    "MAX_BRACKETS",
    "MAX_CHANNELS",
    "MAX_DARKS",
    "MAX_FRAMES",
    "MAX_ISO",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "TMP_DIR",
    "CaptureSettings",
    "FrameRecord",
    "FrameSpec",
    "Session",
    "SessionBusyError",
    "SessionLock",
    "atomic_write_bytes",
    "atomic_write_text",
    "create_temp_file",
    "dark_id",
    "find_darks",
    "frames_by_channel",
    "plan_frames",
    "sha256_file",
    "with_exposures",
]


# -- atomic file helpers (the one writer: tunespec.core.atomic) -------------------------
_fsync_dir = fsync_dir


def sha256_file(path: str | PathLike[str], *, chunk_bytes: int = 1 << 20) -> str:
    """Hex SHA-256 of a file, read in chunks (raw files are tens of MB)."""
    h = hashlib.sha256()
    buf = bytearray(chunk_bytes)  # one buffer, not a fresh 1 MB object per read
    view = memoryview(buf)
    with open(path, "rb", buffering=0) as fh:
        while n := fh.readinto(buf):
            h.update(view[:n])
    return h.hexdigest()


class Session:
    """A session folder and its manifest (see the module docstring).

    Open with :meth:`create` or :meth:`open`. Every change is written to disk before
    the method returns. Not thread-safe: one owner (the capture thread) at a time.
    """

    def __init__(self, root: Path, manifest: dict[str, Any]) -> None:
        self.root = Path(root)
        self._m = manifest

    # -- opening -----------------------------------------------------------------------
    @classmethod
    def create(
        cls,
        root: str | PathLike[str],
        *,
        settings: CaptureSettings,
        devices: Mapping[str, Mapping[str, str]] | None = None,
        layout: TargetLayout | None = None,
        meta: Mapping[str, str] | None = None,
    ) -> Session:
        """Start a new session in ``root`` (created; must not hold a manifest yet).

        Parameters
        ----------
        settings
            Capture settings.
        devices
            Per role (``"light"``, ``"camera"``, ``"stage"``) the device identity as a
            dict (vendor, model, serial, firmware, spec).
        layout
            The target's layout (its ``corners_px`` may be unknown).
        meta
            Free key/value notes (operator, sample name, ...).

        Raises
        ------
        InputError
            If ``root`` already holds a session.
        """
        root = Path(root)
        if (root / MANIFEST_NAME).exists():
            raise InputError(
                "a session already exists here (resume it instead)", path=root
            )
        (root / FRAMES_DIR).mkdir(parents=True, exist_ok=True)
        manifest: dict[str, Any] = {
            "format": SESSION_FORMAT,
            "version": SESSION_VERSION,
            "created_utc": _utc_now(),
            "devices": {k: dict(v) for k, v in (devices or {}).items()},
            "settings": settings.to_dict(),
            "layout": None if layout is None else layout.to_dict(),
            "meta": dict(meta or {}),
            "frames": [],
        }
        session = cls(root, manifest)
        session._write_manifest()
        return session

    @classmethod
    def open(cls, root: str | PathLike[str]) -> Session:
        """Open an existing session folder.

        Raises
        ------
        InputError
            No manifest, not valid JSON, another format or a newer version.
        """
        root = Path(root)
        path = root / MANIFEST_NAME
        if not path.exists():
            raise InputError(f"not a TuneSpec session (no {MANIFEST_NAME})", path=root)
        m = read_json(path)
        if not isinstance(m, dict) or m.get("format") != SESSION_FORMAT:
            raise InputError(
                f"not a session manifest (format != {SESSION_FORMAT!r})", path=path
            )
        version = m.get("version", 0)
        if not isinstance(version, int) or isinstance(version, bool) or version < 0:
            raise InputError(f"bad session version {shown(version)}", path=path)
        if version > SESSION_VERSION:
            raise InputError(
                f"session version {version} is newer than this TuneSpec "
                f"understands ({SESSION_VERSION})",
                path=path,
            )
        # validate eagerly so a damaged manifest fails here, naming the file, and
        # not later with a traceback from whatever reads the bad field first
        if not isinstance(m.get("frames"), list):
            raise InputError("damaged manifest: 'frames' must be a list", path=path)
        if len(m["frames"]) > MAX_FRAMES:
            raise InputError(
                f"damaged manifest: more than {MAX_FRAMES} frames", path=path
            )
        for key in ("devices", "meta"):
            if not isinstance(m.get(key, {}), dict):
                raise InputError(
                    f"damaged manifest: {key!r} must be an object", path=path
                )
        if not all(isinstance(v, dict) for v in m.get("devices", {}).values()):
            raise InputError(
                "damaged manifest: each of 'devices' must be an object", path=path
            )
        if "settings" not in m:
            raise InputError("damaged manifest: no 'settings'", path=path)
        records = [FrameRecord.from_dict(d, source=str(path)) for d in m["frames"]]
        ids = [r.id for r in records]
        if len(set(ids)) != len(ids):
            raise InputError("damaged manifest: a frame id is listed twice", path=path)
        CaptureSettings.from_dict(m["settings"], source=path)
        layout = m.get("layout")
        if layout is not None:
            if not isinstance(layout, dict):
                raise InputError(
                    "damaged manifest: 'layout' must be an object or null", path=path
                )
            TargetLayout.from_dict(layout, source=str(path))
        return cls(root, m)

    def reload(self) -> None:
        """Read the manifest again (another writer may have changed it before this
        process took the lock)."""
        self._m = Session.open(self.root)._m

    # -- manifest ----------------------------------------------------------------------
    @property
    def manifest_path(self) -> Path:
        return self.root / MANIFEST_NAME

    def _write_manifest(self, manifest: dict[str, Any] | None = None) -> None:
        """Write ``manifest`` (default the current one) and only then adopt it.

        If the write fails, the file on disk and this object both keep the previous
        state, so they never disagree.
        """
        m = self._m if manifest is None else manifest
        atomic_write_text(self.manifest_path, dumps_json(m, indent=1))
        self._m = m

    def _edited(self) -> dict[str, Any]:
        """A deep copy of the manifest to change and pass to :meth:`_write_manifest`."""
        return copy.deepcopy(self._m)

    @property
    def manifest(self) -> dict[str, Any]:
        """A deep copy of the manifest (read-only view for reports)."""
        copied: dict[str, Any] = json.loads(json.dumps(self._m))
        return copied

    @property
    def devices(self) -> dict[str, dict[str, str]]:
        return {k: dict(v) for k, v in self._m.get("devices", {}).items()}

    def set_devices(self, devices: Mapping[str, Mapping[str, str]]) -> None:
        """Record the devices in use (a resumed session may use other serials)."""
        m = self._edited()
        old = m.get("devices", {})
        new = {k: dict(v) for k, v in devices.items()}
        if old and old != new:
            history = m.setdefault("device_history", [])
            history.append({"until_utc": _utc_now(), "devices": old})
        m["devices"] = new
        self._write_manifest(m)

    @property
    def settings(self) -> CaptureSettings:
        return CaptureSettings.from_dict(self._m["settings"])

    def set_settings(self, settings: CaptureSettings) -> None:
        """Replace the capture settings (e.g. once exposures are metered)."""
        m = self._edited()
        m["settings"] = settings.to_dict()
        self._write_manifest(m)

    @property
    def layout(self) -> TargetLayout | None:
        d = self._m.get("layout")
        return (
            None
            if d is None
            else TargetLayout.from_dict(d, source=str(self.manifest_path))
        )

    def set_layout(self, layout: TargetLayout | None) -> None:
        m = self._edited()
        m["layout"] = None if layout is None else layout.to_dict()
        self._write_manifest(m)

    @property
    def meta(self) -> dict[str, str]:
        return dict(self._m.get("meta", {}))

    # -- frames ------------------------------------------------------------------------
    @property
    def frames(self) -> tuple[FrameRecord, ...]:
        """Every recorded frame, in capture order."""
        return tuple(FrameRecord.from_dict(d) for d in self._m["frames"])

    def frame(self, frame_id: str) -> FrameRecord | None:
        """The record of ``frame_id``, or ``None``."""
        for d in self._m["frames"]:
            if d["id"] == frame_id:
                return FrameRecord.from_dict(d)
        return None

    def fingerprint(self) -> str:
        """SHA-256 over the ids and checksums of the frames with status ok.

        Results computed from a session store it; when a frame is retaken or marked
        bad the fingerprint changes, so stale results can be recognised.
        """
        h = hashlib.sha256()
        for f in sorted(self.ok_frames(), key=lambda f: f.id):
            h.update(f"{f.id}:{f.sha256}\n".encode())
        return h.hexdigest()

    def ok_frames(self, kind: str | None = None) -> list[FrameRecord]:
        """Frames with status ok (of one ``kind`` if given)."""
        return [f for f in self.frames if f.status == "ok" and kind in (None, f.kind)]

    def path_of(self, record: FrameRecord) -> Path:
        """Absolute path of a frame's raw file (inside the session, no link).

        Raises
        ------
        InputError
            The file, or ``frames/``, is a link (possibly out of the session).
        """
        return self.inside(record.file)

    def inside(self, rel: str) -> Path:
        """``root / rel`` when it is a path inside the session with no link on the
        way (``frames/`` or the file itself a link would let a session received
        from someone else read any file); the session folder itself may be a link.

        Raises
        ------
        InputError
            Naming the manifest and the file.
        """
        path = self.root / rel
        parts = PurePosixPath(rel).parts
        try:
            real = path.resolve()
            expected = self.root.resolve().joinpath(*parts)
        except (OSError, RuntimeError):
            real, expected = path, None
        if ".." in parts or PurePosixPath(rel).is_absolute() or real != expected:
            raise InputError(
                f"{rel} is a link (or leaves the session folder): frames are read "
                "only from files inside the session",
                path=self.manifest_path,
            )
        return path

    def plan(self) -> list[FrameSpec]:
        """The frames this session needs (:func:`plan_frames` of its settings)."""
        return plan_frames(self.settings)

    def verify(self, record: FrameRecord) -> bool:
        """True if every file of the frame exists and matches its checksum."""
        return self.problem(record) == ""

    def problem(self, record: FrameRecord, *, checksums: bool = True) -> str:
        """What is wrong with a frame's files ("" if nothing).

        The raw file and the SPD must exist and (``checksums``) match the checksums
        recorded when the frame was committed; an SPD recorded without a checksum
        (older sessions) must at least be readable.
        """
        try:
            return self._problem(record, checksums)
        except OSError as exc:  # a folder where a file was, a link loop, ...
            return f"files of frame {record.id} cannot be read ({exc.strerror})"
        except InputError as exc:  # a link out of the session
            return exc.message

    def _problem(self, record: FrameRecord, checksums: bool) -> str:
        path = self.path_of(record)
        if not path.is_file():
            return f"raw file {record.file} is missing"
        if checksums and sha256_file(path) != record.sha256:
            return f"raw file {record.file} fails its checksum"
        if record.spd_file is None:
            return ""
        spd = self.inside(record.spd_file)
        if not spd.is_file():
            return f"SPD file {record.spd_file} is missing"
        if not checksums:
            return ""
        if record.spd_sha256 is not None:
            if sha256_file(spd) != record.spd_sha256:
                return f"SPD file {record.spd_file} fails its checksum"
            return ""
        try:
            read_spectra_csv(spd)
        except InputError:
            return f"SPD file {record.spd_file} is not readable"
        return ""

    def missing(self, *, verify: bool = True) -> list[FrameSpec]:
        """Planned frames that have no ok record, in capture order.

        A frame counts as missing when it was never recorded, is marked bad, was
        recorded with other parameters than planned, its raw file or SPD is gone,
        or (``verify``) one of them fails its checksum.
        """
        records = {f.id: f for f in self.frames}
        out = []
        for spec in self.plan():
            rec = records.get(spec.id)
            if (
                rec is None
                or rec.status != "ok"
                or not same_spec(rec.spec, spec)
                or self.problem(rec, checksums=verify)
            ):
                out.append(spec)
        return out

    def _tmp_dir(self) -> Path:
        """``tmp/`` as a real folder inside the session (a link there is removed)."""
        tmp = self.root / TMP_DIR
        if tmp.is_symlink() or (tmp.exists() and not tmp.is_dir()):
            tmp.unlink()  # the link itself, never what it points to
        tmp.mkdir(parents=True, exist_ok=True)
        return tmp

    def temp_stem(self, frame_id: str) -> Path:
        """Where a camera should write a frame before :meth:`commit_frame` (no suffix)."""
        return self._tmp_dir() / f"{frame_id}.{os.getpid()}"

    def clean_temp(self) -> None:
        """Remove leftovers of interrupted writes (never referenced by the manifest)
        and the then empty ``tmp/`` folder (:meth:`temp_stem` makes it again).

        Only entries directly in the session's own ``tmp/`` are removed; links are
        removed as links (never followed), folders are left alone.
        """
        tmp = self.root / TMP_DIR
        if not (tmp.is_symlink() or tmp.exists()):
            return
        tmp = self._tmp_dir()
        with os.scandir(tmp) as entries:
            for entry in entries:
                if entry.is_symlink() or entry.is_file(follow_symlinks=False):
                    with contextlib.suppress(OSError):
                        os.unlink(entry.path)
        with contextlib.suppress(OSError):  # not empty: something else is there
            tmp.rmdir()

    def commit_frame(
        self,
        spec: FrameSpec,
        raw_file: str | PathLike[str],
        *,
        spd: Spectra | None = None,
        note: str = "",
    ) -> FrameRecord:
        """Move a finished raw file into the session and record it (atomically).

        Parameters
        ----------
        spec
            The frame it fulfils (with the exposure the camera actually used).
        raw_file
            The file the camera wrote, ideally under :meth:`temp_stem` (same file
            system, so the move is a rename). It is flushed to disk, then renamed to
            ``frames/<id><suffix>``.
        spd
            The measured SPD (one spectrum) for LED frames.
        note
            Stored in the record.

        Returns
        -------
        FrameRecord
            The record now in the manifest (replacing an earlier one of that id).
        """
        src = Path(raw_file)
        if spec.kind not in FRAME_KINDS:
            raise InputError(f"frame {spec.id!r}: unknown kind {spec.kind!r}")
        with open(src, "rb+") as fh:
            os.fsync(fh.fileno())
        frames = self.root / FRAMES_DIR
        if frames.is_symlink():
            raise InputError(
                f"{FRAMES_DIR}/ is a link to another folder; frames are only written "
                "inside the session folder",
                path=self.root,
            )
        frames.mkdir(parents=True, exist_ok=True)
        rel = f"{FRAMES_DIR}/{spec.id}{''.join(src.suffixes[-1:]).lower()}"
        digest = sha256_file(src)
        spd_rel = spd_digest = None
        if spd is not None:
            spd_rel = f"{FRAMES_DIR}/{spec.id}.spd.csv"
            # the stem ends in the pid: two processes never share a temp name
            tmp_spd = Path(f"{self.temp_stem(spec.id)}.spd.csv")
            write_spectra_csv(spd, tmp_spd)
            with open(tmp_spd, "rb+") as fh:
                os.fsync(fh.fileno())
            spd_digest = sha256_file(tmp_spd)
            os.replace(tmp_spd, self.root / spd_rel)
        os.replace(src, self.root / rel)
        _fsync_dir(frames)
        record = FrameRecord(
            id=spec.id,
            kind=spec.kind,
            channel=spec.channel,
            exposure_s=float(spec.exposure_s),
            iso=int(spec.iso),
            bracket=int(spec.bracket),
            file=rel,
            sha256=digest,
            time_utc=_utc_now(),
            status="ok",
            spd_file=spd_rel,
            note=note,
            spd_sha256=spd_digest,
        )
        self._put(record)
        return record

    def mark_bad(self, frame_ids: str | Iterable[str], reason: str = "") -> None:
        """Mark frames bad so that a resume takes them again.

        Raises
        ------
        InputError
            If a frame id is not in the session's plan or records.
        """
        ids = [frame_ids] if isinstance(frame_ids, str) else list(frame_ids)
        try:
            planned = {f.id for f in self.plan()}
        except InputError:
            planned = set()
        known = planned | {d["id"] for d in self._m["frames"]}
        unknown = [i for i in ids if i not in known]
        if unknown:
            raise InputError(
                f"unknown frame id(s): {', '.join(unknown)}", path=self.manifest_path
            )
        m = self._edited()
        for d in m["frames"]:
            if d["id"] in ids:
                d["status"] = "bad"
                d["note"] = reason or "marked bad"
        self._write_manifest(m)

    def read_spd(self, record: FrameRecord) -> Spectra:
        """The SPD measured around a frame (one spectrum).

        Raises
        ------
        InputError
            If the frame has no SPD.
        """
        if record.spd_file is None:
            raise InputError(f"frame {record.id!r} has no measured SPD")
        return read_spectra_csv(self.inside(record.spd_file))

    def _put(self, record: FrameRecord) -> None:
        m = self._edited()
        frames = m["frames"]
        d = record.to_dict()
        for i, old in enumerate(frames):
            if old["id"] == record.id:
                frames[i] = d
                break
        else:
            frames.append(d)
        self._write_manifest(m)

    def __repr__(self) -> str:
        return f"Session({str(self.root)!r}, {len(self._m['frames'])} frames)"
