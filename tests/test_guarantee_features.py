"""The guarantee where the other trials do not tap: ball centres on edges, corners and vertices and in concave
corners (every point of the surface at the ball's radius, not just beside faces), meshes far from their CAD origin,
of 10 mm or 2 m, with non-manifold edges, shared faces, slivers, open shells, fine spheres and cylinders, the
smallest sample bound fixwizard takes, an OBJ of warped quads whose part is cut across them the other way, and
symmetric poses against every bound a solve reports.

Taps: random points around the part projected onto the surface at the ball's radius (outside the solid), so each
feature is tapped as often as its share of that offset surface: edges and vertices about as often as faces. 60 % of
the taps carry the full bound along the direction to their closest surface point, into or off the surface; the rest
noise up to the bound."""

import itertools

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from descent import level_losing_the_true_cell
from fixwizard.fixture import load_fixture
from fixwizard.geometry.se3 import invert, make_transform, transform_points
from fixwizard.solver.search import SearchProblem
from fixwizard.solver.solve import MIN_SAMPLE_BOUND_M, solve
from fixwizard.synthetic import CONTACT_TOLERANCE_M, bounded_noise, closest_on_triangles
from shapes import SHAPES, WARPED_BOX_QUADS, across_other_diagonals, as_fixture, polygons_obj, warped_box_vertices

AT_BOUND_SHARE = 0.6


def closest_points(mesh: trimesh.Trimesh, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest surface points (N, 3, m) and their distances (N,), by brute force in float64."""
    closest, distances = np.empty_like(points_m), np.empty(len(points_m))
    triangles = mesh.triangles
    for first in range(0, len(points_m), 32):
        block = points_m[first:first + 32, None, :]
        candidates = closest_on_triangles(block, triangles[None, :, 0], triangles[None, :, 1], triangles[None, :, 2])
        squared = np.sum((candidates - block) ** 2, axis=-1)
        nearest = np.argmin(squared, axis=1)
        rows = np.arange(len(nearest))
        closest[first:first + 32] = candidates[rows, nearest]
        distances[first:first + 32] = np.sqrt(squared[rows, nearest])
    return closest, distances


def ball_centres_anywhere(mesh: trimesh.Trimesh, count: int, ball_radius_m: float,
                          rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``count`` ball centres (m, mesh frame) at exactly ``ball_radius_m`` from the surface, outside the solid (either
    side of an open mesh), and the unit directions from their closest surface points: random points around the mesh
    projected onto that offset surface."""
    low, high = mesh.bounds
    centres: list[np.ndarray] = []
    directions: list[np.ndarray] = []
    while len(centres) < count:
        points = rng.uniform(low - ball_radius_m - 0.01, high + ball_radius_m + 0.01, (200, 3))
        if mesh.is_watertight:
            points = points[~mesh.contains(points)]
        closest, distances = closest_points(mesh, points)
        away = distances > 1e-6
        outward = (points[away] - closest[away]) / distances[away, None]
        candidates = closest[away] + ball_radius_m * outward
        good = np.abs(closest_points(mesh, candidates)[1] - ball_radius_m) <= CONTACT_TOLERANCE_M
        if mesh.is_watertight and ball_radius_m > 0.0:
            good &= ~mesh.contains(candidates)
        centres.extend(candidates[good])
        directions.extend(outward[good])
    return np.array(centres[:count]), np.array(directions[:count])


def tapped_anywhere(mesh: trimesh.Trimesh, seed: int, sample_bound_m: float | None = None):
    """The mesh as a fixture, a random true pose, taps at ball centres anywhere (noisy as the module doc says), the
    ball diameter and the sample bound (m)."""
    rng = np.random.default_rng(seed)
    fixture = as_fixture("tapped", mesh)
    base_T_cad = make_transform(Rotation.random(random_state=seed), rng.uniform([-0.6, -0.6, 0.0], [0.6, 0.6, 0.4]))
    ball_diameter = float(rng.choice([0.0, 0.003, 0.006]))
    bound = float(rng.uniform(0.0003, 0.002)) if sample_bound_m is None else sample_bound_m
    count = int(rng.integers(6, 14))
    cad_p_centres, outward = ball_centres_anywhere(fixture.mesh, count, ball_diameter / 2, rng)
    noise = bounded_noise(count, bound, rng)
    at_bound = rng.random(count) < AT_BOUND_SHARE
    noise[at_bound] = bound * rng.choice([-1.0, 1.0], (np.count_nonzero(at_bound), 1)) * outward[at_bound]
    return fixture, base_T_cad, transform_points(base_T_cad, cad_p_centres + noise), ball_diameter, bound


def true_cell_kept(mesh: trimesh.Trimesh, seed: int, finest_m: float, sample_bound_m: float | None = None) -> bool:
    fixture, base_T_cad, taps, ball_diameter, bound = tapped_anywhere(mesh, seed, sample_bound_m)
    problem = SearchProblem(fixture.oracle, fixture.radius_m, taps, ball_diameter / 2, bound)
    return level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), finest_m) is None


def test_projected_taps_land_on_edges_and_vertices_as_often_as_beside_faces():
    """What the generator is for: about half the ball centres have an edge or a vertex as their closest feature."""
    mesh = SHAPES["l_prism"]()
    centres, outward = ball_centres_anywhere(mesh, 200, 0.0015, np.random.default_rng(0))
    _, _, faces = trimesh.proximity.closest_point(mesh, centres - 0.0015 * outward)
    beside_a_face = np.abs(np.einsum("ij,ij->i", outward, mesh.face_normals[faces])) > 1 - 1e-9
    assert 0.25 < 1 - np.mean(beside_a_face) < 0.75


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", ["l_prism", "polytope", "cube", "cone"])
def test_taps_on_edges_corners_and_in_concave_corners_keep_the_true_cell_down_to_fine_cells(name, seed):
    assert true_cell_kept(SHAPES[name](), seed, 2e-5)


def _fanned_into_slivers() -> trimesh.Trimesh:
    """A 80 x 50 x 30 mm box whose every side is a fan of four triangles about a point 0.1 um inside one of its
    edges, wound outward: a sliver of height 1e-7 m along that edge."""
    box = trimesh.creation.box((0.08, 0.05, 0.03))
    vertices, faces = list(box.vertices), []
    for facet in box.facets:
        corners = np.unique(box.faces[facet])
        normal, centre = box.face_normals[facet[0]], box.vertices[corners].mean(axis=0)
        across = box.vertices[corners[1]] - box.vertices[corners[0]]
        side = np.cross(normal, across)
        ring = corners[np.argsort(np.arctan2((box.vertices[corners] - centre) @ side,
                                             (box.vertices[corners] - centre) @ across))]
        middle = (box.vertices[ring[0]] + box.vertices[ring[1]]) / 2
        vertices.append(middle + 1e-7 * (centre - middle) / np.linalg.norm(centre - middle))
        for first, second in zip(ring, np.roll(ring, -1), strict=True):
            faces.append([len(vertices) - 1, first, second])
    return trimesh.Trimesh(np.array(vertices), np.array(faces), process=False)


def _two_touching(offset: tuple[float, float, float]) -> trimesh.Trimesh:
    """Two 40 x 30 x 20 mm bricks, the second moved by ``offset`` (m), as one mesh with shared vertices merged."""
    first = trimesh.creation.box((0.04, 0.03, 0.02))
    both = trimesh.util.concatenate([first, first.copy().apply_translation(offset)])
    both.merge_vertices()
    return both


def _hemisphere() -> trimesh.Trimesh:
    sphere = trimesh.creation.icosphere(3, radius=0.04)
    return trimesh.Trimesh(sphere.vertices, sphere.faces[sphere.triangles_center[:, 2] > 0.0])


def _sheet() -> trimesh.Trimesh:
    """An open 100 x 60 mm sheet with a 10 mm peak: no inside, tapped on both sides."""
    corners = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0.06, 0], [0, 0.06, 0], [0.05, 0.03, 0.01]])
    return trimesh.Trimesh(corners, [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]], process=False)


EXPORTS = {
    "5 m from its CAD origin": lambda: SHAPES["l_prism"]().apply_translation([5.0, -3.0, 1.2]),
    "10 mm": lambda: SHAPES["l_prism"]().apply_scale(0.08),
    "2 m": lambda: SHAPES["polytope"]().apply_scale(18.0),
    "two cubes sharing an edge (non-manifold)": lambda: _two_touching((0.04, 0.03, 0.0)),
    "two bricks sharing a face": lambda: _two_touching((0.04, 0.0, 0.0)),
    "sides fanned into slivers": _fanned_into_slivers,
    "open sheet": _sheet,
    "hemisphere shell": _hemisphere,
    "sphere of 1280 facets": lambda: trimesh.creation.icosphere(3, radius=0.04),
    "cylinder of 256 sections": lambda: trimesh.creation.cylinder(radius=0.03, height=0.05, sections=256),
}


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow)])
@pytest.mark.parametrize("kind", sorted(EXPORTS))
def test_meshes_as_cad_tools_export_them_keep_the_true_cell_down_to_fine_cells(kind, seed):
    assert true_cell_kept(EXPORTS[kind](), seed, 2e-5)


@pytest.mark.parametrize("name", ["l_prism", "1 m bar", "2 m polytope"])
def test_the_smallest_sample_bound_keeps_the_true_cell_down_to_cells_of_half_of_it(name):
    """At 0.01 mm the rounding terms of every interval weigh most against the bound: on a 1 m bar of 12 x 6 mm
    section (facets of aspect up to 170) and a 2 m part too."""
    mesh = {"l_prism": SHAPES["l_prism"], "1 m bar": lambda: trimesh.creation.box((1.0, 0.012, 0.006)),
            "2 m polytope": EXPORTS["2 m"]}[name]()
    assert true_cell_kept(mesh, 0, MIN_SAMPLE_BOUND_M / 2, MIN_SAMPLE_BOUND_M)


@pytest.mark.parametrize("seed", range(3))
def test_a_part_cut_across_its_warped_polygons_the_other_way_keeps_the_true_cell(tmp_path, seed):
    """The OBJ of a box with a corner raised 2 mm (quads that are not flat, cut by trimesh along one diagonal), the
    part cut along the other: taps on the part, all of them at the full 0.5 mm bound into or off it. With the
    polygons' warp in every tap's band the true cell survives; without, these three descents lost it."""
    vertices = warped_box_vertices()
    path = tmp_path / "warped.obj"
    path.write_text(polygons_obj(vertices, WARPED_BOX_QUADS))
    fixture = load_fixture(path)
    rng = np.random.default_rng(seed)
    centres, outward = ball_centres_anywhere(across_other_diagonals(vertices, WARPED_BOX_QUADS), 12, 0.0015, rng)
    base_T_cad = make_transform(Rotation.random(random_state=seed), [0.4, 0.1, 0.2])
    taps = transform_points(base_T_cad, centres + 0.0005 * rng.choice([-1.0, 1.0], (12, 1)) * outward)
    problem = SearchProblem(fixture.oracle, fixture.radius_m, taps, 0.0015, 0.0005)
    assert level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), 2e-5) is None


def _symmetries(name: str) -> list[np.ndarray]:
    """The rotations (about the centre) that map the brick or the triangular prism onto itself."""
    if name == "brick":
        return [np.diag(signs) for signs in itertools.product([1, -1], repeat=3) if np.prod(signs) > 0]
    return [Rotation.from_euler("z", angle).as_matrix() for angle in (0.0, 2 * np.pi / 3, 4 * np.pi / 3)]


@pytest.mark.slow  # 1e6 cells: a few seconds a solve
@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("name", ["brick", "triangular_prism"])
def test_every_symmetric_pose_lies_in_the_set_and_within_the_bounds_and_a_modes_bounds(name, seed):
    """With the CAD origin away from the centre every symmetric pose moves the origin: each lies in the set, within
    the reported bounds (origin, rotation, every vertex) and within the bounds of one mode."""
    shift = np.array([0.07, 0.03, -0.02])
    fixture, base_T_cad, taps, ball_diameter, bound = tapped_anywhere(SHAPES[name]().apply_translation(shift), seed,
                                                                      0.0005)
    solution = solve(fixture, taps, ball_diameter, bound, max_cells=1e6, max_samples=500, seed=seed)
    assert solution.status != "unique"

    def within(bounds, pose: np.ndarray) -> bool:
        centre = bounds.base_T_cad_center
        moved = np.linalg.norm(transform_points(pose, fixture.mesh.vertices)
                               - transform_points(centre, fixture.mesh.vertices), axis=1)
        return bool(np.linalg.norm(pose[:3, 3] - centre[:3, 3]) <= bounds.position_m
                    and Rotation.from_matrix(centre[:3, :3].T @ pose[:3, :3]).magnitude() <= bounds.rotation_rad
                    and moved.max() <= bounds.max_point_displacement_m)

    for symmetry in _symmetries(name):
        pose = base_T_cad @ make_transform(symmetry, shift - symmetry @ shift)
        assert solution.contains(pose) and within(solution.bounds, pose)
        assert any(within(mode.bounds, pose) for mode in solution.modes)
