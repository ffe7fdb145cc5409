"""The JSON Schemas of the files fixwizard writes hold for what it really writes: reports (from the CLI and the
wizard, unique and inconsistent), the bundled example report, tip calibrations and every kind of session journal
and tip calibration journal line; and they are strict enough to catch a broken file."""

import copy
import datetime as dt
import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest
import yaml

from fixwizard import report
from fixwizard.calibration.calibrate import calibrate_tip
from fixwizard.calibration.store import save_calibration
from fixwizard.cli import main
from fixwizard.demo import DEMO_MESH, DEMO_TAPS, demo_cell, demo_fixture
from fixwizard.schemas import FILES, load_schema
from fixwizard.solver.solve import solve
from fixwizard.tui.cell import Cell, SavedCalibration
from fixwizard.tui.start.sessions import start_session
from fixwizard.workflow.robot_calibration import RobotTipCalibration
from fixwizard.workflow.session import SamplingSession
from fixwizard.workflow.wizard_report import session_report
from test_calibration_helpers import synthetic_steps
from tui_cell import truth_calibration

REPO = Path(__file__).resolve().parents[1]
EXAMPLE_CALIBRATION = REPO / "calibrations" / "example_matlab_logo.yaml"
EXAMPLE_REPORT = REPO / "examples" / "report.yaml"

FORMATS = jsonschema.FormatChecker()


@FORMATS.checks("date-time", raises=ValueError)
def _iso_time(text: object) -> bool:
    """ISO 8601 with a time zone, as fixwizard writes it (Python's reading of it)."""
    return not isinstance(text, str) or dt.datetime.fromisoformat(text).tzinfo is not None


def validate(document: dict, schema_id: str) -> None:
    validator = jsonschema.Draft202012Validator(load_schema(schema_id), format_checker=FORMATS)
    validator.validate(document)


def invalid(document: dict, schema_id: str) -> bool:
    try:
        validate(document, schema_id)
    except jsonschema.ValidationError:
        return True
    return False


@pytest.mark.parametrize("schema_id", sorted(FILES))
def test_every_schema_is_a_valid_json_schema(schema_id):
    schema = load_schema(schema_id)
    jsonschema.Draft202012Validator.check_schema(schema)
    assert schema["$id"] == schema_id


@pytest.fixture(scope="module")
def demo_reports(tmp_path_factory):
    """Reports of the bundled demo written by `fixwizard solve`: a unique one and one with a tap 5 cm off."""
    folder = tmp_path_factory.mktemp("reports")
    taps = np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"])
    off = taps.copy()
    off[2, 2] += 0.05
    (folder / "off.yaml").write_text(yaml.safe_dump({"frame": "base", "points_m": off.tolist()}))
    common = ["--mesh-units", "mm", "--sample-bound", "1mm", "--ball-diameter", "3mm", "-q"]
    assert main(["solve", str(DEMO_MESH), str(DEMO_TAPS), *common, "--max-cells", "3e5", "-o",
                 str(folder / "unique.yaml")]) == 0
    assert main(["solve", str(DEMO_MESH), str(folder / "off.yaml"), *common, "--max-cells", "2e5", "-o",
                 str(folder / "inconsistent.yaml")]) == 2
    return folder


@pytest.mark.parametrize("name", ["unique.yaml", "inconsistent.yaml"])
def test_reports_written_by_solve_match_the_schema(demo_reports, name):
    data = yaml.safe_load((demo_reports / name).read_text())
    validate(data, "fixwizard.report/2")
    assert data["status"] == name.removesuffix(".yaml")


def test_the_wizard_report_matches_the_schema(tmp_path):
    fixture, calibration = demo_fixture(), truth_calibration(demo_cell(0))
    with SamplingSession.create(tmp_path / "s.jsonl", {"name": "demo_bracket"},
                                {"tcp_p_tip_m": [0, 0, 0.1]}) as session:
        for point in yaml.safe_load(DEMO_TAPS.read_text())["points_m"]:
            session.record_tap(np.eye(4), base_p_ball_m=point)
        solution = solve(fixture, session.base_p_taps, 0.003, 0.001, max_cells=2e5, max_samples=500)
        data = session_report(solution, fixture, session, calibration, simulated=True)
    validate(data, "fixwizard.report/2")
    assert data["simulated"] is True and data["session"]["journal"] == str(session.path)
    assert list(data)[-1] == "search"  # last, so that a copy cut short is refused (report.load)


def test_the_schema_catches_broken_reports(demo_reports):
    good = yaml.safe_load((demo_reports / "unique.yaml").read_text())
    broken = []
    for change in (lambda data: data.update(status="great"), lambda data: data.pop("simulated"),
                   lambda data: data["pose"].pop("guaranteed"), lambda data: data["bounds"].update(rotation_deg=-1),
                   lambda data: data.update(pose=None), lambda data: data["fixture"].update(name="a b"),
                   lambda data: data.update(extra=1), lambda data: data.update(created="yesterday"),
                   lambda data: data["pose"].update(ur="p[1, 2]")):
        data = copy.deepcopy(good)
        change(data)
        broken.append(invalid(data, "fixwizard.report/2"))
    assert all(broken)


def _layout(value):
    """The keys of a document's mappings, nested (lists and values left out): what a layout change changes."""
    return {key: _layout(item) for key, item in value.items()} if isinstance(value, dict) else None


def test_the_example_report_loads_matches_the_schema_and_has_the_current_layout(demo_reports):
    """examples/report.yaml (made by tools/make_example_report.py) is what the code writes today: regenerate it
    when the layout or the bundled bracket changes."""
    example = report.load(EXAMPLE_REPORT)
    validate(example.data, "fixwizard.report/2")
    current = yaml.safe_load((demo_reports / "unique.yaml").read_text())
    assert _layout(example.data) == _layout(current)
    assert example.mesh == Path("fixwizard/data/demo_bracket.stl") and (REPO / example.mesh).is_file()
    assert example.mesh_sha256 == demo_fixture().sha256 and example.simulated and example.status == "unique"
    assert EXAMPLE_REPORT.read_text().startswith("# fixwizard report (fixwizard.report/2)")


def test_tip_calibrations_match_the_schema(tmp_path):
    calibration = calibrate_tip(**synthetic_steps(), ball_diameter_m=0.003, name="bench", robot="UR5e 20235500001")
    path = save_calibration(calibration, tmp_path / "bench.yaml")
    for written in (path, EXAMPLE_CALIBRATION):
        validate(yaml.safe_load(written.read_text()), "fixwizard.tip/1")
    data = yaml.safe_load(path.read_text())
    data["steps"]["pivot"]["excluded"] = [{"index": -1, "file": None, "residual_mm": 1.0, "threshold_mm": 0.5}]
    assert invalid(data, "fixwizard.tip/1")


def test_every_kind_of_session_line_matches_the_schema(tmp_path):
    cell = Cell(robot=None, robot_name="SIMULATED demo cell (seed 0)", simulated=True,
                sessions_dir=tmp_path / "sessions")
    session = start_session(cell, demo_fixture(), SavedCalibration(truth_calibration(demo_cell(0)),
                                                                   tmp_path / "truth.yaml"))
    pose = np.eye(4)
    pose[:3, 3] = [0.4, 0.0, 0.2]
    session.record_tap(pose, force={"peak_n": 5.0, "travel_m": 0.004, "settle_s": 0.2})
    session.record_tap(pose)
    session.undo()
    session.record_tap(pose)
    session.drop(1)
    session.restore()
    session.drop(1)
    session.close(report=str(tmp_path / "reports" / "r.yaml"))
    lines = [json.loads(line) for line in session.path.read_text().splitlines()]
    assert [line.get("kind") for line in lines] == [None, "tap", "tap", "undo", "tap", "drop", "restore", "drop",
                                                    "closed"]
    for line in lines:
        validate(line, "fixwizard.session/1")
    assert invalid({key: value for key, value in lines[1].items() if key != "crc"}, "fixwizard.session/1")
    assert invalid({**lines[1], "base_p_ball_m": [0.4, 0.0]}, "fixwizard.session/1")


def test_every_kind_of_tip_calibration_journal_line_matches_the_schema(tmp_path):
    cell = demo_cell(0)
    cell.connect()
    workflow = RobotTipCalibration.journaled(cell, "SIMULATED demo cell (seed 0)", tmp_path, 0.003)
    workflow.capture_pivot_pose()
    workflow.restart()
    workflow.capture_pivot_pose()
    workflow.close(tmp_path / "tip.yaml")
    path = workflow.journal.path
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [line.get("kind") for line in lines] == [None, "pose", "clear", "pose", "closed"]
    for line in lines:
        validate(line, "fixwizard.tip-calibration-journal/1")
    assert invalid({**lines[1], "base_T_tcp": [[1, 0, 0, 0]] * 3}, "fixwizard.tip-calibration-journal/1")
    assert invalid({**lines[2], "steps": ["tap"]}, "fixwizard.tip-calibration-journal/1")
