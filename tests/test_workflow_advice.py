"""Advice for an ambiguous result: the reachable surface point where two candidate poses differ most."""

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation
from shapes import as_fixture

from fixwizard.demo import demo_fixture
from fixwizard.geometry.se3 import make_transform
from fixwizard.workflow.advice import distinguishing_tap
from fixwizard.workflow.live import tap_surface_distances_m


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
