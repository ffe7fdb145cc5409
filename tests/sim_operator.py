"""What the operator does by hand in a tip calibration on the simulated cell, for workflow tests."""

from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.workflow.robot_calibration import TABLE_POINTS, RobotTipCalibration


def operator_steps(cell: SimulatedCell, workflow: RobotTipCalibration, table_points: int = len(TABLE_POINTS)) -> None:
    """Pivot about a table point, then tap the first ``table_points`` of A, B (corner), C counter-clockwise."""
    hands = SimulatedHands(cell, seed=2)
    for index in range(hands.pivot_count):
        hands.pivot(index)
        workflow.capture_pivot_pose()
    for label in TABLE_POINTS[:table_points]:
        hands.table_point(label)
        workflow.tap_table_point()
