"""The robot-driven tip calibration on the simulated cell: it recovers the hidden tip, the calibrated tip
locates the fixture, progress and cancel work between taps, robot errors name the step and keep the
recorded taps, and no commanded move brings the ball below the approach height."""

import threading

import numpy as np
import pytest

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.robot import MotionStopped, MoveBlocked, ProtectiveStop
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.solve import solve
from fixwizard.workflow.robot_calibration import Cancelled, RobotTipCalibration
from fixwizard.workflow.session import SamplingSession
from shapes import as_fixture
from sim_operator import operator_steps

TRUE_TIP_M = np.array([0.0012, -0.0007, 0.049])
FK_BOUND_M = 0.0003
APPROACH_M = 0.03
PLAN = {"table": 16, "tilted": 40}  # 4 x 4 grid; 8 azimuths x 5 tilts


class MoveLog:
    """The cell as the workflow sees it, keeping every ``move_linear`` target."""

    def __init__(self, cell: SimulatedCell) -> None:
        self.cell = cell
        self.targets: list[np.ndarray] = []

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
        self.targets.append(np.array(base_T_tcp))
        self.cell.move_linear(base_T_tcp, speed_m_s, stop_mark)

    def __getattr__(self, name: str):
        return getattr(self.cell, name)


@pytest.fixture(scope="module")
def fixture():
    return as_fixture("polytope")


def new_cell(fixture) -> SimulatedCell:
    cell = SimulatedCell.with_fixture(fixture, seed=11, tcp_p_tip_m=TRUE_TIP_M, fk_error_bound_m=FK_BOUND_M)
    cell.connect()
    return cell


@pytest.fixture(scope="module")
def calibrated(fixture):
    cell = new_cell(fixture)
    log = MoveLog(cell)
    workflow = RobotTipCalibration(log, cell.truth.ball_diameter_m, approach_height_m=APPROACH_M)
    operator_steps(cell, workflow)
    reports = []
    workflow.run_table_taps(lambda *report: reports.append(report))
    workflow.run_tilted_taps(lambda *report: reports.append(report))
    return cell, log, workflow, workflow.result("sim-tip", robot="sim"), reports


@pytest.fixture
def ready(fixture):
    """A fresh cell and workflow with the operator's steps done."""
    cell = new_cell(fixture)
    workflow = RobotTipCalibration(cell, cell.truth.ball_diameter_m)
    operator_steps(cell, workflow)
    return cell, workflow


def test_calibration_recovers_the_hidden_tip_and_proposes_a_bound_covering_the_robot(calibrated):
    _, _, workflow, calibration, _ = calibrated
    error_m = calibration.tcp_p_tip_m - TRUE_TIP_M
    assert np.linalg.norm(error_m) < FK_BOUND_M  # within the simulated robot's error bound
    assert np.all(np.abs(error_m) <= 3 * calibration.tip_standard_error_m)
    assert calibration.sample_bound_m >= FK_BOUND_M
    assert {step: len(series.base_T_tcp) for step, series in calibration.steps.items()} == {
        "pivot": 5, "table_coarse": 3, **PLAN}
    assert workflow.pivot_fit().stats.max_m < 2 * FK_BOUND_M


@pytest.mark.slow
def test_the_calibrated_tip_locates_the_fixture(calibrated, fixture, tmp_path):
    cell, _, _, calibration, _ = calibrated
    hands = SimulatedHands(cell, seed=5)
    with SamplingSession.create(tmp_path / "s.jsonl", {"name": "polytope"},
                                {"tcp_p_tip_m": calibration.tcp_p_tip_m.tolist()}) as session:
        for index in range(12):
            hands.near_spread_point(index)
            session.record_tap(cell.tap().base_T_tcp_contact)
        base_p_taps = session.base_p_taps
    assert len(base_p_taps) == 12
    solution = solve(fixture, base_p_taps, calibration.ball_diameter_m, sample_bound_m=calibration.sample_bound_m,
                     max_cells=8e6, max_samples=2000)
    assert solution.status == "unique"
    assert solution.contains(cell.truth.base_T_cad)
    assert solution.bounds.max_point_displacement_m < 0.01  # no fixture point moves more than 1 cm in the set


def test_progress_is_reported_after_every_tap(calibrated):
    reports = calibrated[-1]
    assert reports == [(step, done, total) for step, total in PLAN.items() for done in range(1, total + 1)]


def test_no_move_brings_the_ball_below_the_approach_height(calibrated):
    cell, log, _, _, _ = calibrated
    heights_m = ball_centres_m(np.array(log.targets), TRUE_TIP_M)[:, 2] - cell.truth.ball_diameter_m / 2
    assert len(log.targets) >= sum(PLAN.values()) + 1  # a lift from table point C before the first hover
    # the hover poses are planned with the pivot tip, which errs by less than a millimetre
    assert heights_m.min() >= APPROACH_M - 0.001


def test_cancel_stops_between_taps_and_running_again_continues(ready):
    _, workflow = ready
    cancel = threading.Event()

    def cancel_after_three(step, done, total):
        if done == 3:
            cancel.set()

    with pytest.raises(Cancelled, match="table taps were cancelled after 3 of 16 taps; the recorded taps are kept"):
        workflow.run_table_taps(cancel_after_three, cancel)
    assert len(workflow.poses("table")) == 3
    workflow.run_table_taps()
    assert len(workflow.poses("table")) == 16


def test_a_stop_as_a_move_ends_lets_no_tap_start(ready):
    """STOP (which sets the cancel request) pressed just as a move to a hover pose ends: the tap after it must
    not start (it did: cancel was looked at only before each move)."""
    cell, workflow = ready
    cancel = threading.Event()
    taps: list[float] = []

    class StopAsTheMoveEnds(MoveLog):
        def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
            super().move_linear(base_T_tcp, speed_m_s, stop_mark)
            if len(self.targets) == 3:  # the lift, then two hover poses
                cancel.set()

        def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
                stop_mark: int | None = None, on_contact=None):
            taps.append(max_travel_m)
            return self.cell.tap(max_travel_m, speed_m_s, force_limit_n, stop_mark, on_contact)

    workflow.robot = StopAsTheMoveEnds(cell)
    with pytest.raises(Cancelled, match="table taps were cancelled after 1 of 16 taps"):
        workflow.run_table_taps(None, cancel)
    assert len(taps) == 1 and len(workflow.poses("table")) == 1


class StopAsTheCallLeaves(MoveLog):
    """STOP (the wizard sets the cancel request, then stops the robot) landing after the workflow looked at the cancel
    request and before its call reaches the robot, at the ``nth`` call of ``motion`` ("move_linear" or "tap")."""

    def __init__(self, cell: SimulatedCell, cancel: threading.Event, motion: str, nth: int) -> None:
        super().__init__(cell)
        self.cancel, self.motion, self.left = cancel, motion, nth
        self.started: list[str] = []

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
        self._maybe_stop("move_linear")
        super().move_linear(base_T_tcp, speed_m_s, stop_mark)
        self.started.append("move")

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
            stop_mark: int | None = None, on_contact=None):
        self._maybe_stop("tap")
        result = self.cell.tap(max_travel_m, speed_m_s, force_limit_n, stop_mark, on_contact)
        self.started.append("tap")
        return result

    def _maybe_stop(self, motion: str) -> None:
        if motion == self.motion:
            self.left -= 1
            if self.left == 0:
                self.cancel.set()
                self.cell.stop()


@pytest.mark.parametrize("motion, nth, started", [("move_linear", 1, []), ("move_linear", 3, ["move", "move", "tap"]),
                                                  ("tap", 2, ["move", "move", "tap", "move"])])
def test_a_stop_between_the_look_at_cancel_and_the_robot_call_moves_nothing(ready, motion, nth, started):
    """The workflow looks at the cancel request before each motion; a STOP landing right after that look let the
    motion start (the robot counted STOPs from the call). The robot now gets the STOP count read before the look and
    refuses the motion; the taps before it stay recorded."""
    cell, workflow = ready
    cancel = threading.Event()
    workflow.robot = robot = StopAsTheCallLeaves(cell, cancel, motion, nth)
    with pytest.raises(MotionStopped, match="stopped on request"):
        workflow.run_table_taps(None, cancel)
    assert robot.started == started
    assert len(workflow.poses("table")) == started.count("tap")


def test_protective_stop_names_the_step_and_keeps_the_recorded_taps(ready):
    cell, workflow = ready

    def stop_after_four(step, done, total):
        if done == 4:
            cell.inject_fault("protective_stop_during_tap")

    with pytest.raises(ProtectiveStop, match="^table taps, tap 5 of 16: the robot made a protective stop .* unlock"):
        workflow.run_table_taps(stop_after_four)
    assert len(workflow.poses("table")) == 4
    cell.unlock()
    workflow.run_table_taps()
    assert len(workflow.poses("table")) == 16


class RetractMeetsSomething(MoveLog):
    """A UR's tap whose retract meets something once the contact was reported (``on_contact``): the error comes
    after the contact, which the robot recorded."""

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
            stop_mark: int | None = None, on_contact=None):
        result = self.cell.tap(max_travel_m, speed_m_s, force_limit_n, stop_mark, on_contact)
        error = MoveBlocked(60.0)
        error.tap_result = result
        raise error


def test_a_contact_counts_as_the_robot_reports_it_even_when_the_retract_then_fails(ready):
    """The automatic taps saved a contact only once its tap had returned, so a wizard killed while the ball retracted
    (or a retract that met something) kept nothing of it: it now counts, journaled, as the robot reports it."""
    cell, workflow = ready
    workflow.robot = RetractMeetsSomething(cell)
    with pytest.raises(MoveBlocked, match="^table taps, tap 1 of 16: "):
        workflow.run_table_taps()
    assert len(workflow.poses("table")) == 1
    workflow.robot = cell
    workflow.run_table_taps()
    assert len(workflow.poses("table")) == 16


def test_steps_out_of_order_and_unsafe_heights_are_refused(fixture):
    cell = new_cell(fixture)
    with pytest.raises(CalibrationError, match="choose a lower approach height"):
        RobotTipCalibration(cell, 0.003, approach_height_m=0.045)
    workflow = RobotTipCalibration(cell, 0.003)
    with pytest.raises(CalibrationError, match="tap the table points A, B .* first"):
        workflow.run_table_taps()
    with pytest.raises(CalibrationError, match="at least 3 flange poses"):
        workflow.pivot_fit()


def test_the_automatic_taps_start_only_above_the_table_corner(ready):
    """A calibration continued after the arm was moved: the way to the first hover point runs at the approach
    height, so from elsewhere (here 300 mm beyond the corner, the flange low) the robot does not move at all."""
    cell, workflow = ready
    log = MoveLog(cell)
    workflow.robot = log
    away = cell.base_T_tcp()
    away[:3, 3] += [0.3, 0.3, 0.0]
    cell.guide_by_hand(away)
    with pytest.raises(CalibrationError, match=r"the ball is \d+ mm away from the table corner of A, B and C, .* so "
                                               "the robot did not move: bring it a few centimetres above the corner B"):
        workflow.run_table_taps()
    assert log.targets == [] and len(workflow.poses("table")) == 0
    SimulatedHands(cell, seed=3).table_point("B")  # the operator brings it back
    workflow.run_table_taps()
    assert len(workflow.poses("table")) == 16
