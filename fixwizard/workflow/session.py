"""The sampling session: the taps of one fixture, journaled so that no acknowledged tap is ever lost.

The journal is JSON Lines, appended to and never rewritten. Line 1 is the header
``{"schema": "fixwizard.session/1", "created", "fixture", "tip", "robot"}``; then one record per line:

- ``{"kind": "tap", "id", "time", "base_T_tcp_ur": [x, y, z, rx, ry, rz] (m, rad), "base_p_ball_m": [3],
  "force": {...} or null}``
- ``{"kind": "undo", "id": <id of the tap undone>, "time"}``
- ``{"kind": "drop", "id": <id of any active tap>, "time"}``: that tap no longer counts (e.g. the solver's suspect)
- ``{"kind": "closed", "time", ...}`` once the session is finished.

Every line carries ``"crc"``, the CRC32 (8 hex digits) of the line's canonical JSON without that key, so
a damaged line is found even when it still parses. A record is written whole (one ``write``, repeated
only for the rest of a short write), then ``fsync``-ed before the caller hears of it. A write that fails
(a full disk) is cut off again at once, so the next record never follows a partial one; the caller is told
that the record was not saved.

A record that never finished (a crash, or a failed write whose cut-off did not happen) is a *torn* record:
the start of a line without its end. On resume a torn last line is moved aside into
``<name>.torn-<time>`` (evidence kept) and the journal continues after the last complete record; a torn
record followed on the same line by a complete one (journals of older versions appended after a failed
write) is skipped and the records after it are kept. A complete line that fails its checksum is damage to
an acknowledged record: an error naming the line, since fixwizard will not guess which taps it held.
One writer at a time, enforced with a non-blocking ``flock``.

Why JSON Lines and not SQLite: see the README ("Files: nothing clobbered, nothing stranded").
"""

import errno
import fcntl
import json
import os
import zlib
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Self

import numpy as np

from fixwizard.atomic import check_output
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.errors import InputError, file_problem
from fixwizard.geometry.se3 import from_ur_pose, to_ur_pose
from fixwizard.points import write_points

SCHEMA = "fixwizard.session/1"
SESSIONS_DIR = Path("sessions")
SUFFIX = ".jsonl"
RECORD_NAMES = {"tap": "tap", "undo": "undo", "drop": "dropped tap", "closed": "end of the session"}


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
class TornRecord:
    """A record found incomplete on resume (1-based line, size in bytes): never acknowledged, so skipped.
    ``moved_to`` is where a torn last line went (None for one left in place before a complete record)."""

    line_number: int
    size_bytes: int
    moved_to: Path | None

    def __str__(self) -> str:
        where = (f"it was moved to {self.moved_to}" if self.moved_to is not None
                 else "it stays in the journal and is skipped")
        return (f"line {self.line_number} of the session journal holds a record that was never finished (a crash "
                f"or a full disk, {self.size_bytes} bytes, never acknowledged); {where}, and every saved record "
                "is kept")


@dataclass(frozen=True)
class _Journal:
    """A journal file read back: its header, complete records and torn records, each with its 1-based line
    number; ``torn_tail`` is a torn last line (cut off on resume), if any."""

    header: dict
    records: list[tuple[int, dict]]
    torn: list[tuple[int, bytes]]
    torn_tail: tuple[int, bytes] | None


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


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


def _decode_own(line: bytes) -> dict:
    """The record of a line this process has just encoded (it always decodes)."""
    record = _decode(line)
    assert record is not None
    return record


def _no_constant(name: str) -> float:
    raise ValueError(f"{name} is no number a journal holds")


def _decode(line: bytes) -> dict | None:
    """The record of a complete line, or None when it does not parse (NaN and infinities included, which no
    record holds, and JSON nested too deeply to read) or its checksum does not match."""
    try:
        record = json.loads(line, parse_constant=_no_constant)
        crc = record.pop("crc")
        return record if crc == f"{zlib.crc32(_canonical(record).encode()):08x}" else None
    except (ValueError, TypeError, AttributeError, KeyError, RecursionError):
        return None


def _after_torn(line: bytes) -> tuple[int, dict] | None:
    """Where a complete record starts after a torn one on the same line (the rest of the line decodes) and
    that record, or None. A torn record is the start of a line, so it holds no newline and never decodes."""
    start = line.find(b"{", 1)
    while start != -1:
        record = _decode(line[start:])
        if record is not None:
            return start, record
        start = line.find(b"{", start + 1)
    return None


def _header_of(lines: list[bytes]) -> dict | None:
    """The session header on the first line (with its newline), or None for a file that is no journal."""
    header = _decode(lines[0]) if lines and lines[0].endswith(b"\n") else None
    return header if header is not None and header.get("schema") == SCHEMA else None


def _read_journal(path: Path, data: bytes) -> _Journal:
    """Split a journal into header, records and torn records; SessionError for a foreign or damaged file."""
    lines = data.splitlines(keepends=True)
    header = _header_of(lines)
    if header is None:
        raise SessionError(f"{path} is not a fixwizard session journal ({SCHEMA}); "
                           "choose a session file from the sessions folder")
    torn_tail = None
    if len(lines) > 1 and (not lines[-1].endswith(b"\n")
                           or (_decode(lines[-1]) is None and _after_torn(lines[-1]) is None)):
        torn_tail = (len(lines), lines.pop())
    records, torn = [], []
    for number, line in enumerate(lines[1:], start=2):
        record = _decode(line)
        if record is None:
            after_torn = _after_torn(line)
            if after_torn is None:
                raise SessionError(f"line {number} of the session {path} is damaged (checksum or JSON); "
                                   "fixwizard will not guess which taps it held. Keep the file and "
                                   "start a new session, or repair that line by hand")
            start, record = after_torn
            torn.append((number, line[:start]))
        records.append((number, record))
    return _Journal(header, records, torn, torn_tail)


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


def _tap_from(record: dict) -> Tap:
    return Tap(int(record["id"]), str(record["time"]), from_ur_pose(np.asarray(record["base_T_tcp_ur"], float)),
               np.asarray(record["base_p_ball_m"], float).reshape(3), record.get("force"))


def _write_all(handle: int, line: bytes) -> None:
    """Write every byte of ``line`` (a short write is continued; a write that writes nothing is a full disk)."""
    view = memoryview(line)
    while view:
        written = os.write(handle, view)
        if written == 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view = view[written:]


class SamplingSession:
    """An open, locked session journal and the active taps it replays to. Use ``create`` or ``open``."""

    def __init__(self, path: Path, handle: int, header: dict, records: list[tuple[int, dict]],
                 recovered: tuple[TornRecord, ...] = ()) -> None:
        self.path = path
        self.header = header
        self.recovered = recovered
        self._handle: int | None = handle
        self._end = os.fstat(handle).st_size  # the journal's length up to its last saved record
        self._taps: dict[int, Tap] = {}
        self._next_id = 1
        self.closed = False
        for number, record in records:
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
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            if not path.parent.is_dir():
                raise SessionError(f"cannot start the session {path}: {path.parent} is a file, not a folder; move it "
                                   "away or work in another folder") from None
            raise SessionError(f"a session {path} exists already; resume it or choose another name") from None
        except OSError as error:
            raise SessionError(f"cannot start the session {path}: {file_problem(error)}") from error
        _lock(handle, path)
        session = cls(path, handle, _decode_own(line), [])
        try:
            session._append(line, "the session")
            _fsync_dir(path.parent)
        except BaseException:
            session.release()
            path.unlink(missing_ok=True)
            raise
        return session

    @classmethod
    def open(cls, path: str | Path) -> Self:
        """Resume a journal: replay it, skipping torn records and moving a torn last line aside (see
        ``recovered``)."""
        path = Path(path)
        if path.is_dir():
            raise SessionError(f"{path} is a folder, not a session journal; give a .jsonl file in it")
        try:
            handle = os.open(path, os.O_RDWR | os.O_APPEND)
        except OSError as error:
            raise SessionError(f"cannot open the session: {file_problem(error)}") from error
        _lock(handle, path)
        try:
            data = path.read_bytes()
            journal = _read_journal(path, data)
            recovered = [TornRecord(number, len(piece), None) for number, piece in journal.torn]
            if journal.torn_tail is not None:
                number, piece = journal.torn_tail
                try:
                    recovered.append(_move_aside(path, handle, number, len(data) - len(piece), piece))
                except OSError as error:
                    raise SessionError(f"cannot set aside the unfinished last record of the session {path}: "
                                       f"{file_problem(error)}; then resume again") from error
            return cls(path, handle, journal.header, journal.records, tuple(recovered))
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
        return self._write_tap(record)

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
        return self._write_tap({"kind": "drop", "id": tap_id, "time": _now()})

    def export_points(self, path: str | Path) -> Path:
        """Write the active taps as a POINTS YAML for ``fixwizard solve``, naming this session as source; never over
        the journal itself (replaced, the taps after it would go to a file no longer in the folder)."""
        if not self._taps:
            raise SessionError(f"the session {self.path} has no taps to export; record some taps first")
        check_output(path, [("session journal", self.path)], "give the points file another name, e.g. points.yaml")
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

    def _write_tap(self, record: dict) -> Tap:
        """``_write`` of a tap or drop record, which replays to its tap."""
        tap = self._write(record)
        assert tap is not None
        return tap

    def _write(self, record: dict) -> Tap | None:
        if self.closed:
            raise SessionError(f"the session {self.path} is finished; start a new session to record more taps")
        if self._handle is None:
            raise SessionError(f"the session {self.path} was released; resume it to record more taps")
        line = _encode(record)
        self._append(line, f"this {RECORD_NAMES[record['kind']]}")
        return self._apply(_decode_own(line), None)

    def _append(self, line: bytes, what: str) -> None:
        """Write and fsync one record; on failure cut the journal back to its last saved record, so that the
        next record never follows a partial one, and raise SessionError saying ``what`` was not saved."""
        assert self._handle is not None
        try:
            _write_all(self._handle, line)
            os.fsync(self._handle)
        except OSError as error:
            problem = SessionError(f"could not save to the session {self.path}: {file_problem(error)}. "
                                   f"{what[:1].upper()}{what[1:]} was not saved; everything saved before is kept, "
                                   "so try again once that is fixed")
            try:
                os.ftruncate(self._handle, self._end)
                os.fsync(self._handle)
            except OSError:
                self.release()  # resume cuts the partial record off; writing on could follow it
                problem = SessionError(f"{problem} (quit and resume the session: the partial record could not "
                                       "be removed now)")
            raise problem from error
        self._end += len(line)

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


def _move_aside(path: Path, handle: int, line_number: int, offset: int, torn: bytes) -> TornRecord:
    """Save the torn last line next to the journal, durably, then cut it off the journal."""
    stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S%fZ")
    target = path.with_name(f"{path.name}.torn-{stamp}")
    with open(target, "xb") as stream:
        stream.write(torn)
        stream.flush()
        os.fsync(stream.fileno())
    _fsync_dir(path.parent)
    os.ftruncate(handle, offset)
    os.fsync(handle)
    return TornRecord(line_number, len(torn), target)


def find_unfinished(folder: str | Path = SESSIONS_DIR) -> list[Path]:
    """Session journals (``*.jsonl``) in ``folder`` without a closed record, oldest name first (a damaged one
    too: resuming it says what is wrong)."""
    unfinished = []
    for path in sorted(Path(folder).glob(f"*{SUFFIX}")):
        try:
            lines = path.read_bytes().splitlines(keepends=True)
        except OSError:
            continue
        if _header_of(lines) is not None and not any(_kind(line) == "closed" for line in lines[1:]):
            unfinished.append(path)
    return unfinished


def _kind(line: bytes) -> str | None:
    """The kind of the record a line holds (after a torn one, if need be), or None."""
    record = _decode(line)
    if record is None:
        after_torn = _after_torn(line)
        record = after_torn[1] if after_torn is not None else {}
    return record.get("kind")
