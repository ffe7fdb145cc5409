"""What the start screen offers: fixture meshes, stored tip calibrations and unfinished sessions, each with
the one line an operator needs to choose. Lengths are shown in mm."""

from dataclasses import dataclass
from datetime import datetime
from pathlib import Path

from fixwizard.calibration.errors import CalibrationFileError
from fixwizard.calibration.store import TipCalibration, load_calibration
from fixwizard.calibration.verdict import tip_verdict
from fixwizard.demo import DEMO_MESH, DEMO_MESH_UNITS, DISC_MESH
from fixwizard.fixture import MESH_SUFFIXES, Fixture
from fixwizard.tui.tip_origin import other_robot_note
from fixwizard.workflow.calibration_journal import Unfinished
from fixwizard.workflow.session import find_unfinished

CAD_UNITS = "mm"  # what CAD exports usually use; the operator confirms it on the start screen


@dataclass(frozen=True)
class FixtureChoice:
    """A mesh the operator can pick and the units to try first."""

    label: str
    path: Path
    units: str


@dataclass(frozen=True, eq=False)
class CalibrationChoice:
    """A stored tip calibration, or why it cannot be used (``problem``)."""

    path: Path
    calibration: TipCalibration | None
    problem: str | None = None


def fixture_choices(fixtures_dir: Path) -> list[FixtureChoice]:
    """The bundled demo bracket and round plate, then every mesh in ``fixtures_dir`` by name."""
    meshes = sorted(path for path in fixtures_dir.glob("*") if path.suffix.lower() in MESH_SUFFIXES) \
        if fixtures_dir.is_dir() else []
    return [FixtureChoice("Demo bracket (bundled)", DEMO_MESH, DEMO_MESH_UNITS),
            FixtureChoice("Round plate (bundled)", DISC_MESH, DEMO_MESH_UNITS),
            *(FixtureChoice(path.name, path, CAD_UNITS) for path in meshes)]


def calibration_choices(calibrations_dir: Path) -> list[CalibrationChoice]:
    """Every regular ``*.yaml`` file in ``calibrations_dir`` (a pipe would wait for a writer): readable ones newest
    first, then unreadable ones."""
    readable, unreadable = [], []
    for path in sorted(calibrations_dir.glob("*.yaml")) if calibrations_dir.is_dir() else []:
        if not path.is_file():
            continue
        try:
            readable.append(CalibrationChoice(path, load_calibration(path)))
        except CalibrationFileError as error:
            unreadable.append(CalibrationChoice(path, None, str(error)))
    return sorted(readable, key=lambda choice: choice.calibration.created if choice.calibration else "",
                  reverse=True) + unreadable


def describe_calibration(calibration: TipCalibration, robot_name: str) -> str:
    """The ball diameter, date and robot (said when it is not ``robot_name``, the robot connected), then the verdict
    with its first reason."""
    created = calibration.created.replace("T", " ")[:16]
    verdict = tip_verdict(calibration)
    lines = [f"Ball diameter {calibration.ball_diameter_m * 1e3:.1f} mm (check it is the ball on the tool), "
             f"calibrated {created} on {calibration.robot or 'an unknown robot'}",
             other_robot_note(calibration, robot_name),
             f"{verdict.level.capitalize()}: {verdict.reasons[0]}"]
    return "\n".join(line for line in lines if line)


def describe_unfinished_calibration(unfinished: Unfinished) -> str:
    """What an unfinished tip calibration holds, and when continuing it is right."""
    return (f"Recorded so far: {unfinished.describe()}. Continue goes on where it stopped: only if the ball and "
            "the tool were not touched since (otherwise start a new one).")


def describe_fixture(fixture: Fixture) -> str:
    """Size (mm) and units of a loaded fixture, and its warnings."""
    size_mm = " x ".join(f"{extent * 1e3:.1f}" for extent in fixture.mesh.extents)
    lines = [f"{size_mm} mm (file units: {fixture.units}); check that this is the fixture's real size"]
    lines += [message for _, message in fixture.warnings]
    return "\n".join(lines)


def session_choices(sessions_dir: Path) -> dict[Path, datetime]:
    """Unfinished sessions, newest first, with the time of their last change (one removed since it was read is
    left out)."""
    changed = {}
    for path in find_unfinished(sessions_dir):
        try:
            changed[path] = datetime.fromtimestamp(path.stat().st_mtime)
        except OSError:
            continue
    return dict(sorted(changed.items(), key=lambda item: item[1], reverse=True))
