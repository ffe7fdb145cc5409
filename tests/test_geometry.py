"""Geometry pieces against brute force: enclosing balls, the SOCP box, rotation and position cells."""

import itertools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.se3 import quaternion_angle_rad, rotation_angle_rad
from fixwizard.geometry.so3_grid import RotationGrid
from fixwizard.geometry.socp_box import ball_intersection_box


def brute_force_ball_radius(points: np.ndarray) -> float:
    """Smallest ball through 1..d+1 of the points that holds them all."""
    dim = points.shape[1]
    best = np.inf
    for size in range(1, dim + 2):
        for support in itertools.combinations(points, size):
            origin = support[0]
            edges = np.array([p - origin for p in support[1:]]).reshape(-1, dim)
            gram = edges @ edges.T
            coefficients = np.linalg.lstsq(2 * gram, np.diag(gram), rcond=None)[0] if size > 1 else np.zeros(0)
            center = origin + coefficients @ edges
            radius = np.linalg.norm(origin - center)
            if np.all(np.linalg.norm(points - center, axis=1) <= radius * (1 + 1e-9) + 1e-12):
                best = min(best, radius)
    return best


@pytest.mark.parametrize("dim", [2, 3, 4])
@pytest.mark.parametrize("seed", range(8))
def test_minimum_enclosing_ball_matches_brute_force(dim, seed):
    points = np.random.default_rng(seed).normal(size=(9, dim))
    ball = minimum_enclosing_ball(points)
    assert ball.radius == pytest.approx(brute_force_ball_radius(points), rel=1e-9)
    assert np.all(np.linalg.norm(points - ball.center, axis=1) <= ball.radius)


def _centre_is_in_the_hull_of_the_boundary_points(points: np.ndarray, ball) -> bool:
    """The optimality certificate of an enclosing ball: its centre is a convex combination of the points on its
    boundary (else moving the centre towards them would shrink it)."""
    from scipy.optimize import nnls

    distances = np.linalg.norm(points - ball.center, axis=1)
    boundary = np.unique(points[distances >= ball.radius * (1 - 1e-7)], axis=0)
    system = np.vstack([boundary.T, np.ones(len(boundary)) * 10.0])
    weights, residual = nnls(system, np.append(ball.center, 10.0))
    return residual <= 1e-7 * max(ball.radius, 1e-6 * float(np.abs(points).max()), 1e-12)


@pytest.mark.parametrize("kind", ["sphere surface", "cube", "clusters", "flat", "on a line", "repeated",
                                  "far offset", "one point"])
@pytest.mark.parametrize("count", [2, 7, 3000, 300_000])
def test_minimum_enclosing_ball_of_many_points_holds_them_and_is_smallest(kind, count):
    """Point sets as meshes and cell sets make them: a sphere's surface (every point on the hull), a cube's
    lattice, clusters, flat and collinear sets, repeated points, far from the origin; from 2 to 300,000 points."""
    rng = np.random.default_rng(count)
    if kind == "sphere surface":
        points = rng.normal(size=(count, 3))
        points /= np.linalg.norm(points, axis=1, keepdims=True)
    elif kind == "cube":
        points = rng.integers(0, 20, (count, 3)) * 0.01
    elif kind == "clusters":
        points = rng.normal(size=(5, 3))[rng.integers(0, 5, count)] + rng.normal(size=(count, 3)) * 0.01
    elif kind == "flat":
        points = np.column_stack([rng.normal(size=(count, 2)), np.zeros(count)])
    elif kind == "on a line":
        points = np.outer(rng.normal(size=count), [0.3, -0.2, 0.5])
    elif kind == "repeated":
        points = np.repeat(rng.normal(size=(3, 3)), count // 3 + 1, axis=0)[:count]
    elif kind == "far offset":
        points = rng.normal(size=(count, 3)) * 0.05 + [4e4, -2e4, 1e3]
    else:
        points = np.repeat(rng.normal(size=(1, 3)), count, axis=0)
    ball = minimum_enclosing_ball(points)
    assert np.all(np.linalg.norm(points - ball.center, axis=1) <= ball.radius)
    assert _centre_is_in_the_hull_of_the_boundary_points(points, ball)


def test_minimum_enclosing_ball_of_two_points_is_centred_between_them():
    ball = minimum_enclosing_ball(np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.1, 0]]))
    assert ball.center == pytest.approx([0.5, 0, 0])
    assert ball.radius == pytest.approx(0.5)


@pytest.mark.parametrize("seed", range(6))
def test_socp_box_holds_every_point_of_the_ball_intersection(seed):
    rng = np.random.default_rng(seed)
    radius = 0.15
    centres = np.array([0.4, 0.1, 0.2]) + rng.normal(size=(rng.integers(3, 15), 3)) * 0.03
    low, high = ball_intersection_box(centres, radius)
    candidates = centres[0] + rng.uniform(-radius, radius, size=(400_000, 3))
    inside = np.all(np.linalg.norm(candidates[:, None, :] - centres[None], axis=2) <= radius, axis=1)
    points = candidates[inside]
    assert len(points) > 100
    assert np.all(points >= low) and np.all(points <= high)
    # tight: the extreme sampled points come close to every face of the box
    assert np.all(points.min(axis=0) - low < 0.01) and np.all(high - points.max(axis=0) < 0.01)


def test_socp_box_is_none_when_the_balls_do_not_meet():
    assert ball_intersection_box(np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.5, 0]]), 0.3) is None


@pytest.mark.parametrize("level", range(7))
def test_rotation_cell_bound_gamma_holds_for_random_rotations(level):
    grid = RotationGrid()
    rotations = Rotation.random(100_000, random_state=level)
    cells = grid.cell_of(level, rotations)
    angles = (grid.centers(level, cells).inv() * rotations).magnitude()
    assert np.all(angles <= grid.gamma(level, cells))


@pytest.mark.parametrize("level", range(5))
def test_rotation_children_partition_their_parent(level):
    grid = RotationGrid()
    rotations = Rotation.random(20_000, random_state=100 + level)
    parents = grid.cell_of(level, rotations)
    children = grid.cell_of(level + 1, rotations)
    family = grid.children(level, parents).reshape(-1, 8)
    assert np.all(np.any(family == children[:, None], axis=1))
    assert len(np.unique(grid.children(level, np.arange(grid.n_cells(level))))) == grid.n_cells(level + 1)


def test_rotation_samples_lie_in_their_cells():
    grid = RotationGrid()
    cells = np.random.default_rng(3).integers(0, grid.n_cells(4), 5000)
    samples = grid.sample(4, cells, np.random.default_rng(4))
    assert np.all(grid.cell_of(4, samples) == cells)


def test_rotation_cell_centres_lie_in_their_cells():
    grid = RotationGrid()
    cells = np.arange(grid.n_cells(2))
    assert np.all(grid.cell_of(2, grid.centers(2, cells)) == cells)


def test_rotation_cell_centre_matrices_are_proper_rotations_and_match_the_centres():
    grid = RotationGrid()
    cells = np.random.default_rng(6).integers(0, grid.n_cells(5), 2000)
    matrices = grid.center_matrices(5, cells)
    assert np.allclose(np.swapaxes(matrices, 1, 2) @ matrices, np.eye(3), atol=1e-14)
    assert np.allclose(np.linalg.det(matrices), 1.0, atol=1e-14)
    assert np.allclose(grid.centers(5, cells).as_matrix(), matrices, atol=1e-14)


def _rotations_by(angles_rad: np.ndarray, seed: int) -> Rotation:
    """Rotations by the given angles about random axes."""
    axes = np.random.default_rng(seed).normal(size=(len(angles_rad), 3))
    return Rotation.from_rotvec(axes / np.linalg.norm(axes, axis=1, keepdims=True) * angles_rad[:, None])


def test_the_rotation_angle_matches_scipy_for_random_rotations():
    rotations = Rotation.random(20000, random_state=3)
    assert np.allclose(rotation_angle_rad(rotations.as_matrix()), rotations.magnitude(), rtol=0.0, atol=1e-14)


@pytest.mark.parametrize("angle_rad", [1e-12, 1e-9, 1e-6, 1e-3])
def test_the_rotation_angle_keeps_its_digits_near_zero(angle_rad):
    """Where ``arccos((trace - 1) / 2)`` returns 0 (the cosine rounds to 1), the angle keeps 7 digits."""
    rotations = _rotations_by(np.full(1000, angle_rad), 4)
    assert np.allclose(rotation_angle_rad(rotations.as_matrix()), angle_rad, rtol=1e-7, atol=0.0)


@pytest.mark.parametrize("below_pi_rad", [0.0, 1e-12, 1e-9, 1e-6, 1e-3])
def test_the_rotation_angle_keeps_its_digits_near_a_half_turn(below_pi_rad):
    """Near pi ``arccos`` of the trace errs by about ``sqrt(u)`` (1e-8 rad); the angle stays within 1e-13."""
    rotations = _rotations_by(np.full(1000, np.pi - below_pi_rad), 5)
    assert np.allclose(rotation_angle_rad(rotations.as_matrix()), np.pi - below_pi_rad, rtol=0.0, atol=1e-13)
    assert np.allclose(rotation_angle_rad(rotations.as_matrix()), rotations.magnitude(), rtol=0.0, atol=1e-13)


def test_the_angle_between_two_rotations_is_the_angle_of_the_relative_rotation_and_broadcasts():
    reference = Rotation.random(random_state=8)
    offsets = _rotations_by(np.geomspace(1e-9, np.pi, 5000), 8)
    others = (reference * offsets).as_matrix()
    angles = rotation_angle_rad(reference.as_matrix().T @ others)
    assert angles.shape == (5000,)
    assert np.allclose(angles, offsets.magnitude(), rtol=1e-7, atol=1e-14)
    assert rotation_angle_rad(others.reshape(50, 100, 3, 3)).shape == (50, 100)
    assert float(rotation_angle_rad(np.eye(3))) == 0.0
    assert float(rotation_angle_rad(np.diag([1.0, -1.0, -1.0]))) == pytest.approx(np.pi, abs=1e-15)


@pytest.mark.parametrize("angle_rad", [0.0, 1e-12, 1e-6, 1e-2, 1.0, np.pi - 1e-6, np.pi])
def test_the_quaternion_angle_is_the_relative_rotation_angle_for_either_sign(angle_rad):
    """Also where the dot product rounds to 1 (tiny angles) and near a half turn, whichever sign each quaternion
    has."""
    reference = Rotation.random(1000, random_state=9)
    others = reference * _rotations_by(np.full(1000, angle_rad), 10)
    signs = np.where(np.random.default_rng(11).random(1000) < 0.5, -1.0, 1.0)[:, None]
    angles = quaternion_angle_rad(reference.as_quat(), signs * others.as_quat())
    assert np.allclose(angles, angle_rad, rtol=1e-7, atol=1e-14)
    assert np.all((angles >= 0.0) & (angles <= np.pi))


def test_the_quaternion_angle_matches_the_matrix_angle_for_random_pairs():
    first, second = Rotation.random(20000, random_state=12), Rotation.random(20000, random_state=13)
    matrix_angles = rotation_angle_rad(np.swapaxes(first.as_matrix(), 1, 2) @ second.as_matrix())
    assert np.allclose(quaternion_angle_rad(first.as_quat(), second.as_quat()), matrix_angles, rtol=0.0, atol=1e-13)


def test_position_cell_bound_holds_for_points_in_the_cell():
    grid = PositionGrid(corner_m=np.array([0.1, -0.2, 0.3]), side_m=0.08)
    rng = np.random.default_rng(0)
    for level in range(6):
        points = grid.corner_m + rng.random((10_000, 3)) * grid.side_m
        cells = np.array([grid.cell_of(level, point) for point in points[:500]])
        distance = np.linalg.norm(points[:500] - grid.centers_m(level, cells), axis=1)
        assert np.all(distance <= grid.half_diagonal_m(level))
        children = grid.children(cells).reshape(-1, 8, 3)
        finer = np.array([grid.cell_of(level + 1, point) for point in points[:500]])
        assert np.all(np.any(np.all(children == finer[:, None, :], axis=2), axis=1))


@pytest.mark.parametrize("gap", [1e-3, 1e-5, 1e-7, 1e-9, 1e-11, 0.0])
def test_the_start_box_of_two_nearly_tangent_balls_holds_their_touching_point(gap):
    """cvxopt raises ValueError ('math domain error') on such problems; the box falls back to the balls' boxes."""
    radius = 0.13
    centres = np.array([[0.4, 0.0, 0.1], [0.4 + 2 * radius - gap, 0.0, 0.1]])
    low, high = ball_intersection_box(centres, radius)
    touching = centres.mean(axis=0)
    assert np.all(low <= touching) and np.all(touching <= high)


def test_the_finest_rotation_level_still_holds_each_rotation_within_gamma_of_its_cell_centre():
    """Cell ids are int64: level 19 would overflow (and did place rotations in cells 130 degrees away), so the
    grid stops at level 18 and the search then splits positions only."""
    from fixwizard.geometry.so3_grid import MAX_LEVEL, RotationGrid

    grid = RotationGrid()
    rotations = Rotation.random(2000, random_state=3)
    for level in (MAX_LEVEL - 2, MAX_LEVEL):
        cells = grid.cell_of(level, rotations)
        assert np.all(cells >= 0) and np.all(cells < grid.n_cells(level))
        angles = (grid.centers(level, cells).inv() * rotations).magnitude()
        assert np.all(angles <= grid.gamma(level, cells))
    with pytest.raises(ValueError):
        grid.children(MAX_LEVEL, cells[:1])


@pytest.mark.parametrize("kind", ["ellipsoid", "box lattice", "rounded bar", "few"])
@pytest.mark.parametrize("count", [300, 20_000, 200_000])
def test_the_hull_cover_holds_every_hull_vertex_in_a_few_small_balls(kind, count):
    """A finely tessellated rounded part has every vertex on its hull: the displacement bounds then run over at
    most ``MAX_POINTS`` balls that hold every hull vertex (a few per cent of the radius wide); a hull of few
    vertices is its own cover (radii zero)."""
    from scipy.spatial import ConvexHull, cKDTree

    from fixwizard.geometry.hull_cover import MAX_POINTS, hull_cover

    rng = np.random.default_rng(count)
    if kind == "ellipsoid":
        points = rng.normal(size=(count, 3))
        points = points / np.linalg.norm(points, axis=1, keepdims=True) * [0.08, 0.05, 0.02] + [0.3, -0.1, 0.02]
    elif kind == "box lattice":
        points = rng.integers(0, 50, (count, 3)) * [0.002, 0.001, 0.0005]
    elif kind == "rounded bar":
        angle = rng.uniform(0, 2 * np.pi, count)
        points = np.column_stack([rng.uniform(0, 1.0, count), 0.01 * np.cos(angle), 0.01 * np.sin(angle)])
    else:
        points = rng.normal(size=(12, 3))[rng.integers(0, 12, count)]
    cover = hull_cover(points)
    vertices = points[ConvexHull(points).vertices]
    assert len(cover.points_m) <= MAX_POINTS
    # each vertex against its nearest centres, and against every centre where those do not hold it
    distances, nearest = cKDTree(cover.points_m).query(vertices, k=min(16, len(cover.points_m)))
    distances, nearest = distances.reshape(len(vertices), -1), nearest.reshape(len(vertices), -1)
    outside = vertices[np.min(distances - cover.radii_m[nearest], axis=1) > 0.0]
    gaps = np.linalg.norm(outside[:, None] - cover.points_m[None], axis=2) - cover.radii_m
    assert np.all(np.min(gaps, axis=1) <= 0.0)
    size = np.max(np.ptp(points, axis=0))
    assert np.max(cover.radii_m) <= 0.03 * size
    if len(vertices) <= MAX_POINTS:  # a hull of few vertices is its own cover (up to rounding, for a large cloud)
        assert len(cover.points_m) == len(vertices) and np.all(cover.radii_m <= 1e-9 * size)


def test_the_enclosing_ball_of_cell_corners_far_from_the_origin_ends_at_once():
    """Seven corners of a 0.1 mm cube of cells 0.6 m from the origin (cospherical, as sibling cells are): rounding
    left a corner a hair outside a ball that could not grow, and the pivoting looped with a growing support."""
    import itertools
    import time

    rng = np.random.default_rng(0)
    for _ in range(200):
        side = 10 ** rng.uniform(-6, -3)
        corners = np.array(list(itertools.product([0.0, 1.0], repeat=3)))[rng.permutation(8)[:rng.integers(5, 9)]]
        points = rng.uniform(-0.6, 0.6, 3) + corners * side
        started = time.perf_counter()
        ball = minimum_enclosing_ball(points)
        assert time.perf_counter() - started < 0.5
        assert np.all(np.linalg.norm(points - ball.center, axis=1) <= ball.radius)
        assert ball.radius <= np.sqrt(3) / 2 * side * (1 + 1e-9)
