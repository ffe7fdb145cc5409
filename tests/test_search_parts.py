"""Pieces of the search that carry the guarantee: the distance lattice and the cell sets."""

import numba
import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fixwizard.geometry.mesh_distance import triangle_interval_m
from fixwizard.geometry.octree import PositionGrid
from fixwizard.geometry.se3 import make_transform
from fixwizard.solver.cells import root_cells
from fixwizard.solver.distance_grid import DistanceGrid
from fixwizard.solver.interval_kernel import _nearest_vertex_interval_m, signed_interval_m
from shapes import SHAPES, as_fixture


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_distance_lattice_interval_holds_the_exact_signed_distance(name):
    fixture = as_fixture(name)
    grid = DistanceGrid(fixture.oracle)
    rng = np.random.default_rng(0)
    points = rng.uniform(-2.0, 2.0, (100_000, 3)) * fixture.radius_m
    exact_low, exact_high, _ = fixture.oracle.distance_interval_m(points)
    low, high = grid.interval_m(points)
    assert np.all(exact_high >= low) and np.all(exact_low <= high)


@numba.njit
def _nearest_vertex_intervals_m(points_m, lattice):
    bounds = np.empty((len(points_m), 2))
    for row in range(len(points_m)):
        bounds[row, 0], bounds[row, 1], _ = _nearest_vertex_interval_m(points_m[row, 0], points_m[row, 1],
                                                                       points_m[row, 2], lattice)
    return bounds


@pytest.mark.parametrize("name", ["l_prism", "cylinder"])
def test_the_nearest_vertex_bound_of_the_cheap_pass_holds_and_the_voxel_interval_lies_within_it(name):
    fixture = as_fixture(name)
    grid = DistanceGrid(fixture.oracle)
    points = np.random.default_rng(2).uniform(-2.0, 2.0, (50_000, 3)) * fixture.radius_m
    exact_low, exact_high, _ = fixture.oracle.distance_interval_m(points)
    nearest = _nearest_vertex_intervals_m(points, grid.kernel_arguments)
    assert np.all(exact_high >= nearest[:, 0]) and np.all(exact_low <= nearest[:, 1])
    low, high = grid.interval_m(points)
    assert np.all(low >= nearest[:, 0]) and np.all(high <= nearest[:, 1])
    assert np.mean(high - low) < np.mean(nearest[:, 1] - nearest[:, 0])


def test_a_degenerate_face_still_bounds_the_distance_from_above():
    from fixwizard.geometry.mesh_distance import MeshDistance
    from fixwizard.solver.interval_kernel import face_distances_m

    vertices = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.0, 0.0]])
    triangles = np.array([[0, 1, 2], [0, 3, 1], [0, 3, 3], [0, 0, 0]])  # collinear, two corners equal, a point
    points = np.random.default_rng(5).uniform(-0.03, 0.03, (300, 3))
    rows = MeshDistance(vertices, triangles).rows
    for face in range(len(triangles)):
        bound = face_distances_m(points, np.full(len(points), face), rows)
        corners = vertices[triangles[face]]
        farthest = np.max([np.linalg.norm(points - corner, axis=1) for corner in corners], axis=0)
        assert np.all(np.isfinite(bound)) and np.all(bound <= farthest + 1e-8)  # a point of the face, not beyond
        along_x = np.clip(points[:, 0], corners[:, 0].min(), corners[:, 0].max())
        assert np.all(bound >= np.linalg.norm(points - np.column_stack([along_x, 0 * along_x, 0 * along_x]), axis=1))


def test_a_cached_lattice_is_the_computed_one_and_a_damaged_cache_file_is_rebuilt(tmp_path, monkeypatch):
    monkeypatch.setenv("FIXWIZARD_CACHE", str(tmp_path))
    fixture = as_fixture("l_prism")
    built = DistanceGrid(fixture.oracle)
    [cached] = tmp_path.glob("lattice-*.npz")
    loaded = DistanceGrid(fixture.oracle)
    for mine, theirs in zip(built.kernel_arguments, loaded.kernel_arguments, strict=True):
        assert np.array_equal(mine, theirs)
    cached.write_bytes(b"not a lattice")
    rebuilt = DistanceGrid(fixture.oracle)
    assert np.array_equal(rebuilt.kernel_arguments[3], built.kernel_arguments[3])
    with np.load(cached) as stored:
        assert np.array_equal(stored["values"], built.kernel_arguments[3])


def test_cell_set_split_and_subset_keep_each_pose_in_exactly_one_cell():
    cells = root_cells(PositionGrid(corner_m=np.zeros(3), side_m=0.1))
    cells = cells.split_rotations().split_positions().split_rotations()
    rng = np.random.default_rng(1)
    for _ in range(20):
        pose = make_transform(Rotation.random(random_state=rng.integers(1 << 30)), rng.random(3) * 0.1)
        assert cells.contains(pose)
        rotation = cells.rotation_grid.cell_of(cells.rotation_level, Rotation.from_matrix(pose[:3, :3]))[0]
        assert not cells.subset(cells.rotation_cells != rotation).contains(pose)
    assert len(np.unique(np.column_stack([cells.rotation_cells, cells.position_cells]), axis=0)) == len(cells)


def small_problem():
    from fixwizard.solver.search import SearchProblem
    from fixwizard.synthetic import touching_ball_centres

    fixture = as_fixture("l_prism")
    taps = touching_ball_centres(fixture.mesh, 8, 0.0015, np.random.default_rng(0))
    return fixture, SearchProblem(fixture.oracle, fixture.radius_m, taps, 0.0015, 0.0005)


def test_search_reports_progress_per_level_and_stops_when_cancelled():
    import threading

    from fixwizard.solver.search import SearchCancelled, search

    _, problem = small_problem()
    steps = []
    search(problem, 5e4, progress=steps.append)
    assert steps[0].rotation_level == 0 and steps[0].evaluated == 72
    assert [step.elapsed_s for step in steps] == sorted(step.elapsed_s for step in steps)
    cancel = threading.Event()
    with pytest.raises(SearchCancelled):
        search(problem, 5e4, progress=lambda step: cancel.set(), cancel=cancel)


@pytest.mark.parametrize("bound, diameter, match", [(0.0, 0.003, "sample bound"), (-0.001, 0.003, "sample bound"),
                                                    (float("nan"), 0.003, "sample bound"),
                                                    (0.001, -0.003, "ball diameter")])
def test_solve_refuses_impossible_bounds(bound, diameter, match):
    from fixwizard.errors import InputError
    from fixwizard.solver.solve import solve

    fixture, problem = small_problem()
    with pytest.raises(InputError, match=match):
        solve(fixture, problem.base_p_taps, diameter, bound)


def test_float32_interval_ends_are_rounded_outward():
    from fixwizard.solver.search import _round_down_f32, _round_up_f32

    values = np.random.default_rng(3).normal(size=100_000) * np.logspace(-6, 0, 100_000)
    assert np.all(_round_down_f32(values).astype(np.float64) <= values)
    assert np.all(_round_up_f32(values).astype(np.float64) >= values)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_the_distance_to_any_one_face_bounds_the_distance_from_above_and_is_exact_for_its_face(name):
    from fixwizard.solver.interval_kernel import face_distances_m
    from fixwizard.synthetic import closest_on_triangles, exact_distances_m

    fixture = as_fixture(name)
    rng = np.random.default_rng(4)
    points = rng.uniform(-1.5, 1.5, (2000, 3)) * fixture.radius_m
    vertices, triangles = fixture.oracle.mesh_arrays
    faces = rng.integers(0, len(triangles), len(points))
    corners = vertices[triangles[faces]]
    on_face = np.linalg.norm(points - closest_on_triangles(points, corners[:, 0], corners[:, 1], corners[:, 2]), axis=1)
    bound = face_distances_m(points, faces, fixture.oracle.triangle_rows)
    assert np.all(bound >= on_face) and np.all(bound - on_face <= 1e-12)
    surface = exact_distances_m(trimesh.Trimesh(vertices, triangles, process=False), points)
    assert np.all(bound >= surface)


def test_locate_finds_the_cell_holding_each_pose_and_no_cell_outside_the_set():
    from fixwizard.solver.cells import root_cells

    cells = root_cells(PositionGrid(np.array([-0.1, -0.1, -0.1]), 0.2))
    for _ in range(2):
        cells = cells.split_rotations().split_positions()
    rng = np.random.default_rng(0)
    kept = rng.random(len(cells)) < 0.3
    subset = cells.subset(kept)
    rows = rng.integers(0, len(cells), 20_000)
    rotations = cells.rotation_grid.sample(cells.rotation_level, cells.rotation_cells[rows], rng)
    side = cells.position_grid.cell_side_m(cells.position_level)
    positions = cells.positions_m(rows) + (rng.random((len(rows), 3)) - 0.5) * side
    found = subset.locate(rotations, positions)
    assert np.array_equal(found >= 0, kept[rows])
    assert np.array_equal(np.flatnonzero(kept)[found[found >= 0]], rows[found >= 0])
    outside = subset.locate(rotations[:10], positions[:10] + 1.0)  # a metre beyond the root cube
    assert np.all(outside == -1)


def test_a_located_set_pickles_as_before_and_locates_alike_after_the_trip():
    import pickle

    cells = root_cells(PositionGrid(np.array([-0.1, -0.1, -0.1]), 0.2)).split_rotations().split_positions()
    rng = np.random.default_rng(1)
    rows = rng.integers(0, len(cells), 500)
    rotations = cells.rotation_grid.sample(cells.rotation_level, cells.rotation_cells[rows], rng)
    positions = cells.positions_m(rows)
    before = pickle.dumps(cells)
    found = cells.locate(rotations, positions)  # builds the set's lookup
    assert pickle.dumps(cells) == before  # the lookup stays behind, not sent to or from a solver process
    assert np.array_equal(pickle.loads(before).locate(rotations, positions), found)
    assert np.array_equal(found, rows)


@numba.njit
def _signed_intervals(points: np.ndarray, mesh: tuple,
                      cap: float = np.inf) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    low, high = np.empty(len(points)), np.empty(len(points))
    faces, signable = np.empty(len(points), np.int64), np.empty(len(points), np.bool_)
    for row in range(len(points)):
        low[row], high[row], faces[row], signable[row] = signed_interval_m(points[row], -1, False, mesh, cap)
    return low, high, faces, signable


def _knife() -> trimesh.Trimesh:
    """A wedge with a 6 degree knife edge along z: beyond the edge, points above the plane of one face lie below
    the other's, so a face's plane tells their sign wrongly."""
    outline = np.array([[0.0, 0.0], [0.08, -0.0042], [0.08, 0.0042]])
    mesh = trimesh.creation.extrude_triangulation(outline, np.array([[0, 1, 2]]), height=0.02)
    return mesh if mesh.volume > 0 else trimesh.Trimesh(mesh.vertices, np.asarray(mesh.faces)[:, ::-1])


@pytest.mark.parametrize("name", ["knife", *sorted(SHAPES)])
def test_the_compiled_exact_stage_signs_as_the_oracle_does_or_leaves_the_sign_to_it(name):
    """Points all around the surface (and around the knife's edge): where the compiled stage signs an interval, it
    is the oracle's, bit for bit; it leaves to the oracle every point whose closest point lies on an edge or a
    corner (beyond the knife's edge those are outside, though below one face's plane)."""
    fixture = as_fixture(name, _knife()) if name == "knife" else as_fixture(name)
    rng = np.random.default_rng(7)
    vertices, triangles = fixture.oracle.mesh_arrays
    surface = np.vstack([trimesh.sample.sample_surface(trimesh.Trimesh(vertices, triangles), 3000, seed=7)[0],
                         vertices[rng.integers(len(vertices), size=1000)]])
    points = np.vstack([surface + rng.normal(0.0, 0.003, surface.shape),
                        surface + rng.normal(0.0, 1e-5, surface.shape)])
    if name == "knife":
        edge = np.array([[0.0, 0.0, z] for z in rng.uniform(0.002, 0.018, 3000)]) - fixture.cad_p_center
        points = np.vstack([points, edge + rng.normal(0.0, 0.002, edge.shape) * [1.0, 1.0, 0.0]])
    low, high, faces, signable = _signed_intervals(points, fixture.oracle.kernel_arguments)
    oracle_low, oracle_high, oracle_faces = fixture.oracle.distance_interval_m(points)
    assert fixture.signed
    np.testing.assert_array_equal(low[signable], oracle_low[signable])
    np.testing.assert_array_equal(high[signable], oracle_high[signable])
    np.testing.assert_array_equal(faces, oracle_faces)
    assert 0 < np.count_nonzero(signable) < len(points)


@pytest.mark.parametrize("name", ["knife", *sorted(SHAPES)])
def test_the_capped_exact_stage_calls_a_point_far_only_where_the_oracle_puts_it_beyond_the_cap_on_either_side(name):
    """The exact stage caps its search at the band's outer edge (a distance beyond it, of either sign, misses the
    band): a point it calls far has the oracle's signed distance at least the cap away from the surface, inside
    or outside; every other point gets the uncapped result bit for bit."""
    fixture = as_fixture(name, _knife()) if name == "knife" else as_fixture(name)
    rng = np.random.default_rng(13)
    vertices, triangles = fixture.oracle.mesh_arrays
    surface = trimesh.sample.sample_surface(trimesh.Trimesh(vertices, triangles), 3000, seed=13)[0]
    points = np.vstack([surface + rng.normal(0.0, 0.004, surface.shape),
                        rng.uniform(vertices.min(axis=0) - 0.02, vertices.max(axis=0) + 0.02, (3000, 3))])
    uncapped = _signed_intervals(points, fixture.oracle.kernel_arguments)
    oracle_low, oracle_high, _ = fixture.oracle.distance_interval_m(points)
    for cap_m in (5e-4, 0.002, 0.01):
        low, high, faces, signable = _signed_intervals(points, fixture.oracle.kernel_arguments, cap_m)
        far = faces < 0
        assert 0 < np.count_nonzero(far) < len(points)
        assert np.all((oracle_low[far] >= cap_m * (1.0 - 1e-12)) | (oracle_high[far] <= -cap_m * (1.0 - 1e-12)))
        assert np.all(signable[far]) and np.all(low[far] == cap_m) and np.all(high[far] == np.inf)
        for capped, exact in zip((low, high, faces, signable), uncapped, strict=True):
            np.testing.assert_array_equal(capped[~far], exact[~far])


def _rotation_within(rng: np.random.Generator, gamma_rad: float) -> np.ndarray:
    """A rotation matrix turning by at most ``gamma_rad`` (often exactly that much) about a random axis."""
    axis = rng.normal(size=3)
    angle = gamma_rad * (1.0 if rng.random() < 0.3 else rng.random() ** (1 / 3))
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix()


def test_a_cell_is_called_too_near_a_face_only_where_every_pose_of_it_is():
    """The cheap pass's directional test (``_too_near_everywhere``): a cell ``(R_c, gamma) x (t_c +- h)`` it calls
    too near a triangle has the query point ``R^T (p - t)`` nearer than the limit at every pose of the cell,
    rotations up to gamma from ``R_c`` (beyond 90 deg too) and the cube's corners included; and it does call
    many cells so that the Lipschitz bound (the centre's distance plus the largest shift) does not."""
    from fixwizard.geometry.mesh_distance import triangle_row
    from fixwizard.geometry.so3_grid import chord
    from fixwizard.solver.interval_kernel import _too_near_everywhere

    rng = np.random.default_rng(11)
    called = beyond_lipschitz = 0
    for _ in range(3000):
        corners = rng.normal(size=(3, 3)) * 10 ** rng.uniform(-3, -1)
        row = triangle_row(*corners)
        base_R_centre = Rotation.random(random_state=rng).as_matrix()
        gamma = 10 ** rng.uniform(-5, 0.4)
        half_side = 10 ** rng.uniform(-6, -2)
        base_p_centre = rng.normal(size=3) * 0.3
        normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
        fix_p_query = (rng.dirichlet([1, 1, 1]) @ corners
                       + normal / np.linalg.norm(normal) * rng.choice([-1, 1]) * 10 ** rng.uniform(-6, -2))
        base_p_tap = base_R_centre @ fix_p_query + base_p_centre
        shift = half_side * np.sqrt(3) + (np.linalg.norm(fix_p_query) + half_side * np.sqrt(3)) * chord(gamma)
        centre_distance = triangle_interval_m(fix_p_query, *corners)[1]
        near = centre_distance + rng.uniform(0, 1.5) * shift
        if not _too_near_everywhere(*fix_p_query, np.ascontiguousarray(base_R_centre.T), chord(gamma), half_side,
                                    shift, row, near):
            continue
        called += 1
        beyond_lipschitz += centre_distance + shift >= near
        for _ in range(60):
            base_R_fix = base_R_centre @ _rotation_within(rng, gamma)
            corner = rng.random() < 0.3
            base_p_fix = base_p_centre + half_side * (rng.choice([-1.0, 1.0], 3) if corner else rng.uniform(-1, 1, 3))
            moved = base_R_fix.T @ (base_p_tap - base_p_fix)
            assert triangle_interval_m(moved, *corners)[1] < near
    assert called > 300 and beyond_lipschitz > 100
