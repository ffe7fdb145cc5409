"""The robot's way above a suggested point: up, across high enough that no turn of the tool brings the ball down,
and down to a hover gap that stays clear of the fixture at every pose the set of possible poses allows; no way
at all when the set is too wide for that."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot.sim import SimulatedCell
from fixwizard.solver.estimates import Bounds
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import (
    CLEARANCE_M,
    HOVER_M,
    HOVER_STEP_M,
    MARGIN_M,
    MAX_HOVER_M,
    PATH_STEP_M,
    guaranteed_gap_m,
    hover_path,
    plan_hover,
)
from shapes import as_fixture

BALL_RADIUS_M = 0.0015
TCP_P_TIP_M = np.array([0.0, 0.0, 0.1])
ON_TABLE = make_transform(np.eye(3), [0.4, 0.0, 0.015])  # the 100 x 60 x 30 mm brick resting on the table


@pytest.fixture(scope="module")
def brick():
    return as_fixture("brick")


def within(displacement_m: float) -> list[Bounds]:
    """Bounds around the brick on the table that allow any fixture point to move ``displacement_m``."""
    return [Bounds(ON_TABLE, displacement_m, 0.0, displacement_m)]


def on_face(cad_p_point: list[float], cad_n_face: list[float]) -> TapAdvice:
    """Advice to tap the brick on the table at a CAD point, on the face with that outward normal."""
    cad_p_point = np.array(cad_p_point)
    return TapAdvice(transform_points(ON_TABLE, cad_p_point[None])[0], cad_p_point, np.array(cad_n_face, float), 0.0)


def pose_within(displacement_m: float, rng: np.random.Generator, fixture) -> np.ndarray:
    """A random brick pose near ``ON_TABLE`` that moves no fixture point farther than ``displacement_m``: a turn by
    w and a shift by t move a point at distance r from the CAD origin by at most |w| r + |t|."""
    turn, shift = rng.normal(size=3), rng.normal(size=3)
    radius_m = np.linalg.norm(fixture.mesh.vertices, axis=1).max()
    scale = displacement_m / (np.linalg.norm(turn) * radius_m + np.linalg.norm(shift))
    return ON_TABLE @ make_transform(Rotation.from_rotvec(turn * scale), shift * scale)


@pytest.mark.parametrize("displacement_m", [0.0, 0.004, 0.008, 0.012])
def test_the_hover_gap_is_the_narrowest_clear_of_every_possible_surface(brick, displacement_m):
    plan = plan_hover(on_face([0.0, 0.0, 0.015], [0, 0, 1]), brick, within(displacement_m), BALL_RADIUS_M)
    # over the top face the nearest surface is the face itself: the gap less the displacement must keep the margin
    needed_m = displacement_m + MARGIN_M + PATH_STEP_M
    gaps = np.arange(HOVER_M, MAX_HOVER_M + HOVER_STEP_M / 2, HOVER_STEP_M)
    assert plan.hover_m == pytest.approx(gaps[gaps >= needed_m - 1e-12][0])
    assert plan.safe_ball_z_m == pytest.approx(0.03 + displacement_m + CLEARANCE_M)


def test_there_is_no_way_down_when_the_possible_poses_differ_more_than_the_widest_gap_allows(brick):
    advice = on_face([0.0, 0.0, 0.015], [0, 0, 1])
    assert plan_hover(advice, brick, within(MAX_HOVER_M - MARGIN_M), BALL_RADIUS_M) is None


def test_every_mode_of_an_ambiguous_set_must_be_clear(brick):
    advice = on_face([0.04, 0.0, 0.015], [0, 0, 1])
    shifted = make_transform(np.eye(3), [0.4 + 0.05, 0.0, 0.04])  # a second mode whose top lies above the point
    assert plan_hover(advice, brick, within(0.0), BALL_RADIUS_M) is not None
    assert plan_hover(advice, brick, within(0.0) + [Bounds(shifted, 0.0, 0.0, 0.0)], BALL_RADIUS_M) is None


def test_the_guaranteed_gap_is_never_more_than_the_gap_at_any_allowed_pose(brick):
    rng = np.random.default_rng(0)
    base_p_points = transform_points(ON_TABLE, rng.uniform(-0.08, 0.08, (500, 3)))
    guaranteed = guaranteed_gap_m(brick, within(0.005), base_p_points)
    for _ in range(20):
        true_pose = pose_within(0.005, rng, brick)
        fix_p_points = transform_points(brick.fix_T_cad @ np.linalg.inv(true_pose), base_p_points)
        assert np.all(guaranteed <= brick.oracle.signed_distance_m(fix_p_points) + 1e-9)


def test_the_path_rises_then_crosses_then_comes_straight_down_to_face_the_point(brick):
    plan = plan_hover(on_face([0.05, 0.0, 0.0], [1, 0, 0]), brick, within(0.0), BALL_RADIUS_M)
    now = make_transform(Rotation.from_euler("x", 180, degrees=True), [0.3, 0.0, 0.12])
    lifted, across, hover = hover_path(plan, TCP_P_TIP_M, now)
    np.testing.assert_allclose(transform_points(hover, TCP_P_TIP_M[None])[0],
                               plan.advice.base_p_point_m + (BALL_RADIUS_M + plan.hover_m) * plan.advice.base_n_face,
                               atol=1e-12)
    np.testing.assert_allclose(hover[:3, 2], -plan.advice.base_n_face, atol=1e-12)
    for pose in (lifted, across):  # the flange so high that the ball clears the fixture however the tool turns
        assert pose[2, 3] - np.linalg.norm(TCP_P_TIP_M) >= plan.safe_ball_z_m - 1e-12
    np.testing.assert_allclose(lifted[:2, 3], now[:2, 3])
    np.testing.assert_allclose(across[:2, 3], hover[:2, 3])
    assert np.isclose(np.linalg.det(hover[:3, :3]), 1.0)


# the tool starts flat, pointing -x, spun so that turning it to point +x swings the ball down through the fixture
# unless the flange is high enough
TOOL_FLAT = make_transform(np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]]), [0.6, 0.0, 0.02])


@pytest.mark.parametrize("cad_p_point, cad_n_face", [([-0.05, 0.0, 0.0], [-1, 0, 0]), ([0.02, 0.01, 0.015], [0, 0, 1]),
                                                     ([-0.01, -0.03, 0.005], [0, -1, 0])])
def test_the_robot_gets_above_the_point_without_touching_the_fixture_wherever_the_set_allows_it_to_be(
        brick, cad_p_point, cad_n_face):
    """The simulated cell makes a protective stop if the ball hits anything on the way."""
    rng = np.random.default_rng(1)
    advice = on_face(cad_p_point, cad_n_face)
    plan = plan_hover(advice, brick, within(0.006), BALL_RADIUS_M)
    for _ in range(5):
        cell = SimulatedCell.with_fixture(brick, base_T_cad=pose_within(0.006, rng, brick), tcp_p_tip_m=TCP_P_TIP_M,
                                          fk_error_bound_m=0.0)
        cell.connect()
        cell.guide_by_hand(TOOL_FLAT)
        for pose in hover_path(plan, TCP_P_TIP_M, cell.base_T_tcp()):
            cell.move_linear(pose)
        base_p_ball = transform_points(cell.base_T_tcp(), TCP_P_TIP_M[None])
        fix_p_ball = transform_points(brick.fix_T_cad @ np.linalg.inv(cell.truth.base_T_cad), base_p_ball)
        assert brick.oracle.signed_distance_m(fix_p_ball)[0] >= BALL_RADIUS_M + MARGIN_M
        result = cell.tap()
        assert result.travel_m <= plan.hover_m + 0.006 + 1e-3  # it touched the fixture near the point
