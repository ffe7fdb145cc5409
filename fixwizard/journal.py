"""Append-only JSON Lines journals that lose no acknowledged record: the sampling session's taps and the poses of a
tip calibration in progress each live in one.

Line 1 is the header (``{"schema": ..., ...}``), then one record per line. Every line carries ``"crc"``, the CRC32
(8 hex digits) of the line's canonical JSON without that key, so a damaged line is found even when it still
parses. A record is written whole (one ``write``, repeated only for the rest of a short write), then ``fsync``-ed
before the caller hears of it. A write that fails (a full disk) is cut off again at once, so the next record never
follows a partial one; the caller is told that the record was not saved.

A record that never finished (a crash, or a failed write whose cut-off did not happen) is a *torn* record: the start
of a line without its end. A last line that holds a whole record and only lacks its newline (an editor that strips
the final newline, or a crash just before it) is complete: its newline is added on open. On open a torn last line is
moved aside into ``<name>.torn-<time>`` (evidence kept) and the journal continues after the last complete record; a
torn record followed on the same line by a complete one (journals of older versions appended after a failed write)
is skipped and the records after it are kept. A complete line that fails its checksum is damage to an acknowledged
record: an error naming the line, since fixwizard will not guess what it held; the last line too, unless it is no
JSON at all (a power cut before its fsync kept the page with its end and lost the one with its start): that one is
torn. A blank line, or a line that repeats an earlier one byte for byte (left by an editor or a copy: fixwizard
writes no blank line, and each of its records names the millisecond it was written, stamped again should it repeat
an earlier line), holds no record of its own and is skipped, said so on open (``SkippedLine``). One writer at a
time, enforced with a non-blocking ``flock``. A journal deleted or moved away while open (its folder removed) is
written back at its path before the next record (from the copy of the saved records kept in memory); a file another
program put at the path or changed there (renamed or copied over it) is left alone, and records are refused until it
is moved away.
"""

import errno
import fcntl
import json
import os
import stat
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Self, TypeVar

import numpy as np

from fixwizard.errors import InputError, file_problem, other_version

T = TypeVar("T")
HEADER_BYTES = 1 << 20  # a journal's header is a few hundred bytes: a file whose first line is longer is none


@dataclass(frozen=True)
class JournalKind:
    """What a journal holds, for its checks and messages: the header's ``schema``, the ``noun`` a message names it
    by ("session"), the error raised for it, and what to do instead of using a damaged or foreign one
    (``start_over``: "start a new session")."""

    schema: str
    noun: str
    error: type[InputError]
    start_over: str


@dataclass(frozen=True)
class TornRecord:
    """A record found incomplete on open (1-based line, size in bytes): never acknowledged, so skipped.
    ``moved_to`` is where a torn last line went (None for one left in place before a complete record)."""

    noun: str
    line_number: int
    size_bytes: int
    moved_to: Path | None

    def __str__(self) -> str:
        where = (f"it was moved to {self.moved_to}" if self.moved_to is not None
                 else "it stays in the journal and is skipped")
        return (f"line {self.line_number} of the {self.noun} journal holds a record that was never finished (a crash "
                f"or a full disk, {self.size_bytes} bytes, never acknowledged); {where}, and every saved record "
                "is kept")


@dataclass(frozen=True)
class SkippedLine:
    """A line found on open that holds no record of its own (1-based line): blank, or the same bytes as the earlier
    line ``repeats`` (None for a blank one). Skipped: the record it repeats counts once."""

    noun: str
    line_number: int
    repeats: int | None

    def __str__(self) -> str:
        what = "is blank" if self.repeats is None else f"repeats line {self.repeats} exactly"
        return (f"line {self.line_number} of the {self.noun} journal {what} (an edit or a copy: fixwizard writes "
                "no such line), so it is skipped; every record is kept")


def said(recovered: tuple[TornRecord | SkippedLine, ...]) -> list[str]:
    """What opening a journal found, as sentences to show: each torn record, and the lines skipped in one sentence
    when there are several (a file double-spaced by an editor would otherwise fill the screen with a note per
    line)."""
    skipped = [note for note in recovered if isinstance(note, SkippedLine)]
    if len(skipped) < 2:
        return [str(note) for note in recovered]
    blank = [note.line_number for note in skipped if note.repeats is None]
    repeated = [note.line_number for note in skipped if note.repeats is not None]
    parts = ([f"{_lines_named(blank)} {'is' if len(blank) == 1 else 'are'} blank"] if blank else []) + \
        ([f"{_lines_named(repeated)} {'repeats an earlier line' if len(repeated) == 1 else 'repeat earlier lines'} "
          "exactly"] if repeated else [])
    return [str(note) for note in recovered if isinstance(note, TornRecord)] + [
        f"{' and '.join(parts)} in the {skipped[0].noun} journal (an edit or a copy: fixwizard writes no such line), "
        "so they are skipped; every record is kept"]


def _lines_named(numbers: list[int], shown: int = 5) -> str:
    """"line 3", "lines 3, 5 and 7", "lines 3, 5, 7, 9, 11 and 40 more"."""
    if len(numbers) == 1:
        return f"line {numbers[0]}"
    head = ", ".join(str(number) for number in numbers[:min(shown, len(numbers) - 1)])
    rest = len(numbers) - min(shown, len(numbers) - 1)
    return f"lines {head} and {numbers[-1] if rest == 1 else f'{rest} more'}"


def now() -> str:
    """The time a record is written: UTC, ISO 8601 with milliseconds."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


class Journal:
    """An open, locked journal file and the records it held when opened. Use ``create`` or ``open``."""

    def __init__(self, kind: JournalKind, path: Path, handle: int, header: dict, records: list[tuple[int, dict]],
                 recovered: tuple[TornRecord | SkippedLine, ...] = ()) -> None:
        self.kind = kind
        self.path = path
        self.header = header
        self.records = records  # (1-based line, record) as read on open
        self.recovered = recovered
        self.handle: int | None = handle
        self._saved = _read_all(handle)  # the journal up to its last saved record, to write it back if need be
        self._lines = set(bytes(self._saved).splitlines(keepends=True))  # each saved line, to write none twice

    @classmethod
    def create(cls, kind: JournalKind, path: str | Path, header: dict) -> Self:
        """A new journal at ``path`` (refused if it exists) starting with ``header`` (its schema added)."""
        path = Path(path)
        noun, error = kind.noun, kind.error
        line = _encode({"schema": kind.schema, **header})
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            handle = os.open(path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            if not path.parent.is_dir():
                raise error(f"cannot start the {noun} {path}: {path.parent} is a file, not a folder; move it "
                            "away or work in another folder") from None
            raise error(f"a {noun} {path} exists already; resume it or choose another name") from None
        except OSError as problem:
            raise error(f"cannot start the {noun} {path}: {file_problem(problem, access='write')}") from problem
        _lock(kind, handle, path)
        journal = cls(kind, path, handle, _decode_own(line), [])
        try:
            journal._append(line, f"the {noun}")
            _fsync_dir(path.parent)
        except BaseException:
            journal.release()
            path.unlink(missing_ok=True)
            raise
        return journal

    @classmethod
    def open(cls, kind: JournalKind, path: str | Path) -> Self:
        """Open a journal to go on with it: its records read back, torn ones, blank lines and repeats skipped and a
        torn last line moved aside (see ``recovered``)."""
        path = Path(path)
        noun, error = kind.noun, kind.error
        if path.is_dir():
            raise error(f"{path} is a folder, not a {noun} journal; give a .jsonl file in it")
        try:
            handle = os.open(path, os.O_RDWR | os.O_APPEND)
        except OSError as problem:
            raise error(f"cannot open the {noun}: {file_problem(problem, access='read and write')}") from problem
        if not stat.S_ISREG(os.fstat(handle).st_mode):  # reading a pipe would wait for a writer forever
            os.close(handle)
            raise error(f"{path} is not a regular file (a pipe or a device), so it is no {noun} journal; give a "
                        ".jsonl file the wizard wrote")
        _lock(kind, handle, path)
        try:
            data = path.read_bytes()
            read = _read(kind, path, data)
            recovered: list[TornRecord | SkippedLine] = [TornRecord(noun, number, len(piece), None)
                                                         for number, piece in read.torn]
            recovered += [SkippedLine(noun, number, repeats) for number, repeats in read.skipped]
            recovered.sort(key=lambda note: note.line_number)
            if read.torn_tail is not None:
                number, piece = read.torn_tail
                try:
                    recovered.append(_move_aside(noun, path, handle, number, len(data) - len(piece), piece))
                except OSError as problem:
                    raise error(f"cannot set aside the unfinished last record of the {noun} {path}: "
                                f"{file_problem(problem, access='write')}; then resume again") from problem
            if read.unended:
                try:
                    _write_all(handle, b"\n")
                    os.fsync(handle)
                except OSError as problem:
                    raise error(f"cannot end the last line of the {noun} {path} with a newline: "
                                f"{file_problem(problem, access='write')}; then resume again") from problem
            return cls(kind, path, handle, read.header, read.records, tuple(recovered))
        except BaseException:
            os.close(handle)
            raise

    @property
    def released(self) -> bool:
        return self.handle is None

    def append(self, record: dict, what: str) -> dict:
        """Write ``record`` durably and return it as read back; ``what`` names it in the message of a failed write
        ("this tap"). A record that would repeat a line of the journal byte for byte (the same drop of a tap within
        one millisecond) gets a ``time`` a millisecond later than now, or later still until it repeats none."""
        if self.handle is None:
            raise self.kind.error(f"the {self.kind.noun} {self.path} was released; resume it to record more")
        line, stamp = _encode(record), datetime.now(UTC)
        while line in self._lines:  # the same record within one millisecond: read back, it would pass for a copy
            stamp += timedelta(milliseconds=1)  # not waiting for the clock, which may stand still (a test's)
            line = _encode({**record, "time": stamp.isoformat(timespec="milliseconds")})
        self._append(line, what)
        return _decode_own(line)

    def release(self) -> None:
        """Let go of the file and its lock (the journal stays as written)."""
        if self.handle is not None:
            os.close(self.handle)
            self.handle = None

    def _append(self, line: bytes, what: str) -> None:
        """Write and fsync one line; on failure cut the journal back to its last saved record, so that the next
        record never follows a partial one, and raise the kind's error saying ``what`` was not saved."""
        assert self.handle is not None
        noun, error = self.kind.noun, self.kind.error
        try:
            self._rejoin(what)
            _write_all(self.handle, line)
            os.fsync(self.handle)
        except OSError as failure:
            problem = error(f"could not save to the {noun} {self.path}: {file_problem(failure, access='write')}. "
                            f"{what[:1].upper()}{what[1:]} was not saved; everything saved before is kept, so try "
                            "again once that is fixed")
            try:
                os.ftruncate(self.handle, len(self._saved))
                os.fsync(self.handle)
            except OSError:
                self.release()  # opening again cuts the partial record off; writing on could follow it
                problem = error(f"{problem} (quit and resume the {noun}: the partial record could not be removed "
                                "now)")
            raise problem from failure
        self._saved += line
        self._lines.add(line)

    def _rejoin(self, what: str) -> None:
        """Put the journal back at its path when the file open here is no longer there (deleted, its folder removed,
        moved away): records written on to it would be lost or go elsewhere. Everything saved is written into a new
        file there, which is written to from then on. A file that another program put at the path (renamed over
        the journal, an editor saving it) or changed (copied over it) is left alone: the kind's error says ``what``
        was not saved and to move that file away."""
        assert self.handle is not None
        held = os.fstat(self.handle)
        try:
            found = os.stat(self.path)
        except FileNotFoundError:
            found = None
        except OSError:  # its folder may not be searched now (its permissions changed): the file open here is written
            return
        if found is not None and (found.st_dev, found.st_ino) == (held.st_dev, held.st_ino) and \
                held.st_size == len(self._saved):
            return
        if found is not None:
            changed = "replaced by another file" if found.st_ino != held.st_ino else "changed by another program"
            raise self.kind.error(f"the {self.kind.noun} {self.path} was {changed} while fixwizard was writing to "
                                  f"it, so {what} was not saved; move that file away and try again: fixwizard then "
                                  "writes every saved record back there")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        handle = os.open(self.path, os.O_RDWR | os.O_APPEND | os.O_CREAT | os.O_EXCL, 0o666)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            _write_all(handle, bytes(self._saved))
            os.fsync(handle)
            _fsync_dir(self.path.parent)
        except BaseException:
            os.close(handle)
            self.path.unlink(missing_ok=True)
            raise
        os.close(self.handle)
        self.handle = handle


def replay(kind: JournalKind, path: str | Path, replayed: Callable[[Journal], T]) -> T:
    """``replayed`` of the journal at ``path``, opened to go on with it; the journal is released again when
    replaying it fails (a record the caller cannot use)."""
    journal = Journal.open(kind, path)
    try:
        return replayed(journal)
    except BaseException:
        journal.release()
        raise


def read_unfinished(kind: JournalKind, path: Path) -> tuple[dict, list[dict]] | None:
    """An unfinished journal's header and the records that decode (after a torn one on the same line, if need be),
    read without opening it for writing; None when ``path`` cannot be read (or is no regular file), is no journal of
    ``kind`` or ends with its closed record (told from that last line alone: a folder of finished journals is listed
    quickly). Only the first line of another file is read (at most ``HEADER_BYTES``), however large it is."""
    try:
        if not stat.S_ISREG(path.stat().st_mode):  # a pipe: reading it would wait for a writer forever
            return None
        with open(path, "rb") as stream:
            first = stream.readline(HEADER_BYTES)
            header = _header_of(kind, [_ended(first)])  # without its newline, a first line is all the file holds
            if header is None:
                return None
            lines = [first, *stream.read().splitlines(keepends=True)]
    except OSError:
        return None
    if len(lines) > 1 and (_decode(lines[-1]) or {}).get("kind") == "closed":
        return None
    records = []
    for _, line, repeats in _lines_of_records(lines):
        if repeats is not None:
            continue
        record = _decode(line)
        if record is None:
            after_torn = _after_torn(line)
            record = after_torn[1] if after_torn is not None else None
        if record is not None:
            records.append(record)
    return header, records


# --- lines ---

def _plain(value):
    """JSON fallback for numpy arrays and scalars and paths."""
    if isinstance(value, (np.ndarray, np.generic)):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} cannot be written to a journal")


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


def _torn_last(line: bytes) -> bool:
    """Whether the last line is a record that never finished: without its newline, or with bytes a power cut lost
    before the line's end (no JSON at all, no complete record after a torn one). A last line that is JSON but fails
    its checksum was written whole, so acknowledged: damage, refused like any other line."""
    if not line.endswith(b"\n"):
        return True
    if _decode(line) is not None or _after_torn(line) is not None:
        return False
    try:
        json.loads(line)
    except ValueError:
        return True
    except RecursionError:  # nested deeper than any record: no torn write makes that
        return False
    return False


def _header_of(kind: JournalKind, lines: list[bytes]) -> dict | None:
    """The header on the first line (with its newline), or None for a file that is no journal of ``kind``."""
    header = _decode(lines[0]) if lines and lines[0].endswith(b"\n") else None
    return header if header is not None and header.get("schema") == kind.schema else None


@dataclass(frozen=True)
class _Read:
    """A journal file read back: its header, complete records, torn records and lines that hold no record of their
    own (``SkippedLine``), each with its 1-based line number; ``torn_tail`` is a torn last line (cut off on open), if
    any."""

    header: dict
    records: list[tuple[int, dict]]
    torn: list[tuple[int, bytes]]
    torn_tail: tuple[int, bytes] | None
    skipped: list[tuple[int, int | None]]  # (line, the earlier line it repeats; None: blank)
    unended: bool  # the last line holds a whole record but no newline (add one before appending)


def _read(kind: JournalKind, path: Path, data: bytes) -> _Read:
    """Split a journal into header, records and torn records; the kind's error for a foreign or damaged file."""
    lines = data.splitlines(keepends=True)
    unended = bool(lines) and _ended(lines[-1]) != lines[-1] and (_decode(lines[-1]) is not None
                                                                  or _after_torn(lines[-1]) is not None)
    if unended:
        lines[-1] = _ended(lines[-1])
    header = _header_of(kind, lines)
    if header is None:
        found = (_decode(lines[0]) or {}).get("schema") if lines else None
        if found == kind.schema:  # the header itself checks out: only its newline is missing
            raise kind.error(f"the first line of the {kind.noun} {path} does not end with a newline (LF) as "
                             "fixwizard writes it: an editor or a copy changed its line ends; change them back to "
                             "newlines and resume again")
        newer = other_version(path, f"{kind.noun} journal", found, (kind.schema,))
        if newer is not None:
            raise kind.error(newer)
        raise kind.error(f"{path} is not a fixwizard {kind.noun} journal ({kind.schema}); choose a {kind.noun} file "
                         "the wizard wrote")
    torn_tail = None
    if len(lines) > 1 and not _blank(lines[-1]) and _torn_last(lines[-1]):
        torn_tail = (len(lines), lines.pop())
    records, torn, skipped = [], [], []
    for number, line, repeats in _lines_of_records(lines):
        if repeats is not None or _blank(line):
            skipped.append((number, repeats))
            continue
        record = _decode(line)
        if record is None:
            after_torn = _after_torn(line)
            if after_torn is None:
                raise kind.error(f"line {number} of the {kind.noun} {path} is damaged (checksum or JSON); "
                                 f"fixwizard will not guess what it held. Keep the file and {kind.start_over}, or "
                                 "repair that line by hand")
            start, record = after_torn
            torn.append((number, line[:start]))
        records.append((number, record))
    return _Read(header, records, torn, torn_tail, skipped, unended)


def _ended(line: bytes) -> bytes:
    """``line`` with its newline (added if it has none)."""
    return line if line.endswith(b"\n") else line + b"\n"


def _blank(line: bytes) -> bool:
    """Whether a whole line (with its newline) holds nothing but white space."""
    return line.endswith(b"\n") and not line.strip()


def _lines_of_records(lines: list[bytes]) -> Iterator[tuple[int, bytes, int | None]]:
    """Each line after the header: its 1-based number, its bytes and the number of the earlier line (the header
    included) it repeats byte for byte, None when it repeats none (a blank line never counts as a repeat)."""
    first_seen = {lines[0]: 1}
    for number, line in enumerate(lines[1:], start=2):
        repeats = None if _blank(line) else first_seen.setdefault(line, number)
        yield number, line, repeats if repeats != number else None


# --- files ---

def _fsync_dir(directory: Path) -> None:
    handle = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(handle)
    finally:
        os.close(handle)


def _lock(kind: JournalKind, handle: int, path: Path) -> None:
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(handle)
        raise kind.error(f"the {kind.noun} {path} is open in another fixwizard; close that one first "
                         "(or wait for it to finish) and resume again") from None


def _write_all(handle: int, line: bytes) -> None:
    """Write every byte of ``line`` (a short write is continued; a write that writes nothing is a full disk)."""
    view = memoryview(line)
    while view:
        written = os.write(handle, view)
        if written == 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        view = view[written:]


def _read_all(handle: int) -> bytearray:
    """The whole file open at ``handle``, read from its start."""
    data = bytearray()
    while chunk := os.pread(handle, 1 << 20, len(data)):
        data += chunk
    return data


def _move_aside(noun: str, path: Path, handle: int, line_number: int, offset: int, torn: bytes) -> TornRecord:
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
    return TornRecord(noun, line_number, len(torn), target)
