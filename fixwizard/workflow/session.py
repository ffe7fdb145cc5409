"""The sampling session: the taps of one fixture, journaled so that no acknowledged tap is ever lost.

The journal is JSON Lines, appended to and never rewritten. Line 1 is the header
``{"schema": "fixwizard.session/1", "created", "fixture", "tip", "robot"}``; then one record per line:

- ``{"kind": "tap", "id", "time", "base_T_tcp_ur": [x, y, z, rx, ry, rz] (m, rad), "base_p_ball_m": [3],
  "force": {...} or null}``
- ``{"kind": "undo", "id": <id of the tap undone>, "time"}``
- ``{"kind": "drop", "id": <id of any active tap>, "time"}``: that tap no longer counts (e.g. the solver's suspect)
- ``{"kind": "closed", "time", ...}`` once the session is finished.

Every line carries ``"crc"``, the CRC32 (8 hex digits) of the line's canonical JSON without that key, so
a damaged line is found even when it still parses. A line is written in one ``write``, then flushed and
``fsync``-ed before the caller hears of it; a line without its newline was therefore never
acknowledged. On resume such a torn last line (or a last line failing its checksum) is moved aside
into ``<name>.torn-<time>`` (evidence kept) and the journal continues after the last complete record;
damage anywhere else is an error naming the line. One writer at a time, enforced with a non-blocking ``flock``.
"""

import fcntl
import json
import os
import zlib
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Self

import numpy as np

from fixwizard.calibration.taps import ball_centres_m
from fixwizard.errors import InputError
from fixwizard.geometry.se3 import from_ur_pose, to_ur_pose
from fixwizard.points import write_points

SCHEMA = "fixwizard.session/1"
SESSIONS_DIR = Path("sessions")
SUFFIX = ".jsonl"


class SessionError(InputError):
    """A session journal cannot be created, resumed or written."""


@dataclass(frozen=True, eq=False)
class Tap:
    """One acknowledged tap: flange pose ``base_T_tcp`` (4x4) and ball centre in the base frame (m)."""

    id: int
    time: str
    base_T_tcp: np.ndarray
    base_p_ball_m: np.ndarray
    force: dict | None = None


@dataclass(frozen=True)
class TornLine:
    """The incomplete last line found on resume (1-based line number, size in bytes) and where it went."""

    line_number: int
    size_bytes: int
    moved_to: Path

    def __str__(self) -> str:
        return (f"line {self.line_number} of the session journal was cut off by a crash ({self.size_bytes} bytes, "
                f"never acknowledged); it was moved to {self.moved_to} and every complete tap before it is kept")


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def _plain(value):
    """JSON fallback for numpy arrays and scalars and paths."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} cannot be written to a session journal")


def _canonical(record: dict) -> str:
    return json.dumps(record, sort_keys=True, separators=(",", ":"), allow_nan=False, default=_plain)


def _encode(record: dict) -> bytes:
    """One journal line (with its checksum and newline) for a record."""
    body = json.loads(_canonical(record))
    body["crc"] = f"{zlib.crc32(_canonical(body).encode()):08x}"
    return (_canonical(body) + "\n").encode()


def _decode(line: bytes) -> dict | None:
    """The record of a complete line, or None when it does not parse or its checksum does not match."""
    try:
        record = json.loads(line)
        crc = record.pop("crc")
    except (ValueError, TypeError, AttributeError, KeyError):
        return None
    return record if crc == f"{zlib.crc32(_canonical(record).encode()):08x}" else None


def _fsync_dir(directory: Path) -> None:
    handle = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


def _lock(handle: int, path: Path) -> None:
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(handle)
        raise SessionError(f"the session {path} is open in another fixwizard; close that one first "
                           "(or wait for it to finish) and resume again") from None


def _header_ok(line: bytes) -> bool:
    """Whether a line (with its newline) is a complete session header."""
    record = _decode(line)
    return line.endswith(b"\n") and record is not None and record.get("schema") == SCHEMA


def _tap_from(record: dict) -> Tap:
    return Tap(int(record["id"]), str(record["time"]), from_ur_pose(np.asarray(record["base_T_tcp_ur"], float)),
               np.asarray(record["base_p_ball_m"], float).reshape(3), record.get("force"))


class SamplingSession:
    """An open, locked session journal and the active taps it replays to. Use ``create`` or ``open``."""

    def __init__(self, path: Path, handle: int, header: dict, records: list[dict],
                 recovery_note: TornLine | None = None) -> None:
        self.path = path
        self.header = header
        self.recovery_note = recovery_note
        self._handle: int | None = handle
        self._taps: dict[int, Tap] = {}
        self._next_id = 1
        self.closed = False
        for number, record in enumerate(records, start=2):
            self._apply(record, number)

    @classmethod
    def create(cls, path: str | Path, fixture_info: dict, tip_info: dict, robot: str | None = None
               ) -> Self:
        """A new journal at ``path`` (refused if it exists); ``tip_info`` holds ``tcp_p_tip_m`` (3, m)."""
        path = Path(path)
        if np.asarray(tip_info.get("tcp_p_tip_m", ()), float).shape != (3,):
            raise SessionError("a session needs the tip position tcp_p_tip_m (x, y, z in metres); "
                               "calibrate the tip first")
        header = {"schema": SCHEMA, "created": _now(), "fixture": fixture_info, "tip": tip_info, "robot": robot}
        line = _encode(header)
        path.parent.mkdir(parents=True, exist_ok=True)
        try:
            handle = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            raise SessionError(f"a session {path} exists already; resume it or choose another name") from None
        _lock(handle, path)
        session = cls(path, handle, _decode(line), [])
        session._append(line)
        _fsync_dir(path.parent)
        return session

    @classmethod
    def open(cls, path: str | Path) -> Self:
        """Resume a journal: replay it, moving a torn last line aside (see ``recovery_note``)."""
        path = Path(path)
        try:
            handle = os.open(path, os.O_RDWR | os.O_APPEND)
        except OSError as error:
            raise SessionError(f"cannot open the session {path}: {error.strerror}") from error
        _lock(handle, path)
        try:
            data = path.read_bytes()
            lines = data.splitlines(keepends=True)
            if not lines or not _header_ok(lines[0]):
                raise SessionError(f"{path} is not a fixwizard session journal ({SCHEMA}); "
                                   "choose a session file from the sessions folder")
            torn_line = len(lines) > 1 and (not lines[-1].endswith(b"\n") or _decode(lines[-1]) is None)
            torn_bytes = lines.pop() if torn_line else b""
            records = []
            for number, line in enumerate(lines[1:], start=2):
                record = _decode(line)
                if record is None:
                    raise SessionError(f"line {number} of the session {path} is damaged (checksum or JSON); "
                                       "fixwizard will not guess which taps it held. Keep the file and "
                                       "start a new session, or repair that line by hand")
                records.append(record)
            torn = None
            if torn_line:
                torn = _move_aside(path, handle, len(lines) + 1, len(data) - len(torn_bytes), torn_bytes)
            return cls(path, handle, _decode(lines[0]), records, torn)
        except BaseException:
            os.close(handle)
            raise

    @property
    def taps(self) -> list[Tap]:
        """The active taps (not undone), in the order they were recorded."""
        return list(self._taps.values())

    @property
    def base_p_taps(self) -> np.ndarray:
        """Ball centres (N, 3, m, base frame) of the active taps."""
        return np.array([tap.base_p_ball_m for tap in self.taps], dtype=float).reshape(-1, 3)

    def record_tap(self, base_T_tcp: np.ndarray, base_p_ball_m: np.ndarray | None = None,
                   force: dict | None = None) -> Tap:
        """Journal a tap (flange pose 4x4, ball centre in m; computed from the tip when None) durably."""
        base_T_tcp = np.asarray(base_T_tcp, float)
        if base_p_ball_m is None:
            base_p_ball_m = ball_centres_m(base_T_tcp[None], np.asarray(self.header["tip"]["tcp_p_tip_m"], float))[0]
        record = {"kind": "tap", "id": self._next_id, "time": _now(), "base_T_tcp_ur": to_ur_pose(base_T_tcp),
                  "base_p_ball_m": np.asarray(base_p_ball_m, float).reshape(3), "force": force}
        return self._write(record)

    def undo(self) -> Tap | None:
        """Journal the undo of the last active tap and return it; None when there is no tap to undo."""
        if not self._taps:
            return None
        last = self.taps[-1]
        self._write({"kind": "undo", "id": last.id, "time": _now()})
        return last

    def drop(self, tap_id: int) -> Tap:
        """Journal that the active tap ``tap_id`` no longer counts (it stays in the journal) and return it."""
        if tap_id not in self._taps:
            raise SessionError(f"tap id {tap_id} is not an active tap of the session {self.path}; "
                               "choose one of the taps shown")
        return self._write({"kind": "drop", "id": tap_id, "time": _now()})

    def export_points(self, path: str | Path) -> Path:
        """Write the active taps as a POINTS YAML for ``fixwizard solve``, naming this session as source."""
        if not self._taps:
            raise SessionError(f"the session {self.path} has no taps to export; record some taps first")
        return write_points(path, self.base_p_taps, source_session=str(self.path),
                            tap_ids=[tap.id for tap in self.taps])

    def close(self, **extra) -> None:
        """Mark the session finished (``extra``, e.g. the report path, is journaled) and release it."""
        self._write({"kind": "closed", "time": _now(), **extra})
        self.release()

    def release(self) -> None:
        """Let go of the file and its lock without finishing the session (it stays resumable)."""
        if self._handle is not None:
            os.close(self._handle)
            self._handle = None

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info) -> None:
        self.release()

    def _write(self, record: dict) -> Tap | None:
        if self.closed:
            raise SessionError(f"the session {self.path} is finished; start a new session to record more taps")
        if self._handle is None:
            raise SessionError(f"the session {self.path} was released; resume it to record more taps")
        line = _encode(record)
        self._append(line)
        return self._apply(_decode(line), None)

    def _append(self, line: bytes) -> None:
        written = os.write(self._handle, line)
        if written != len(line):
            raise SessionError(f"could not write the whole record to {self.path} (disk full?); "
                               "free space and resume the session")
        os.fsync(self._handle)

    def _apply(self, record: dict, number: int | None) -> Tap | None:
        """Replay one record; ``number`` is its journal line when replaying from the file."""
        invalid = SessionError(f"line {number} of the session {self.path} is not a valid tap, undo, drop or "
                               "closed record; keep the file and start a new session")
        try:
            kind = record["kind"]
            if kind == "tap":
                tap = _tap_from(record)
                self._taps[tap.id] = tap
                self._next_id = max(self._next_id, tap.id + 1)
                return tap
            if kind in ("undo", "drop"):
                return self._taps.pop(int(record["id"]))
        except (KeyError, TypeError, ValueError):
            raise invalid from None
        if kind != "closed":
            raise invalid
        self.closed = True
        return None


def _move_aside(path: Path, handle: int, line_number: int, offset: int, torn: bytes) -> TornLine:
    """Save the torn last line next to the journal, durably, then cut it off the journal."""
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S%fZ")
    target = path.with_name(f"{path.name}.torn-{stamp}")
    with open(target, "xb") as stream:
        stream.write(torn)
        stream.flush()
        os.fsync(stream.fileno())
    _fsync_dir(path.parent)
    os.ftruncate(handle, offset)
    os.fsync(handle)
    return TornLine(line_number, len(torn), target)


def find_unfinished(folder: str | Path = SESSIONS_DIR) -> list[Path]:
    """Session journals (``*.jsonl``) in ``folder`` without a closed record, oldest name first."""
    unfinished = []
    for path in sorted(Path(folder).glob(f"*{SUFFIX}")):
        try:
            lines = path.read_bytes().splitlines(keepends=True)
        except OSError:
            continue
        if lines and _header_ok(lines[0]) and not any(
                (_decode(line) or {}).get("kind") == "closed" for line in lines[1:]):
            unfinished.append(path)
    return unfinished
