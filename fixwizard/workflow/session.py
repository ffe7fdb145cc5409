"""The sampling session: the taps of one fixture, journaled so that no acknowledged tap is ever lost.

The journal is JSON Lines, appended to and never rewritten. Line 1 is the header
``{"schema": "fixwizard.session/1", "created", "fixture", "tip", "robot"}``; then one record per line:

- ``{"kind": "tap", "id", "time", "base_T_tcp_ur": [x, y, z, rx, ry, rz] (m, rad), "base_p_ball_m": [3],
  "force": {...} or null}``
- ``{"kind": "undo", "id": <id of the tap undone>, "time"}``
- ``{"kind": "drop", "id": <id of any active tap>, "time"}``: that tap no longer counts (e.g. the solver's suspect)
- ``{"kind": "restore", "id": <id of a dropped tap>, "time"}``: the drop is taken back; the tap counts again, in its
  place among the taps
- ``{"kind": "closed", "time", ...}`` once the session is finished.

The journal mechanics (checksums, fsync per record, a full disk, torn records, one writer at a time) are
``fixwizard.journal``'s.

Why JSON Lines and not SQLite: see the README ("Files: nothing clobbered, nothing stranded").
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Self

import numpy as np

from fixwizard.atomic import check_output
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.errors import InputError
from fixwizard.geometry.se3 import from_ur_pose, to_ur_pose
from fixwizard.journal import Journal, JournalKind, SkippedLine, TornRecord, now, read_unfinished, replay
from fixwizard.points import write_points

SCHEMA = "fixwizard.session/1"
SESSIONS_DIR = Path("sessions")
SUFFIX = ".jsonl"
RECORD_NAMES = {"tap": "tap", "undo": "undo", "drop": "dropped tap", "restore": "tap taken back",
                "closed": "end of the session"}


class SessionError(InputError):
    """A session journal cannot be created, resumed or written."""


KIND = JournalKind(SCHEMA, "session", SessionError, "start a new session")


@dataclass(frozen=True, eq=False)
class Tap:
    """One acknowledged tap: flange pose ``base_T_tcp`` (4x4) and ball centre in the base frame (m)."""

    id: int
    time: str
    base_T_tcp: np.ndarray
    base_p_ball_m: np.ndarray
    force: dict | None = None


def _tap_from(record: dict) -> Tap:
    return Tap(int(record["id"]), str(record["time"]), from_ur_pose(np.asarray(record["base_T_tcp_ur"], float)),
               np.asarray(record["base_p_ball_m"], float).reshape(3), record.get("force"))


class SamplingSession:
    """An open, locked session journal and the active taps it replays to. Use ``create`` or ``open``."""

    def __init__(self, journal: Journal) -> None:
        self.journal = journal
        self._taps: dict[int, Tap] = {}
        self._next_id = 1
        self._lines: dict[int, tuple[int | None, int | None]] = {}  # tap id: lines of its tap and its undo or drop
        self._dropped: dict[int, Tap] = {}
        self._last_drop: int | None = None  # the id the last tap, undo, drop or restore record dropped
        self.closed = False
        for number, record in journal.records:
            self._apply(record, number)

    @classmethod
    def create(cls, path: str | Path, fixture_info: dict, tip_info: dict, robot: str | None = None
               ) -> Self:
        """A new journal at ``path`` (refused if it exists); ``tip_info`` holds ``tcp_p_tip_m`` (3, m)."""
        if np.asarray(tip_info.get("tcp_p_tip_m", ()), float).shape != (3,):
            raise SessionError("a session needs the tip position tcp_p_tip_m (x, y, z in metres); "
                               "calibrate the tip first")
        header = {"created": now(), "fixture": fixture_info, "tip": tip_info, "robot": robot}
        return cls(Journal.create(KIND, path, header))

    @classmethod
    def open(cls, path: str | Path) -> Self:
        """Resume a journal: replay it, skipping torn records, blank lines and repeated lines and moving a torn last
        line aside (see ``recovered``); a record that contradicts an earlier one is refused naming both lines."""
        return replay(KIND, path, cls)

    @property
    def path(self) -> Path:
        return self.journal.path

    @property
    def header(self) -> dict:
        return self.journal.header

    @property
    def recovered(self) -> tuple[TornRecord | SkippedLine, ...]:
        """The records found torn, and the lines skipped (blank, repeated), when the session was resumed."""
        return self.journal.recovered

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
        record = {"kind": "tap", "id": self._next_id, "time": now(), "base_T_tcp_ur": to_ur_pose(base_T_tcp),
                  "base_p_ball_m": np.asarray(base_p_ball_m, float).reshape(3), "force": force}
        return self._write_tap(record)

    def undo(self) -> Tap | None:
        """Journal the undo of the last active tap and return it; None when there is no tap to undo."""
        if not self._taps:
            return None
        last = self.taps[-1]
        self._write({"kind": "undo", "id": last.id, "time": now()})
        return last

    def drop(self, tap_id: int) -> Tap:
        """Journal that the active tap ``tap_id`` no longer counts (it stays in the journal) and return it."""
        if tap_id not in self._taps:
            raise SessionError(f"tap id {tap_id} is not an active tap of the session {self.path}; "
                               "choose one of the taps shown")
        return self._write_tap({"kind": "drop", "id": tap_id, "time": now()})

    @property
    def last_dropped(self) -> Tap | None:
        """The tap the last change to the taps dropped (``restore`` takes that back), else None."""
        return None if self._last_drop is None else self._dropped[self._last_drop]

    def restore(self) -> Tap:
        """Journal that the drop of ``last_dropped`` is taken back (the tap counts again, in its place) and return
        the tap."""
        dropped = self.last_dropped
        if dropped is None:
            raise SessionError(f"the last change to the session {self.path} dropped no tap; there is no drop to take "
                               "back")
        return self._write_tap({"kind": "restore", "id": dropped.id, "time": now()})

    def export_points(self, path: str | Path) -> Path:
        """Write the active taps as a POINTS YAML for ``fixwizard solve``, naming this session as source; never over
        the journal itself (replaced, the taps after it would go to a file no longer in the folder)."""
        if not self._taps:
            raise SessionError(f"the session {self.path} has no taps to export; record some taps first")
        check_output(path, [("session journal", self.path)], "give the points file another name, e.g. points.yaml",
                     "points.yaml")
        return write_points(path, self.base_p_taps, source_session=str(self.path),
                            tap_ids=[tap.id for tap in self.taps])

    def close(self, **extra) -> None:
        """Mark the session finished (``extra``, e.g. the report path, is journaled) and release it."""
        self._write({"kind": "closed", "time": now(), **extra})
        self.release()

    def release(self) -> None:
        """Let go of the file and its lock without finishing the session (it stays resumable)."""
        self.journal.release()

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
        return self._apply(self.journal.append(record, f"this {RECORD_NAMES[record['kind']]}"), None)

    def _apply(self, record: dict, number: int | None) -> Tap | None:
        """Replay one record; ``number`` is its journal line when replaying from the file."""
        invalid = SessionError(f"line {number} of the session {self.path} is not a valid tap, undo, drop, restore "
                               "or closed record; keep the file and start a new session")
        if record.get("schema") == SCHEMA:  # ``cat a.jsonl b.jsonl``: the taps before it are good
            raise SessionError(f"line {number} of the session {self.path} is the first line of another session "
                               f"(started {record.get('created')}): the file joins two journals. Keep a copy of it, "
                               f"delete line {number} and the lines after it that belong to that session and resume "
                               "again, or start a new session")
        try:
            kind = record["kind"]
            if kind == "tap":
                tap = _tap_from(record)
                if tap.id in self._lines:
                    raise self._conflict(number, f"records tap {tap.id} again (line {self._lines[tap.id][0]} "
                                                 "recorded it first)")
                self._taps[tap.id] = tap
                self._lines[tap.id] = (number, None)
                self._next_id = max(self._next_id, tap.id + 1)
                self._last_drop = None
                return tap
            if kind in ("undo", "drop"):
                tap_id = int(record["id"])
                if tap_id not in self._taps:
                    removed = self._lines.get(tap_id, (None, None))[1]
                    raise self._conflict(number, f"{'undoes' if kind == 'undo' else 'drops'} tap {tap_id}, which "
                                         + (f"line {removed} took away already" if removed is not None
                                            else "no line before it records"))
                self._lines[tap_id] = (self._lines[tap_id][0], number)
                tap = self._taps.pop(tap_id)
                self._last_drop = tap_id if kind == "drop" else None
                if kind == "drop":
                    self._dropped[tap_id] = tap
                return tap
            if kind == "restore":
                tap_id = int(record["id"])
                if tap_id not in self._dropped:
                    raise self._conflict(number, f"takes back the drop of tap {tap_id}, which no line before it "
                                                 "drops")
                self._lines[tap_id] = (self._lines[tap_id][0], None)
                self._taps[tap_id] = self._dropped.pop(tap_id)
                self._taps = dict(sorted(self._taps.items()))  # ids grow with the time a tap was recorded
                self._last_drop = None
                return self._taps[tap_id]
        except (KeyError, TypeError, ValueError):
            raise invalid from None
        if kind != "closed":
            raise invalid
        self.closed = True
        return None

    def _conflict(self, number: int | None, what: str) -> SessionError:
        """The refusal of a replayed record that contradicts an earlier one: its line ``number`` ``what``."""
        return SessionError(f"line {number} of the session {self.path} {what}: fixwizard never writes that, so the "
                            "file was edited or joined with another. Keep a copy of it, delete the line that does not "
                            "belong and resume again, or start a new session")


def find_unfinished(folder: str | Path = SESSIONS_DIR) -> list[Path]:
    """Session journals (``*.jsonl``) in ``folder`` without a closed record, oldest name first (a damaged one
    too: resuming it says what is wrong)."""
    unfinished = []
    for path in sorted(Path(folder).glob(f"*{SUFFIX}")):
        read = read_unfinished(KIND, path)
        if read is not None and not any(record.get("kind") == "closed" for record in read[1]):
            unfinished.append(path)
    return unfinished
