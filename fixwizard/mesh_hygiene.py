"""Mesh hygiene before any solve: what a CAD export gets wrong, repaired where that is unambiguous, and whether
the distance's sign (inside or outside the solid) can be trusted.

A wrong sign next to the surface rejects the true pose (a ball centre just outside looks like one just inside),
so the signed distance is used only where the mesh is closed and consistently oriented outward:

- vertices that are not finite numbers: refused (nothing sensible can be made of them);
- faces with a repeated vertex or zero area: dropped, unless that opens the mesh (they cover no surface, and a
  closed mesh keeps its sign); a mesh of such faces only: refused (it has no surface to tap);
- open (not watertight): unsigned distance;
- faces wound against their neighbours: re-wound to agree with their neighbours, face by face outward from one
  face of each body (what ``trimesh.repair.fix_winding`` does, without its networkx walk), which is unambiguous on
  a closed manifold; if the mesh still cannot be wound consistently, unsigned distance;
- a body inside out: each connected body is oriented by how deep it is nested, outward where it lies inside an
  even number of other bodies (a solid), inward where odd (a cavity); bodies that cut through each other count
  as separate solids, each oriented outward;
- several bodies: said, since the fixture is then taken as one rigid whole.

Every repair and fallback is a warning that reaches the report.
"""

from dataclasses import dataclass

import igl
import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, shortest_path

from fixwizard.errors import MeshError

# Vertices of a body tested against another body's winding number to tell nesting apart from cutting through.
NESTING_SAMPLE = 64
MAX_COORDINATE = 1e9  # in the file's units: a million kilometres in metres, a thousand in millimetres


@dataclass(frozen=True)
class CleanMesh:
    """A checked mesh (m), whether its signed distance can be trusted, and (code, message) warnings."""

    mesh: trimesh.Trimesh
    signed: bool
    warnings: tuple[tuple[str, str], ...]


def refuse_non_finite(vertices: np.ndarray, name: str) -> None:
    """Raise ``MeshError`` naming the vertices that are not finite numbers."""
    bad = np.flatnonzero(~np.all(np.isfinite(vertices), axis=1))
    if len(bad):
        raise MeshError(f"{name} has {len(bad)} vertices that are not finite numbers (NaN or infinity; the first "
                        f"is vertex {bad[0] + 1}); export the mesh again from CAD")


def refuse_far_vertices(vertices: np.ndarray, name: str) -> None:
    """Raise ``MeshError`` when a coordinate lies beyond ``MAX_COORDINATE`` (no fixture in metres or millimetres
    does; squares of such numbers overflow in every later step)."""
    largest = float(np.max(np.abs(vertices))) if len(vertices) else 0.0
    if largest > MAX_COORDINATE:
        raise MeshError(f"{name} has vertex coordinates up to {largest:.3g}, far beyond any fixture in metres or "
                        "millimetres: the export went wrong (or is in other units); export the mesh again from CAD")


def _adjacency(mesh: trimesh.Trimesh) -> coo_matrix:
    pairs = np.asarray(mesh.face_adjacency)
    count = len(mesh.faces)
    return coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(count, count)).tocsr()


def _bodies(mesh: trimesh.Trimesh) -> list[np.ndarray]:
    """Face indices of each connected body (faces joined by shared edges)."""
    labels = connected_components(_adjacency(mesh), directed=False)[1]
    return [np.flatnonzero(labels == label) for label in np.unique(labels)]


def _agreeing_winding(mesh: trimesh.Trimesh) -> np.ndarray:
    """The faces, each turned where needed to agree with the face it is reached from in a breadth-first walk
    from one face of each body (so neighbours traverse their shared edge in opposite directions)."""
    faces = np.asarray(mesh.faces)
    pairs = np.asarray(mesh.face_adjacency)
    shared = np.asarray(mesh.face_adjacency_edges)

    def forward(face_rows: np.ndarray) -> np.ndarray:
        """Whether each face of a pair traverses the shared edge from its first vertex to its second."""
        corners = faces[face_rows]
        starts = np.argmax(corners == shared[:, :1], axis=1)
        return corners[np.arange(len(corners)), (starts + 1) % 3] == shared[:, 1]

    disagree = forward(pairs[:, 0]) == forward(pairs[:, 1])
    count = len(faces)
    relation = coo_matrix((np.concatenate([disagree, disagree]) + 1.0,
                           (np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]]))),
                          shape=(count, count)).tocsr()
    turn = np.zeros(count, bool)
    seen = np.zeros(count, bool)
    for start in range(count):
        if seen[start]:
            continue
        hops, predecessors = shortest_path(relation, directed=False, indices=start, unweighted=True,
                                           return_predecessors=True)
        reached = np.flatnonzero(np.isfinite(hops))
        seen[reached] = True
        children = reached[reached != start]
        flips = np.asarray(relation[predecessors[children], children]).ravel() == 2.0
        for level in range(1, int(hops[reached].max()) + 1):  # parents are a hop nearer: settled first
            at_level = hops[children] == level
            turn[children[at_level]] = turn[predecessors[children[at_level]]] ^ flips[at_level]
    turned = faces.copy()
    turned[turn] = turned[turn][:, ::-1]
    return turned


def _signed_volume_m3(vertices: np.ndarray, faces: np.ndarray) -> float:
    corners = vertices[faces]
    return float(np.sum(np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))) / 6.0)


def _nesting_depths(mesh: trimesh.Trimesh, bodies: list[np.ndarray]) -> np.ndarray:
    """How many other bodies wholly contain each body (bodies that cut through each other do not count)."""
    vertices = np.asarray(mesh.vertices)
    boxes = [(vertices[mesh.faces[faces]].reshape(-1, 3).min(0), vertices[mesh.faces[faces]].reshape(-1, 3).max(0))
             for faces in bodies]
    depths = np.zeros(len(bodies), int)
    for inner, faces in enumerate(bodies):
        used = np.unique(mesh.faces[faces])
        sample = vertices[used[np.linspace(0, len(used) - 1, min(NESTING_SAMPLE, len(used))).astype(int)]]
        for outer, outer_faces in enumerate(bodies):
            low, high = boxes[outer]
            if outer == inner or np.any(boxes[inner][0] < low) or np.any(boxes[inner][1] > high):
                continue
            winding = np.abs(igl.winding_number(vertices, np.ascontiguousarray(mesh.faces[outer_faces]), sample))
            depths[inner] += bool(np.all(winding > 0.5))
    return depths


def _drop_degenerate(mesh: trimesh.Trimesh, name: str) -> tuple[trimesh.Trimesh, list[tuple[str, str]]]:
    """The mesh without faces that have a repeated vertex or zero area, unless dropping them opens a closed mesh;
    ``MeshError`` when every face is such."""
    faces = np.asarray(mesh.faces)
    corners = np.asarray(mesh.vertices)[faces]
    zero_area = ~np.any(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    repeated = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 0] == faces[:, 2])
    degenerate = zero_area | repeated
    if np.all(degenerate):
        raise MeshError(f"{name}: all {len(faces)} of its faces have zero area (their corners coincide or lie on "
                        "one line), so it holds no surface to tap; export the fixture's surface as a triangle mesh "
                        "again")
    if not np.any(degenerate):
        return mesh, []
    kept = trimesh.Trimesh(mesh.vertices, faces[~degenerate], process=False)
    kept.remove_unreferenced_vertices()
    if mesh.is_watertight and not kept.is_watertight:
        return mesh, []
    return kept, [("mesh_degenerate_faces_dropped",
                   f"{name}: {np.count_nonzero(degenerate)} faces of zero area were dropped (they cover no "
                   "surface).")]


def _orient(mesh: trimesh.Trimesh, name: str) -> tuple[trimesh.Trimesh, bool, list[tuple[str, str]]]:
    """A closed mesh consistently wound with every body oriented by its nesting, and whether that succeeded."""
    original = np.asarray(mesh.faces)
    consistent = mesh.is_winding_consistent
    if not consistent:
        mesh = trimesh.Trimesh(mesh.vertices, _agreeing_winding(mesh), process=False)
        if not mesh.is_winding_consistent:
            return mesh, False, [("mesh_orientation_unknown",
                                  f"{name} is closed but its faces cannot be wound consistently (a non-manifold or "
                                  "non-orientable surface), so fixwizard cannot tell inside from outside and uses "
                                  "the unsigned distance: the bounds stay guaranteed but may be looser. Repair the "
                                  "mesh in CAD for tighter bounds.")]
    bodies = _bodies(mesh)
    depths = _nesting_depths(mesh, bodies) if len(bodies) > 1 else np.zeros(1, int)
    faces = np.asarray(mesh.faces).copy()
    inverted = 0
    for body, depth in zip(bodies, depths, strict=True):
        if (_signed_volume_m3(np.asarray(mesh.vertices), faces[body]) > 0.0) != (depth % 2 == 0):
            faces[body] = faces[body][:, ::-1]
            inverted += 1
    mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
    turned = int(np.count_nonzero(np.any(faces != original, axis=1)))
    warnings: list[tuple[str, str]] = []
    if not consistent:
        warnings.append(("mesh_winding_repaired",
                         f"{name}: {turned} of its {len(faces)} faces were wound the wrong way round (inside out); "
                         "fixwizard turned them to face outward like their neighbours."))
    elif inverted:
        warnings.append(("mesh_inverted_repaired",
                         f"{name}: {inverted} of its {len(bodies)} bodies were inside out (faces pointing inward); "
                         "fixwizard turned them outward."))
    if len(bodies) > 1:
        cavities = int(np.count_nonzero(depths % 2))
        warnings.append(("mesh_several_bodies",
                         f"{name} holds {len(bodies)} separate bodies" + (f" ({cavities} of them cavities)"
                                                                           if cavities else "")
                         + "; fixwizard takes them as one rigid fixture. If they are separate parts, solve each "
                         "with its own mesh."))
    return mesh, True, warnings


def clean_mesh(mesh: trimesh.Trimesh, name: str) -> CleanMesh:
    """Check and repair a mesh (see the module doc); ``name`` names it in messages. Raises ``MeshError`` for
    vertices that are not finite numbers or lie absurdly far."""
    refuse_non_finite(np.asarray(mesh.vertices), name)
    refuse_far_vertices(np.asarray(mesh.vertices), name)
    mesh, warnings = _drop_degenerate(mesh, name)
    if not mesh.is_watertight:
        warnings.append(("mesh_not_watertight",
                         f"{name} is not watertight (it has holes or open edges), so fixwizard cannot tell inside "
                         "from outside and uses the unsigned distance: the bounds stay guaranteed but may be "
                         "looser. Close the mesh in CAD for tighter bounds."))
        return CleanMesh(mesh, False, tuple(warnings))
    mesh, signed, orient_warnings = _orient(mesh, name)
    return CleanMesh(mesh, signed, tuple(warnings + orient_warnings))
