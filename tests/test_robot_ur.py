"""The UR cell (``fixwizard.robot.ur``) driving the real ur_rtde client against a loopback controller: the
control script it uploads is the one the loopback emulates, taps record the contact the controller produced,
and every fault (protective stop, emergency stop, remote control off, lost link) raises its typed error
with a way out. The loopback listens on the controller's fixed ports, so these tests cannot run in parallel."""

import hashlib
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from ur_loopback import LoopbackProcess
from ur_loopback.arm import SURFACE_STIFFNESS_N_M
from ur_loopback.control_program import (
    END_TEACH_MODE,
    FORCE_MODE,
    FORCE_MODE_STOP,
    MOVEL,
    SET_TCP,
    SET_WATCHDOG,
    TEACH_MODE,
    ZERO_FT_SENSOR,
)

from fixwizard.geometry.se3 import make_transform
from fixwizard.robot import (
    ConnectionLost,
    EmergencyStop,
    NoContact,
    NotInRemoteControl,
    ProtectiveStop,
    Robot,
    RobotError,
)
from fixwizard.robot.ur import URRobot

# any loopback address works; set UR_LOOPBACK_HOST=127.0.0.2 to test beside something holding 127.0.0.1's ports
HOST = os.environ.get("UR_LOOPBACK_HOST", "127.0.0.1")
# sha256 of the control script ur_rtde 1.6.5 uploads to a 5.15 controller; the loopback emulates its command
# numbers, so a ur_rtde upgrade that changes the script must fail here first
CONTROL_SCRIPT_SHA256 = "596761a93dfb175355b265245f9b94f8807528bf7ff85a654a61448f82ae8bf8"
UNLOCK_DELAY_S = 1.0  # the loopback's "5 s after the stop" rule, shortened
TIP_OFFSET_M = 0.1  # the loopback's ball tip on the flange z axis
FAST_TAP = {"speed_m_s": 0.02}


def flange_above_surface(hover_m: float) -> np.ndarray:
    """Flange pose with the tool pointing straight down and the tip ``hover_m`` above the surface (z = 0)."""
    return make_transform(Rotation.from_euler("x", np.pi), [0.4, -0.1, TIP_OFFSET_M + hover_m])


@pytest.fixture(scope="module")
def loopback():
    process = LoopbackProcess()
    yield process
    process.close()


@pytest.fixture
def start_controller(loopback):
    """Start a loopback controller (8 mm hover unless told otherwise); closed after the test."""
    controllers = []

    def start(**options):
        options.setdefault("unlock_delay_s", UNLOCK_DELAY_S)
        options.setdefault("host", HOST)
        controllers.append(loopback.start_controller(**options))
        return controllers[-1]

    yield start
    for controller in controllers:
        controller.close()


@pytest.fixture
def controller(start_controller):
    return start_controller()


@pytest.fixture
def robot(controller):
    robot = URRobot(HOST)
    robot.connect()
    yield robot
    robot.close()


def wait_until(condition, timeout_s: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


# --- connecting ---


def test_the_ur_cell_is_a_robot():
    assert isinstance(URRobot(HOST), Robot)


def test_connect_uploads_the_control_script_the_loopback_emulates(robot, controller):
    (script,) = controller.uploaded_scripts()
    assert hashlib.sha256(script.encode()).hexdigest() == CONTROL_SCRIPT_SHA256
    assert controller.program_running()
    status = robot.status()
    assert status.connected and status.program_running and status.mode == "ready"


def test_connect_zeroes_the_tcp_offset_so_poses_are_the_flange(start_controller):
    controller = start_controller(tcp_offset=[0.0, 0.0, 0.05, 0.0, 0.0, 0.3])
    robot = URRobot(HOST)
    robot.connect()
    try:
        np.testing.assert_allclose(robot.base_T_tcp(), controller.flange_pose(), atol=1e-9)
        assert controller.commands()[0] == SET_TCP
    finally:
        robot.close()


def test_connect_sets_the_watchdog_and_keeps_it_fed(robot, controller):
    assert SET_WATCHDOG in controller.commands()
    assert controller.watchdog_frequency_hz() == robot.watchdog_hz
    time.sleep(3.0 / robot.watchdog_hz)  # three watchdog periods without any command
    assert controller.watchdog_trips() == 0
    assert controller.program_running()


def test_the_watchdog_stops_the_robot_when_the_pc_freezes(controller):
    """A second process connects and is then frozen (as a hung PC or a dead SSH session): its sockets stay
    open but it sends nothing, so the controller's watchdog ends the control program."""
    program = f"from fixwizard.robot.ur import URRobot\nURRobot({HOST!r}).connect()\nprint('connected', flush=True)\n" \
              "import time\ntime.sleep(60)\n"
    child = subprocess.Popen([sys.executable, "-c", program], stdout=subprocess.PIPE, text=True)
    try:
        assert "connected" in child.stdout.readline()
        assert controller.program_running()
        os.kill(child.pid, signal.SIGSTOP)
        assert wait_until(lambda: not controller.program_running(), timeout_s=1.0)
        assert controller.watchdog_trips() == 1
    finally:
        child.kill()
        child.wait()


def test_connect_refuses_a_robot_in_local_control(start_controller):
    controller = start_controller()
    controller.set_remote_control(False)
    with pytest.raises(NotInRemoteControl, match="switch it to remote control on the teach pendant"):
        URRobot(HOST).connect()
    assert controller.uploaded_scripts() == []


def test_connect_to_nothing_raises_connection_lost():
    with pytest.raises(ConnectionLost, match="check that the robot is powered on"):
        URRobot(HOST).connect()


# --- freedrive ---


def test_freedrive_lets_the_operator_move_the_arm_and_blocks_motion(robot, controller):
    robot.freedrive(True)
    assert controller.in_freedrive()
    assert robot.status().mode == "freedrive"
    moved = flange_above_surface(0.02) @ make_transform(Rotation.from_euler("z", 0.2), [0.01, 0.0, 0.0])
    controller.move_by_hand(moved)
    assert wait_until(lambda: np.allclose(robot.base_T_tcp(), moved, atol=1e-9))
    with pytest.raises(RobotError, match="turn freedrive off"):
        robot.tap()
    robot.freedrive(False)
    assert not controller.in_freedrive()
    assert controller.commands()[-2:] == [TEACH_MODE, END_TEACH_MODE]
    assert robot.status().mode == "ready"


# --- tapping ---


def test_a_tap_records_the_contact_pose_the_controller_produced(robot, controller):
    base_T_start = robot.base_T_tcp()
    result = robot.tap(max_travel_m=0.02, speed_m_s=0.01, force_limit_n=10.0)
    (base_T_contact,) = controller.contact_poses()
    np.testing.assert_allclose(result.base_T_tcp_contact, base_T_contact, atol=2e-6)
    # the tip started 8 mm above the surface and pressed it in until the force reached the limit
    assert result.travel_m == pytest.approx(0.008 + 10.0 / SURFACE_STIFFNESS_N_M, abs=5e-5)
    assert result.peak_force_n == pytest.approx(10.0, rel=0.05)
    assert 0.0 < result.settle_s < 1.0
    np.testing.assert_allclose(controller.flange_pose(), base_T_start, atol=1e-6)  # retracted
    commands = controller.commands()
    assert commands.index(ZERO_FT_SENSOR) < commands.index(FORCE_MODE) < commands.index(FORCE_MODE_STOP) \
        < len(commands) - 1 - commands[::-1].index(MOVEL)
    assert not controller.zeroed_in_contact()
    assert controller.unhandled_commands() == []


def test_a_tap_refuses_to_zero_the_sensor_while_the_tool_touches(start_controller):
    start_controller(base_T_flange=flange_above_surface(-0.0004))  # pressed 0.4 mm into the surface
    robot = URRobot(HOST)
    robot.connect()
    try:
        with pytest.raises(RobotError, match="already pushes on something"):
            robot.tap()
    finally:
        robot.close()


def test_a_tap_that_finds_nothing_stops_at_its_travel_and_retracts(start_controller):
    controller = start_controller(base_T_flange=flange_above_surface(0.03))
    robot = URRobot(HOST)
    robot.connect()
    try:
        base_T_start = robot.base_T_tcp()
        with pytest.raises(NoContact, match="no surface within 10 mm: move the tool closer"):
            robot.tap(max_travel_m=0.01, **FAST_TAP)
        assert FORCE_MODE_STOP in controller.commands()
        np.testing.assert_allclose(controller.flange_pose(), base_T_start, atol=1e-6)
    finally:
        robot.close()


@pytest.mark.parametrize("travel, speed, force, shown", [(0.1, 0.01, 10.0, "tap travel of 100 mm"),
                                                         (0.02, 0.5, 10.0, "tap speed of 500 mm/s"),
                                                         (0.02, 0.01, 500.0, "tap force limit of 500 N")])
def test_a_tap_outside_the_safe_limits_is_refused_before_anything_else(travel, speed, force, shown):
    with pytest.raises(RobotError, match=f"{shown} is outside the safe range"):
        URRobot(HOST).tap(max_travel_m=travel, speed_m_s=speed, force_limit_n=force)  # not even connected


def test_move_linear_moves_the_flange_to_the_target(robot, controller):
    target = flange_above_surface(0.02) @ make_transform(Rotation.from_euler("y", 0.1), [0.01, -0.02, 0.0])
    robot.move_linear(target, speed_m_s=0.1)
    np.testing.assert_allclose(controller.flange_pose(), target, atol=1e-6)
    np.testing.assert_allclose(robot.base_T_tcp(), target, atol=1e-6)
    with pytest.raises(RobotError, match="linear speed of 1000 mm/s is outside the safe range"):
        robot.move_linear(target, speed_m_s=1.0)


def test_stop_from_another_thread_ends_a_tap(start_controller):
    controller = start_controller(base_T_flange=flange_above_surface(0.04))
    robot = URRobot(HOST)
    robot.connect()
    errors = []

    def tap() -> None:
        try:
            robot.tap(max_travel_m=0.05, speed_m_s=0.01)
        except RobotError as error:
            errors.append(error)

    tapping = threading.Thread(target=tap)
    try:
        tapping.start()
        assert wait_until(lambda: robot.status().mode == "moving")
        time.sleep(0.2)
        started = time.monotonic()
        robot.stop()
        tapping.join(2.0)
        assert time.monotonic() - started < 1.0
        assert len(errors) == 1 and "stopped on request" in str(errors[0])
        assert FORCE_MODE_STOP in controller.commands()
        stopped_at = controller.flange_pose()
        time.sleep(0.1)
        np.testing.assert_allclose(controller.flange_pose(), stopped_at, atol=1e-9)
    finally:
        tapping.join()
        robot.close()


def test_status_and_pose_are_safe_from_another_thread_during_taps(robot):
    errors: list[BaseException] = []
    done = threading.Event()

    def poll() -> None:
        try:
            while not done.is_set():
                assert robot.status().connected
                assert robot.base_T_tcp().shape == (4, 4)
        except BaseException as error:  # noqa: BLE001 - reported to the main thread
            errors.append(error)

    poller = threading.Thread(target=poll)
    poller.start()
    try:
        travels = [robot.tap(**FAST_TAP).travel_m for _ in range(2)]
    finally:
        done.set()
        poller.join()
    assert not errors
    assert travels == pytest.approx([travels[0]] * 2, abs=5e-5)


# --- faults ---


def test_protective_stop_during_a_tap_blocks_until_unlocked_on_the_pendant(robot, controller):
    controller.when("contact", "protective_stop")
    with pytest.raises(ProtectiveStop, match="unlock the protective stop on the teach pendant") as raised:
        robot.tap(**FAST_TAP)
    assert not hasattr(raised.value, "tap_result")  # stopped before the contact was recorded
    status = robot.status()
    assert status.protective_stop and not status.program_running and status.mode == "protective stop"
    with pytest.raises(ProtectiveStop, match="re-uploads its control script"):
        robot.tap(**FAST_TAP)
    controller.unlock_on_pendant()
    assert wait_until(lambda: not robot.status().protective_stop)
    result = robot.tap(**FAST_TAP)  # fixwizard re-uploaded its control script
    assert len(controller.uploaded_scripts()) == 2
    np.testing.assert_allclose(result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)


def test_protective_stop_while_retracting_keeps_the_recorded_contact(robot, controller):
    base_T_start = robot.base_T_tcp()
    earlier = robot.tap(**FAST_TAP)
    controller.when("movel", "protective_stop")
    with pytest.raises(ProtectiveStop, match="during retracting after the tap") as raised:
        robot.tap(**FAST_TAP)
    np.testing.assert_allclose(raised.value.tap_result.base_T_tcp_contact, controller.contact_poses()[-1],
                               atol=2e-6)
    np.testing.assert_allclose(raised.value.tap_result.base_T_tcp_contact, earlier.base_T_tcp_contact, atol=2e-5)
    with pytest.raises(RobotError, match="did not unlock the protective stop .*Cannot unlock protective stop "
                                         "until 5s after occurrence"):
        robot.unlock_protective_stop()
    time.sleep(UNLOCK_DELAY_S)
    robot.unlock_protective_stop()
    assert not robot.status().protective_stop
    assert controller.program_running()
    with pytest.raises(RobotError, match="already pushes on something"):  # the stop left the tool pressed down
        robot.tap(**FAST_TAP)
    robot.move_linear(base_T_start)
    assert robot.tap(**FAST_TAP).travel_m == pytest.approx(earlier.travel_m, abs=5e-5)


def test_emergency_stop_raises_until_released_and_powered_on(robot, controller):
    controller.emergency_stop()
    assert wait_until(lambda: robot.status().emergency_stop)
    assert robot.status().mode == "emergency stop"
    with pytest.raises(EmergencyStop, match="release the emergency stop, power on"):
        robot.tap(**FAST_TAP)
    controller.release_emergency_stop()
    assert wait_until(lambda: robot.status().mode == "powered off")
    with pytest.raises(RobotError, match="the arm is powered off.*: power it on and release the brakes"):
        robot.tap(**FAST_TAP)
    controller.power_on()
    assert wait_until(lambda: robot.status().mode == "control script stopped")
    assert robot.tap(**FAST_TAP).travel_m > 0.008


def test_remote_control_switched_off_while_connected(robot, controller):
    controller.set_remote_control(False)  # which also stops the program
    assert wait_until(lambda: robot.status().mode == "control script stopped")
    with pytest.raises(NotInRemoteControl, match="switch it to remote control"):
        robot.tap(**FAST_TAP)
    assert len(controller.uploaded_scripts()) == 1  # no upload while in local control
    controller.set_remote_control(True)
    assert robot.tap(**FAST_TAP).travel_m > 0.008


def test_connection_dropped_mid_tap_raises_and_reconnect_works(robot, controller):
    base_T_start = robot.base_T_tcp()
    controller.when("force_mode", "go_offline")
    started = time.monotonic()
    with pytest.raises(ConnectionLost, match="during the tap .*robot stops by itself.*check that the robot is "
                                             "powered on and the network cable is plugged in, then reconnect"):
        robot.tap(**FAST_TAP)
    assert time.monotonic() - started < 3.0
    assert not robot.status().connected
    assert wait_until(lambda: controller.watchdog_trips() == 1)  # the controller stopped the arm by itself
    with pytest.raises(ConnectionLost):
        robot.tap(**FAST_TAP)
    controller.go_online()
    robot.connect()
    assert robot.status().connected
    robot.move_linear(base_T_start)  # the arm went on in force mode until the watchdog stopped it
    result = robot.tap(**FAST_TAP)
    np.testing.assert_allclose(result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)


# --- status ---


def test_status_maps_the_controller_state(robot, controller):
    def shows(*expected) -> bool:
        return wait_until(lambda: tuple(vars(robot.status()).values()) == expected)

    assert shows(True, False, False, True, "ready")
    controller.protective_stop()
    assert shows(True, True, False, False, "protective stop")
    controller.unlock_on_pendant()
    assert shows(True, False, False, False, "control script stopped")
    controller.emergency_stop()
    assert shows(True, False, True, False, "emergency stop")
    controller.release_emergency_stop()
    assert shows(True, False, False, False, "powered off")
    controller.go_offline()
    assert shows(False, False, False, False, "disconnected")
