"""The float64 distance intervals hold the exact distance for every triangle shape: needles, caps, collinear and
repeated corners, far from the origin, points on the surface and a metre away; and the hierarchy finds the
nearest triangle of a whole mesh, slivers included, where Open3D's float32 query errs by tenths of a millimetre."""

import subprocess
import sys
from fractions import Fraction

import numpy as np
import open3d as o3d
import pytest
import trimesh

from fixwizard.geometry.mesh_distance import (
    LEAF_TRIANGLES,
    STACK_DEPTH,
    MeshDistance,
    row_normal,
    triangle_interval_m,
    triangle_row,
    triangle_row_reach_high_m,
)
from fixwizard.synthetic import closest_on_triangles, exact_distances_m


def _exact_squared_distance(x, a, b, c) -> Fraction:
    """Squared distance from point x to triangle abc in exact rational arithmetic (the float64 inputs as given)."""
    x, a, b, c = ([Fraction(float(value)) for value in point] for point in (x, a, b, c))

    def sub(p, q):
        return [p[i] - q[i] for i in range(3)]

    def dot(p, q):
        return sum(p[i] * q[i] for i in range(3))

    def cross(p, q):
        return [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]

    def segment(p, q):
        edge, offset = sub(q, p), sub(x, p)
        length = dot(edge, edge)
        t = min(max(dot(offset, edge) / length, Fraction(0)), Fraction(1)) if length else Fraction(0)
        rest = [offset[i] - t * edge[i] for i in range(3)]
        return dot(rest, rest)

    best = min(segment(a, b), segment(b, c), segment(c, a))
    normal = cross(sub(b, a), sub(c, a))
    area = dot(normal, normal)
    if area:
        height = dot(sub(x, a), normal)
        foot = [x[i] - height * normal[i] / area for i in range(3)]
        if all(dot(cross(sub(q, p), sub(foot, p)), normal) >= 0 for p, q in ((a, b), (b, c), (c, a))):
            best = min(best, height * height / area)
    return best


def _random_triangle(rng: np.random.Generator, kind: str) -> np.ndarray:
    """Corners (3, 3) in m: a needle (one short edge), a cap (a corner near the opposite edge), a well-shaped
    triangle, or a degenerate one (collinear, a repeated corner, a single point), up to 2 m from the origin."""
    length = 10 ** rng.uniform(-3, 0)
    aspect = 10 ** rng.uniform(0, 9)
    a = rng.normal(size=3) * rng.choice([0.1, 1.0])
    along = rng.normal(size=3)
    along /= np.linalg.norm(along)
    across = np.cross(along, rng.normal(size=3))
    across /= np.linalg.norm(across)
    b = a + length * along
    if kind == "needle":
        c = a + length * along * rng.uniform(0.5, 1.0) + across * length / aspect
    elif kind == "cap":
        c = a + length * along * rng.uniform(0.0, 1.0) + across * length / aspect
    elif kind == "collinear":
        c = a + length * along * rng.uniform(-0.5, 1.5)
    elif kind == "repeated":
        c = a.copy()
    elif kind == "point":
        b, c = a.copy(), a.copy()
    else:
        c = a + length * rng.normal(size=3)
    corners = np.array([a, b, c])
    return corners[rng.permutation(3)]


KINDS = ("needle", "cap", "well_shaped", "collinear", "repeated", "point")


@pytest.mark.parametrize("kind", KINDS)
def test_the_interval_holds_the_exact_distance_for_every_triangle_shape(kind):
    rng = np.random.default_rng(KINDS.index(kind))
    widest = 0.0
    for _ in range(600):
        a, b, c = _random_triangle(rng, kind)
        weights = rng.dirichlet([1, 1, 1])
        on_triangle = weights @ np.array([a, b, c])
        normal = np.cross(b - a, c - a)
        normal = normal / np.linalg.norm(normal) if np.linalg.norm(normal) > 0 else rng.normal(size=3)
        distance = rng.choice([0.0, 10 ** rng.uniform(-7, 0)])
        x = on_triangle + distance * (normal * rng.choice([-1, 1]) + rng.normal(size=3) * rng.choice([0, 0.3, 3]))
        low, high, _, _ = triangle_interval_m(x, a, b, c)
        exact = _exact_squared_distance(x, a, b, c)
        assert Fraction(low) ** 2 <= exact <= Fraction(high) ** 2, (a, b, c, x)
        size = np.linalg.norm(x - a) + max(np.linalg.norm(b - a), np.linalg.norm(c - a), np.linalg.norm(c - b))
        widest = max(widest, (high - low) / max(size, 1e-300))
    assert widest < 1e-7  # about sqrt(2^-53) of the point's distance plus the triangle's size, whatever its shape


def _float_above(value: Fraction) -> float:
    """The smallest float64 not below an exact value."""
    result = float(value)
    return result if Fraction(result) >= value else float(np.nextafter(result, np.inf))


@pytest.mark.parametrize("kind", KINDS)
def test_the_reach_bound_holds_for_every_point_within_reach_of_a_point_above_the_triangle(kind):
    """``triangle_row_reach_high_m``: from a point whose foot lies inside the triangle, every point within
    ``across`` of it and within ``along`` of it along the row's normal is no farther from the triangle than the
    bound (exact rational arithmetic: the offsets are those of the float64 points), whatever the triangle's
    shape; finite for most feet inside well-shaped triangles."""
    rng = np.random.default_rng(20 + KINDS.index(kind))
    finite = 0
    for _ in range(400):
        a, b, c = _random_triangle(rng, kind)
        row = triangle_row(a, b, c)
        normal = np.array(row_normal(row))
        weights = rng.dirichlet([1, 1, 1]) if rng.random() < 0.8 else rng.normal(size=3) / 2 + 1 / 3
        scale = max(np.linalg.norm(b - a), np.linalg.norm(c - a), 1e-9)
        x = weights @ np.array([a, b, c]) + normal * scale * rng.choice([0.0, 1e-6, 0.01, 0.3]) * rng.choice([-1, 1])
        across = scale * 10 ** rng.uniform(-4, 0)
        along = across * rng.choice([0.0, rng.uniform(0, 1), 1.0])
        tangent = np.cross(normal, rng.normal(size=3))
        tangent /= max(np.linalg.norm(tangent), 1e-300)
        offset_along = along * rng.choice([-1.0, 1.0, rng.uniform(-1, 1)])
        room = np.sqrt(max(across**2 - offset_along**2, 0.0))
        moved = x + offset_along * normal + rng.uniform(0, 1) ** 0.3 * room * tangent
        offset = [Fraction(float(m)) - Fraction(float(y)) for m, y in zip(moved, x, strict=True)]
        exact_along = abs(sum(Fraction(float(n)) * o for n, o in zip(normal, offset, strict=True)))
        exact_across_sq = sum(o * o for o in offset)
        across_used = _float_above(Fraction(np.sqrt(float(exact_across_sq))))
        while Fraction(across_used) ** 2 < exact_across_sq:
            across_used = float(np.nextafter(across_used, np.inf))
        bound = triangle_row_reach_high_m(*x, row, _float_above(exact_along), across_used)
        if not np.isfinite(bound):
            continue
        finite += 1
        assert _exact_squared_distance(moved, a, b, c) <= Fraction(bound) ** 2, (a, b, c, x, moved)
    if kind == "well_shaped":
        assert finite > 200


def test_the_returned_point_gives_the_upper_end():
    rng = np.random.default_rng(9)
    for _ in range(200):
        a, b, c = _random_triangle(rng, "well_shaped")
        x = rng.normal(size=3)
        low, high, v, w = triangle_interval_m(x, a, b, c)
        point = a + v * (b - a) + w * (c - a)
        assert 0.0 <= v and 0.0 <= w and v + w <= 1.0
        assert np.linalg.norm(x - point) <= high and low <= np.linalg.norm(x - point)


def _rail(length_m: float, width_m: float) -> trimesh.Trimesh:
    """A closed rail of square section (width x width), its long faces each two triangles of aspect
    length / width."""
    return trimesh.creation.box((length_m, width_m, width_m))


def _points_above_long_faces(mesh: trimesh.Trimesh, rng: np.random.Generator, count: int) -> np.ndarray:
    """Points 0.01-3 mm above the long faces of a rail lying along x."""
    long_faces = np.flatnonzero(np.abs(mesh.face_normals[:, 0]) < 0.5)
    faces = rng.choice(long_faces, count)
    weights = rng.dirichlet([1, 1, 1], count)
    on_face = np.einsum("ni,nij->nj", weights, mesh.triangles[faces])
    return on_face + mesh.face_normals[faces] * 10 ** rng.uniform(-5, np.log10(0.003), (count, 1))


@pytest.mark.parametrize("aspect", [10, 100, 1000])
def test_slivers_a_metre_long_get_intervals_that_hold_the_float64_truth(aspect):
    rail = _rail(1.0, 1.0 / aspect)
    rng = np.random.default_rng(aspect)
    points = _points_above_long_faces(rail, rng, 3000)
    low, high, faces, _ = MeshDistance(rail.vertices, rail.faces).query(points)
    truth = exact_distances_m(rail, points)
    assert np.all(low <= truth + 1e-10) and np.all(truth - 1e-10 <= high)
    assert np.max(high - low) < 1e-9
    for row in rng.choice(len(points), 30, replace=False):  # exact arithmetic on a few, for the nearest face
        corners = rail.vertices[rail.faces[faces[row]]]
        exact = _exact_squared_distance(points[row], *corners)
        assert Fraction(low[row]) ** 2 <= exact <= Fraction(high[row]) ** 2


def test_open3d_float32_errs_on_the_same_slivers_so_the_test_above_can_tell():
    rail = _rail(1.0, 0.001)
    points = _points_above_long_faces(rail, np.random.default_rng(3), 3000)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(rail.vertices.astype(np.float32)),
                        o3d.core.Tensor(rail.faces.astype(np.uint32)))
    closest = scene.compute_closest_points(o3d.core.Tensor(points.astype(np.float32)))["points"].numpy()
    float32_error = np.abs(np.linalg.norm(points - closest, axis=1) - exact_distances_m(rail, points))
    assert np.max(float32_error) > 1e-5


@pytest.mark.parametrize("seed", range(4))
def test_the_hierarchy_finds_the_nearest_triangle_of_a_whole_mesh(seed):
    rng = np.random.default_rng(seed)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    mesh.vertices += rng.normal(size=mesh.vertices.shape) * 0.003
    slivers = trimesh.creation.cylinder(radius=0.02, height=0.3, sections=256)  # 300 mm x 0.5 mm side faces
    mesh = trimesh.util.concatenate([mesh, slivers.apply_translation([0.03, 0.0, 0.0])])
    points = rng.uniform(-0.2, 0.2, (2000, 3)) * rng.choice([0.05, 0.3, 1.0], (2000, 1))
    low, high, faces, _ = MeshDistance(mesh.vertices, mesh.faces).query(points)
    truth = exact_distances_m(mesh, points)
    assert np.all(low <= truth + 1e-12) and np.all(truth <= high + 1e-12)
    assert np.max(high - low) < 1e-9
    corners = mesh.triangles[faces]  # the face returned is a nearest one
    on_face = np.linalg.norm(points - closest_on_triangles(points, corners[:, 0], corners[:, 1], corners[:, 2]), axis=1)
    assert np.all(np.abs(on_face - truth) <= 1e-12)


def _hierarchy_depth(distance: MeshDistance) -> int:
    children = distance.hierarchy[2]
    levels = np.zeros(len(children), np.int64)
    for node in range(len(children)):  # children are numbered after their parent
        if children[node, 0] >= 0:
            levels[children[node]] = levels[node] + 1
    return int(levels.max())


@pytest.mark.parametrize("ratio", [0.5, 0.25])
def test_a_mesh_graded_towards_a_point_gets_a_hierarchy_the_traversals_can_hold(ratio):
    """Triangles shrinking geometrically towards a point (the surface-area heuristic peels off one per level):
    the hierarchy stays shallower than the traversals' stack (it was 568 levels deep, and queries corrupted
    memory), and the queries and rays are still exact."""
    count = 1000
    sizes = ratio ** np.arange(count)
    corners = np.stack([np.column_stack([sizes, np.zeros(count), 0.01 * sizes]),
                        np.column_stack([sizes * ratio, np.zeros(count), np.zeros(count)]),
                        np.column_stack([sizes, 0.1 * sizes, np.zeros(count)])], axis=1)
    vertices, faces = corners.reshape(-1, 3), np.arange(3 * count).reshape(count, 3)
    distance = MeshDistance(vertices, faces)
    assert _hierarchy_depth(distance) < STACK_DEPTH - 1
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.0, 1.0, (3000, 3)) * rng.choice([1e-6, 1e-3, 1.0], (3000, 1))
    low, high, _, _ = distance.query(points)
    truth = exact_distances_m(trimesh.Trimesh(vertices, faces, process=False), points)
    assert np.all(low <= truth + 1e-12) and np.all(truth <= high + 1e-12)
    first, crossings = distance.rays(points, np.array([0.0, 0.0, -1.0]))
    assert np.all(crossings <= 1) and np.all(np.isinf(first) == (crossings == 0))


@pytest.mark.parametrize("seed", range(6))
def test_every_node_of_the_hierarchy_boxes_exactly_its_own_triangles(seed):
    """Whatever the triangles (coincident centres, a grid, slivers, one triangle): ``order`` holds each triangle
    once, each inner node's range is its two children's, back to back, each leaf holds at most LEAF_TRIANGLES, and
    each node's box is the smallest box around its triangles (a traversal prunes by it, so a box that missed one
    could prune the nearest triangle away)."""
    rng = np.random.default_rng(seed)
    count = int(rng.choice([1, 2, 5, 300, 4000]))
    vertices = rng.normal(size=(3 * count, 3)) * rng.uniform(1e-4, 1.0, 3)
    if seed % 2:
        vertices = np.round(vertices, 1)  # many triangles with the same centre along an axis, or everywhere
    faces = rng.permutation(3 * count).reshape(count, 3)
    node_low, node_high, children, ranges, order = MeshDistance(vertices, faces).hierarchy
    assert np.array_equal(np.sort(order), np.arange(count))
    corners = vertices[faces[order]]
    for node in range(len(children)):
        start, stop = ranges[node]
        assert np.array_equal(node_low[node], corners[start:stop].min(axis=(0, 1)))
        assert np.array_equal(node_high[node], corners[start:stop].max(axis=(0, 1)))
        first, second = children[node]
        if first < 0:
            assert 1 <= stop - start <= LEAF_TRIANGLES or count == 0
        else:
            assert ranges[first, 0] == start and ranges[first, 1] == ranges[second, 0] and ranges[second, 1] == stop
            assert ranges[first, 1] > start and ranges[second, 0] < stop


def test_a_hint_face_only_speeds_the_search_up():
    rng = np.random.default_rng(5)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    distance = MeshDistance(mesh.vertices, mesh.faces)
    points = rng.uniform(-0.08, 0.08, (3000, 3))
    truth = exact_distances_m(mesh, points)
    for hints in (rng.integers(0, len(mesh.faces), len(points)), np.full(len(points), -1)):
        low, high, faces, _ = distance.query(points, hints)
        assert np.all(low <= truth + 1e-12) and np.all(truth <= high + 1e-12) and np.max(high - low) < 1e-9
    with pytest.raises(ValueError):
        distance.query(points[:2], np.array([0, len(mesh.faces)]))


@pytest.mark.parametrize("cap_m", [1e-4, 0.004, 0.03, 0.2])
def test_a_capped_query_is_exact_where_it_names_a_face_and_far_only_where_every_face_lies_beyond_the_cap(cap_m):
    """A noisy sphere with 300 mm slivers beside it, half of its faces flipped and some repeated, queried from
    points on it, near it and far from it, with hints and without: a query names a face exactly where the exact
    distance could be within the cap, and then gives the uncapped interval bit for bit."""
    rng = np.random.default_rng(11)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    sphere.vertices += rng.normal(size=sphere.vertices.shape) * 0.003
    slivers = trimesh.creation.cylinder(radius=0.02, height=0.3, sections=256).apply_translation([0.03, 0.0, 0.0])
    mesh = trimesh.util.concatenate([sphere, slivers])
    faces = np.asarray(mesh.faces).copy()
    flipped = rng.random(len(faces)) < 0.5
    faces[flipped] = faces[flipped][:, ::-1]
    faces = np.vstack([faces, faces[rng.integers(len(faces), size=200)]])
    distance = MeshDistance(mesh.vertices, faces)
    on_surface = trimesh.sample.sample_surface(mesh, 1500, seed=11)[0]
    points = np.vstack([on_surface + rng.normal(0.0, 1e-3, on_surface.shape), on_surface,
                        rng.uniform(-0.3, 0.3, (1500, 3))])
    truth = exact_distances_m(trimesh.Trimesh(mesh.vertices, faces, process=False), points)
    for hints in (np.full(len(points), -1), rng.integers(0, len(faces), len(points))):
        exact = distance.query(points, hints)
        low, high, found, weights = distance.query(points, hints, cap_m)
        far = found < 0
        assert np.all(truth[far] >= cap_m - 1e-12)  # nothing within the cap is called far
        assert np.all(low[far] == cap_m) and np.all(high[far] == np.inf)
        near = ~far
        for capped, uncapped in zip((low, high, found, weights), exact, strict=True):
            np.testing.assert_array_equal(capped[near], uncapped[near])
        assert 0 < np.count_nonzero(far) < len(points) or cap_m == 0.2


def test_rays_find_the_first_hit_and_cross_a_closed_mesh_an_odd_number_of_times_from_inside():
    rng = np.random.default_rng(8)
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    mesh.vertices += rng.normal(size=mesh.vertices.shape) * 0.004
    distance = MeshDistance(mesh.vertices, mesh.faces)
    origins = rng.uniform(-0.08, 0.08, (2000, 3))
    directions = rng.normal(size=(2000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    first, crossings = distance.rays(origins, directions)
    expected = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
    locations, rays, _ = expected.intersects_location(origins, directions, multiple_hits=True)
    travelled = np.einsum("ij,ij->i", locations - origins[rays], directions[rays])
    for ray in range(len(origins)):
        hits = travelled[(rays == ray) & (travelled > 0)]
        assert crossings[ray] == len(hits)
        assert (first[ray] == np.inf) if len(hits) == 0 else first[ray] == pytest.approx(hits.min(), abs=1e-12)
    import igl
    inside = igl.winding_number(np.asarray(mesh.vertices), np.asarray(mesh.faces, np.int64), origins) > 0.5
    assert np.mean((crossings % 2 == 1) == inside) > 0.999


def test_the_warm_up_loads_the_compiled_queries_a_process_uses_first():
    """In a fresh process (the wizard calls it while it says it is starting): afterwards building an oracle and the
    serial point and ray queries run compiled code already loaded, not loaded at the first simulated tap."""
    script = ("import fixwizard.geometry.mesh_distance as m\n"
              "from fixwizard.fixture import warm_up_distance_queries\n"
              "used = (m._build_hierarchy, m._triangle_rows, m._query_range, m._ray_range)\n"
              "assert not any(f.signatures for f in used)\n"
              "warm_up_distance_queries()\n"
              "assert all(f.signatures for f in used)\n")
    subprocess.run([sys.executable, "-c", script], check=True, timeout=300)
