"""The robot-driven tip calibration on a UR arm: the real ur_rtde client in its link process against the loopback
controller (a 6 mm ball on the flange's z axis, the table the plane z = 0). The operator's pivot and table points are
done by hand in freedrive, the table and tilted taps by the robot; every move and tap of the automatic steps runs
as a program on the controller, and the calibrated tip is the loopback's. (It found that no automatic tap ever ran
on a UR: the plan's numpy tap travel made a program URScript cannot read, and the link refused to send it.)"""

import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.verdict import tip_verdict
from fixwizard.geometry.se3 import make_transform
from fixwizard.robot.ur import URRobot
from fixwizard.workflow.robot_calibration import TABLE_POINTS, RobotTipCalibration
from ur_loopback import TIP_OFFSET_M, private_loopback_host

pytestmark = pytest.mark.slow  # 17 taps on the loopback controller: about 30 s
HOST = private_loopback_host()
BALL_RADIUS_M = 0.003
TRUE_TIP_M = np.array([0.0, 0.0, TIP_OFFSET_M])
DOWN = Rotation.from_euler("x", np.pi)
BASE_P_CORNER_M = np.array([0.45, 0.0, 0.0])  # table point B, on the table
TABLE_EDGE_M = 0.06  # A and C from B
PIVOT_TILTS = [(0.0, 0.0), (25.0, 0.0), (-25.0, 0.0), (0.0, 25.0), (0.0, -25.0), (18.0, 18.0)]  # deg about x, y
SAMPLE_WAIT_S = 0.05  # the RTDE stream's next samples after the operator moved the arm


def flange_with_ball_at(base_p_ball_m: np.ndarray, tilt: Rotation | None = None) -> np.ndarray:
    """The flange pose that puts the ball centre at ``base_p_ball_m``, the tool down and tilted by ``tilt``."""
    base_R_tcp = (DOWN if tilt is None else tilt * DOWN).as_matrix()
    return make_transform(base_R_tcp, base_p_ball_m - base_R_tcp @ TRUE_TIP_M)


@pytest.fixture
def controller(loopback):
    controller = loopback.start_controller(host=HOST, unlock_delay_s=1.0, ball_radius_m=BALL_RADIUS_M,
                                           base_T_flange=flange_with_ball_at(BASE_P_CORNER_M + [0, 0, 0.03]))
    yield controller
    controller.close()


@pytest.fixture
def robot(controller):
    robot = URRobot(HOST)
    robot.connect()
    yield robot
    robot.close()


def by_hand(robot: URRobot, controller, base_T_flange: np.ndarray) -> None:
    """The operator moves the arm in freedrive to ``base_T_flange``; freedrive stays on."""
    robot.freedrive(True)
    controller.move_by_hand(base_T_flange)
    time.sleep(SAMPLE_WAIT_S)


def test_a_tip_calibration_on_a_ur_arm_finds_the_tip_and_the_ball(robot, controller):
    workflow = RobotTipCalibration(robot, 2 * BALL_RADIUS_M, approach_height_m=0.01, table_grid=(2, 3),
                                   table_spacing_m=0.02, tilts_deg=(20.0, 35.0), azimuths=4)
    base_p_pivot_m = BASE_P_CORNER_M + [0.08, 0.08, BALL_RADIUS_M]  # the ball resting on one point of the table
    for about_x, about_y in PIVOT_TILTS:
        by_hand(robot, controller, flange_with_ball_at(base_p_pivot_m, Rotation.from_euler("xy", [about_x, about_y],
                                                                                           degrees=True)))
        workflow.capture_pivot_pose()
    np.testing.assert_allclose(workflow.pivot_fit().tcp_p_tip_m, TRUE_TIP_M, atol=1e-6)

    above = [0.0, 0.0, BALL_RADIUS_M + 0.007]  # the ball 7 mm above the table
    for label, base_p_point_m in zip(TABLE_POINTS, (BASE_P_CORNER_M + [TABLE_EDGE_M, 0, 0], BASE_P_CORNER_M,
                                                    BASE_P_CORNER_M + [0, TABLE_EDGE_M, 0]), strict=True):
        by_hand(robot, controller, flange_with_ball_at(base_p_point_m + above))
        robot.freedrive(False)  # as the wizard does before a tap
        contact = workflow.tap_table_point()
        assert contact[2, 3] == pytest.approx(TIP_OFFSET_M + BALL_RADIUS_M, abs=1e-3), label
    workflow.accept_table_points()

    programs_before = len(controller.programs())
    workflow.run_table_taps()
    workflow.run_tilted_taps()
    assert len(controller.contact_poses()) == 3 + 6 + 8
    names = [name for name, _, _ in controller.programs()[programs_before:]]
    assert set(names) == {"move", "tap"} and names.count("tap") == 14  # every motion a program of its own
    assert controller.peak_contact_force_n() < 15.0  # no move pressed on the table, no tap beyond its limit

    calibration = workflow.result("loopback-tip", robot=HOST)
    # no kinematic error in the loopback; its contacts stop within one 2 ms cycle of travel, also on a loaded machine
    assert np.linalg.norm(calibration.tcp_p_tip_m - TRUE_TIP_M) < 0.2e-3
    assert calibration.ball_diameter_m == 2 * BALL_RADIUS_M
    assert tip_verdict(calibration).level != "redo", tip_verdict(calibration).reasons
