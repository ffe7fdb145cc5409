"""Where to tap next: for a unique set the reachable point where a tap rules out most possible poses, for an
ambiguous one the point where the two candidate poses differ most."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fixwizard.demo import DEMO_TAPS, demo_fixture, disc_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.points import load_points
from fixwizard.solver.solve import solve
from fixwizard.workflow.advice import (
    PREFER_SHARE,
    PREFER_TRIES,
    REACHABLE_MIN_NORMAL_Z,
    TABLE_CLEARANCE_M,
    corners_cad_m,
    distinguishing_tap,
    next_tap,
    reachable_points,
)
from fixwizard.workflow.live import tap_surface_distances_m
from shapes import as_fixture


def test_poses_apart_along_x_are_told_apart_on_a_side_face_facing_x():
    brick = as_fixture("brick")  # 100 x 60 x 30 mm
    first = make_transform(np.eye(3), [0.4, 0.0, 0.015])
    second = make_transform(np.eye(3), [0.41, 0.0, 0.015])  # 10 mm further along x
    advice = distinguishing_tap(brick, first, second)
    assert advice.face in ("the side face towards base +x", "the side face towards base -x")
    assert advice.separation_m > 0.009
    assert "mm apart there" in advice.sentence() and advice.face in advice.sentence()


def test_the_advised_point_is_on_the_first_pose_and_off_the_second_by_the_separation():
    fixture = demo_fixture()
    first = make_transform(np.eye(3), [0.4, 0.0, 0.0])
    second = make_transform(Rotation.from_euler("z", 8.0, degrees=True), [0.4, 0.0, 0.0])
    advice = distinguishing_tap(fixture, first, second)
    distances = tap_surface_distances_m(fixture, np.stack([advice.base_p_point_m] * 2), 0.0, first)
    np.testing.assert_allclose(distances, 0.0, atol=1e-6)
    off_second = abs(tap_surface_distances_m(fixture, advice.base_p_point_m[None], 0.0, second)[0])
    assert off_second == np.float64(advice.separation_m)
    assert advice.base_n_face[2] >= -0.2  # the tool reaches it from above
    np.testing.assert_allclose(first[:3, :3] @ advice.cad_p_point_m + first[:3, 3], advice.base_p_point_m)


def test_no_advice_when_no_face_is_reachable_from_above():
    ceiling = trimesh.Trimesh([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]], [[0, 2, 1]])  # one face, facing down
    fixture = as_fixture("ceiling", ceiling)
    assert fixture.mesh.face_normals[0][2] == -1.0
    pose = make_transform(np.eye(3), [0.4, 0.0, 0.3])
    assert distinguishing_tap(fixture, pose, make_transform(np.eye(3), [0.41, 0.0, 0.3])) is None


@pytest.fixture(scope="module")
def demo_set():
    fixture = demo_fixture()
    return fixture, solve(fixture, load_points(DEMO_TAPS)[:12], 0.003, 0.001, max_cells=2e6)


def test_the_next_tap_lies_on_the_estimated_surface_where_a_tap_rules_out_most_poses(demo_set):
    fixture, solution = demo_set
    assert solution.status == "unique"
    advice = next_tap(fixture, solution, 0.001)
    distance = tap_surface_distances_m(fixture, advice.base_p_point_m[None], 0.0, solution.base_T_cad)[0]
    assert abs(distance) < 1e-6 and advice.base_n_face[2] >= REACHABLE_MIN_NORMAL_Z
    assert 0.5 < advice.ruled_out <= 1.0 and advice.separation_m > 0.001
    assert "rules out about" in advice.sentence() and advice.face in advice.sentence()
    base_p_vertices = transform_points(solution.base_T_cad, fixture.mesh.vertices)
    assert advice.base_p_point_m[2] >= base_p_vertices[:, 2].min() + TABLE_CLEARANCE_M
    assert np.min(np.linalg.norm(base_p_vertices - advice.base_p_corner_m, axis=1)) < 1e-9  # a real corner
    assert "mm from the corner at x" in advice.sentence()


def test_a_preference_picks_the_first_acceptable_of_the_candidates_nearly_as_good_as_the_best(demo_set):
    fixture, solution = demo_set
    best = next_tap(fixture, solution, 0.001)
    offered = []

    def refuse_all(advice) -> bool:
        offered.append(advice)
        return False

    assert np.array_equal(next_tap(fixture, solution, 0.001, prefer=refuse_all).base_p_point_m, best.base_p_point_m)
    assert 1 <= len(offered) <= PREFER_TRIES
    assert all(advice.ruled_out >= PREFER_SHARE * best.ruled_out for advice in offered)
    assert [advice.ruled_out for advice in offered] == sorted((advice.ruled_out for advice in offered), reverse=True)
    last = offered[-1]
    chosen = next_tap(fixture, solution, 0.001, prefer=lambda advice: advice.ruled_out == last.ruled_out
                      and np.array_equal(advice.base_p_point_m, last.base_p_point_m))
    np.testing.assert_array_equal(chosen.base_p_point_m, last.base_p_point_m)


def test_corners_are_the_vertices_where_three_face_directions_meet():
    assert len(corners_cad_m(demo_fixture())) == 16  # the bracket is a prism: every vertex is a corner
    assert len(corners_cad_m(disc_fixture())) == 12  # the round plate: the flat's and the notch's ends only


@pytest.mark.slow
def test_an_ambiguous_set_is_told_apart_and_a_set_without_an_estimate_gets_no_advice():
    from tui_cell import spread_taps, symmetric_cell

    cell = symmetric_cell()
    cell.connect()
    taps = spread_taps(cell, 12)
    ambiguous = solve(cell.fixture, taps, 0.003, 0.00035, max_cells=8e6)
    assert ambiguous.status == "ambiguous"
    advice = next_tap(cell.fixture, ambiguous, 0.00035)
    assert advice.ruled_out is None and "two most likely poses" in advice.sentence()
    inconsistent = solve(cell.fixture, np.vstack([taps, taps[-1] + [0.0, 0.0, 0.2]]), 0.003, 0.00035,
                         max_cells=2e5)
    assert inconsistent.status == "inconsistent" and next_tap(cell.fixture, inconsistent, 0.00035) is None


def test_no_point_under_an_overhang_is_offered():
    fixture = demo_fixture()  # an L-bracket with a step: lying on its side, the step overhangs part of the base
    pose = make_transform(Rotation.from_euler("x", 90, degrees=True), [0.4, 0.0, 0.0])
    pose[2, 3] -= transform_points(pose, fixture.mesh.vertices)[:, 2].min()
    cad_p_points, base_n_points = reachable_points(fixture, pose, seed=0)
    base_p_points = transform_points(pose, cad_p_points)
    fix_T_base = fixture.fix_T_cad @ np.linalg.inv(pose)
    for along_m in (0.01, 0.08):
        starts = transform_points(fix_T_base, base_p_points + along_m * base_n_points)
        up = np.broadcast_to(fix_T_base[:3, :3] @ [0.0, 0.0, 1.0], starts.shape)
        assert np.all(np.isinf(fixture.oracle.ray_hit_distance_m(starts, up)))
    assert len(cad_p_points) > 100
