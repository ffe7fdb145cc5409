"""The journal of a tip calibration in progress, so that a crash, a lost SSH connection or kill -9 loses none of its
poses: the pivot poses, the table points A, B, C and every automatic tap, each saved (fsync) as it is recorded.

JSON Lines (``fixwizard.journal``): line 1 is the header
``{"schema": "fixwizard.tip-calibration-journal/1", "created", "robot", "settings": {...}}`` (the settings
``RobotTipCalibration`` was made with, lengths in m, angles in deg); then one record per line:

- ``{"kind": "pose", "step": "pivot" | "table_coarse" | "table" | "tilted", "base_T_tcp": 4x4 (m), "time"}``
- ``{"kind": "clear", "steps": [...], "time"}``: those steps' poses no longer count (table points that made no
  table frame; every step on a redo)
- ``{"kind": "closed", "outcome": "saved" | "discarded", "time", ...}`` once the calibration is saved or given up.

Journals live in ``<calibrations folder>/journals/``; closed ones stay there as a record of how each calibration was
taken (a discarded one that recorded nothing is removed).
"""

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Literal, Self, get_args

import numpy as np

from fixwizard.errors import InputError
from fixwizard.journal import Journal, JournalKind, SkippedLine, TornRecord, now, read_unfinished, replay

SCHEMA = "fixwizard.tip-calibration-journal/1"
JOURNALS_DIR = "journals"
SUFFIX = ".jsonl"
Step = Literal["pivot", "table_coarse", "table", "tilted"]
STEPS: tuple[Step, ...] = get_args(Step)
Outcome = Literal["saved", "discarded"]


class CalibrationJournalError(InputError):
    """A tip calibration journal cannot be created, continued or written."""


KIND = JournalKind(SCHEMA, "tip calibration", CalibrationJournalError, "start a new tip calibration")


def journals_dir(calibrations_dir: Path) -> Path:
    """Where the journals of the tip calibrations saved in ``calibrations_dir`` live."""
    return calibrations_dir / JOURNALS_DIR


@dataclass(frozen=True)
class Unfinished:
    """An unfinished tip calibration as the start screen offers it: its journal, the time of its last change and the
    number of poses recorded in each step."""

    path: Path
    changed: datetime
    counts: dict[Step, int]

    def describe(self) -> str:
        """The recorded poses in words."""
        counts = self.counts
        return ", ".join(_count(number, what) for number, what in (
            (counts["pivot"], "pivot pose"), (counts["table_coarse"], "table point"),
            (counts["table"] + counts["tilted"], "automatic tap")))


class CalibrationJournal:
    """An open, locked tip calibration journal and the poses it replays to. Use ``create`` or ``open``."""

    def __init__(self, journal: Journal, continued: bool = False) -> None:
        self.journal = journal
        self.continued = continued  # opened to go on with it after the wizard left it (not created now)
        self.poses: dict[Step, list[np.ndarray]] = {step: [] for step in STEPS}
        self.closed = False
        self._written = 0  # records written since opened
        for number, record in journal.records:
            self._apply(record, number)

    @classmethod
    def create(cls, folder: Path, robot: str | None, settings: dict) -> Self:
        """A new journal in ``folder`` for a calibration on ``robot`` with ``settings``."""
        stamp = datetime.now()
        path = folder / f"tip-{stamp:%Y%m%d-%H%M%S}-{stamp.microsecond // 1000:03d}{SUFFIX}"
        return cls(Journal.create(KIND, path, {"created": now(), "robot": robot, "settings": settings}))

    @classmethod
    def open(cls, path: Path) -> Self:
        """Continue a journal: its poses replayed, torn records, blank and repeated lines skipped (see
        ``recovered``)."""
        opened = replay(KIND, path, lambda journal: cls(journal, continued=True))
        if opened.closed:
            opened.release()
            raise CalibrationJournalError(f"the tip calibration {path.name} is finished already; start a new one, "
                                          "or choose a saved calibration")
        return opened

    @property
    def path(self) -> Path:
        return self.journal.path

    @property
    def robot(self) -> str | None:
        return self.journal.header.get("robot")

    @property
    def settings(self) -> dict:
        settings = self.journal.header.get("settings")
        return settings if isinstance(settings, dict) else {}

    @property
    def recovered(self) -> tuple[TornRecord | SkippedLine, ...]:
        return self.journal.recovered

    def record_pose(self, step: Step, base_T_tcp: np.ndarray) -> None:
        """Save one recorded flange pose (4x4, m) of ``step``."""
        self._write({"kind": "pose", "step": step, "base_T_tcp": np.asarray(base_T_tcp, float), "time": now()},
                    f"this {step.replace('_coarse', '')} pose")

    def record_clear(self, steps: tuple[Step, ...]) -> None:
        """Save that the poses of ``steps`` no longer count."""
        self._write({"kind": "clear", "steps": list(steps), "time": now()}, "the clearing of the recorded poses")

    def close(self, outcome: Outcome, **extra) -> None:
        """Mark the calibration saved (``extra``: where) or discarded, and let go of the journal; a discarded one
        that holds no record at all is removed."""
        if outcome == "discarded" and not self.journal.records and not self._written and not self.closed:
            self.release()
            self.path.unlink(missing_ok=True)
            return
        self._write({"kind": "closed", "outcome": outcome, "time": now(), **extra}, "the end of the calibration")
        self.release()

    def release(self) -> None:
        """Let go of the file and its lock, the calibration unfinished (it stays offered on the start screen)."""
        self.journal.release()

    def _write(self, record: dict, what: str) -> None:
        if self.closed:
            raise CalibrationJournalError(f"the tip calibration {self.path.name} is finished; start a new one to "
                                          "record more")
        self._apply(self.journal.append(record, what), None)
        self._written += 1

    def _apply(self, record: dict, number: int | None) -> None:
        """Replay one record; ``number`` is its journal line when replaying from the file."""
        invalid = CalibrationJournalError(
            f"line {number} of the tip calibration {self.path} is not a valid pose, clear or closed record; keep "
            "the file and start a new tip calibration")
        try:
            kind = record["kind"]
            if kind == "pose":
                step = _step(record["step"])
                base_T_tcp = np.asarray(record["base_T_tcp"], float)
                if base_T_tcp.shape != (4, 4) or not np.isfinite(base_T_tcp).all():
                    raise ValueError("not a 4x4 pose")
                self.poses[step].append(base_T_tcp)
            elif kind == "clear":
                for step in [_step(step) for step in record["steps"]]:
                    self.poses[step].clear()
            elif kind == "closed":
                self.closed = True
            else:
                raise ValueError(f"unknown record {kind!r}")
        except (KeyError, TypeError, ValueError):
            raise invalid from None


def _count(number: int, what: str) -> str:
    return f"{number} {what}{'' if number == 1 else 's'}"


def _step(name: object) -> Step:
    if name not in STEPS:
        raise ValueError(f"unknown step {name!r}")
    return name


def find_unfinished_calibrations(calibrations_dir: Path, robot: str | None) -> list[Unfinished]:
    """The unfinished tip calibrations taken on ``robot`` that hold a pose, newest change first (a damaged journal
    too: continuing it says what is wrong)."""
    unfinished = []
    folder = journals_dir(calibrations_dir)
    for path in sorted(folder.glob(f"*{SUFFIX}")) if folder.is_dir() else []:
        read = read_unfinished(KIND, path)
        if read is None or read[0].get("robot") != robot:
            continue
        counts = _counts(read[1])
        try:
            changed = datetime.fromtimestamp(path.stat().st_mtime)
        except OSError:  # removed since it was read
            continue
        if counts is not None and any(counts.values()):
            unfinished.append(Unfinished(path, changed, counts))
    return sorted(unfinished, key=lambda found: found.changed, reverse=True)


def _counts(records: list[dict]) -> dict[Step, int] | None:
    """The poses per step the records replay to, or None once closed (records that do not replay are skipped:
    continuing the journal names them)."""
    counts = dict.fromkeys(STEPS, 0)
    for record in records:
        kind = record.get("kind")
        if kind == "closed":
            return None
        if kind == "pose" and record.get("step") in counts:
            counts[record["step"]] += 1
        elif kind == "clear" and isinstance(record.get("steps"), list):
            for step in record["steps"]:
                if step in counts:
                    counts[step] = 0
    return counts
