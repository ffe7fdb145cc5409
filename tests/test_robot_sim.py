"""The simulated cell: taps touch the true surfaces within the forward-kinematics bound, faults raise typed
errors with a way out, and the taps it records calibrate the fixture."""

import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.taps import ball_centres_m
from fixwizard.demo import demo_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot import (
    ConnectionLost,
    MotionStopped,
    MoveBlocked,
    NoContact,
    ProtectiveStop,
    Robot,
    RobotError,
)
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.solve import solve
from shapes import as_fixture

FK_BOUND_M = 0.0003
CONTACT_TOLERANCE_M = 1e-6


@pytest.fixture(scope="module")
def fixture():
    return as_fixture("l_prism")


@pytest.fixture
def cell(fixture) -> SimulatedCell:
    cell = SimulatedCell.with_fixture(fixture, seed=3, fk_error_bound_m=FK_BOUND_M)
    cell.connect()
    return cell


def tap_centres(cell: SimulatedCell, target: str, count: int, seed: int) -> np.ndarray:
    """Ball centres (count, 3, base frame, m) of ``count`` taps on ``target``, computed with the true tip."""
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(count):
        cell.place_tip_near(target, rng)
        poses.append(cell.tap().base_T_tcp_contact)
    return ball_centres_m(np.array(poses), cell.truth.tcp_p_tip_m)


def offset_residual_m(cell: SimulatedCell, fixture, base_p_centres: np.ndarray) -> np.ndarray:
    """Signed distance of the ball centres to the fixture minus the ball radius (m)."""
    return fixture.signed_distance_at_m(cell.truth.base_T_cad, base_p_centres) - cell.truth.ball_diameter_m / 2.0


def test_the_cell_is_a_robot(cell):
    assert isinstance(cell, Robot)


def test_random_fixture_pose_rests_on_the_table(cell, fixture):
    base_p_vertices = transform_points(cell.truth.base_T_cad, fixture.mesh.vertices)
    assert base_p_vertices[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert 0.3 < np.linalg.norm(cell.truth.base_T_cad[:2, 3]) < 0.7


def test_fixture_taps_land_on_the_ball_offset_surface(cell, fixture):
    residual = offset_residual_m(cell, fixture, tap_centres(cell, "fixture", 10, seed=1))
    assert np.all(np.abs(residual) <= FK_BOUND_M + CONTACT_TOLERANCE_M)


def test_table_taps_give_ball_centres_at_ball_radius_height(cell):
    heights = tap_centres(cell, "table", 8, seed=2)[:, 2]
    assert np.all(np.abs(heights - cell.truth.ball_diameter_m / 2.0) <= FK_BOUND_M + CONTACT_TOLERANCE_M)


def test_tap_at_a_given_point_touches_there(cell):
    cell.place_tip_near("table", np.random.default_rng(4), point=np.array([0.2, -0.3, 0.0]))
    centre = ball_centres_m(cell.tap().base_T_tcp_contact[None], cell.truth.tcp_p_tip_m)[0]
    # the tool tilts up to 30 deg, so the ball lands within hover / cos(30 deg) of the point
    assert np.linalg.norm(centre[:2] - [0.2, -0.3]) < 0.006 + FK_BOUND_M


@pytest.mark.slow
def test_twelve_spread_taps_calibrate_the_bundled_fixture_to_a_few_millimetres():
    fixture = demo_fixture()
    cell = SimulatedCell.with_fixture(fixture, seed=3, fk_error_bound_m=FK_BOUND_M)
    cell.connect()
    hands = SimulatedHands(cell, seed=5)
    poses = []
    for index in range(12):
        hands.near_spread_point(index)
        poses.append(cell.tap().base_T_tcp_contact)
    centres = ball_centres_m(np.array(poses), cell.truth.tcp_p_tip_m)
    solution = solve(fixture, centres, cell.truth.ball_diameter_m, sample_bound_m=FK_BOUND_M + 2e-5,
                     max_cells=8e6, max_samples=2000)
    assert solution.status == "unique"
    assert solution.contains(cell.truth.base_T_cad)
    assert solution.bounds.position_m < 0.006
    assert np.degrees(solution.bounds.rotation_rad) < 3.0


def test_paced_motion_is_cut_short_by_stop_and_the_next_tap_works(fixture):
    cell = SimulatedCell.with_fixture(fixture, seed=3, pace_s=5.0)
    cell.connect()
    cell.place_tip_near("table", np.random.default_rng(8))
    cell.pace_s = 5.0
    stopper = threading.Timer(0.2, cell.stop)
    stopper.start()
    with pytest.raises(MotionStopped, match="the tap was stopped on request; nothing was recorded"):
        cell.tap()
    cell.pace_s = 0.0
    assert cell.tap().travel_m > 0


def test_status_says_moving_only_while_a_motion_takes_its_time(fixture):
    """The wizard's status line shows ``mode``: the simulated cell said idle while it tapped."""
    cell = SimulatedCell.with_fixture(fixture, seed=3, pace_s=0.6)
    cell.connect()
    cell.place_tip_near("table", np.random.default_rng(8))
    seen = []
    looker = threading.Timer(0.2, lambda: seen.append(cell.status().mode))
    looker.start()
    cell.tap()
    looker.join()
    assert seen == ["moving"] and cell.status().mode == "idle"
    cell.freedrive(True)
    cell.pace_s = 60.0  # a refused tap does not start: it fails at once, never moving
    with pytest.raises(RobotError, match="freedrive is on"):
        cell.tap()
    assert cell.status().mode == "freedrive"


def test_stop_ends_freedrive_as_a_controllers_stop_ends_its_program(cell):
    cell.freedrive(True)
    assert cell.status().mode == "freedrive"
    cell.stop()
    assert cell.status().mode == "idle"
    cell.freedrive(True)  # turned on again as on the real arm
    assert cell.status().mode == "freedrive"


MOTIONS = {"tap": lambda cell, mark: cell.tap(stop_mark=mark),
           "move": lambda cell, mark: cell.move_linear(cell.base_T_tcp() @ make_transform(np.eye(3), [0, 0, -0.01]),
                                                       stop_mark=mark),
           "freedrive": lambda cell, mark: cell.freedrive(True, stop_mark=mark)}


@pytest.mark.parametrize("motion", MOTIONS)
def test_a_motion_asked_for_before_a_stop_never_starts_after_it(fixture, motion):
    """A motion whose ``stop_mark`` was read before a STOP is refused, however late it reaches the cell (the
    cell forgot every STOP before a motion began); asked for after the STOP, it runs."""
    cell = SimulatedCell.with_fixture(fixture, seed=3)
    cell.connect()
    cell.place_tip_near("table", np.random.default_rng(8))
    before = cell._base_T_tcp.copy()
    stop_mark = cell.stop_count()
    cell.stop()
    said = "freedrive did not come on" if motion == "freedrive" else f"the {motion} was stopped on request"
    with pytest.raises(MotionStopped, match=said):
        MOTIONS[motion](cell, stop_mark)
    assert cell.status().mode == "idle"
    np.testing.assert_array_equal(cell._base_T_tcp, before)
    MOTIONS[motion](cell, cell.stop_count())
    MOTIONS[motion](cell, None)


def test_tap_pointing_away_finds_no_contact(cell):
    cell.move_linear(make_transform(np.eye(3), [0.3, 0.0, 0.3]))  # tool z points up, into free space
    with pytest.raises(NoContact, match="no surface within 20 mm: move the tool closer"):
        cell.tap()


@pytest.mark.parametrize("target_m", [[0.3, 0.0, 0.81], [300.0, 0.0, 300.0]], ids=["0.51 m away", "mm as m"])
def test_a_move_farther_than_a_ur_move_may_go_is_refused_and_nothing_moves(fixture, target_m):
    """As a UR's move program: the demo meets the same 0.5 m bound as the arm."""
    cell = SimulatedCell.with_fixture(fixture, seed=3, pace_s=1.0)
    cell.connect()
    cell.move_linear(make_transform(np.eye(3), [0.3, 0.0, 0.3]), 0.25)
    before = cell.base_T_tcp()
    started = time.monotonic()
    with pytest.raises(RobotError, match="farther than the 500 mm one move may go, so the robot did not move"):
        cell.move_linear(make_transform(np.eye(3), target_m), 0.25)
    assert time.monotonic() - started < 0.5  # refused before the motion's time, never shown as moving
    np.testing.assert_allclose(cell.base_T_tcp()[:3, 3], before[:3, 3], atol=1e-3)  # readings carry FK noise


def test_a_move_into_the_fixture_or_the_table_goes_back_to_where_it_began(fixture):
    """As fixwizard's move program on a UR: blocked at the force limit, back at the start, no stop to unlock."""
    cell = SimulatedCell.with_fixture(fixture, seed=3, base_T_cad=make_transform(np.eye(3), [0.4, 0.0, 0.0]),
                                      tcp_p_tip_m=np.array([0.0, 0.0, 0.1]), fk_error_bound_m=0.0)
    cell.connect()
    down = Rotation.from_euler("x", 180, degrees=True)
    above = make_transform(down, [0.41, 0.01, 0.15])  # the ball 50 mm above the 10 mm thick plate
    cell.move_linear(above)
    for into in (make_transform(down, [0.41, 0.01, 0.105]),  # the ball 5 mm deep into the plate
                 make_transform(down, [0.3, 0.0, 0.1])):  # beside the plate, into the table
        with pytest.raises(MoveBlocked, match=r"^the arm met something on its way \(50 N\), stopped and went back"):
            cell.move_linear(into)
        np.testing.assert_allclose(cell.base_T_tcp(), above, atol=1e-12)
        assert not cell.status().protective_stop
    cell.move_linear(make_transform(down, [0.41, 0.01, 0.12]))  # free: the ball 8.5 mm above the plate


def test_tap_never_reaches_beyond_its_travel(cell):
    cell.place_tip_near("table", np.random.default_rng(6))
    travel = cell.tap().travel_m
    assert 0.005 <= travel <= 0.010  # the hover height
    with pytest.raises(NoContact, match="no surface within"):
        cell.tap(max_travel_m=travel - 0.001)
    assert cell.tap(max_travel_m=travel + 1e-4).travel_m == pytest.approx(travel, abs=1e-9)


@pytest.mark.parametrize("travel, speed, force, shown", [(0.1, 0.01, 10.0, "tap travel of 100 mm"),
                                                         (0.02, 0.5, 10.0, "tap speed of 500 mm/s"),
                                                         (0.02, 0.0, 10.0, "tap speed of 0 mm/s"),
                                                         (0.02, 0.01, 500.0, "tap force limit of 500 N")])
def test_tap_outside_the_safe_limits_is_refused(cell, travel, speed, force, shown):
    with pytest.raises(RobotError, match=f"{shown} is outside the safe range"):
        cell.tap(max_travel_m=travel, speed_m_s=speed, force_limit_n=force)


@pytest.mark.parametrize("fault, error, advice, blocked, recover", [
    ("protective_stop_during_tap", ProtectiveStop, "unlock the protective stop on the teach pendant, then retry",
     lambda status: status.protective_stop, SimulatedCell.unlock),
    ("connection_loss", ConnectionLost, "check that the robot is powered on .* then reconnect",
     lambda status: not status.connected, SimulatedCell.connect)])
def test_fault_during_a_tap_blocks_the_cell_until_recovered(cell, fault, error, advice, blocked, recover):
    cell.place_tip_near("table", np.random.default_rng(7))
    cell.inject_fault(fault)
    with pytest.raises(error, match=advice):
        cell.tap()
    assert blocked(cell.status())
    with pytest.raises(error):
        cell.tap()
    recover(cell)
    assert not blocked(cell.status())
    assert cell.tap().travel_m > 0


def test_no_surface_fault_raises_no_contact_once(cell):
    cell.place_tip_near("fixture", np.random.default_rng(9))
    cell.inject_fault("no_surface")
    with pytest.raises(NoContact, match="move the tool closer to the fixture and retry"):
        cell.tap()
    assert cell.tap().travel_m > 0


def test_freedrive_blocks_robot_motion_but_not_the_operators_hands(cell):
    cell.freedrive(True)
    assert cell.status().mode == "freedrive"
    with pytest.raises(RobotError, match="turn freedrive off"):
        cell.tap()
    before = cell.base_T_tcp()
    SimulatedHands(cell).pivot(1)
    assert not np.allclose(cell.base_T_tcp()[:3, :3], before[:3, :3])
    cell.freedrive(False)


def test_reported_pose_errs_within_the_bound(cell):
    cell.place_tip_near("table", np.random.default_rng(10))
    poses = np.array([cell.base_T_tcp() for _ in range(200)])
    spread = np.linalg.norm(poses[:, :3, 3] - poses[:, :3, 3].mean(axis=0), axis=1)
    assert np.all(spread <= 2 * FK_BOUND_M)
    assert np.ptp(poses[:, :3, 3], axis=0).max() > 0  # a real error, not a constant offset


def test_status_and_pose_are_safe_from_another_thread(cell):
    errors: list[BaseException] = []
    done = threading.Event()

    def poll() -> None:
        try:
            while not done.is_set():
                assert cell.status().connected
                assert cell.base_T_tcp().shape == (4, 4)
        except BaseException as error:  # noqa: BLE001 - reported to the main thread
            errors.append(error)

    pollers = [threading.Thread(target=poll) for _ in range(2)]
    for poller in pollers:
        poller.start()
    try:
        centres = tap_centres(cell, "table", 10, seed=11)
    finally:
        done.set()
        for poller in pollers:
            poller.join()
    assert not errors
    assert np.all(np.abs(centres[:, 2] - cell.truth.ball_diameter_m / 2.0) <= FK_BOUND_M + CONTACT_TOLERANCE_M)
