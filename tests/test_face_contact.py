"""Which faces another face meets inside: the separating axes never call touching triangles apart (libigl's exact
triangle-triangle test is the reference), find a clear gap whatever the triangles' shapes, and on meshes a CAD tool
exports find no face met."""

import os
from pathlib import Path

import igl
import numpy as np
import pytest
import trimesh

import fixwizard
import shapes
from fixwizard.geometry.face_contact import (
    CROWDED,
    INNER_MARGIN,
    MET,
    UNMET,
    faces_met,
    segment_apart,
    triangles_apart,
)
from fixwizard.geometry.mesh_distance import MeshDistance
from fixwizard.mesh_hygiene import reliable_normals

RUNS = int(os.environ.get("FUZZ_RUNS", "1"))
TOLERANCE_M = 1e-15


def _random_triangle(rng: np.random.Generator, size_m: float) -> np.ndarray:
    """A triangle of any shape: well shaped, a needle, a flat sliver, or one of zero area."""
    corners = rng.normal(0.0, size_m, (3, 3))
    shape = rng.integers(4)
    if shape == 1:  # a needle
        corners[2] = corners[1] + rng.normal(0.0, size_m * 1e-6, 3)
    elif shape == 2:  # a flat sliver: the third corner near the segment of the others
        corners[2] = corners[0] + rng.random() * (corners[1] - corners[0]) + rng.normal(0.0, size_m * 1e-7, 3)
    elif shape == 3:  # zero area: the third corner on the line of the others
        corners[2] = corners[0] + rng.uniform(-1.0, 2.0) * (corners[1] - corners[0])
    return corners


def _touching_pair(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Two triangles that meet: crossing, one's corner on the other, coplanar and overlapping, sharing a corner or
    an edge and folded onto each other."""
    first = _random_triangle(rng, 1.0)
    second = _random_triangle(rng, 1.0)
    weights = rng.dirichlet(np.ones(3))
    on_first = weights @ first
    kind = rng.integers(5)
    if kind == 0:  # a corner on the other triangle
        second += on_first - second[rng.integers(3)]
    elif kind in (1, 2):  # coplanar and overlapping, or crossing: the other's centroid moved onto a point of this one
        normal = np.cross(first[1] - first[0], first[2] - first[0])
        if kind == 1 and np.linalg.norm(normal) > 0.0:
            normal /= np.linalg.norm(normal)
            second -= np.outer((second - first[0]) @ normal, normal)
        second += on_first - second.mean(axis=0)
    elif kind == 3:  # folded onto each other along a shared edge
        second[0], second[1] = first[0], first[1]
        second[2] = first[2] + rng.normal(0.0, 1e-3, 3) * rng.integers(2)
    else:  # sharing a corner, the other's opposite edge through this one
        second[0] = first[0]
        second[1] = on_first + rng.normal(0.0, 0.5, 3)
        second[2] = 2.0 * on_first - second[1]
    return first, second


@pytest.mark.parametrize("seed", range(RUNS))
def test_triangles_that_meet_are_never_called_apart(seed):
    """Pairs made to meet (each has a point of the other), of every shape; and random pairs that libigl's exact test
    finds crossing (it is no reference for triangles of zero area, which it takes as coplanar and hit)."""
    rng = np.random.default_rng(seed)
    for _ in range(3000):
        first, second = _touching_pair(rng)
        assert not triangles_apart(first, second, TOLERANCE_M), (seed, first.tolist(), second.tolist())
        assert not triangles_apart(second, first, TOLERANCE_M)
    crossing = 0
    for _ in range(3000):
        first, second = rng.normal(0.0, 1.0, (3, 3)), rng.normal(0.5, 1.0, (3, 3))
        if igl.tri_tri_intersection_test_3d(*(row[None] for row in first), *(row[None] for row in second))[0]:
            crossing += 1
            assert not triangles_apart(first, second, TOLERANCE_M), (seed, first.tolist(), second.tolist())
    assert crossing > 300


@pytest.mark.parametrize("seed", range(RUNS))
def test_triangles_a_clear_gap_apart_are_found_apart_whatever_their_shape(seed):
    """A face with a normal (as every face checked has) and a triangle of any shape, separated by a plane (random,
    or in the face's own plane, so coplanar pairs side by side too) with a gap of 1e-8 of their size: some axis
    shows it."""
    rng = np.random.default_rng(seed)
    for _ in range(3000):
        first, second = _random_triangle(rng, 1.0), _random_triangle(rng, 1.0)
        while not reliable_normals(first, np.arange(3)[None])[0]:  # a face whose plane signs (the one checked)
            first = _random_triangle(rng, 1.0)
        if rng.random() < 0.5:
            direction = rng.normal(size=3)
        else:  # in the first triangle's plane: coplanar triangles side by side
            normal = np.cross(first[1] - first[0], first[2] - first[0])
            second -= np.outer((second - first[0]) @ normal, normal) / max(normal @ normal, 1e-300)
            direction = np.cross(normal, rng.normal(size=3))
        direction /= np.linalg.norm(direction)
        gap = 1e-8
        second += ((first @ direction).max() - (second @ direction).min() + gap) * direction
        assert triangles_apart(first, second, TOLERANCE_M)
        assert triangles_apart(second, first, TOLERANCE_M)


@pytest.mark.parametrize("seed", range(RUNS))
def test_a_segment_through_a_triangle_or_along_it_is_never_apart_and_one_beside_it_is(seed):
    rng = np.random.default_rng(seed)
    for _ in range(3000):
        corners = _random_triangle(rng, 1.0)
        on_triangle = rng.dirichlet(np.ones(3)) @ corners
        along = rng.normal(size=3) * rng.choice([1.0, 1e-6])
        if rng.random() < 0.3:  # in the triangle's plane
            normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            along -= normal * (along @ normal) / max(normal @ normal, 1e-300)
        share = rng.random()
        ends = np.array([on_triangle - share * along, on_triangle + (1.0 - share) * along])
        assert not segment_apart(ends, corners, TOLERANCE_M)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        ends += ((corners @ direction).max() - (ends @ direction).min() + 1e-8) * direction
        assert segment_apart(ends, corners, TOLERANCE_M)


def _met(mesh: trimesh.Trimesh, step_m: float = 1e-7) -> np.ndarray:
    vertices, faces = np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)
    checked = np.flatnonzero(reliable_normals(vertices, faces))
    met = np.zeros(len(faces), bool)
    met[checked] = faces_met(MeshDistance(vertices, faces), vertices, faces, checked, step_m) == MET
    return met


def _uncrossed_meshes(name: str) -> list[trimesh.Trimesh]:
    if name == "box in 768 faces":
        return [trimesh.creation.box((0.2, 0.1, 0.02)).subdivide().subdivide().subdivide()]
    if name == "knife edge of 0.01 deg":
        tip = 0.1 * np.tan(np.radians(0.01))
        return [shapes.fan_capped_prism(np.array([[0.0, 0.0], [0.1, 0.0], [0.1, tip]]), 0.05)]
    if name == "fine sphere":
        return [trimesh.creation.icosphere(subdivisions=5, radius=0.05)]
    if name == "40 m from the origin":
        return [trimesh.creation.box((0.05, 0.04, 0.03)).apply_translation([40.0, -12.0, 3.0])]
    if name == "T-junctions":
        return [shapes.with_t_junctions(shapes.two_boss_bar(), np.random.default_rng(3))[0]]
    if name == "test shapes":
        return [shapes.l_prism(), shapes.cube(), shapes.brick(), shapes.triangular_prism(), shapes.cylinder(),
                shapes.cone(), shapes.two_boss_bar()] + [shapes.random_polytope(seed) for seed in range(5)]
    return [trimesh.load_mesh(path) for path in sorted((Path(fixwizard.__file__).parent / "data").glob("*.stl"))]


@pytest.mark.parametrize("name", ["box in 768 faces", "knife edge of 0.01 deg", "fine sphere", "40 m from the origin",
                                  "T-junctions", "test shapes", "demo meshes"])
def test_on_surfaces_that_do_not_cross_themselves_no_face_is_met(name):
    """Neighbours share only an edge or a corner, which lie outside every face's inner triangle: a flat face cut
    into many triangles, a knife edge, a fine sphere, a plant layout 40 m from its origin."""
    for mesh in _uncrossed_meshes(name):
        assert not np.any(_met(mesh)), name


def test_a_face_met_inside_is_found_even_where_the_crossing_is_small():
    """A spike of the surface through a large face, poking out 1 mm: the large face and the spike's faces."""
    box = trimesh.creation.box((0.1, 0.1, 0.02))
    vertices, faces = np.asarray(box.vertices), np.asarray(box.faces)
    apex = np.array([[0.013, 0.007, -0.011]])  # under the bottom (z = -0.01)
    top = np.flatnonzero(np.all(np.isclose(vertices[faces][:, :, 2], 0.01), axis=1))
    fan = [[8, 1, 5], [8, 5, 7], [8, 7, 3], [8, 3, 1]]  # trimesh's box: its top corners 1, 5, 7, 3 in turn
    mesh = trimesh.Trimesh(np.vstack([vertices, apex]), np.vstack([np.delete(faces, top, axis=0), fan]),
                           process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    met = _met(mesh)
    bottom = np.all(np.isclose(np.asarray(mesh.vertices)[mesh.faces][:, :, 2], -0.01), axis=1)
    assert np.count_nonzero(met & bottom) == 1  # the bottom triangle the spike pierces
    assert np.count_nonzero(met[-4:]) == 4  # the spike's four faces


def test_a_face_lying_just_over_another_is_met_through_its_centroid_segment():
    """A face hovering 50 nm over another's centre, touching nothing: inside the segment that the side check's
    points span, so the check could not trust them."""
    lower = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    upper = lower * 0.1 + [0.03, 0.03, 5e-8]
    vertices = np.vstack([lower, upper])
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    surface = MeshDistance(vertices, faces)
    assert faces_met(surface, vertices, faces, np.array([0]), 1e-7)[0] == MET
    assert faces_met(surface, vertices, faces, np.array([0]), 1e-8)[0] == UNMET


def test_the_inner_triangle_leaves_room_for_the_rounding_of_the_oracles_feature_margin():
    from fixwizard.fixture import DistanceOracle

    assert 0.0 < INNER_MARGIN < DistanceOracle.FEATURE_MARGIN


def test_a_face_with_more_faces_near_it_than_the_limit_is_left_crowded_never_called_unmet():
    """A disc's caps cut in fans of 400 thin faces: each cap face has about 100 faces near it (their boxes overlap
    its own), more than a limit of 50: crowded; the walls' faces have a few."""
    disc = trimesh.creation.cylinder(radius=0.05, height=0.02, sections=400)
    vertices, faces = np.asarray(disc.vertices, float), np.asarray(disc.faces, np.int64)
    status = faces_met(MeshDistance(vertices, faces), vertices, faces, np.arange(len(faces)), 1e-7, candidate_limit=50)
    on_caps = np.abs(np.asarray(disc.face_normals)[:, 2]) > 0.99
    assert np.all(status[on_caps] == CROWDED) and np.all(status[~on_caps] == UNMET)
