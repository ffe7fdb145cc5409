"""Tap plans: hover poses for the robot-driven table and fine-tip steps."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.calibration.plans import grid_hover_poses, tilted_hover_poses
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.geometry.se3 import invert, transform_points
from test_calibration_helpers import BASE_T_TABLE, TCP_P_TIP_M, tap

HEIGHT_M = 0.015
SPACING_M = 0.01
PLANS = {
    "grid": grid_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, 4, 5, SPACING_M, HEIGHT_M),
    "tilted": tilted_hover_poses(BASE_T_TABLE, TCP_P_TIP_M, SPACING_M, HEIGHT_M, (10, 20, 30), 6),
}


def in_table(base_T_tcp: np.ndarray) -> np.ndarray:
    return transform_points(invert(BASE_T_TABLE), ball_centres_m(base_T_tcp, TCP_P_TIP_M))


def tilts_deg(base_T_tcp: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(-(base_T_tcp[:, :3, 2] @ BASE_T_TABLE[:3, 2])))


def path_lengths(base_T_tcp: np.ndarray) -> tuple[float, float]:
    """Flange travel (m) and total turn (rad) from pose to pose."""
    rotations = Rotation.from_matrix(base_T_tcp[:, :3, :3])
    return (float(np.linalg.norm(np.diff(base_T_tcp[:, :3, 3], axis=0), axis=1).sum()),
            float((rotations[:-1].inv() * rotations[1:]).magnitude().sum()))


def test_plans_have_one_rigid_pose_per_grid_point_and_orientation():
    assert PLANS["grid"].shape == (20, 4, 4)
    assert PLANS["tilted"].shape == (18, 4, 4)
    for poses in PLANS.values():
        np.testing.assert_allclose(np.linalg.det(poses[:, :3, :3]), 1.0)
        np.testing.assert_allclose(poses[:, 3], np.tile([0, 0, 0, 1.0], (len(poses), 1)))


def test_grid_taps_keep_the_tool_straight_down_and_tilted_taps_lean_by_the_planned_tilts():
    np.testing.assert_allclose(tilts_deg(PLANS["grid"]), 0, atol=1e-6)
    assert set(np.round(tilts_deg(PLANS["tilted"]), 6)) == {10, 20, 30}
    azimuths_deg = np.degrees(np.arctan2(*(PLANS["tilted"][:, :3, 2] @ BASE_T_TABLE[:3, 1::-1]).T))
    assert len(set(np.round(azimuths_deg, 6) % 360)) == 6


def test_the_tilt_does_not_follow_the_position_on_the_table():
    poses = PLANS["tilted"]
    columns = np.round(in_table(tap(poses))[:, 0] / SPACING_M - 0.5).astype(int)
    tilts = np.round(tilts_deg(poses), 6)
    for column in np.unique(columns):
        assert len(set(tilts[columns == column])) > 1


@pytest.mark.parametrize("name", PLANS)
def test_the_ball_hovers_at_the_approach_height_and_the_approach_along_tool_z_lands_on_the_grid(name):
    poses = PLANS[name]
    np.testing.assert_allclose(in_table(poses)[:, 2], HEIGHT_M, atol=1e-12)
    landed = in_table(tap(poses))
    np.testing.assert_allclose(landed[:, 2], 0, atol=1e-12)
    cells = landed[:, :2] / SPACING_M - 0.5
    np.testing.assert_allclose(cells, np.round(cells), atol=1e-9)
    assert len({tuple(cell) for cell in np.round(cells)}) == len(poses)


@pytest.mark.parametrize("name", PLANS)
def test_the_order_moves_less_than_row_by_row(name):
    poses = PLANS[name]
    cells = np.round(in_table(tap(poses))[:, :2] / SPACING_M).astype(int)
    row_by_row = poses[np.lexsort((cells[:, 0], cells[:, 1]))]
    travel, turn = path_lengths(poses)
    naive_travel, naive_turn = path_lengths(row_by_row)
    assert travel < naive_travel
    assert turn <= naive_turn + 1e-9
