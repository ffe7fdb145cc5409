"""Test fixtures generated with trimesh: asymmetric shapes and symmetric ones with known symmetry orders."""

from pathlib import Path

import numpy as np
import trimesh

from fixwizard.fixture import Fixture, fixture_from_mesh


def l_prism() -> trimesh.Trimesh:
    """An L-shaped plate with unequal arms and a notch, 10 mm thick: no rotational symmetry."""
    outline = np.array([[0, 0], [0.12, 0], [0.12, 0.03], [0.05, 0.03], [0.05, 0.06], [0.035, 0.06],
                        [0.035, 0.08], [0, 0.08]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [0, 5, 7], [5, 6, 7]])
    mesh = trimesh.creation.extrude_triangulation(outline, faces, height=0.01)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def random_polytope(seed: int) -> trimesh.Trimesh:
    """Convex hull of random points in a 10 x 6 x 4 cm box: almost surely asymmetric."""
    points = np.random.default_rng(seed).random((14, 3)) * [0.1, 0.06, 0.04]
    return trimesh.convex.convex_hull(points)


def cube() -> trimesh.Trimesh:
    """A 6 cm cube: 24 rotational symmetries."""
    return trimesh.creation.box((0.06, 0.06, 0.06))


def brick() -> trimesh.Trimesh:
    """A 10 x 6 x 3 cm box: 4 rotational symmetries."""
    return trimesh.creation.box((0.10, 0.06, 0.03))


def triangular_prism() -> trimesh.Trimesh:
    """An equilateral triangular prism, 2 cm thick: 6 rotational symmetries."""
    return trimesh.creation.cylinder(radius=0.05, height=0.02, sections=3)


def cylinder() -> trimesh.Trimesh:
    return trimesh.creation.cylinder(radius=0.03, height=0.08, sections=48)


def cone() -> trimesh.Trimesh:
    return trimesh.creation.cone(radius=0.04, height=0.07, sections=48)


def two_boss_bar(boss_spacing_m: float = 0.05) -> trimesh.Trimesh:
    """A 300 x 20 x 30 mm bar (x, y, z) with two identical 10 x 10 mm bosses on its top (y = 20 mm), at x = 20 mm and
    x = 20 mm + ``boss_spacing_m``: taps on one boss fit the other as well."""
    first, second = 0.02, 0.02 + boss_spacing_m
    outline = np.array([[-0.15, 0], [0.15, 0], [0.15, 0.02], [second + 0.005, 0.02], [second + 0.005, 0.03],
                        [second - 0.005, 0.03], [second - 0.005, 0.02], [first + 0.005, 0.02], [first + 0.005, 0.03],
                        [first - 0.005, 0.03], [first - 0.005, 0.02], [-0.15, 0.02]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 6], [0, 6, 7], [0, 7, 10], [0, 10, 11], [3, 4, 5], [3, 5, 6],
                      [7, 8, 9], [7, 9, 10]])
    mesh = trimesh.creation.extrude_triangulation(outline, faces, height=0.03)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def fan_capped_prism(outline: np.ndarray, height_m: float) -> trimesh.Trimesh:
    """A prism over an outline (counter-clockwise, m; one that crosses itself gives a prism crossing itself), its caps
    cut in fans from the outline's first vertex, as an extruded sketch exports."""
    count = len(outline)
    vertices = np.vstack([np.column_stack([outline, np.zeros(count)]),
                          np.column_stack([outline, np.full(count, height_m)])])
    bottom = [[0, k + 1, k] for k in range(1, count - 1)]
    top = [[count, count + k, count + k + 1] for k in range(1, count - 1)]
    walls = [face for k in range(count)
             for face in ([k, (k + 1) % count, count + (k + 1) % count], [k, count + (k + 1) % count, count + k])]
    return trimesh.Trimesh(vertices, np.array(bottom + top + walls), process=False)


def with_t_junctions(mesh: trimesh.Trimesh, rng: np.random.Generator, share: float = 0.3,
                     rounds: int = 2) -> tuple[trimesh.Trimesh, np.ndarray]:
    """The mesh with a random ``share`` of its faces split at their edges' midpoints, ``rounds`` times (each round
    among the faces of the last), the neighbours left whole, as STL exporters leave them: T-junctions, up to three
    on an edge and on several edges of a face. Returns it and the indices of its new vertices."""
    split = mesh.copy()
    chosen = rng.random(len(split.faces)) < share
    chosen[rng.integers(len(chosen))] = True
    for _ in range(rounds):
        before = len(split.faces)
        split = split.subdivide(face_index=np.flatnonzero(chosen))
        new_faces = np.arange(len(split.faces)) >= before - np.count_nonzero(chosen)
        chosen = new_faces & (rng.random(len(split.faces)) < 0.5)
    return split, np.arange(len(mesh.vertices), len(split.vertices))


def moved(mesh: trimesh.Trimesh, vertices: np.ndarray, length_m: float, rng: np.random.Generator) -> trimesh.Trimesh:
    """The mesh with the given vertices each moved ``length_m`` in a random direction (a T-junction's vertex off its
    edge by an export's rounding)."""
    directions = rng.normal(size=(len(vertices), 3))
    shifted = np.asarray(mesh.vertices).copy()
    shifted[vertices] += length_m * directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return trimesh.Trimesh(shifted, mesh.faces, process=False)


def cracked(mesh: trimesh.Trimesh, rng: np.random.Generator, length_m: float,
            share: float = 0.3) -> trimesh.Trimesh:
    """The mesh with a random ``share`` of its faces (one at least) given their own copies of their corners, each
    moved up to ``length_m`` in a random direction: a patch whose shared vertices an exporter wrote apart, a crack
    along its rim."""
    faces, vertices = np.asarray(mesh.faces).copy(), np.asarray(mesh.vertices)
    patch = rng.random(len(faces)) < share
    patch[rng.integers(len(faces))] = True
    corners = np.unique(faces[patch])
    directions = rng.normal(size=(len(corners), 3))
    directions *= length_m * rng.random((len(corners), 1)) / np.linalg.norm(directions, axis=1, keepdims=True)
    copy_of = np.arange(len(vertices))
    copy_of[corners] = len(vertices) + np.arange(len(corners))
    faces[patch] = copy_of[faces[patch]]
    return trimesh.Trimesh(np.vstack([vertices, vertices[corners] + directions]), faces, process=False)


WARPED_BOX_QUADS = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])


def warped_box_vertices(raise_m: float = 0.002) -> np.ndarray:
    """The corners (8, 3, m) of a 100 x 60 x 30 mm box with the top corner at +x +y raised by ``raise_m``: its top
    and two of its sides (``WARPED_BOX_QUADS``, wound outward) are quads that are not flat."""
    vertices = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0.06, 0], [0, 0.06, 0], [0, 0, 0.03], [0.1, 0, 0.03],
                         [0.1, 0.06, 0.03], [0, 0.06, 0.03]])
    vertices[6, 2] += raise_m
    return vertices


def polygons_obj(vertices: np.ndarray, polygons: np.ndarray) -> str:
    """An OBJ file of polygon faces (rows of corner indices), every digit of the vertices kept."""
    return "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist()) + "".join(
        "f " + " ".join(str(corner + 1) for corner in polygon) + "\n" for polygon in polygons.tolist())


def across_other_diagonals(vertices: np.ndarray, quads: np.ndarray) -> trimesh.Trimesh:
    """The quads each cut along the diagonal trimesh does not cut them along (it fans from the first corner)."""
    return trimesh.Trimesh(vertices, np.vstack([quads[:, [1, 2, 3]], quads[:, [1, 3, 0]]]), process=False)


SHAPES = {"l_prism": l_prism, "polytope": lambda: random_polytope(7), "cube": cube, "brick": brick,
          "triangular_prism": triangular_prism, "cylinder": cylinder, "cone": cone}


def as_fixture(name: str, mesh: trimesh.Trimesh | None = None) -> Fixture:
    """A generated shape as a Fixture (metres), with a stand-in path for messages."""
    mesh = mesh if mesh is not None else SHAPES[name]()
    return fixture_from_mesh(mesh, Path(f"{name}.stl"), "m", "generated")
