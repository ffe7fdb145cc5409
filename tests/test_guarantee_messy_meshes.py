"""The guarantee on meshes as CAD tools export them: taps made on the true solid, solved with a mesh that has
facets turned inside out (many, or a single one), is inside out as a whole, holds two bodies (one inside out),
holds two bodies that overlap (an assembly exported without a union), repeats facets (some of the copies turned),
is open, has T-junctions (on their edges, or off them by rounding) or cracks (a patch's corners written apart by
rounding), is a metre-long bar or rail of long thin facets (aspect up to 400), or is a binary STL far from its CAD
origin (float32 coordinates 7.6 micrometres apart). Noise up to the bound, 30 % of the taps exactly at the bound
along the normal. Zero misses and zero false "inconsistent" allowed."""

import numpy as np
import open3d as o3d
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from descent import level_losing_the_true_cell
from fixwizard.fixture import FLOAT32_REFUSED_M, FLOAT32_WARNED_M, load_fixture
from fixwizard.geometry.se3 import invert, make_transform, transform_points
from fixwizard.mesh_hygiene import ZIP_SHARE
from fixwizard.solver.cells import root_cells
from fixwizard.solver.search import SearchProblem, filter_cells, rotation_splits_first, start_position_grid
from fixwizard.solver.solve import MIN_SAMPLE_BOUND_M, solve
from fixwizard.synthetic import bounded_noise, exact_distances_m, touching_ball_contacts
from shapes import SHAPES, as_fixture, cracked, moved, with_t_junctions

SEEDS = range(3)
BALL_DIAMETERS_M = (0.0, 0.003, 0.006)


def _flipped(mesh: trimesh.Trimesh, rng: np.random.Generator, share: float) -> trimesh.Trimesh:
    faces = np.asarray(mesh.faces).copy()
    turned = rng.choice(len(faces), max(1, int(share * len(faces))), replace=False)
    faces[turned] = faces[turned][:, ::-1]
    return trimesh.Trimesh(mesh.vertices, faces, process=False)


def _rail() -> trimesh.Trimesh:
    """The L-plate's outline at half size, extruded 1 m: long faces of aspect 20 to 400."""
    outline = np.array([[0, 0], [0.12, 0], [0.12, 0.03], [0.05, 0.03], [0.05, 0.06], [0.035, 0.06],
                        [0.035, 0.08], [0, 0.08]]) * 0.5
    triangles = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 7], [5, 6, 7]])
    rail = trimesh.creation.extrude_triangulation(outline, triangles, height=1.0)
    return rail if rail.volume > 0 else trimesh.Trimesh(rail.vertices, np.asarray(rail.faces)[:, ::-1])


def _bar() -> trimesh.Trimesh:
    """A 1 m bar of 12 x 6 mm section: each long face two triangles of aspect 80 to 170, where Open3D's float32
    closest points err by tens of micrometres."""
    return trimesh.creation.box((1.0, 0.012, 0.006))


def messy_case(kind: str, seed: int):
    """(true mesh, mesh as exported, faces the taps may touch)."""
    rng = np.random.default_rng(seed)
    name = ("l_prism", "polytope", "brick", "cylinder")[seed % 4]
    truth = SHAPES[name]()
    everywhere = np.ones(len(truth.faces), bool)
    if kind == "flipped facets":
        return truth, _flipped(truth, rng, 0.2), everywhere
    if kind == "one flipped facet":
        return truth, _flipped(truth, rng, 0.0), everywhere
    if kind == "inside out":
        return truth, trimesh.Trimesh(truth.vertices, np.asarray(truth.faces)[:, ::-1], process=False), everywhere
    if kind == "two bodies, one inside out":
        second = trimesh.creation.box((0.03, 0.02, 0.02)).apply_translation(truth.bounds[1] + 0.02)
        both = trimesh.util.concatenate([truth, second])
        exported = trimesh.util.concatenate([truth, trimesh.Trimesh(second.vertices, second.faces[:, ::-1])])
        return both, exported, np.ones(len(both.faces), bool)
    if kind == "two overlapping bodies":
        extent = truth.bounds[1] - truth.bounds[0]
        second = trimesh.creation.box(0.6 * extent).apply_translation(truth.bounds[1] - 0.2 * extent)
        both = trimesh.util.concatenate([truth, second])
        return both, both, np.ones(len(both.faces), bool)
    if kind == "repeated facets, some copies turned":
        faces = np.asarray(truth.faces)
        copies = faces[rng.choice(len(faces), max(2, len(faces) // 4), replace=False)]
        copies[::2] = copies[::2, ::-1]
        return truth, trimesh.Trimesh(truth.vertices, np.vstack([faces, copies]), process=False), everywhere
    if kind == "open":
        kept = np.ones(len(truth.faces), bool)
        kept[rng.choice(len(kept), 2, replace=False)] = False
        return truth, trimesh.Trimesh(truth.vertices, np.asarray(truth.faces)[kept], process=False), kept
    if kind == "T-junctions":
        return truth, with_t_junctions(truth, rng)[0], everywhere
    if kind == "T-junctions off their edges":  # the exported surface is the true one: rounding is in the part too
        split, new = with_t_junctions(truth, rng)  # moved 0.4 of the tolerance, with their edges' ends: 0.8 off them
        exported = moved(split, new, 0.4 * ZIP_SHARE * float(np.linalg.norm(split.extents)), rng)
        return exported, exported, np.ones(len(exported.faces), bool)
    if kind == "cracks":  # a patch's corners written apart: the exported surface is the true one
        exported = cracked(truth, rng, 0.4 * ZIP_SHARE * float(np.linalg.norm(truth.extents)))
        return exported, exported, np.ones(len(exported.faces), bool)
    if kind == "slivers":
        long_one = _rail() if seed % 2 == 0 else _bar()
        return long_one, _flipped(long_one, rng, 0.1), np.ones(len(long_one.faces), bool)
    raise ValueError(kind)


KINDS = ("flipped facets", "one flipped facet", "inside out", "two bodies, one inside out", "two overlapping bodies",
         "repeated facets, some copies turned", "open", "T-junctions", "T-junctions off their edges", "cracks",
         "slivers")


def _outside_every_body(truth: trimesh.Trimesh, centres: np.ndarray, ball_radius_m: float) -> np.ndarray:
    """Which ball centres (m) lie at least the ball radius outside each body of ``truth`` (overlapping bodies: a
    ball touching one body's facet inside the other is no tap)."""
    outside = np.ones(len(centres), bool)
    for body in truth.split(only_watertight=False):
        outside &= trimesh.proximity.signed_distance(body, centres) <= -ball_radius_m + 1e-9
    return outside


def messy_taps(kind: str, seed: int):
    """The exported mesh as a fixture, its true pose, noisy taps made on the true solid, ball and bound (m)."""
    truth, exported, tappable = messy_case(kind, seed)
    fixture = as_fixture("messy", exported)
    rng = np.random.default_rng(100 + seed)
    base_T_cad = make_transform(Rotation.random(random_state=seed), rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 0.3]))
    ball_diameter = BALL_DIAMETERS_M[seed % 3]
    sample_bound = float(rng.uniform(0.0003, 0.0015))
    count = int(rng.integers(8, 14))
    if kind == "two overlapping bodies":
        cad_p_centres, cad_normals = touching_ball_contacts(truth, 4 * count, ball_diameter / 2, rng)
        kept = np.flatnonzero(_outside_every_body(truth, cad_p_centres, ball_diameter / 2))[:count]
        assert len(kept) == count
        cad_p_centres, cad_normals = cad_p_centres[kept], cad_normals[kept]
    else:
        cad_p_centres, cad_normals = touching_ball_contacts(truth, count, ball_diameter / 2, rng,
                                                            tappable.astype(float))
    noise = bounded_noise(count, sample_bound, rng)
    along_normal = rng.random(count) < 0.3
    noise[along_normal] = (sample_bound * rng.choice([-1.0, 1.0], size=(np.count_nonzero(along_normal), 1))
                           * (cad_normals[along_normal] @ base_T_cad[:3, :3].T))
    return fixture, base_T_cad, transform_points(base_T_cad, cad_p_centres) + noise, ball_diameter, sample_bound


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("kind", [pytest.param(kind, marks=pytest.mark.slow) if kind == "slivers" else kind
                                  for kind in KINDS])  # slivers: 30 s a solve
def test_no_miss_and_no_false_inconsistent_on_messy_meshes(kind, seed):
    fixture, base_T_cad, taps, ball_diameter, sample_bound = messy_taps(kind, seed)
    rng = np.random.default_rng(200 + seed)
    solution = solve(fixture, taps, ball_diameter, sample_bound, max_cells=float(rng.choice([3e4, 1e5])),
                     max_samples=500, seed=seed, diagnose_inconsistent=False)
    assert solution.status != "inconsistent"
    assert solution.contains(base_T_cad)
    centre = solution.bounds.base_T_cad_center
    assert np.linalg.norm(base_T_cad[:3, 3] - centre[:3, 3]) <= solution.bounds.position_m
    assert Rotation.from_matrix(centre[:3, :3].T @ base_T_cad[:3, :3]).magnitude() <= solution.bounds.rotation_rad
    if kind != "open":  # a repaired mesh keeps the sign: the tighter, signed distance is used
        assert fixture.signed


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("kind", ["slivers", "flipped facets"])
def test_the_true_cell_survives_every_level_down_to_fine_cells_on_slivers_and_flipped_facets(kind, seed):
    """The exact stage runs on cells a few micrometres from the surface here, where float32 distances to 1 m
    facets err by tenths of a millimetre."""
    fixture, base_T_cad, taps, ball_diameter, sample_bound = messy_taps(kind, seed)
    problem = SearchProblem(fixture.oracle, fixture.radius_m, taps, ball_diameter / 2, sample_bound)
    assert level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), 2e-5) is None


def test_taps_where_float32_distances_err_most_keep_the_true_cell_to_the_finest_level():
    """On a 1 m bar of 4 mm section, Open3D's float32 closest point overstates the distance by up to 0.2 mm at
    some points. Taps placed exactly there, at the full bound off the surface, reject the true cell of a search
    whose exact stage trusts float32 (this test fails with it); the float64 intervals keep it."""
    bar = trimesh.creation.box((1.0, 0.004, 0.004))
    fixture = as_fixture("bar", bar)
    ball_radius, bound = 0.0015, 0.0005
    rng = np.random.default_rng(7)
    faces = rng.choice(np.flatnonzero(np.abs(bar.face_normals[:, 0]) < 0.5), 20_000)
    contacts = np.einsum("ni,nij->nj", rng.dirichlet([1, 1, 1], len(faces)), bar.triangles[faces])
    candidates = contacts + bar.face_normals[faces] * (ball_radius + bound)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(bar.vertices.astype(np.float32)), o3d.core.Tensor(bar.faces.astype(np.uint32)))
    closest = scene.compute_closest_points(o3d.core.Tensor(candidates.astype(np.float32)))["points"].numpy()
    overstated = np.linalg.norm(candidates - closest, axis=1) - exact_distances_m(bar, candidates)
    worst = np.argsort(-overstated)[:8]
    assert overstated[worst[-1]] > 5e-5  # the float32 error these taps sit on
    cad_p_taps = np.vstack([candidates[worst], candidates[rng.choice(len(candidates), 6, replace=False)]])
    base_T_cad = make_transform(Rotation.from_rotvec([0.1, 0.2, 0.3]), [0.3, 0.1, 0.2])
    problem = SearchProblem(fixture.oracle, fixture.radius_m, transform_points(base_T_cad, cad_p_taps), ball_radius,
                            bound)
    assert level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), 1e-5) is None


@pytest.mark.parametrize("offset_in_band", [True, False])
def test_taps_beside_t_junctions_off_their_edges_keep_the_true_cell_down_to_submicrometre_cells(offset_in_band):
    """A box whose top's triangles are split, the sides' whole: the four T-junction vertices lie 0.9 of
    ``ZIP_SHARE`` of the diagonal (1.1 micrometres) out from their sides, so the closed mesh's sides bulge out by
    that beside them. A ball pressed into a side by the full bound just below such a vertex is then more than the
    bound into the closed surface: with each tap's band widened by the surface offset the true cell survives to
    cells of half of it; without (``offset_in_band`` false, the search of before) it is lost."""
    box = trimesh.creation.box((0.1, 0.06, 0.04))
    split = box.subdivide(face_index=np.flatnonzero(box.face_normals[:, 2] > 0.5))
    new = np.arange(len(box.vertices), len(split.vertices))
    on_sides = new[np.any(np.isclose(np.abs(split.vertices[new, :2]), [0.05, 0.03]), axis=1)]
    outward = np.where(np.isclose(np.abs(split.vertices[on_sides, :2]), [0.05, 0.03]),
                       np.sign(split.vertices[on_sides, :2]), 0.0)
    lift_m = 0.9 * ZIP_SHARE * float(np.linalg.norm(split.extents))
    vertices = np.asarray(split.vertices).copy()
    vertices[on_sides, :2] += lift_m * outward
    exported = trimesh.Trimesh(vertices, split.faces, process=False)
    fixture = as_fixture("box", exported)
    assert fixture.signed and fixture.surface_offset_m >= lift_m
    ball_radius, bound = 0.0015, 0.0005
    normals = np.hstack([outward, np.zeros((4, 1))])
    pressed_in = split.vertices[on_sides] - [0.0, 0.0, 0.0005] + (ball_radius - bound) * normals
    assert np.allclose(exact_distances_m(exported, pressed_in), ball_radius - bound, atol=1e-12)
    rng = np.random.default_rng(3)
    others, _ = touching_ball_contacts(exported, 8, ball_radius, rng)
    cad_p_taps = np.vstack([pressed_in, others + bounded_noise(8, bound, rng)])
    base_T_cad = make_transform(Rotation.from_rotvec([0.3, -0.2, 0.5]), [0.4, 0.1, 0.2])
    oracle = fixture.oracle
    oracle.surface_offset_m = fixture.surface_offset_m if offset_in_band else 0.0
    problem = SearchProblem(oracle, fixture.radius_m, transform_points(base_T_cad, cad_p_taps), ball_radius, bound)
    closed_distances = oracle.signed_distance_m(cad_p_taps[:4] - fixture.cad_p_center)
    assert np.all(closed_distances < ball_radius - bound - 0.5 * lift_m)  # beyond the bound from the closed surface
    lost_at = level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), 0.5 * lift_m)
    assert (lost_at is None) is offset_in_band


@pytest.mark.parametrize("widened", [True, False])
def test_taps_on_a_binary_stl_far_from_its_origin_keep_the_true_cell_by_the_float32_widening(tmp_path, monkeypatch,
                                                                                             widened):
    """An L-plate about 100 m from its CAD origin (a plant's coordinates) exported as binary STL: its float32
    coordinates are 7.6 micrometres apart there, so the loaded surface lies up to half of that off the exact one.
    Taps made on the exact solid, pressed in by the smallest sample bound (0.01 mm) where the loaded surface lies
    farthest out, are 3.7 micrometres beyond the bound from it: with every tap's band widened by the spacing
    (``fixture._float32_spacing_m``) the true cell survives to cells of a micrometre; without (``widened`` false: the
    spacing taken as 0) it is lost."""
    truth = SHAPES["l_prism"]().apply_translation([97.3, -84.1, 71.9])  # every coordinate between 64 and 128 m
    path = tmp_path / "far.stl"
    truth.export(path)
    if not widened:
        monkeypatch.setattr("fixwizard.fixture._float32_spacing_m", lambda *_: 0.0)
    fixture = load_fixture(path)
    spacing_m = float(np.spacing(np.float32(np.max(np.abs(truth.vertices)))))
    assert FLOAT32_WARNED_M < spacing_m < FLOAT32_REFUSED_M
    assert fixture.surface_offset_m == (spacing_m if widened else 0.0)
    ball_radius, bound = 0.0015, MIN_SAMPLE_BOUND_M
    rng = np.random.default_rng(0)
    centres, normals = touching_ball_contacts(truth, 3000, ball_radius, rng)
    pressed_in = centres - bound * normals
    beyond_m = ball_radius - bound - fixture.oracle.signed_distance_m(pressed_in - fixture.cad_p_center)
    worst = np.argsort(-beyond_m)[:6]
    assert beyond_m[worst[-1]] > 0.45 * spacing_m and beyond_m.max() < spacing_m  # out of the bound, in the widening
    others, _ = touching_ball_contacts(truth, 6, ball_radius, rng)
    cad_p_taps = np.vstack([pressed_in[worst], others + bounded_noise(6, bound, rng)])
    rotation = Rotation.from_rotvec([0.3, -0.2, 0.5])
    base_T_cad = make_transform(rotation, [0.4, 0.1, 0.2] - rotation.apply(truth.bounds.mean(axis=0)))  # on the table
    problem = SearchProblem(fixture.oracle, fixture.radius_m, transform_points(base_T_cad, cad_p_taps), ball_radius,
                            bound)
    lost_at = level_losing_the_true_cell(problem, base_T_cad @ invert(fixture.fix_T_cad), 1e-6)
    assert (lost_at is None) is widened


@pytest.mark.parametrize("seed", range(2))
@pytest.mark.parametrize("kind", KINDS)
def test_every_survivors_interval_holds_the_signed_distance_at_its_query_point(kind, seed):
    """What children inherit: each survivor's interval, per tap, holds the distance at its query point, signed as
    the oracle signs it (pseudonormal, ray parity, winding number), whether the compiled exact stage signed it (by
    the closest face's plane) or left it to the oracle. Checked on every survivor of a level (a random 1500 of them
    go on down, with the true cell), twelve levels down; intervals narrower than a micrometre come from exact
    queries, so the check covers them."""
    fixture, base_T_cad, taps, ball_diameter, sample_bound = messy_taps(kind, seed)
    base_T_fix = base_T_cad @ invert(fixture.fix_T_cad)
    problem = SearchProblem(fixture.oracle, fixture.radius_m, taps, ball_diameter / 2, sample_bound)
    rng = np.random.default_rng(seed)
    cells, parents, exact_ones = root_cells(start_position_grid(problem)), None, 0
    for _ in range(12):
        survivors = filter_cells(problem, cells, parents)
        rotations = survivors.frames.fix_R_base[survivors.frames.rotation_index]
        fix_p_queries = np.einsum("cij,tj->cti", rotations, taps) - survivors.rotated_positions[:, None, :]
        points = fix_p_queries.reshape(-1, 3)
        low, high, _ = fixture.oracle.distance_interval_m(points)
        unsigned_low, unsigned_high, _ = fixture.oracle.distance_interval_m(points, np.zeros(len(points), bool))
        stored_low, stored_high = survivors.low_m.ravel() - 1e-9, survivors.high_m.ravel() + 1e-9
        holds = (stored_low <= low) & (stored_high >= high)
        sign_free = (low == -high) & (high <= fixture.oracle.SIGN_FREE_M)  # either sign may be the true one
        holds_either = (((stored_low <= unsigned_high) & (stored_high >= unsigned_low))
                        | ((stored_low <= -unsigned_low) & (stored_high >= -unsigned_high)))
        assert np.all(holds | (sign_free & holds_either))
        exact_ones += int(np.count_nonzero(survivors.high_m - survivors.low_m < 1e-6))
        rotation = survivors.cells.rotation_grid.cell_of(survivors.cells.rotation_level,
                                                         Rotation.from_matrix(base_T_fix[:3, :3]))
        position = survivors.cells.position_grid.cell_of(survivors.cells.position_level, base_T_fix[:3, 3])
        true_cell = (survivors.cells.rotation_cells == rotation[0]) & np.all(
            survivors.cells.position_cells == position, axis=1)
        going_on = true_cell.copy()
        going_on[rng.choice(len(survivors), min(1500, len(survivors)), replace=False)] = True
        parents = survivors.subset(going_on)
        cells = (parents.cells.split_rotations() if rotation_splits_first(parents.cells, problem)
                 else parents.cells.split_positions())
    assert exact_ones > 0
