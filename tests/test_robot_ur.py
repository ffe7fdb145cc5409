"""The UR cell (``fixwizard.robot.ur``) driving the real ur_rtde client, in its own link process, against a
loopback controller that runs twins of fixwizard's URScript programs: taps record the contact the controller
produced, every motion runs on a program whose watchdog is armed, the tap's limits hold on the controller
when the PC stalls, and every fault (protective, emergency and safeguard stops, local control, a dropped,
frozen or silent link, a crashed or stalled link process) raises its typed error with a way out, without
crashing or freezing this process and without motion after the error. The loopback listens on the
controller's fixed ports at a loopback address of this run's own, so parallel runs do not clash."""

import multiprocessing
import os
import random
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot import (
    ConnectionLost,
    EmergencyStop,
    MotionStopped,
    MoveBlocked,
    NoContact,
    NotInRemoteControl,
    ProtectiveStop,
    Robot,
    RobotError,
)
from fixwizard.robot.base import MOVE_FORCE_LIMIT_N, TapResult
from fixwizard.robot.ur import CONNECT_DEADLINE_S, URRobot
from fixwizard.robot.ur_link import PROGRAM_START_TIMEOUT_S, _tells_remote_control
from fixwizard.robot.ur_script import (
    BACK_OFF_M,
    GO_TIMEOUT_S,
    KICK_REGISTER,
    MAX_MOVE_TRAVEL_M,
    PHASE_BACK_OFF_STOPPED,
    PHASE_BACKING_OFF,
    PHASE_NO_GO,
    PHASE_REGISTER,
    PHASE_RETURN_BLOCKED,
    PHASE_TOO_FAR,
    REQUEST_GO,
    REQUEST_REGISTER,
    REQUEST_STOP,
    freedrive_program,
    move_program,
    request_value,
    setup_program,
    tap_program,
)
from fixwizard.robot.ur_state import LOST_REASON_BYTES, ControllerState, SharedState
from fixwizard.tui.tapping import tap_and_record
from fixwizard.workflow.session import SamplingSession, Tap
from ur_loopback import TIP_OFFSET_M, flange_above_surface, private_loopback_host
from ur_loopback.arm import COLLISION_FORCE_N, FIXTURE_STIFFNESS_N_M, SURFACE_STIFFNESS_N_M
from ur_loopback.link_faults import (
    serve_whose_first_run_id_is_the_last_one_run,
    serve_whose_writes_are_lost_once_connected,
    serve_with_a_bug_in_the_move,
    stall_link,
)
from ur_loopback.programs import unknown_functions, variables_named_like_functions

HOST = private_loopback_host()
# drop/reconnect cycles of the acceptance test: the 100 in CI (about 3 min), 20 on a developer's run
DROP_CYCLES = int(os.environ.get("UR_DROP_CYCLES", "100" if os.environ.get("CI") else "20"))
# cycles of random faults mid-motion: 30 in CI (about 1 min), 12 on a developer's run
FAULT_CYCLES = int(os.environ.get("UR_FAULT_CYCLES", "30" if os.environ.get("CI") else "12"))
UNLOCK_DELAY_S = 1.0  # the loopback's "5 s after the stop" rule, shortened
FAST_TAP = {"speed_m_s": 0.02}
TRAVEL_SLACK_M = 0.001  # the bound on travel past the limit when the PC stalls
REBOOT_S = 1.0  # how long a rebooting loopback controller answers nothing (a real one: about a minute)


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
        if trips := controller.watchdog_trips():  # shown with a failure: a stalled test machine trips it too
            print(f"the loopback controller's watchdog stopped {trips} program(s) in this test")
        controller.close()


@pytest.fixture
def controller(start_controller):
    return start_controller()


@pytest.fixture
def connect():
    """Connect a URRobot to the loopback; every one is closed after the test."""
    robots = []

    def make(**options) -> URRobot:
        robot = URRobot(HOST, **options)
        robots.append(robot)
        robot.connect()
        return robot

    yield make
    for robot in robots:
        robot.close()


@pytest.fixture
def robot(controller, connect):
    return connect()


def wait_until(condition, timeout_s: float = 2.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def assert_arm_stands(controller, for_s: float = 0.3) -> None:
    """No program runs and the flange does not move for ``for_s`` seconds."""
    before = controller.flange_pose()
    assert not controller.program_running()
    time.sleep(for_s)
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


class MotionInThread:
    """A robot call in a worker thread, as the wizard runs it; ``outcome`` is what it returned or its RobotError and
    ``pose_at_outcome`` the controller's flange pose the moment it came back."""

    def __init__(self, motion, controller) -> None:
        self.outcome = self.pose_at_outcome = None
        self._thread = threading.Thread(target=self._run, args=(motion, controller))
        self._thread.start()

    def _run(self, motion, controller) -> None:
        try:
            self.outcome = motion()
        except RobotError as error:
            self.outcome = error
        self.pose_at_outcome = controller.flange_pose()

    def join(self, timeout_s: float):
        self._thread.join(timeout_s)
        assert not self._thread.is_alive(), f"the motion did not come back within {timeout_s} s"
        return self.outcome


class TapInThread(MotionInThread):
    """``robot.tap(**tap)`` in a worker thread."""

    def __init__(self, robot: URRobot, controller, **tap) -> None:
        super().__init__(lambda: robot.tap(**tap), controller)


# --- the process boundary and the programs ---


def test_the_ur_cell_is_a_robot():
    assert isinstance(URRobot(HOST), Robot)


def test_ur_rtde_runs_only_in_the_link_process(robot):
    assert robot.link_pid not in (None, os.getpid())
    assert not {"rtde_receive", "rtde_io", "rtde_control", "dashboard_client"} & set(sys.modules)
    status = robot.status()
    assert status.connected and not status.program_running and status.mode == "ready"


@pytest.mark.parametrize("program", [
    tap_program(7, 2.0, 0.02, 0.01, 10.0), move_program(7, 2.0, [0.4, -0.1, 0.2, 3.14, 0.0, 0.0], 0.05),
    freedrive_program(7, 2.0)])
def test_every_program_arms_its_watchdog_before_anything_else(program):
    first_statement = program.splitlines()[2]
    assert first_statement == f'  rtde_set_watchdog("input_int_register_{KICK_REGISTER}", 2.0, "stop")'
    assert program.index("rtde_set_watchdog") < program.index("write_output_integer_register")
    for motion in ("movel(", "teach_mode(", "zero_ftsensor("):
        assert motion not in program or program.index("rtde_set_watchdog") < program.index(motion)


@pytest.mark.parametrize("program", [
    tap_program(7, 2.0, 0.02, 0.01, 10.0), move_program(7, 2.0, [0.4, -0.1, 0.2, 3.14, 0.0, 0.0], 0.05),
    freedrive_program(7, 2.0), setup_program(7, 2.0)])
def test_every_program_calls_only_functions_urscript_has(program):
    """A UR controller refuses to compile a program calling a function it lacks (the tap called max()); no variable
    bears a URScript function's name (the way back's force = ... beside URScript's force()), which the manual
    leaves undefined."""
    assert unknown_functions(program) == set()
    assert variables_named_like_functions(program) == set()


@pytest.mark.parametrize("write", [lambda: tap_program(7, 2.0, 1.0, 0.01, 10.0),
                                   lambda: tap_program(7, 2.0, 0.02, 0.5, 10.0),
                                   lambda: tap_program(7, 2.0, 0.02, 0.01, 1e3),
                                   lambda: tap_program(7, 2.0, 0.02, float("nan"), 10.0),
                                   lambda: move_program(7, 2.0, [0.4, -0.1, 0.2, 3.14, 0.0, 0.0], 2.0),
                                   lambda: move_program(7, 2.0, [0.4, float("nan"), 0.2, 3.14, 0.0, 0.0], 0.05),
                                   lambda: move_program(7, 2.0, [0.4, -0.1, 0.2], 0.05),
                                   lambda: freedrive_program(7, 0.1),
                                   lambda: setup_program(7, float("nan"))])
def test_no_program_is_written_beyond_the_safe_limits(write):
    """The last gate before the controller: whatever the link is asked (a caller that skipped the wizard's checks),
    no program with a tap, a speed or a watchdog beyond the safe ranges, or a target that is not a pose, is written."""
    with pytest.raises(RobotError, match="safe range|not a finite UR pose|watchdog of"):
        write()


def test_numbers_in_programs_are_written_without_exponents_and_read_back_equal():
    """Python writes a rotation vector's 1e-17 or a slow tap's 5e-05 with an exponent, for which URScript's manual
    has no form; every float is written positionally, the same value to the last bit."""
    target = [0.4, -1.2e-17, 0.2, 3.14, 2.5e-300, -0.0]
    programs = (tap_program(7, 2.0, 0.02, 5e-05, 10.0), move_program(7, 2.0, target, 1e-5))
    assert all(re.search(r"\d[eE][-+]?\d", program) is None for program in programs)
    written = re.search(r"global target = p\[(.*)\]", programs[1]).group(1).split(", ")
    assert [float(number) for number in written] == target
    assert "global speed_m_s = 0.00005" in programs[0]


def test_numpy_numbers_are_written_as_urscript_numbers():
    """A plan computed with numpy hands the programs numpy scalars (the tip calibration's tap travel): written as
    the numbers they are (repr wrote np.float64(0.0222), and the program was never sent)."""
    program = tap_program(np.int64(9), np.float64(2.0), np.float64(0.0222), np.float32(0.01), np.float64(10.0))
    assert "global run_id = 9" in program and "global max_travel_m = 0.0222" in program
    assert "global speed_m_s = 0.009999999776482582" in program and "np." not in program


def test_every_motion_runs_on_a_program_whose_watchdog_is_armed(robot, controller):
    robot.tap(**FAST_TAP)
    robot.move_linear(flange_above_surface(0.02))
    robot.freedrive(True)
    assert controller.watchdog_frequency_hz() == robot.watchdog_hz
    robot.freedrive(False)
    assert [name for name, _, _ in controller.programs()] == ["setup", "tap", "move", "freedrive"]
    assert {variable for _, _, variable in controller.programs()} == {f"input_int_register_{KICK_REGISTER}"}
    assert controller.unsafe_programs() == [] and controller.compile_errors() == []
    assert len({run_id for _, run_id, _ in controller.programs()}) == 4


def test_connect_zeroes_the_tcp_offset_so_poses_are_the_flange(start_controller, connect):
    controller = start_controller(tcp_offset=[0.0, 0.0, 0.05, 0.0, 0.0, 0.3])
    robot = connect()
    np.testing.assert_allclose(robot.base_T_tcp(), controller.flange_pose(), atol=1e-9)


def test_the_watchdog_stops_the_arm_when_the_link_process_freezes(robot, controller):
    """The link process is stopped (as a hung PC): it sends nothing, so the controller's watchdog ends the
    freedrive program; the wizard's process sees the link lost within a second and can reconnect."""
    robot.freedrive(True)
    os.kill(robot.link_pid, signal.SIGSTOP)
    assert wait_until(lambda: not controller.program_running(), timeout_s=2.0)
    assert controller.watchdog_trips() == 1
    assert wait_until(lambda: not robot.status().connected, timeout_s=1.0)
    with pytest.raises(ConnectionLost, match="no data from the robot"):
        robot.freedrive(False)
    robot.connect()
    assert robot.status().mode == "ready"


def test_connect_refuses_a_robot_in_local_control(start_controller):
    controller = start_controller()
    controller.set_remote_control(False)
    with pytest.raises(NotInRemoteControl, match="switch it to remote control on the teach pendant"):
        URRobot(HOST).connect()
    assert controller.uploaded_scripts() == []


def test_a_refused_connect_leaves_no_half_made_link(start_controller):
    """A connect the controller refuses (local control) left its link process as the robot's link, never connected:
    every call after it said "fixwizard is still connecting to the robot ...: wait until the status line says it is
    connected", which it never would. It says fixwizard is not connected (reconnect), and no link process is left."""
    controller = start_controller()
    controller.set_remote_control(False)
    robot = URRobot(HOST)
    try:
        with pytest.raises(NotInRemoteControl):
            robot.connect()
        assert robot.link_pid is None
        controller.set_remote_control(True)
        with pytest.raises(ConnectionLost, match="fixwizard is not connected to the robot at .* before the tap: "
                                                 "reconnect$"):
            robot.tap(**FAST_TAP)
        robot.connect()
        assert robot.tap(**FAST_TAP).travel_m > 0.008
    finally:
        robot.close()


def test_a_cb3_whose_dashboard_cannot_tell_remote_control_connects_and_taps(start_controller, connect):
    """A CB3 (PolyScope 3) has no local or remote control, and its dashboard no "is in remote control" (PolyScope
    5.6 on): ur_rtde then says False without asking, and fixwizard refused every CB3 with "switch it to remote
    control", a switch the pendant does not have. Its programs run as an e-Series' do."""
    controller = start_controller(cb3=True)
    robot = connect()
    assert robot.tap(**FAST_TAP).travel_m > 0.008
    assert [name for name, _, _ in controller.programs()] == ["setup", "tap"]
    assert "is in remote control" not in controller.dashboard_commands()


@pytest.mark.slow
def test_an_e_series_before_5_6_in_local_control_is_named_as_a_cause_when_no_program_starts(start_controller,
                                                                                             connect):
    """PolyScope 5.0-5.5 has local control but its dashboard cannot be asked about it (ur_rtde says False without
    asking, so the link takes it to be in remote control); in local control the controller takes a program and runs
    none. The error named a program loaded on the pendant and a URCap, never the switch the operator must press."""
    controller = start_controller(polyscope="URSoftware 5.4.1.60000 (Jun 11 2019)")
    controller.set_remote_control(False)
    with pytest.raises(RobotError, match="took fixwizard's program on port 30003 but did not start it .* a URCap "
                                         "holding the arm, or the pendant in local control, which PolyScope before "
                                         "5.6 cannot tell fixwizard: switch it to remote control\\), then retry$"):
        URRobot(HOST).connect()
    assert "is in remote control" not in controller.dashboard_commands()
    controller.set_remote_control(True)
    assert connect().tap(**FAST_TAP).travel_m > 0.008


@pytest.mark.parametrize("version, asked", [("URSoftware 5.15.0.1234 (Nov 11 2023)", True),
                                            ("URSoftware 5.6.0.90886 (Dec 11 2019)", True),
                                            ("URSoftware 5.5.1.82256 (Oct 28 2019)", False),
                                            ("URSoftware 3.15.7.106331 (Mar 28 2022)", False),
                                            ("URSoftware 10.7.0.1234 (Jan 1 2025)", False), ("", False)])
def test_remote_control_is_asked_only_where_ur_rtde_asks_the_dashboard(version, asked):
    """ur_rtde's isInRemoteControl asks a PolyScope 5.6 to 5.x and says False without asking any other: the link
    must not take that False for local control (a PolyScope 10 was refused so)."""
    assert _tells_remote_control(version) == asked


def test_connect_to_nothing_names_the_port():
    started = time.monotonic()
    with pytest.raises(ConnectionLost, match=f"^cannot connect to the robot at {HOST}: port 29999 does not "
                                             "accept connections .*: check that the robot is powered on and "
                                             "reachable, then reconnect$"):
        URRobot(HOST).connect()
    assert time.monotonic() - started < 5.0


@pytest.mark.slow
@pytest.mark.parametrize("port, named", [("rtde", "the RTDE data stream \\(port 30004\\)"),
                                         ("dashboard", "the dashboard server \\(port 29999\\)")])
def test_connect_to_a_silent_port_fails_within_its_deadline_and_names_it(start_controller, port, named):
    controller = start_controller()
    controller.silence(port)
    robot = URRobot(HOST)
    started = time.monotonic()
    with pytest.raises(ConnectionLost, match=f"{named}.* did not answer|did not answer within 10 s while "
                                             f"connecting while fixwizard was waiting for {named}"):
        robot.connect()
    assert time.monotonic() - started < 11.0  # the 10 s deadline (nothing was sent that could move the arm)
    assert robot.link_pid is None and not robot.status().connected


@pytest.mark.slow
def test_connect_to_a_silent_script_port_says_the_program_did_not_start(start_controller):
    controller = start_controller()
    controller.silence("script")
    started = time.monotonic()
    with pytest.raises(RobotError, match="took fixwizard's program on port 30003 but did not start it") as refused:
        URRobot(HOST).connect()
    assert time.monotonic() - started < 10.0
    assert "local control" not in str(refused.value)  # a PolyScope 5.15 is asked: it was in remote control


@pytest.mark.slow
def test_a_program_the_controller_starts_after_the_link_gave_up_on_it_ends_before_it_moves(robot, controller):
    """The controller starts the move after the link's start deadline (a busy controller, a late network): the
    error was shown, so the program must not move the arm (it did: the link kept kicking its watchdog)."""
    controller.delay_programs(PROGRAM_START_TIMEOUT_S + 0.5)
    before = controller.flange_pose()
    with pytest.raises(RobotError, match="took fixwizard's program on port 30003 but did not start it"):
        robot.move_linear(flange_above_surface(0.06))
    assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "move"])
    assert wait_until(lambda: not controller.program_running())
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


@pytest.mark.slow
def test_a_late_program_never_moves_even_once_the_next_command_replaced_its_stop_request(robot, controller):
    """The controller starts each program 4 s after it arrives. The first move is given up on at 3 s (its stop
    request written); the operator retries at once, and that command's request replaces the stop request before the
    late first program starts: the program still never moves, as it gets no go (it moved 52 mm before the go)."""
    controller.delay_programs(PROGRAM_START_TIMEOUT_S + 1.0)
    before = controller.flange_pose()
    for target in (flange_above_surface(0.06), flange_above_surface(0.04)):
        with pytest.raises(RobotError, match="took fixwizard's program on port 30003 but did not start it"):
            robot.move_linear(target)
    assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "move", "move"], 6.0)
    assert wait_until(lambda: not controller.program_running(), GO_TIMEOUT_S + 1.0)  # no go: each ends unmoved
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


def test_a_program_that_gets_no_go_ends_unmoved(robot, controller):
    """A program the link does not answer (it gave up on it, or it stalled) ends by itself after its timeout."""
    program = move_program(7, robot.watchdog_hz, [*flange_above_surface(0.03)[:3, 3], np.pi, 0.0, 0.0], 0.1)
    before = controller.flange_pose()
    with socket.create_connection((HOST, 30003)) as script_port:
        script_port.sendall(program.encode())
        assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "move"])
        started = time.monotonic()
        assert wait_until(lambda: not controller.program_running(), GO_TIMEOUT_S + 1.0)
    assert time.monotonic() - started > GO_TIMEOUT_S - 0.1
    assert controller.output_int(PHASE_REGISTER) == PHASE_NO_GO
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


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
    assert not controller.in_freedrive() and not controller.program_running()
    assert robot.status().mode == "ready"


# --- tapping and moving ---


def test_a_second_client_is_refused_and_starts_or_stops_nothing_on_the_arm(robot, controller, connect):
    """A second fixwizard connects while the first one's freedrive runs: the controller gives it no RTDE inputs
    (they are the first one's), so it cannot feed a watchdog or send a request; it sends no program and stops
    nothing. It was told to check that the robot is powered on and reachable, with ur_rtde's advice to disable
    fieldbus adapters, and its failure sent the dashboard's stop, which ended the first one's motion."""
    robot.freedrive(True)
    with pytest.raises(RobotError, match="^another client holds the RTDE inputs .*another fixwizard or program "
                                         "connected to this robot") as refused:
        connect()
    assert not isinstance(refused.value, ConnectionLost)
    time.sleep(0.5)
    assert [name for name, _, _ in controller.programs()] == ["setup", "freedrive"]
    assert controller.program_running() and "stop" not in controller.dashboard_commands()
    robot.freedrive(False)
    robot.move_linear(flange_above_surface(0.02))  # the first one goes on


def test_a_tap_records_the_contact_pose_the_controller_produced(robot, controller):
    base_T_start = robot.base_T_tcp()
    result = robot.tap(max_travel_m=0.02, speed_m_s=0.01, force_limit_n=10.0)
    (base_T_contact,) = controller.contact_poses()
    np.testing.assert_allclose(result.base_T_tcp_contact, base_T_contact, atol=2e-6)
    # the tip started 8 mm above the surface and pressed it in until the force reached the limit; the
    # controller stops within a cycle of the limit (a starved loopback cycle is up to 20 ms: 0.2 mm)
    assert 0.008 + 10.0 / SURFACE_STIFFNESS_N_M <= result.travel_m <= 0.008 + 10.0 / SURFACE_STIFFNESS_N_M + 2e-4
    assert result.travel_m == pytest.approx(controller.tap_travels()[0], abs=1e-6)
    assert 10.0 <= result.peak_force_n <= 10.0 + 2e-4 * SURFACE_STIFFNESS_N_M
    assert 0.1 <= result.settle_s < 1.0
    np.testing.assert_allclose(controller.flange_pose(), base_T_start, atol=1e-6)  # retracted
    assert not controller.zeroed_in_contact()
    assert_arm_stands(controller, 0.05)


def test_a_tap_on_a_fixture_the_controller_holds_stops_with_the_ball_on_its_face(start_controller, connect):
    """The loopback's fixture (as the UR monkey taps it): a block turned 30 degrees about x on the table, tapped
    along a face's normal tilted by 10 degrees; the contact leaves the ball on that face, pressed in by the force
    limit over the fixture's stiffness (plus a cycle's travel)."""
    block = trimesh.creation.box((0.1, 0.1, 0.1))
    base_T_cad = make_transform(Rotation.from_euler("x", 30, degrees=True), [0.4, -0.1, 0.1])
    ball_radius_m, hover_m = 0.0015, 0.006
    base_n_face = base_T_cad[:3, :3] @ [0.0, 0.0, 1.0]  # the top face, turned
    base_p_ball = transform_points(base_T_cad, [[0.01, 0.02, 0.05]])[0] + (ball_radius_m + hover_m) * base_n_face
    base_R_tool = Rotation.from_euler("y", 10, degrees=True) * \
        Rotation.align_vectors([-base_n_face], [[0.0, 0.0, 1.0]])[0]
    base_T_flange = make_transform(base_R_tool, base_p_ball - base_R_tool.apply([0.0, 0.0, TIP_OFFSET_M]))
    controller = start_controller(base_T_flange=base_T_flange, ball_radius_m=ball_radius_m,
                                  fixture=(np.asarray(block.vertices), np.asarray(block.faces), base_T_cad))
    result = connect().tap(max_travel_m=0.02, speed_m_s=0.01, force_limit_n=10.0)
    base_p_contact = transform_points(result.base_T_tcp_contact, [[0.0, 0.0, TIP_OFFSET_M]])[0]
    gap_m = float((base_p_contact - transform_points(base_T_cad, [[0.0, 0.0, 0.05]])[0]) @ base_n_face)
    pressed_m = 10.0 / FIXTURE_STIFFNESS_N_M  # the loopback's distances are float32's: 0.1 micrometre of slack
    assert ball_radius_m - pressed_m - 2e-4 <= gap_m <= ball_radius_m - pressed_m + 1e-7
    assert result.travel_m == pytest.approx(hover_m / np.cos(np.radians(10.0)), abs=3e-4)
    np.testing.assert_allclose(controller.flange_pose(), base_T_flange, atol=1e-6)  # retracted


def test_a_tap_refuses_to_zero_the_sensor_while_the_tool_touches(start_controller, connect):
    start_controller(base_T_flange=flange_above_surface(-0.0004))  # pressed 0.4 mm into the surface
    with pytest.raises(RobotError, match="already pushes on something"):
        connect().tap()


def test_a_tap_that_finds_nothing_stops_at_its_travel_and_retracts(start_controller, connect):
    controller = start_controller(base_T_flange=flange_above_surface(0.03))
    robot = connect()
    base_T_start = robot.base_T_tcp()
    with pytest.raises(NoContact, match="no surface within 10 mm: move the tool closer"):
        robot.tap(max_travel_m=0.01, **FAST_TAP)
    assert controller.tap_travels()[0] == pytest.approx(0.01, abs=1e-9)  # the movel's target is the limit
    np.testing.assert_allclose(controller.flange_pose(), base_T_start, atol=1e-6)


@pytest.mark.parametrize("travel, speed, force, shown", [(0.1, 0.01, 10.0, "tap travel of 100 mm"),
                                                         (0.02, 0.5, 10.0, "tap speed of 500 mm/s"),
                                                         (0.02, 0.01, 500.0, "tap force limit of 500 N"),
                                                         (float("nan"), 0.01, 10.0, "tap travel of nan mm"),
                                                         (0.02, float("inf"), 10.0, "tap speed of inf mm/s")])
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


def test_move_linear_refuses_a_target_beyond_one_move_s_travel(robot, controller):
    """A target 0.6 m off, or a pose in mm taken for m, is refused before anything is sent (the arm went there)."""
    far = flange_above_surface(0.02)
    far[0, 3] += 0.6
    in_mm = flange_above_surface(0.02)
    in_mm[:3, 3] *= 1e3
    for target, shown in ((far, "600"), (in_mm, "4[0-9]{5}")):
        started = time.monotonic()
        with pytest.raises(RobotError, match=f"^the move's target is {shown} mm from the flange, farther than the "
                                             "500 mm one move may go, so the robot did not move: bring the arm"):
            robot.move_linear(target)
        assert time.monotonic() - started < 0.5  # no program's start (seconds); room for a loaded machine
    assert [name for name, _, _ in controller.programs()] == ["setup"]
    assert_arm_stands(controller, 0.05)


def test_the_move_program_holds_its_travel_bound_on_the_controller(robot, controller):
    """The bound is the program's own, measured from where the flange stands when it runs: a move program
    with a far target (whatever the PC computed) ends without moving."""
    far = flange_above_surface(0.02)
    far[0, 3] += MAX_MOVE_TRAVEL_M + 0.01
    program = move_program(5, robot.watchdog_hz, [*far[:3, 3], np.pi, 0.0, 0.0], 0.25)
    assert program.index("point_dist(get_actual_tcp_pose(), target) > max_travel_m") < program.index("run motion()")
    before = controller.flange_pose()
    with socket.create_connection((HOST, 30003)) as script_port:
        script_port.sendall(program.encode())
        assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "move"])
        controller.write_input_int(REQUEST_REGISTER, request_value(5, REQUEST_GO))  # the link's go
        assert wait_until(lambda: not controller.program_running())
    assert controller.output_int(PHASE_REGISTER) == PHASE_TOO_FAR
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


def test_a_move_into_something_stops_at_its_force_limit_and_goes_back(start_controller, connect):
    """The tip 20 mm into the surface as the target: the move program stops where the contact force reaches its
    limit, far below the controller's protective stop, and takes the arm back to where the move began."""
    controller = start_controller(base_T_flange=flange_above_surface(0.01))
    robot = connect()
    before = controller.flange_pose()
    with pytest.raises(MoveBlocked, match=r"^the arm met something on its way \((5[0-9]|6[0-9]) N\), stopped and went "
                                          "back to where the move began: clear the path"):
        robot.move_linear(flange_above_surface(-0.02), speed_m_s=0.05)
    assert MOVE_FORCE_LIMIT_N <= controller.peak_contact_force_n() < COLLISION_FORCE_N
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-6)
    assert robot.status().mode == "ready"
    assert_arm_stands(controller)
    robot.move_linear(flange_above_surface(0.02), speed_m_s=0.05)  # nothing to unlock: the next move runs


def test_a_move_whose_way_back_meets_something_stops_there_and_backs_off(start_controller, connect):
    """The move is blocked by the surface; on its way back up, something has come over the arm 3 mm above the
    flange: the way back stops where the force has grown by the move's limit again, far below the controller's
    protective stop, and backs off half the way it came, so it presses neither on what it met nor on the
    surface."""
    controller = start_controller(base_T_flange=flange_above_surface(0.01))
    robot = connect()
    controller.when("blocked", "reach_over_the_arm", 0.003)
    with pytest.raises(RobotError, match=r"^the arm met something on its way back to where the move began "
                                         r"\((5[0-9]|6[0-9]) N\), stopped and backed off a few millimetres the way "
                                         "it came: look at what it met, turn freedrive on and move the arm clear"):
        robot.move_linear(flange_above_surface(-0.02), speed_m_s=0.05)
    assert controller.peak_contact_force_n() < MOVE_FORCE_LIMIT_N + 20.0
    assert controller.contact_force_n() == 0.0
    assert robot.status().mode == "ready"
    assert_arm_stands(controller)


def test_a_tap_is_saved_as_the_robot_reports_its_contact_while_the_ball_still_retracts(start_controller, connect,
                                                                                        tmp_path):
    """The wizard saved a tap once the retract had ended: killed meanwhile (kill -9, an SSH session lost with it), it
    kept nothing of a contact the arm had made. The contact now reaches the session as the retract starts (15 mm at
    50 mm/s: 0.3 s)."""
    controller = start_controller(base_T_flange=flange_above_surface(0.015))
    robot = connect()
    session = SamplingSession.create(tmp_path / "taps.jsonl", {"name": "plate"}, {"tcp_p_tip_m": [0.0, 0.0, 0.1]},
                                     robot="ur")
    start = controller.flange_pose()
    when_saved = []

    def record(contact: TapResult) -> Tap:
        tap = session.record_tap(contact.base_T_tcp_contact)
        when_saved.append((controller.program_running(), start[2, 3] - controller.flange_pose()[2, 3]))
        return tap

    tap = tap_and_record(robot, record, lambda: len(session.taps), threading.Event())
    ((retracting, below_start_m),) = when_saved
    assert retracting and below_start_m > 0.005, "the tap was saved only after its retract"
    assert session.taps == [tap]
    np.testing.assert_allclose(tap.base_T_tcp, controller.contact_poses()[-1], atol=2e-6)
    np.testing.assert_allclose(controller.flange_pose(), start, atol=1e-6)  # retracted all the same
    session.release()


def test_a_retract_that_meets_something_is_said_first_when_the_contact_could_not_be_saved(start_controller, connect):
    """A full disk refusing the contact and a retract that met something: the arm's fault is what the operator must
    read first (the disk's said after it); it was the disk's error alone."""
    controller = start_controller(base_T_flange=flange_above_surface(0.015))
    robot = connect()
    controller.when("settled", "reach_over_the_arm", 0.012)

    def full_disk(contact: TapResult) -> Tap:
        raise OSError(28, "No space left on device")

    with pytest.raises(RobotError, match="^the arm met something on its way back") as raised:
        tap_and_record(robot, full_disk, lambda: 0, threading.Event())
    notes = raised.value.__notes__
    assert notes[0] == "The contact could not be saved: [Errno 28] No space left on device"
    assert notes[1].startswith("Freedrive stays off after this")


def test_what_the_contact_s_receiver_raises_is_raised_once_the_tap_has_ended(robot, controller):
    """A full disk refusing the contact's record must not leave the link mid-tap: the tap retracts, then the error."""
    start = controller.flange_pose()

    def full_disk(contact: TapResult) -> None:
        raise OSError(28, "No space left on device")

    with pytest.raises(OSError, match="No space left on device"):
        robot.tap(**FAST_TAP, on_contact=full_disk)
    np.testing.assert_allclose(controller.flange_pose(), start, atol=1e-6)
    assert not controller.program_running()
    assert robot.tap(**FAST_TAP).travel_m > 0.008  # the link goes on


@pytest.mark.parametrize("clearance_m", [0.004, 0.012])
def test_a_tap_whose_retract_meets_something_backs_off_and_keeps_the_contact(start_controller, connect, clearance_m):
    """Something comes over the arm 4 or 12 mm above the flange while the tap stands in contact: the retract stops
    where the force has grown by the move's limit and backs off half the way it came, at most 5 mm, so nothing
    stays pressed (neither what it met nor the surface); the recorded contact is kept."""
    controller = start_controller(base_T_flange=flange_above_surface(0.02))
    robot = connect()
    controller.when("settled", "reach_over_the_arm", clearance_m)
    with pytest.raises(RobotError, match=r"^the arm met something on its way back to where the tap began "
                                         r"\((5[0-9]|6[0-9]) N\), stopped and backed off a few millimetres the way "
                                         "it came; the contact was recorded: look at") as raised:
        robot.tap(max_travel_m=0.03, **FAST_TAP)
    contact = controller.contact_poses()[-1]
    np.testing.assert_allclose(raised.value.tap_result.base_T_tcp_contact, contact, atol=2e-6)
    assert controller.peak_contact_force_n() < MOVE_FORCE_LIMIT_N + 20.0
    assert controller.contact_force_n() == 0.0
    above_contact_m = controller.flange_pose()[2, 3] - contact[2, 3]
    assert max(clearance_m / 2, clearance_m - BACK_OFF_M) <= above_contact_m < clearance_m
    assert robot.status().mode == "ready"
    assert_arm_stands(controller)



@pytest.mark.parametrize("stop", [False, True])
def test_the_move_program_reports_whether_its_back_off_ended_or_a_stop_cut_it_short(robot, controller, stop):
    """The move program, sent as the link sends it, is blocked by the surface and on its way back meets something 3 mm
    above the flange: it backs off and ends with PHASE_RETURN_BLOCKED, clear of what it met; a stop requested as its
    back-off starts stops it there, and it ends with PHASE_BACK_OFF_STOPPED (it said PHASE_RETURN_BLOCKED, as if
    clear), the arm still pressing on what it met."""
    run_id = 5
    target = flange_above_surface(-0.02)
    program = move_program(run_id, robot.watchdog_hz, [*target[:3, 3], np.pi, 0.0, 0.0], 0.05)
    back_off = program[program.index("def back_off_and_finish("):program.index("def retract_and_finish(")]
    assert back_off.index("PHASE_BACKING_OFF)") < back_off.index("run back_off_motion()") \
        < back_off.index("finish(PHASE_BACK_OFF_STOPPED)")
    controller.when("blocked", "reach_over_the_arm", 0.003)
    if stop:
        controller.when("back_off", "write_input_int", REQUEST_REGISTER, request_value(run_id, REQUEST_STOP))
    with socket.create_connection((HOST, 30003)) as script_port:
        script_port.sendall(program.encode())
        assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "move"])
        controller.write_input_int(REQUEST_REGISTER, request_value(run_id, REQUEST_GO))  # the link's go
        assert wait_until(lambda: not controller.program_running(), 5.0)
    assert controller.output_int(PHASE_REGISTER) == (PHASE_BACK_OFF_STOPPED if stop else PHASE_RETURN_BLOCKED)
    assert (controller.contact_force_n() > MOVE_FORCE_LIMIT_N / 2) == stop


@pytest.mark.parametrize("motion", ["tap", "move"])
def test_a_stop_that_cuts_the_back_off_short_says_the_arm_may_still_press_on_what_it_met(start_controller, connect,
                                                                                         motion):
    """STOP while the way back backs off from what it met (the speed slider turned down as it starts, so it takes
    seconds): the tap said it 'backed off a few millimetres', the move only that it 'was stopped on request'; now
    both say that STOP halted the back-off and the arm may still press on what it met (it does), whether the program
    heeded the stop request or the dashboard's stop ended it first. A tap's contact is kept; nothing moves after."""
    controller = start_controller(base_T_flange=flange_above_surface(0.02 if motion == "tap" else 0.01))
    robot = connect()
    if motion == "tap":
        controller.when("settled", "reach_over_the_arm", 0.012)
        call = lambda: robot.tap(max_travel_m=0.03, **FAST_TAP)  # noqa: E731
    else:
        controller.when("blocked", "reach_over_the_arm", 0.003)
        call = lambda: robot.move_linear(flange_above_surface(-0.02), speed_m_s=0.05)  # noqa: E731
    controller.when("back_off", "set_speed_slider", 0.01)
    moving = MotionInThread(call, controller)
    assert wait_until(lambda: controller.output_int(PHASE_REGISTER) == PHASE_BACKING_OFF, 5.0)
    robot.stop()
    outcome = moving.join(3.0)
    kept = "; the contact was recorded" if motion == "tap" else ""
    assert isinstance(outcome, RobotError) and re.match(
        rf"the arm met something on its way back to where the {motion} began \((5[0-9]|6[0-9]) N\) and stopped; STOP "
        rf"halted it while it backed off, so it may still press on what it met{kept}: look at what it met, turn "
        "freedrive on and move the arm clear by hand, then retry$", str(outcome)), outcome
    assert controller.output_int(PHASE_REGISTER) in (PHASE_BACK_OFF_STOPPED, PHASE_BACKING_OFF)
    assert controller.contact_force_n() > MOVE_FORCE_LIMIT_N / 2
    if motion == "tap":
        np.testing.assert_allclose(outcome.tap_result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)
    assert robot.status().mode == "ready"
    assert_arm_stands(controller)


@pytest.mark.parametrize("fault", ["protective_stop", "safeguard_stop"])
def test_a_fault_that_ends_the_back_off_says_the_arm_may_still_press_on_what_it_met(start_controller, connect, fault):
    """A protective or safeguard stop (not the wizard's STOP) ends the tap's program while its way back backs off from
    what it met: the message said only which stop it was; now it also says the arm was backing off and may still
    press on what it met (it does). Nothing moves after."""
    controller = start_controller(base_T_flange=flange_above_surface(0.02))
    robot = connect()
    controller.when("settled", "reach_over_the_arm", 0.012)
    controller.when("back_off", "set_speed_slider", 0.01)
    moving = MotionInThread(lambda: robot.tap(max_travel_m=0.03, **FAST_TAP), controller)
    assert wait_until(lambda: controller.output_int(PHASE_REGISTER) == PHASE_BACKING_OFF, 5.0)
    getattr(controller, fault)()
    outcome = moving.join(3.0)
    assert isinstance(outcome, RobotError) and re.search(
        r"stop(ped the arm)? during the tap as the arm backed off from something it met on its way back "
        r"\((5[0-9]|6[0-9]) N\), so it may still press on it: ", str(outcome)), outcome
    assert controller.contact_force_n() > MOVE_FORCE_LIMIT_N / 2
    assert_arm_stands(controller)


@pytest.mark.slow
@pytest.mark.parametrize("stall_s", [0.3, 1.0])
def test_the_move_force_limit_holds_on_the_controller_when_the_pc_stalls(start_controller, connect, stall_s):
    """The link process is frozen (SIGSTOP) while a move heads 20 mm into the surface: the program alone stops it
    at its force limit (or the watchdog stops the arm first); the surface never pushes back with the force of a
    protective stop."""
    controller = start_controller(base_T_flange=flange_above_surface(0.005))
    robot = connect()
    move = MotionInThread(lambda: robot.move_linear(flange_above_surface(-0.02), speed_m_s=0.05), controller)
    assert wait_until(lambda: robot.status().mode == "moving")
    stall_link(robot.link_pid, stall_s)
    outcome = move.join(10.0)
    assert isinstance(outcome, (MoveBlocked, ConnectionLost)), outcome
    assert controller.peak_contact_force_n() < COLLISION_FORCE_N
    assert_arm_stands(controller)


@pytest.mark.parametrize("spoil", [lambda pose: pose.__setitem__((0, 3), np.nan),
                                   lambda pose: pose.__setitem__((1, 1), np.inf),
                                   lambda pose: pose.__setitem__((slice(0, 3), slice(0, 3)), 2 * pose[:3, :3]),
                                   lambda pose: pose.__setitem__((3, 0), 1.0)])
def test_move_linear_refuses_a_target_that_is_not_a_finite_rigid_pose(robot, controller, spoil):
    target = flange_above_surface(0.02)
    spoil(target)
    started = time.monotonic()
    with pytest.raises(RobotError, match="target is not a (finite 4x4|rigid) pose"):
        robot.move_linear(target)
    assert time.monotonic() - started < 0.5  # no program's start (seconds); room for a loaded machine
    assert [name for name, _, _ in controller.programs()] == ["setup"]


def test_stop_from_another_thread_ends_a_tap_at_once(start_controller, connect):
    controller = start_controller(base_T_flange=flange_above_surface(0.04))
    robot = connect()
    tap = TapInThread(robot, controller, max_travel_m=0.05, speed_m_s=0.01)
    assert wait_until(lambda: robot.status().mode == "moving")
    time.sleep(0.2)
    started = time.monotonic()
    robot.stop()
    assert time.monotonic() - started < 0.5  # never blocks the caller (the link's answer would take seconds)
    assert isinstance(tap.join(2.0), MotionStopped)
    assert time.monotonic() - started < 1.0
    assert_arm_stands(controller)


def test_stop_refuses_a_motion_asked_for_before_it_that_had_not_started(start_controller, connect):
    """A move asked for from a second thread waits for the tap's lock; STOP ends the tap, and the move, asked
    for before the STOP, must not start once the lock is free (it did: the link counted STOPs from when it got
    the command)."""
    controller = start_controller(base_T_flange=flange_above_surface(0.04))
    robot = connect()
    tap = TapInThread(robot, controller, max_travel_m=0.05, speed_m_s=0.01)
    assert wait_until(lambda: robot.status().mode == "moving")
    queued = MotionInThread(lambda: robot.move_linear(flange_above_surface(0.06)), controller)
    time.sleep(0.2)
    robot.stop()
    assert isinstance(tap.join(2.0), MotionStopped)
    outcome = queued.join(3.0)
    assert isinstance(outcome, MotionStopped) and "the move was stopped on request" in str(outcome), outcome
    assert [name for name, _, _ in controller.programs()] == ["setup", "tap"]
    assert_arm_stands(controller)
    robot.move_linear(flange_above_surface(0.06))  # asked for after the STOP: it runs


@pytest.mark.parametrize("motion", ["tap", "move", "freedrive"])
def test_a_motion_whose_stop_mark_is_older_than_a_stop_never_starts(start_controller, connect, motion):
    """The wizard reads the STOP count before it looks at its own STOP request, then asks for the motion with that
    mark: a STOP landing in between refuses the motion on the link, however late the call comes (the link counted
    STOPs from the call, so such a motion started after the STOP). Asked for with a fresh mark, it runs."""
    controller = start_controller(base_T_flange=flange_above_surface(0.01))
    robot = connect()
    ask = {"tap": lambda mark: robot.tap(stop_mark=mark),
           "move": lambda mark: robot.move_linear(flange_above_surface(0.02), stop_mark=mark),
           "freedrive": lambda mark: robot.freedrive(True, stop_mark=mark)}[motion]
    stop_mark = robot.stop_count()
    robot.stop()
    said = "freedrive did not come on" if motion == "freedrive" else f"the {motion} was stopped on request"
    with pytest.raises(MotionStopped, match=said):
        ask(stop_mark)
    assert [name for name, _, _ in controller.programs()] == ["setup"]
    assert_arm_stands(controller)
    ask(robot.stop_count())
    assert [name for name, _, _ in controller.programs()] == ["setup", motion]


def test_stop_before_the_controller_starts_a_sent_program_ends_it_before_it_moves(robot, controller):
    """STOP after the link sent a move but before the controller started it (the dashboard's stop finds nothing
    running): the link writes the stop request for that run, and the program ends before its movel starts
    (before, its loop stopped the movel a cycle after it started)."""
    controller.delay_programs(0.5)
    before = controller.flange_pose()
    moving = MotionInThread(lambda: robot.move_linear(flange_above_surface(0.06)), controller)
    assert wait_until(lambda: len(controller.uploaded_scripts()) == 2)  # the set-up program and the move
    robot.stop()
    script = controller.uploaded_scripts()[-1]
    assert script.index("if requested(REQUEST_STOP):") < script.index("run motion()")  # before any motion
    assert isinstance(moving.join(4.0), MotionStopped)
    assert [name for name, _, _ in controller.programs()] == ["setup", "move"]  # it started, then ended
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)


@pytest.mark.parametrize("when", ["as the link process starts", "as the set-up program waits"])
def test_a_call_while_another_thread_reconnects_leaves_the_connect_alone(robot, controller, when):
    """The wizard's status poll asked for the pose while Reconnect was connecting: before the new link process had
    data, the call abandoned it and killed it, so the Reconnect failed with "link process ended unexpectedly while
    connecting"; once data flowed but before the set-up program had zeroed the TCP offset, it read a pose that may
    not be the flange's. Now the call says the link is still connecting, and the connect succeeds."""
    controller.delay_programs(1.0)  # the set-up program starts late: the connect waits for it
    old_pid = robot.link_pid
    connecting = MotionInThread(robot.connect, controller)
    if when == "as the link process starts":
        assert wait_until(lambda: robot.link_pid not in (None, old_pid), CONNECT_DEADLINE_S)
    else:
        assert wait_until(lambda: len(controller.uploaded_scripts()) == 2, CONNECT_DEADLINE_S)  # both set-ups
    with pytest.raises(ConnectionLost, match="still connecting"):
        robot.base_T_tcp()
    assert connecting.join(CONNECT_DEADLINE_S + 2.0) is None
    assert robot.status().connected
    robot.base_T_tcp()


def test_stop_does_not_block_on_a_frozen_link(robot, controller):
    controller.freeze_link()
    started = time.monotonic()
    robot.stop()
    assert time.monotonic() - started < 0.5  # a frozen link's answer would never come; room for a loaded machine


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
    assert travels == pytest.approx([travels[0]] * 2, abs=2e-4)


# --- stops ---


def test_protective_stop_during_a_tap_blocks_until_unlocked_on_the_pendant(robot, controller):
    controller.when("contact", "protective_stop")
    with pytest.raises(ProtectiveStop, match="unlock the protective stop on the teach pendant or with Unlock in "
                                             "fixwizard") as raised:
        robot.tap(**FAST_TAP)
    assert not hasattr(raised.value, "tap_result")  # stopped before the contact was recorded
    status = robot.status()
    assert status.protective_stop and not status.program_running and status.mode == "protective stop"
    with pytest.raises(ProtectiveStop):
        robot.tap(**FAST_TAP)
    controller.unlock_on_pendant()
    assert wait_until(lambda: robot.status().mode == "ready")
    robot.move_linear(flange_above_surface(0.008))
    result = robot.tap(**FAST_TAP)
    np.testing.assert_allclose(result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)


def test_protective_stop_as_a_move_starts_is_named_and_nothing_moves(robot, controller):
    before = controller.flange_pose()
    controller.when("movel", "protective_stop")
    with pytest.raises(ProtectiveStop, match="protective stop during the move"):
        robot.move_linear(flange_above_surface(0.05))
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)
    assert_arm_stands(controller)


def test_protective_stop_after_the_contact_keeps_the_recorded_contact(robot, controller):
    base_T_start = robot.base_T_tcp()
    earlier = robot.tap(**FAST_TAP)
    controller.when("settled", "protective_stop")
    with pytest.raises(ProtectiveStop, match="during the tap") as raised:
        robot.tap(**FAST_TAP)
    np.testing.assert_allclose(raised.value.tap_result.base_T_tcp_contact, controller.contact_poses()[-1],
                               atol=2e-6)
    np.testing.assert_allclose(raised.value.tap_result.base_T_tcp_contact, earlier.base_T_tcp_contact, atol=2e-4)
    with pytest.raises(RobotError, match="did not unlock the protective stop .*Cannot unlock protective stop "
                                         "until 5s after occurrence"):
        robot.unlock_protective_stop()
    time.sleep(UNLOCK_DELAY_S)
    robot.unlock_protective_stop()
    assert not robot.status().protective_stop
    with pytest.raises(RobotError, match="already pushes on something"):  # the stop left the tool pressed down
        robot.tap(**FAST_TAP)
    robot.move_linear(base_T_start)
    assert robot.tap(**FAST_TAP).travel_m == pytest.approx(earlier.travel_m, abs=2e-4)


@pytest.mark.parametrize("motion", ["tap", "move", "retract"])
def test_a_program_paused_on_the_pendant_is_stopped_so_that_play_moves_nothing(start_controller, connect, motion):
    """Pause on the teach pendant mid-tap, mid-move or mid-retract: fixwizard's program is stopped before the error
    is shown, so the play button afterwards moves nothing."""
    controller = start_controller(base_T_flange=flange_above_surface(0.03))
    robot = connect()
    if motion == "move":
        call = lambda: robot.move_linear(flange_above_surface(0.08), speed_m_s=0.05)  # noqa: E731
    else:
        call = lambda: robot.tap(max_travel_m=0.05, speed_m_s=0.05)  # noqa: E731
    controller.when({"tap": "tap", "move": "movel", "retract": "settled"}[motion], "pause_on_pendant")
    outcome = MotionInThread(call, controller).join(5.0)
    assert isinstance(outcome, RobotError) and "paused" in str(outcome), outcome
    controller.play_on_pendant()
    assert_arm_stands(controller)
    robot.move_linear(flange_above_surface(0.03), speed_m_s=0.05)  # the next motion runs


def test_a_program_left_paused_is_stopped_on_connecting_before_anything_is_sent(controller, connect):
    """A fixwizard move paused on the pendant as its link died: the next link stops it with the dashboard's stop
    before it sends a program (a controller need not replace a paused program by a new one, and the new link's
    kicks would keep the old program's watchdog content), so play afterwards moves nothing."""
    target = flange_above_surface(0.2)
    program = move_program(5, 10.0, [*target[:3, 3], np.pi, 0.0, 0.0], 0.05)
    controller.when("movel", "pause_on_pendant")
    with socket.create_connection((HOST, 30003)) as script_port:
        script_port.sendall(program.encode())
        assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["move"])
        controller.write_input_int(REQUEST_REGISTER, request_value(5, REQUEST_GO))
        assert wait_until(controller.program_paused)
    connect()
    assert "stop" in controller.dashboard_commands()
    assert [name for name, _, _ in controller.programs()] == ["move", "setup"]
    controller.play_on_pendant()
    assert_arm_stands(controller)


@pytest.mark.parametrize("source", ["robot", "system"])
def test_emergency_stop_raises_until_released_and_powered_on(robot, controller, source):
    controller.emergency_stop(source)
    assert wait_until(lambda: robot.status().emergency_stop)
    assert robot.status().mode == "emergency stop"
    with pytest.raises(EmergencyStop, match="release the emergency stop, power on"):
        robot.tap(**FAST_TAP)
    controller.release_emergency_stop()
    assert wait_until(lambda: robot.status().mode == "powered off")
    with pytest.raises(RobotError, match="the arm is powered off.*: power it on and release the brakes"):
        robot.tap(**FAST_TAP)
    controller.power_on()
    assert wait_until(lambda: robot.status().mode == "ready")
    assert robot.tap(**FAST_TAP).travel_m > 0.008


def test_safeguard_stop_names_the_safeguard(robot, controller):
    controller.safeguard_stop()
    assert wait_until(lambda: robot.status().mode == "safeguard stop")
    with pytest.raises(RobotError, match="a safeguard stop .* stopped the arm before the tap: clear the cell"):
        robot.tap(**FAST_TAP)


def test_remote_control_switched_off_while_connected(robot, controller):
    controller.set_remote_control(False)
    with pytest.raises(NotInRemoteControl, match="switch it to remote control"):
        robot.tap(**FAST_TAP)
    assert [name for name, _, _ in controller.programs()] == ["setup"]  # nothing sent in local control
    controller.set_remote_control(True)
    assert robot.tap(**FAST_TAP).travel_m > 0.008


# --- a lost link ---


@pytest.mark.parametrize("fault", ["go_offline", "drop_connections"])
def test_a_link_dropped_mid_tap_stops_the_arm_before_the_error_and_reconnect_works(robot, controller, fault):
    base_T_start = robot.base_T_tcp()
    controller.when("tap", fault)
    started = time.monotonic()
    with pytest.raises(ConnectionLost, match="during the tap.*watchdog stopped the arm.*then reconnect. The tap "
                                             "was not recorded"):
        robot.tap(**FAST_TAP)
    assert time.monotonic() - started < 3.0
    assert_arm_stands(controller)
    assert not robot.status().connected
    with pytest.raises(ConnectionLost, match="not connected"):
        robot.tap(**FAST_TAP)
    if fault == "go_offline":
        controller.go_online()
    robot.connect()
    robot.move_linear(base_T_start)
    result = robot.tap(**FAST_TAP)
    np.testing.assert_allclose(result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)


@pytest.mark.parametrize("when", ["tap", "retract"])
def test_a_controller_reboot_mid_tap_stops_it_keeps_a_recorded_contact_and_reconnects_once_it_is_back(
        robot, controller, when):
    """The controller restarts as the tap approaches, or once its contact is recorded and it retracts: every
    connection drops, nothing answers for a while, and it comes back with no program and fresh registers. The
    tap's error says whether its contact was kept (the controller's own), nothing moves after it, and once the
    controller is back a reconnect and a tap work."""
    if when == "tap":
        controller.when("tap", "reboot", REBOOT_S)
    else:  # the retract's movel, the first after the contact settled
        controller.when("settled", "when", "movel", "reboot", REBOOT_S)
    tap = TapInThread(robot, controller, **FAST_TAP)
    outcome = tap.join(5.0)
    assert isinstance(outcome, ConnectionLost), outcome
    assert hasattr(outcome, "tap_result") == (when == "retract")
    assert ("contact was recorded" if when == "retract" else "tap was not recorded") in str(outcome)
    if when == "retract":
        np.testing.assert_allclose(outcome.tap_result.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)
    assert_arm_stands(controller)
    np.testing.assert_allclose(controller.flange_pose(), tap.pose_at_outcome, atol=1e-9)
    assert wait_until(lambda: socket_accepts(29999), timeout_s=REBOOT_S + 1.0)
    robot.connect()
    robot.move_linear(flange_above_surface(0.008))
    np.testing.assert_allclose(robot.tap(**FAST_TAP).base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)


def test_rtde_data_in_bursts_still_gives_the_controller_s_contact(robot, controller):
    """A congested network delivers the RTDE data in bursts 0.3 s apart (samples of the controller's rate, late):
    the tap's contact is still the one the controller made, and a move still gets there."""
    controller.burst_rtde(0.3)
    np.testing.assert_allclose(robot.tap(**FAST_TAP).base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6)
    robot.move_linear(flange_above_surface(0.02))
    np.testing.assert_allclose(controller.flange_pose(), flange_above_surface(0.02), atol=1e-3)


def socket_accepts(port: int) -> bool:
    try:
        socket.create_connection((HOST, port), timeout=0.2).close()
    except OSError:
        return False
    return True


def test_a_lost_link_is_shown_only_once_the_watchdog_has_stopped_the_arm_at_its_latest(robot, controller):
    """A controller checks its watchdog once a period, so it may fire two periods (1 s) after the last kick: the
    network drops mid-move just after a check, the latest case, with no dashboard to stop the arm. The error comes
    only once the arm stands."""
    move = MotionInThread(lambda: robot.move_linear(flange_above_surface(0.2), speed_m_s=0.05), controller)
    assert wait_until(lambda: robot.status().mode == "moving")
    controller.when("watchdog_check", "go_offline")
    error = move.join(5.0)
    assert isinstance(error, ConnectionLost) and "watchdog stopped the arm within 1 s" in str(error), error
    assert not controller.program_running()
    np.testing.assert_allclose(controller.flange_pose(), move.pose_at_outcome, atol=1e-9)


def test_a_call_while_another_waits_for_the_watchdog_of_a_lost_link_errs_only_once_the_arm_stands(robot, controller):
    """The link drops mid-move; the move's call abandons the link and waits for the watchdog to stop the arm. A call
    from another thread meanwhile (the wizard's status saw the link go and asks for the pose, to show the error) found
    no link and raised "not connected" at once, while the move's program still ran: the wizard showed the error and
    the arm moved on after it. It waits for the same watchdog."""
    move = MotionInThread(lambda: robot.move_linear(flange_above_surface(0.2), speed_m_s=0.05), controller)
    assert wait_until(lambda: controller.program_running() and controller.programs()[-1][0] == "move")
    controller.go_offline()
    assert wait_until(lambda: robot.link_pid is None)  # the move's call abandoned the link and waits
    with pytest.raises(ConnectionLost, match="not connected"):
        robot.base_T_tcp()
    assert_arm_stands(controller)
    assert isinstance(move.join(5.0), ConnectionLost)


@pytest.mark.slow
def test_a_frozen_link_shows_disconnected_within_a_second_and_stops_the_arm(robot, controller):
    assert robot.status().mode == "ready"
    controller.freeze_link()
    assert wait_until(lambda: not robot.status().connected, timeout_s=1.0)
    with pytest.raises(ConnectionLost):
        robot.tap(**FAST_TAP)
    controller.thaw_link()
    robot.connect()
    robot.freedrive(True)
    controller.freeze_link()  # the inputs are lost too: the controller's watchdog ends freedrive
    assert wait_until(lambda: not controller.program_running(), timeout_s=2.0)
    assert controller.watchdog_trips() == 1


WIZARD_THAT_MOVES = """
import sys, time
from fixwizard.robot.ur import URRobot
from ur_loopback import flange_above_surface
robot = URRobot(sys.argv[1])
robot.connect()
print(robot.link_pid, flush=True)
robot.move_linear(flange_above_surface(0.3), speed_m_s=0.05)
"""


@pytest.mark.slow
def test_the_wizard_s_process_killed_mid_move_stops_the_arm_and_its_link(controller):
    """kill -9 of the wizard's process while a 6 s move runs: its link process ends with it, so the watchdog
    stops the arm (within 1 s of the link's end), and no link process is left behind."""
    wizard = subprocess.Popen([sys.executable, "-c", WIZARD_THAT_MOVES, HOST], stdout=subprocess.PIPE, text=True,
                              env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    try:
        link_pid = int(wizard.stdout.readline())
        assert wait_until(lambda: controller.program_running() and [name for name, _, _ in controller.programs()]
                          == ["setup", "move"], timeout_s=5.0)
        wizard.kill()
        assert wait_until(lambda: not controller.program_running(), timeout_s=2.5)
        assert_arm_stands(controller)
        assert wait_until(lambda: not os.path.exists(f"/proc/{link_pid}"), timeout_s=1.0)
    finally:
        wizard.kill()
        wizard.wait()
        wizard.stdout.close()


LINK_WHOSE_WIZARD_GOES = """
import multiprocessing, sys
from fixwizard.robot.ur import WATCHDOG_HZ
from fixwizard.robot.ur_link import serve
from fixwizard.robot.ur_state import SharedState
context = multiprocessing.get_context("spawn")
conn, child_conn = context.Pipe()
link = context.Process(target=serve, args=(sys.argv[1], WATCHDOG_HZ, child_conn, SharedState(context),
                                           context.Value("q", 0, lock=False)), daemon=True)
link.start()
child_conn.close()
conn.send(("connect", ()))
while (answer := conn.recv())[0] == "step":
    pass
print(answer[0], flush=True)
conn.send(("tap", (0, 0.02, 0.02, 10.0)))
conn.close()
link.join(10.0)
print(link.exitcode, flush=True)
"""


@pytest.mark.slow
def test_a_link_whose_wizard_is_gone_mid_tap_ends_at_once_without_a_traceback(controller):
    """The wizard's end of the link's pipe goes away while a tap runs (its process died, but its parent-watch has not
    seen it yet): the link's next message (the contact) has nowhere to go. It ended with a BrokenPipeError traceback
    on the terminal the wizard ran in, and went on holding the robot's RTDE inputs; it now ends at once, quietly, and
    the arm stands (the tap's program ended, or the watchdog ended it)."""
    wizard = subprocess.run([sys.executable, "-c", LINK_WHOSE_WIZARD_GOES, HOST], capture_output=True, text=True,
                            timeout=30, env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert wizard.stdout.split() == ["done", "0"], wizard.stderr
    assert "Traceback" not in wizard.stderr
    assert [name for name, _, _ in controller.programs()] == ["setup", "tap"]
    assert wait_until(lambda: not controller.program_running(), timeout_s=2.0)
    assert_arm_stands(controller)


@pytest.mark.parametrize("kill", [signal.SIGSEGV, signal.SIGKILL])
def test_a_crashed_link_process_leaves_the_wizard_running(robot, controller, kill):
    tap = TapInThread(robot, controller, **FAST_TAP)
    # the tap's program runs (the status says "moving" from the call on: under load the link had not been asked yet)
    assert wait_until(lambda: [name for name, _, _ in controller.programs()] == ["setup", "tap"])
    os.kill(robot.link_pid, kill)
    error = tap.join(3.0)
    assert isinstance(error, ConnectionLost)
    assert f"link process ended unexpectedly during the tap (killed by {kill.name})" in str(error)
    assert_arm_stands(controller)
    robot.connect()
    assert robot.status().mode == "ready"


def test_a_bug_in_the_link_mid_move_stops_the_arm_before_the_error(controller, connect, monkeypatch):
    """An unexpected exception in the link process while its move runs (a bug, or ur_rtde raising something else
    than RuntimeError): the link counts as lost, so its kicks stop and the watchdog has stopped the arm by the time
    the error is shown."""
    monkeypatch.setattr("fixwizard.robot.ur.serve", serve_with_a_bug_in_the_move)
    robot = connect()
    with pytest.raises(ConnectionLost, match="robot link failed while trying to move_linear .ValueError.*a bug "
                                             "while the move runs.*watchdog stopped the arm"):
        robot.move_linear(flange_above_surface(0.058), speed_m_s=0.05)
    assert_arm_stands(controller)
    assert not robot.status().connected


def test_a_new_link_never_takes_the_last_run_s_id_for_its_own_program(controller, connect, monkeypatch):
    """A link's random first run id equal to the one the run register still shows (the last program run): the link
    would take that run's end for its own move's while its program, started a moment later by a busy controller,
    got the go and moved after the error. The link skips that id: the move runs as asked."""
    monkeypatch.setattr("fixwizard.robot.ur.serve", serve_whose_first_run_id_is_the_last_one_run)
    robot = connect()
    controller.delay_programs(0.3)
    target = flange_above_surface(0.03)
    robot.move_linear(target, speed_m_s=0.1)
    np.testing.assert_allclose(controller.flange_pose(), target, atol=1e-6)
    run_ids = [run_id for _, run_id, _ in controller.programs()]
    assert len(set(run_ids)) == len(run_ids) == 2


def test_writes_that_ur_rtde_drops_without_raising_drop_the_link_before_anything_moves(controller, connect,
                                                                                       monkeypatch):
    """ur_rtde's write returns False, raising nothing, when a send failed that it could not redo: the link went on
    as if its kicks and requests had arrived, and a move ended in 'this computer was too busy to answer' after the
    watchdog fired. The link is lost at the first such write, and nothing is sent that could move the arm."""
    monkeypatch.setattr("fixwizard.robot.ur.serve", serve_whose_writes_are_lost_once_connected)
    robot = connect()
    before = controller.flange_pose()
    # the move's own write names the cause; on a loaded machine the watchdog's kick may fail first, and the move
    # then finds the link already down, with that cause
    with pytest.raises(ConnectionLost, match="writing to the controller failed .ur_rtde could not send it"):
        robot.move_linear(flange_above_surface(0.03), speed_m_s=0.05)
    assert [name for name, _, _ in controller.programs()] == ["setup"]
    np.testing.assert_allclose(controller.flange_pose(), before, atol=1e-9)
    assert not robot.status().connected


@pytest.mark.parametrize("field", ["actual_TCP_pose", "actual_TCP_force", "output_double_register_17"])
def test_rtde_data_that_is_not_a_number_drops_the_link_mid_tap(robot, controller, field):
    """NaN from the RTDE stream mid-tap (a pose, a force, the tap's travel): nothing of it is recorded or trusted;
    the link is down, so the watchdog stops the arm before the error, as for a lost link."""
    tap = TapInThread(robot, controller, **FAST_TAP)
    assert wait_until(lambda: robot.status().mode == "moving")
    controller.garble(field)
    error = tap.join(3.0)
    assert isinstance(error, ConnectionLost), error
    assert "not a number" in str(error) and "The tap was not recorded" in str(error)
    assert_arm_stands(controller)


def test_a_pose_that_is_not_a_number_is_never_moved_from(robot, controller):
    """The flange pose reads NaN: the wizard gets no pose, and a move (whose distance, deadline and end check would
    all be NaN) is refused without a program sent."""
    controller.garble("actual_TCP_pose")
    assert wait_until(lambda: not robot.status().connected)
    with pytest.raises(ConnectionLost, match=r"dropped \(the controller's RTDE data holds a value that is not a "
                                             r"number \(x\)\)"):
        robot.base_T_tcp()
    with pytest.raises(ConnectionLost):
        robot.move_linear(flange_above_surface(0.02))
    assert [name for name, _, _ in controller.programs()] == ["setup"]


@pytest.mark.parametrize("fault", ["go_offline", "drop_connections"])
def test_a_link_that_drops_while_nothing_runs_names_its_cause_at_the_next_command(robot, controller, fault):
    """A switch that resets, or a network that fails, while the operator reads the screen: the next command says
    why the link dropped (what the link process saw), not only that it did; nothing moves."""
    getattr(controller, fault)()
    assert wait_until(lambda: not robot.status().connected, 3.0)
    with pytest.raises(ConnectionLost, match=r"^the link to the robot dropped before the tap \((the controller "
                                             r"closed the RTDE connection|writing to the controller failed|reading "
                                             r"the RTDE data failed|no RTDE data from the controller)"):
        robot.tap(**FAST_TAP)
    assert [name for name, _, _ in controller.programs()] == ["setup"]
    assert_arm_stands(controller)


def test_the_shared_state_keeps_the_first_cause_of_a_drop_whole_or_cut_at_a_character():
    shared = SharedState(multiprocessing.get_context("spawn"))
    assert shared.lost_reason() == ""
    reason = "writing to the controller failed (" + "ü" * LOST_REASON_BYTES + ")"
    shared.lose(reason)
    assert shared.read()[2]
    said = shared.lost_reason()
    assert reason.startswith(said) and LOST_REASON_BYTES - 1 <= len(said.encode()) <= LOST_REASON_BYTES
    shared.lose("the controller closed the RTDE connection")  # shorter: nothing of the first is left after it
    assert shared.lost_reason() == "the controller closed the RTDE connection"


def test_a_link_stalled_longer_than_the_watchdog_says_this_computer_stalled(start_controller, connect):
    """The link process frozen (SIGSTOP) for 0.6 s mid-move, longer than the watchdog's 0.5 s (a real controller
    has ended the move by then) but shorter than the wizard's 0.75 s: the link says that this computer stalled,
    not that the controller sent nothing, and the arm stands."""
    controller = start_controller(base_T_flange=flange_above_surface(0.03))
    robot = connect()
    move = MotionInThread(lambda: robot.move_linear(flange_above_surface(0.13), speed_m_s=0.05), controller)
    assert wait_until(lambda: robot.status().mode == "moving")
    stall_link(robot.link_pid, 0.6)
    error = move.join(5.0)
    assert isinstance(error, ConnectionLost) and "this computer stalled" in str(error), error
    assert_arm_stands(controller)


@pytest.mark.slow
@pytest.mark.parametrize("stall_s", [0.2, 0.4, 1.0, 3.0])
def test_the_tap_travel_holds_on_the_controller_when_the_pc_stalls(start_controller, connect, stall_s):
    """A 20 mm tap at 50 mm/s into nothing; the link process is frozen (SIGSTOP) for ``stall_s`` partway."""
    controller = start_controller(base_T_flange=flange_above_surface(0.03))
    robot = connect()
    tap = TapInThread(robot, controller, max_travel_m=0.02, speed_m_s=0.05)
    assert wait_until(lambda: robot.status().mode == "moving")
    time.sleep(random.uniform(0.0, 0.3))
    stall_link(robot.link_pid, stall_s)
    outcome = tap.join(5.0)
    # a stall before the program was sent: the link says it stalled and sends nothing (no tap program at all)
    assert max(controller.tap_travels(), default=0.0) <= 0.02 + TRAVEL_SLACK_M
    assert isinstance(outcome, (NoContact, ConnectionLost))
    if isinstance(outcome, ConnectionLost):
        assert "no surface" not in str(outcome)
        assert_arm_stands(controller)


@pytest.mark.slow
def test_drop_and_reconnect_cycles_never_crash_move_after_the_error_or_lose_a_tap(start_controller):
    """The acceptance run: ``DROP_CYCLES`` cycles, idle and mid-tap, the link dropped (offline, or every
    connection reset while the controller listens) at a random moment."""
    controller = start_controller()
    robot = URRobot(HOST)
    rng = random.Random(17)
    outcomes: dict[str, int] = {}
    try:
        for cycle in range(DROP_CYCLES):
            robot.connect()
            robot.move_linear(flange_above_surface(0.008))
            fault = rng.choice(["go_offline", "drop_connections"])
            if cycle % 2 == 0:  # idle
                time.sleep(rng.uniform(0.0, 0.3))
                getattr(controller, fault)()
                with pytest.raises(ConnectionLost):
                    robot.move_linear(flange_above_surface(0.008))
                kind = "idle"
            else:
                tap = TapInThread(robot, controller, speed_m_s=0.05)
                time.sleep(rng.uniform(0.0, 0.6))
                getattr(controller, fault)()
                outcome = tap.join(5.0)
                if isinstance(outcome, ConnectionLost):
                    recorded = hasattr(outcome, "tap_result")
                    assert ("contact was recorded" if recorded else "tap was not recorded") in str(outcome)
                    kind = "tap recorded, link lost" if recorded else "tap lost and reported"
                else:
                    assert not isinstance(outcome, RobotError), outcome
                    kind = "tap done"
                np.testing.assert_allclose(controller.flange_pose(), tap.pose_at_outcome, atol=1e-9)
            assert_arm_stands(controller, 0.1)
            outcomes[kind] = outcomes.get(kind, 0) + 1
            if fault == "go_offline":
                controller.go_online()
    finally:
        robot.close()
    print(f"\n{DROP_CYCLES} drop/reconnect cycles: {outcomes}; watchdog trips {controller.watchdog_trips()}")
    assert sum(outcomes.values()) == DROP_CYCLES


class FaultMix:
    """Random faults a cell has, each at a random moment of a random tap or move, and the way back to a ready arm."""

    FAULTS = ("go_offline", "drop_connections", "reboot", "freeze_link", "burst_rtde", "stall", "kill_link",
              "protective_stop", "emergency_stop", "safeguard_stop", "pause_on_pendant", "local_control",
              "stop_button")

    def __init__(self, controller, robot: URRobot, rng: random.Random) -> None:
        self.controller, self.robot, self.rng = controller, robot, rng

    def motion(self):
        """A tap (some into nothing: the travel is short) or a move (some into the surface: blocked)."""
        robot, rng = self.robot, self.rng
        if rng.random() < 0.5:
            travel_m, speed_m_s = rng.uniform(0.004, 0.03), rng.uniform(0.01, 0.05)
            return "tap", lambda: robot.tap(max_travel_m=travel_m, speed_m_s=speed_m_s)
        target = flange_above_surface(rng.uniform(-0.01, 0.05))
        target[:2, 3] += [rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03)]
        return "move", lambda: robot.move_linear(target, speed_m_s=rng.uniform(0.02, 0.1))

    def inject(self, fault: str) -> None:
        controller = self.controller
        if fault == "stall":
            stall_link(self.robot.link_pid, self.rng.uniform(0.1, 1.5))
        elif fault == "reboot":
            controller.reboot(self.rng.uniform(0.05, REBOOT_S))
        elif fault == "burst_rtde":  # some longer than the link lets its data go quiet
            controller.burst_rtde(self.rng.uniform(0.1, 0.7))
        elif fault == "kill_link":
            os.kill(self.robot.link_pid, signal.SIGKILL)
        elif fault == "local_control":
            controller.set_remote_control(False)
        elif fault == "stop_button":
            self.robot.stop()
        else:
            getattr(controller, fault)()

    def recover(self, fault: str) -> None:
        """Undo ``fault`` on the controller, as the operator does, and reconnect if the link is down."""
        controller = self.controller
        if fault == "go_offline":
            controller.go_online()
        assert wait_until(lambda: socket_accepts(29999), timeout_s=REBOOT_S + 1.0)  # a reboot is over
        controller.burst_rtde(0.0)
        controller.thaw_link()
        controller.play_on_pendant()  # must move nothing: fixwizard stopped its paused program
        controller.set_remote_control(True)
        controller.release_emergency_stop()
        controller.power_on()
        if fault == "protective_stop":
            time.sleep(UNLOCK_DELAY_S)
            controller.unlock_on_pendant()
        if not self.robot.status().connected:
            self.robot.connect()


@pytest.mark.slow
def test_random_faults_mid_motion_never_leave_the_arm_moving_or_lose_a_contact(start_controller):
    """Taps and moves of random length and speed, each hit at a random moment by a random fault (a dropped, frozen
    or reset link, a controller reboot, RTDE data in bursts, a stalled or killed link process, a protective,
    emergency or safeguard stop, pause on the pendant, local control, STOP): every call comes back within its
    deadline, the arm stands from the moment it does (nothing moves after an error, nor after the operator undoes
    the fault), and every contact it reports is the one the controller made."""
    controller = start_controller()
    robot = URRobot(HOST)
    seed = random.randrange(1 << 30)
    mix = FaultMix(controller, robot, random.Random(seed))
    seen: dict[str, int] = {}
    try:
        robot.connect()
        for cycle in range(FAULT_CYCLES):
            robot.move_linear(flange_above_surface(0.008))
            name, call = mix.motion()
            fault = mix.rng.choice(FaultMix.FAULTS)
            where = f"seed {seed}, cycle {cycle}: {fault} during the {name}"
            motion = MotionInThread(call, controller)
            time.sleep(mix.rng.uniform(0.0, 0.6))
            mix.inject(fault)
            outcome = motion.join(15.0)
            time.sleep(0.2)
            np.testing.assert_allclose(controller.flange_pose(), motion.pose_at_outcome, atol=1e-9, err_msg=where)
            contact = outcome if name == "tap" and not isinstance(outcome, RobotError) else getattr(
                outcome, "tap_result", None)
            if contact is not None:
                np.testing.assert_allclose(contact.base_T_tcp_contact, controller.contact_poses()[-1], atol=2e-6,
                                           err_msg=where)
            kind = type(outcome).__name__
            seen[kind] = seen.get(kind, 0) + 1
            mix.recover(fault)
            assert_arm_stands(controller, 0.1)
    finally:
        robot.close()
    print(f"\n{FAULT_CYCLES} random faults (seed {seed}): {seen}; watchdog trips {controller.watchdog_trips()}")


@pytest.mark.parametrize("safety_mode, bits, emergency, protective", [
    (7, 0, True, False), (6, 0, True, False),  # the safety mode alone
    (1, 1 << 5, True, False), (1, 1 << 6, True, False), (1, 1 << 7, True, False),  # any e-stop bit alone
    (3, 0, False, True), (1, 1 << 2, False, True), (1, 1, False, False)])
def test_the_state_reads_stops_from_the_safety_mode_and_every_bit(safety_mode, bits, emergency, protective):
    state = ControllerState(0.0, 0.0, np.eye(4), 0.0, 0.0, 7, safety_mode, bits, 1, 0, 0, 0.0, 0.0, 0.0)
    assert (state.emergency_stop, state.protective_stop) == (emergency, protective)
    assert state.ready_to_move == (not emergency and not protective)
