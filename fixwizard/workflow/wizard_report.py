"""The report the wizard writes after a solve: the ``fixwizard.report/2`` document of the session's taps, with
where the taps came from (the session journal) and, on a simulated cell, ``simulated: true``. The fixture's name
in it is derived from the mesh file's stem (``report.name_from_stem``): the reports of a cell with several
fixtures are told apart by it (``workflow/cell_reports.py``)."""

import datetime as dt
from pathlib import Path

from fixwizard import report
from fixwizard.atomic import check_output
from fixwizard.calibration.store import TipCalibration
from fixwizard.fixture import Fixture
from fixwizard.solver.solve import Solution
from fixwizard.workflow.session import SamplingSession

REPORT_SUFFIX = ".yaml"


def default_report_path(reports_dir: Path, fixture: Fixture, now: dt.datetime) -> Path:
    """``<reports_dir>/<mesh file stem>-<local time as YYYYmmdd-HHMMSS>.yaml``."""
    return reports_dir / f"{fixture.path.stem}-{now:%Y%m%d-%H%M%S}{REPORT_SUFFIX}"


def session_report(solution: Solution, fixture: Fixture, session: SamplingSession, calibration: TipCalibration,
                   simulated: bool) -> dict:
    """The report of a solve of the session's active taps, with the calibration's ball and sample bound."""
    data = report.report_dict(solution, fixture, session.base_p_taps, calibration.ball_diameter_m,
                              calibration.sample_bound_m, calibration.sample_bound_m / 3.0, simulated=simulated)
    search = data.pop("search")  # put back last, where a report cut short is told by its missing lines
    data["session"] = {"journal": str(session.path), "tap_ids": [tap.id for tap in session.taps],
                       "tip_calibration": calibration.name}
    data["search"] = search
    return data


def report_target(path: str | Path, fixture: Fixture, session: SamplingSession) -> Path:
    """The file a report written to ``path`` replaces (``atomic.check_output``); InputError for a path that is one of
    the inputs (mesh, journal, tip calibration), a folder or a device."""
    return check_output(path, [("fixture mesh", fixture.path), ("session journal", session.path),
                               ("tip calibration", session.header.get("tip", {}).get("calibration"))],
                        "choose another report path")


def write_session_report(path: str | Path, solution: Solution, fixture: Fixture, session: SamplingSession,
                         calibration: TipCalibration, simulated: bool) -> Path:
    """Write the report atomically and return its absolute path; InputError for a path ``report_target`` refuses,
    OSError when the disk refuses it."""
    report_target(path, fixture, session)
    return report.write(Path(path), session_report(solution, fixture, session, calibration, simulated)).resolve()
