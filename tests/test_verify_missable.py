"""How far a check's taps let the fixture be from the report's pose (``missable_move``), against the real ``verify``
search: the fixture moved along the direction the taps see least, by random small amounts, never lies farther from
the report's pose than a consistent verdict says; the direction net behind the figure comes as close to every unit
vector as its documented angle; taps no move fits to first order get no figure."""

import os

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard import report
from fixwizard.demo import demo_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot.sim import SimulatedCell
from fixwizard.solver.solve import solve
from fixwizard.synthetic import touching_ball_contacts
from fixwizard.workflow.missable_move import NET_ANGLE_RAD, missable_move, net_directions
from fixwizard.workflow.verify import fixture_of, suggest_check_points, verify
from shapes import as_fixture
from tui_cell import spread_taps

BALL_M, BOUND_M = 0.003, 0.00035
RUNS = int(os.environ.get("FUZZ_RUNS", "4"))


def test_the_direction_net_comes_within_its_angle_of_every_direction():
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(200_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    nearest = np.max(directions @ net_directions().T, axis=1)
    assert np.arccos(np.clip(np.min(nearest), -1.0, 1.0)) <= NET_ANGLE_RAD


def test_taps_no_pose_fits_to_first_order_get_no_figure():
    """One point of a brick tapped twice, 1.5 sample bounds above and below touching: no move fits both within the
    bound, so no figure is given (the verdict then never says to keep the pose), rather than a number or inf."""
    fixture = as_fixture("brick")
    rng = np.random.default_rng(1)
    taps, normals = touching_ball_contacts(fixture.mesh, 40, BALL_M / 2, rng)
    twice = np.vstack([taps, taps[:1] + 1.5 * BOUND_M * normals[:1], taps[:1] - 1.5 * BOUND_M * normals[:1]])
    assert 0.0 < missable_move(fixture, np.eye(4), taps, BALL_M, BOUND_M).point_m < fixture.radius_m
    assert missable_move(fixture, np.eye(4), twice, BALL_M, BOUND_M).point_m is None


@pytest.fixture(scope="module")
def demo_report(tmp_path_factory):
    """The simulated demo cell calibrated from 14 spread taps: the loaded report and its fixture."""
    fixture = demo_fixture()
    cell = SimulatedCell.with_fixture(fixture, seed=3)
    cell.connect()
    taps = spread_taps(cell, 14)
    solution = solve(fixture, taps, BALL_M, BOUND_M, max_cells=2e6, max_samples=2000)
    assert solution.status == "unique"
    path = report.write(tmp_path_factory.mktemp("missable") / "r.yaml",
                        report.report_dict(solution, fixture, taps, BALL_M, BOUND_M, BOUND_M / 3, simulated=True))
    loaded = report.load(path)
    return loaded, fixture_of(loaded)


def moved_about(base_p_centre: np.ndarray, base_m_move: np.ndarray, radius_m: float) -> np.ndarray:
    """The rigid move (4x4, base frame) ``(v, R w)``: a turn ``w`` about the centre, then the slide ``v``."""
    turn = Rotation.from_rotvec(base_m_move[3:] / radius_m)
    return (make_transform(np.eye(3), base_p_centre + base_m_move[:3]) @ make_transform(turn, np.zeros(3))
            @ make_transform(np.eye(3), -base_p_centre))


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(RUNS))
def test_a_move_along_the_least_seen_direction_verify_calls_consistent_stays_within_its_figure(demo_report, seed):
    """Eight suggested taps at the report's pose, then the fixture moved along the move they see least by a random
    0.2-1.5 times their figure (either way), its taps moved with it and given random errors within the sample
    bound: where ``verify`` calls them consistent, every fixture point lies within the figure the verdict gives of
    the report's pose (its largest displacement, over the mesh's vertices)."""
    loaded, fixture = demo_report
    base_T_cad = loaded.pose_to_use()[0]
    taps = np.array([point.base_p_ball_m for point in suggest_check_points(fixture, base_T_cad, BALL_M, count=8)])
    least = missable_move(fixture, base_T_cad, taps, BALL_M, BOUND_M)
    assert least.point_m is not None and 0.0 < least.point_m < fixture.radius_m
    rng = np.random.default_rng(seed)
    size = rng.uniform(0.2, 1.5) * least.point_m * rng.choice([-1.0, 1.0])
    move = moved_about(least.base_p_centre, size * least.base_m_move / np.linalg.norm(least.base_m_move),
                       fixture.radius_m)
    errors = rng.normal(size=taps.shape)
    errors *= (0.99 * BOUND_M * rng.random(len(taps)) / np.linalg.norm(errors, axis=1))[:, None]
    result = verify(loaded, fixture, transform_points(move, taps) + errors, BALL_M, BOUND_M)
    if not result.moved:
        base_p_vertices = transform_points(base_T_cad, fixture.mesh.vertices)
        displaced_m = np.max(np.linalg.norm(transform_points(move, base_p_vertices) - base_p_vertices, axis=1))
        assert result.missable is not None and result.missable.point_m is not None
        assert displaced_m <= result.missable.point_m
