"""Sampling sessions as the wizard opens them: a new journal for the chosen fixture, tip calibration and
robot, or an unfinished one resumed with the fixture and calibration its header names. Blocking (files,
mesh loading): call from a worker thread."""

import itertools
from datetime import datetime
from pathlib import Path

import numpy as np

from fixwizard.calibration.errors import CalibrationFileError
from fixwizard.calibration.store import TipCalibration, load_calibration
from fixwizard.errors import FixwizardError
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.journal import said
from fixwizard.tui import keys
from fixwizard.tui.cell import Cell, Resumed, Sampling, SavedCalibration
from fixwizard.tui.widgets.errors import ResumeRefused, error_text
from fixwizard.workflow.session import (
    SUFFIX,
    SamplingSession,
    SessionError,
    find_unfinished,
)


def start_session(cell: Cell, fixture: Fixture, tip: SavedCalibration) -> SamplingSession:
    """Create ``sessions_dir/<fixture>-<time>.jsonl`` for ``fixture`` and the tip calibration (``-2``, ``-3`` ... after
    the time when another wizard on this folder started one in the same second, also where it took the name
    between this one looking at it and creating it)."""
    calibration = tip.calibration
    fixture_info = {"name": fixture.path.stem, "path": str(fixture.path.resolve()), "units": fixture.units,
                    "sha256": fixture.sha256}
    tip_info = {"name": calibration.name, "calibration": str(tip.path.resolve()),
                "tcp_p_tip_m": calibration.tcp_p_tip_m.tolist(), "ball_diameter_m": calibration.ball_diameter_m,
                "sample_bound_m": calibration.sample_bound_m}
    stem = f"{fixture.path.stem}-{datetime.now():%Y%m%d-%H%M%S}"
    names = (cell.sessions_dir / f"{stem}{'' if number == 1 else f'-{number}'}{SUFFIX}"
             for number in itertools.count(1))
    while True:
        path = next(path for path in names if not path.exists())
        try:
            return SamplingSession.create(path, fixture_info, tip_info, robot=cell.robot_name)
        except SessionError:
            if not path.exists():  # not the name taken meanwhile by another wizard
                raise


def started_text(session: SamplingSession, tip: SavedCalibration, calibrated_now: bool) -> str:
    """Which session was started and with which tip calibration (saved just now, or chosen)."""
    tip_words = f"Tip calibration saved to {tip.path}" if calibrated_now else f"Tip calibration {tip.path.name}"
    return f"{tip_words}. New session {session.path.name}: every tap is saved there as you go."


def resume_session(cell: Cell, path: Path) -> Resumed:
    """Open the session at ``path`` with the fixture and tip calibration it names, and say what was opened, in
    words. Refused when it is finished, was recorded on another robot or its mesh changed since."""
    session = SamplingSession.open(path)
    try:
        if session.closed:  # asked for by its path: the start screen lists only unfinished ones
            raise SessionError(f"the session {path.name} is finished already (its report was written): start a new "
                               "session to tap again")
        header = session.header
        if header.get("robot") != cell.robot_name:
            raise SessionError(f"the session {path.name} was recorded on '{header.get('robot')}', not on "
                               f"'{cell.robot_name}': resume it with that robot, or start a new session")
        fixture_info, tip_info = header.get("fixture"), header.get("tip")
        if not (isinstance(fixture_info, dict) and isinstance(tip_info, dict)
                and all(isinstance(fixture_info.get(key), str) for key in ("path", "units", "sha256"))
                and isinstance(tip_info.get("calibration"), str)):
            raise SessionError(f"the session {path.name} was not started by the wizard (its header names no fixture "
                               "mesh and tip calibration file): solve its points with `fixwizard solve`, or start a "
                               "new session")
        fixture = load_fixture(fixture_info["path"], fixture_info["units"])
        if fixture.sha256 != fixture_info["sha256"]:
            raise SessionError(f"the mesh {fixture.path} changed since the session {path.name} started: put the "
                               "original mesh back, or start a new session")
        calibration_path = Path(tip_info["calibration"])
        try:
            calibration = load_calibration(calibration_path)
        except CalibrationFileError as error:
            raise SessionError(f"{str(error).rstrip('.')}. The session was recorded with that tip calibration: put "
                               "it back, or start a new session") from error
        changes = calibration_changes(tip_info, calibration)
        if changes:
            raise SessionError(f"the tip calibration {calibration_path.name} changed since the session started "
                               f"({'; '.join(changes)}): its taps were made with the one before. Put that one back, "
                               "or start a new session")
    except BaseException:
        session.release()
        raise
    return Resumed(Sampling(session, fixture, SavedCalibration(calibration, calibration_path)),
                   resumed_text(session, fixture.path, calibration_path))


def calibration_changes(tip_info: dict, calibration: TipCalibration) -> list[str]:
    """How ``calibration`` differs from the tip calibration a session header's ``tip_info`` holds (ball diameter,
    tip position, sample bound), in words; nothing for a value the header does not hold."""
    changes = []
    for key, words in (("ball_diameter_m", "ball"), ("sample_bound_m", "sample bound")):
        now, then = float(getattr(calibration, key)), _recorded(tip_info.get(key), ())
        if then is not None and not np.isclose(now, then, rtol=1e-9, atol=0.0):
            changes.append(f"{words} {now * 1e3:.1f} mm, the session's taps: {float(then) * 1e3:.1f} mm")
    tip_then = _recorded(tip_info.get("tcp_p_tip_m"), (3,))
    if tip_then is not None and (moved_m := float(np.linalg.norm(calibration.tcp_p_tip_m - tip_then))) > 1e-9:
        changes.append(f"the tip {moved_m * 1e3:.2f} mm from where the session's taps had it")
    return changes


def _recorded(value: object, shape: tuple[int, ...]) -> np.ndarray | None:
    """A header's value as finite numbers of ``shape`` (m), or None when it holds no such value."""
    try:
        array = np.asarray(value, float)
    except (TypeError, ValueError):
        return None
    return array if array.shape == shape and np.isfinite(array).all() else None


def resumed_text(session: SamplingSession, mesh: Path, calibration_path: Path) -> str:
    """Which session was opened, with how many taps, its fixture and tip calibration, any record that was never
    finished and any line skipped, and a drop that the undo key takes back."""
    count = len(session.taps)
    lines = [f"Resumed the session {session.path}: {count} tap{'' if count == 1 else 's'} recorded, fixture "
             f"{mesh.name}, tip calibration {calibration_path.name}."]
    lines += [f"Note: {note}." for note in said(session.recovered)]
    return "\n".join(lines + [drop_to_take_back(session)]).strip()


def drop_to_take_back(session: SamplingSession) -> str:
    """The drop the undo key takes back (the session's last change), in words; "" when its last change was none."""
    dropped = session.last_dropped
    if dropped is None:
        return ""
    place = sum(tap.id < dropped.id for tap in session.taps) + 1
    return (f"Tap {place} was dropped last: it does not count (the journal keeps it, marked dropped). Press "
            f"{keys.name(keys.UNDO)} to take the drop back.")


def resume_refusal(requested: str | Path, error: FixwizardError | OSError) -> ResumeRefused:
    """The refusal of a resume as the operator reads it: which session, why, and what to do next."""
    what = "the newest unfinished session" if requested == "" else Path(requested).name
    return ResumeRefused(f"could not resume {what}: {error_text(error)}\nOn the start screen, resume another "
                         "session or start a new one.")


def newest_unfinished(sessions_dir: Path) -> Path:
    """The most recently changed unfinished session in ``sessions_dir``."""
    unfinished = find_unfinished(sessions_dir)
    if not unfinished:
        raise SessionError(f"there is no unfinished session in {sessions_dir}: start fixwizard without --resume")
    return max(unfinished, key=lambda path: path.stat().st_mtime)
