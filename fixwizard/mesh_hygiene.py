"""Mesh hygiene before any solve: what a CAD export gets wrong, repaired where that is unambiguous, and whether
the distance's sign (inside or outside the solid) can be trusted.

A wrong sign next to the surface rejects the true pose (a ball centre just outside looks like one just inside),
so the signed distance is used only where the mesh is closed and consistently oriented outward:

- vertices that are not finite numbers: refused (nothing sensible can be made of them);
- faces with a repeated vertex or zero area: dropped, unless that opens the mesh (they cover no surface, and a
  closed mesh keeps its sign); a mesh of such faces only: refused (it has no surface to tap);
- faces that repeat another (the same three corners, wound either way): dropped (a copy adds no surface, and
  leaves the edges around it with four faces, so the mesh would look open);
- open only at cracks, as STL exporters leave them: vertices of open edges within rounding of one another (two
  patches whose shared vertices were written apart) are merged, and T-junctions (a vertex of some faces on an
  edge of their neighbour, which was not split there) are split, which closes the mesh; a vertex may lie off by
  rounding (up to ``ZIP_SHARE`` of the mesh's size), so the closed surface lies up to that far from the exported
  one (``CleanMesh.surface_offset_m``), and the search widens every tap's band by it;
- open (not watertight) otherwise: unsigned distance;
- faces wound against their neighbours: re-wound to agree with their neighbours, face by face outward from one
  face of each body (what ``trimesh.repair.fix_winding`` does, without its networkx walk), which is unambiguous on
  a closed manifold; if the mesh still cannot be wound consistently, unsigned distance;
- a body inside out: each connected body is oriented by how deep it is nested, outward where it lies inside an
  even number of other bodies (a solid), inward where odd (a cavity); bodies that cut through or touch each
  other count as separate solids, each oriented outward (a body counts as nested only when its vertices lie inside
  the other and the two surfaces do not meet: corners inside a concave body do not prove it);
- a surface that crosses itself, or lays faces over one another facing opposite ways (a self-crossing outline
  extruded): found where another face meets a face inside (``geometry.face_contact``, a proof by separating axes),
  or where points just off a face lie inside on its outer side or outside on its inner side
  (``_faces_whose_side_misleads``), unsigned distance;
- several bodies: said, since the fixture is then taken as one rigid whole.

Every repair and fallback is a warning that reaches the report.
"""

import itertools
from dataclasses import dataclass

import igl
import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, shortest_path
from scipy.spatial import cKDTree

from fixwizard.errors import MeshError
from fixwizard.geometry.face_contact import CROWDED, MET, UNMET, faces_met
from fixwizard.geometry.mesh_distance import MeshDistance

# Vertices of a body tested against another body's winding number to tell nesting apart from cutting through.
NESTING_SAMPLE = 64
TOUCH_M = 1e-7  # a vertex this near another body's surface (m) counts as meeting it
MAX_COORDINATE = 1e9  # in the file's units: a million kilometres in metres, a thousand in millimetres
# A vertex of an open edge this near another vertex or open edge (a share of the mesh's bounding-box diagonal) is
# that place written apart by rounding: a crack or a T-junction. An ASCII STL of six significant digits puts it up to
# about 2e-6 of the size off; 1e-5 of a 300 mm fixture is 3 micrometres, which the bounds carry (``surface_offset_m``).
ZIP_SHARE = 1e-5
# float64 rounding of a vertex's distance from another vertex or off an edge (a difference, a projection and a norm of
# coordinates) and of a face's centroid, as a share of the largest coordinate: a few ulps each, taken generously.
ZIP_ROUNDING = 16.0 * float(np.finfo(np.float64).eps)
# Whether each face's plane tells inside from outside next to it is looked at just off its centroid, on both sides,
# this share of the mesh's bounding-box diagonal away (0.3 micrometres off a 300 mm fixture: far thinner than any
# wall), once no other face is found to meet it inside (``face_contact``).
SIDE_STEP_SHARE = 1e-6
# A face whose largest angle has a sine below this has no normal worth trusting for a sign (a sliver of zero area
# left in to keep the mesh closed): points nearest to it are checked by ray parity, and its sides are not looked at.
RELIABLE_NORMAL_SINE = 1e-6
SIDE_RAY = np.array([0.0117, 0.0131, 1.0]) / np.linalg.norm([0.0117, 0.0131, 1.0])  # off every axis: parity rays


@dataclass(frozen=True)
class CleanMesh:
    """A checked mesh (m), whether its signed distance can be trusted, (code, message) warnings, which faces'
    planes do not sign the distance (``plane_unsigned_faces``, one per face; points nearest to them are signed as
    near an edge, by ray parity and the winding number): those of a body that meets another (a point nearest to one
    may lie inside the other body), and those the self-crossing check did not look at (slivers, and faces too
    crowded by long thin faces: ``face_contact.CROWDED``); and
    how far the mesh's surface may lie from the exported one (m: every point of either within that of the other; zero
    unless cracks were closed)."""

    mesh: trimesh.Trimesh
    signed: bool
    warnings: tuple[tuple[str, str], ...]
    plane_unsigned_faces: np.ndarray
    surface_offset_m: float = 0.0


def used_vertices(faces: np.ndarray) -> np.ndarray:
    """The vertices that ``faces`` name, ascending, each once: np.unique's hash table took seconds for the millions
    of corners of a large export, a sort takes a tenth of a second (and, unlike counting up to the largest vertex
    number, only as long as ``faces`` is: one body's faces of a large assembly are checked many times)."""
    named = np.sort(np.asarray(faces, np.int64).ravel())
    return named[np.concatenate([[True], named[1:] != named[:-1]])] if len(named) else named


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


def _meets(vertices: np.ndarray, faces: np.ndarray, other: MeshDistance) -> bool:
    """Whether a surface (``faces`` of ``vertices``, m) meets the surface ``other``: an edge of it crosses one of
    ``other``'s triangles, or a vertex of it lies within ``TOUCH_M`` of them."""
    starts = vertices[faces].reshape(-1, 3)
    edges = vertices[np.roll(faces, -1, axis=1)].reshape(-1, 3) - starts
    first_hit = other.rays(starts, edges)[0]  # in edge lengths
    if np.any(first_hit <= 1.0 + 1e-9):
        return True
    corners = vertices[used_vertices(faces)]
    return bool(np.any(other.query(corners, cap_m=2.0 * TOUCH_M)[0] <= TOUCH_M))


def _nesting(mesh: trimesh.Trimesh, bodies: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """How many other bodies wholly contain each body, and which bodies meet another (their surfaces cross or
    touch). A body counts as contained when its vertices lie inside the other (winding number) and the two do
    not meet: a body whose corners all lie inside a concave one can still cut through it. Bodies that meet count
    as separate solids, each oriented outward, which is safe (the mesh then holds their union, or a cavity filled
    in, which no tap can reach), where orienting a body that cuts through as a cavity turns its surface outside
    in."""
    vertices = np.asarray(mesh.vertices)
    boxes = [(vertices[mesh.faces[faces]].reshape(-1, 3).min(0), vertices[mesh.faces[faces]].reshape(-1, 3).max(0))
             for faces in bodies]
    surfaces: dict[int, MeshDistance] = {}

    def surface(body: int) -> MeshDistance:
        if body not in surfaces:
            surfaces[body] = MeshDistance(vertices, mesh.faces[bodies[body]])
        return surfaces[body]

    depths = np.zeros(len(bodies), int)
    meeting = np.zeros(len(bodies), bool)
    for first, second in itertools.combinations(range(len(bodies)), 2):
        (low_1, high_1), (low_2, high_2) = boxes[first], boxes[second]
        if np.any(high_1 < low_2 - TOUCH_M) or np.any(high_2 < low_1 - TOUCH_M):
            continue
        if (_meets(vertices, mesh.faces[bodies[first]], surface(second))
                or _meets(vertices, mesh.faces[bodies[second]], surface(first))):
            meeting[[first, second]] = True
            continue
        for inner, outer in ((first, second), (second, first)):
            used = used_vertices(mesh.faces[bodies[inner]])
            sample = vertices[used[np.linspace(0, len(used) - 1, min(NESTING_SAMPLE, len(used))).astype(int)]]
            winding = igl.winding_number(vertices, np.ascontiguousarray(mesh.faces[bodies[outer]]), sample)
            depths[inner] += bool(np.all(np.abs(winding) > 0.5))
    return depths, meeting


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


def _drop_repeated(mesh: trimesh.Trimesh, name: str) -> tuple[trimesh.Trimesh, list[tuple[str, str]]]:
    """The mesh with each face that repeats an earlier one (the same three corners, wound either way) dropped: a
    copy adds no surface, and a copy wound the other way would leave the mesh open in trimesh's eyes (each edge
    then has four faces), unsigned. The faces kept are wound as ``_orient`` then says."""
    faces = np.asarray(mesh.faces)
    first = np.sort(np.unique(np.sort(faces, axis=1), axis=0, return_index=True)[1])
    if len(first) == len(faces):
        return mesh, []
    kept = trimesh.Trimesh(mesh.vertices, faces[first], process=False)
    return kept, [("mesh_repeated_faces_dropped",
                   f"{name}: {len(faces) - len(first)} faces repeat another face (the same three corners) and were "
                   "dropped (a copy adds no surface).")]


@dataclass(frozen=True)
class Closed:
    """A mesh closed at its cracks (m): how many vertices of its open edges were merged into another within
    rounding, how many T-junctions were split, and how far its surface may lie from the exported one (m: every
    point of either within that of the other)."""

    mesh: trimesh.Trimesh
    merged: int
    junctions: int
    offset_m: float


def _open_edges(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, float]:
    """The rows of ``mesh.edges`` (face ``row // 3``, from its corner ``row % 3`` to the next) that no other face
    shares, the vertices on them, and how near two places must be to count as one: ``ZIP_SHARE`` of the mesh's
    diagonal (m)."""
    edges = np.asarray(mesh.edges)
    open_rows = trimesh.grouping.group_rows(np.sort(edges, axis=1), require_count=1)
    tolerance_m = ZIP_SHARE * float(np.linalg.norm(np.ptp(np.asarray(mesh.vertices), axis=0)))
    return open_rows, used_vertices(edges[open_rows]), tolerance_m


def _facing_as_before(vertices: np.ndarray, faces: np.ndarray, replaced_normals: np.ndarray) -> bool:
    """Whether each face (corners in ``vertices``) has area and faces as the face it replaces."""
    corners = vertices[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    return bool(np.all(np.einsum("ij,ij->i", normals, replaced_normals) > 0.0))


def _merge_near_rim_vertices(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, int, float] | None:
    """The mesh with the vertices of its open edges that lie within ``_open_edges``'s tolerance of one another
    merged into one of them (a crack between two patches whose shared vertices were written apart by rounding),
    how many were merged into another, and the farthest any moved (m). Two corners of one face are never merged
    (a T-junction near a corner is split instead). Unchanged when none lie so near; None when merging would
    collapse or turn a face."""
    _, rim, tolerance_m = _open_edges(mesh)
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    pairs = cKDTree(vertices[rim]).query_pairs(tolerance_m, output_type="ndarray")
    count = len(vertices)
    edge_keys = np.unique(np.sort(np.asarray(mesh.edges), axis=1) @ [count, 1])
    pairs = pairs[~np.isin(np.sort(rim[pairs], axis=1) @ [count, 1], edge_keys)]  # two corners of a face stay two
    if len(pairs) == 0:
        return mesh, 0, 0.0
    groups = connected_components(coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                                             shape=(len(rim), len(rim))), directed=False)[1]
    first_of_group = np.unique(groups, return_index=True)[1]
    kept = np.arange(len(vertices))
    kept[rim] = rim[first_of_group[groups]]
    merged_faces = kept[faces]
    changed = np.any(merged_faces != faces, axis=1)
    if not _facing_as_before(vertices, merged_faces[changed], np.asarray(mesh.face_normals)[changed]):
        return None
    merged = trimesh.Trimesh(vertices, merged_faces, process=False)
    merged.remove_unreferenced_vertices()
    moved_m = float(np.max(np.linalg.norm(vertices[rim] - vertices[kept[rim]], axis=1)))
    return merged, int(np.count_nonzero(kept[rim] != rim)), moved_m


def _t_junctions(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The T-junctions of a mesh: for each, the row of ``mesh.edges`` of the open edge it lies on, the vertex, its
    place along the edge (0 to 1, in the face's direction) and its distance off the edge (m). A vertex counts where
    it lies on an open edge's inner part within ``_open_edges``'s tolerance and is no corner of that edge's face."""
    open_rows, rim, tolerance_m = _open_edges(mesh)
    faces, vertices, edges = np.asarray(mesh.faces), np.asarray(mesh.vertices), np.asarray(mesh.edges)
    starts, ends = vertices[edges[open_rows, 0]], vertices[edges[open_rows, 1]]
    reach = 0.5 * np.linalg.norm(ends - starts, axis=1) + tolerance_m
    near = cKDTree(vertices[rim]).query_ball_point(0.5 * (starts + ends), reach)
    rows = np.repeat(open_rows, np.fromiter(map(len, near), np.int64, len(near)))
    candidates = rim[np.fromiter(itertools.chain.from_iterable(near), np.int64, len(rows))]
    start, along = vertices[edges[rows, 0]], vertices[edges[rows, 1]] - vertices[edges[rows, 0]]
    places = np.einsum("ij,ij->i", vertices[candidates] - start, along) / np.einsum("ij,ij->i", along, along)
    off_m = np.linalg.norm(vertices[candidates] - start - places[:, None] * along, axis=1)
    own_corner = np.any(faces[rows // 3] == candidates[:, None], axis=1)
    junction = ~own_corner & (places > 0.0) & (places < 1.0) & (off_m <= tolerance_m)
    return rows[junction], candidates[junction], places[junction], off_m[junction]


def _split_t_junctions(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, int, float] | None:
    """The mesh with every face that has T-junctions on its open edges split there (a fan from the face's centroid
    through its corners and those vertices, in the face's winding), how many there were, and the farthest of them
    off its edge (m). Unchanged when there is none; None when a new face would not face as the face it replaces
    (a vertex off its edge by more than the face is wide)."""
    rows, junction_vertices, places, off_m = _t_junctions(mesh)
    if len(rows) == 0:
        return mesh, 0, 0.0
    faces, vertices = np.asarray(mesh.faces), np.asarray(mesh.vertices)
    split, face_of_junction = np.unique(rows // 3, return_inverse=True)
    # each split face's outline: corner k (place -1 on edge k), then the junctions on edge k by their place
    face_of = np.concatenate([np.repeat(np.arange(len(split)), 3), face_of_junction])
    edge_of = np.concatenate([np.tile(np.arange(3), len(split)), rows % 3])
    place_of = np.concatenate([np.full(3 * len(split), -1.0), places])
    order = np.lexsort((place_of, edge_of, face_of))
    face_of, outline = face_of[order], np.concatenate([faces[split].ravel(), junction_vertices])[order]
    following = np.arange(1, len(outline) + 1)
    ends = following == np.searchsorted(face_of, face_of, side="right")
    following[ends] = np.searchsorted(face_of, face_of[ends], side="left")
    fan_faces = np.stack([outline, outline[following], len(vertices) + face_of], axis=1)
    split_vertices = np.vstack([vertices, vertices[faces[split]].mean(axis=1)])
    if not _facing_as_before(split_vertices, fan_faces, np.asarray(mesh.face_normals)[split][face_of]):
        return None
    split_mesh = trimesh.Trimesh(split_vertices, np.vstack([np.delete(faces, split, axis=0), fan_faces]),
                                 process=False)
    return split_mesh, len(rows), float(np.max(off_m))


def _close_cracks(mesh: trimesh.Trimesh) -> Closed | None:
    """An open mesh closed where it is open only by rounding and T-junctions: near vertices of open edges merged
    (``_merge_near_rim_vertices``), then T-junctions split (``_split_t_junctions``); the surface offsets of the two
    steps add up. None when that leaves it open, changes nothing, or would collapse or turn a face."""
    merged = _merge_near_rim_vertices(mesh)
    if merged is None:
        return None
    merged_mesh, merged_count, moved_m = merged
    split = _split_t_junctions(merged_mesh)
    if split is None:
        return None
    closed, junctions, off_m = split
    if merged_count + junctions == 0 or not closed.is_watertight:
        return None
    rounding_m = ZIP_ROUNDING * float(np.max(np.abs(np.asarray(closed.vertices))))
    offset_m = moved_m + off_m + rounding_m
    return Closed(closed, merged_count, junctions, offset_m)


def _orient(mesh: trimesh.Trimesh, name: str) -> tuple[trimesh.Trimesh, bool, list[tuple[str, str]], np.ndarray]:
    """A closed mesh consistently wound with every body oriented by its nesting, whether that succeeded, and its
    faces whose planes do not sign the distance (``CleanMesh.plane_unsigned_faces``)."""
    original = np.asarray(mesh.faces)
    consistent = mesh.is_winding_consistent
    if not consistent:
        mesh = trimesh.Trimesh(mesh.vertices, _agreeing_winding(mesh), process=False)
        if not mesh.is_winding_consistent:
            return mesh, False, [("mesh_orientation_unknown",
                                  f"{name} is closed but its faces cannot be wound consistently (a non-manifold or "
                                  "non-orientable surface), so fixwizard cannot tell inside from outside and uses "
                                  "the unsigned distance: the bounds stay guaranteed but may be looser. Repair the "
                                  "mesh in CAD for tighter bounds.")], np.zeros(len(original), bool)
    bodies = _bodies(mesh)
    depths, meeting = _nesting(mesh, bodies) if len(bodies) > 1 else (np.zeros(1, int), np.zeros(1, bool))
    faces = np.asarray(mesh.faces).copy()
    inverted = [0, 0]  # solids that faced inward, cavities that faced outward
    for body, depth in zip(bodies, depths, strict=True):
        if (_signed_volume_m3(np.asarray(mesh.vertices), faces[body]) > 0.0) != (depth % 2 == 0):
            faces[body] = faces[body][:, ::-1]
            inverted[depth % 2] += 1
    mesh = trimesh.Trimesh(mesh.vertices, faces, process=False)
    plane_unsigned_faces = np.zeros(len(faces), bool)
    for meets, body_faces in zip(meeting, bodies, strict=True):
        plane_unsigned_faces[body_faces] = meets
    turned = int(np.count_nonzero(np.any(faces != original, axis=1)))
    warnings: list[tuple[str, str]] = []
    if not consistent:
        warnings.append(("mesh_winding_repaired",
                         f"{name}: {turned} of its {len(faces)} faces were wound the wrong way round (inside out); "
                         "fixwizard turned them to face outward like their neighbours."))
    elif any(inverted):
        solids, cavities = inverted
        found = [f"{solids} solid{'s' if solids != 1 else ''} faced inward (inside out)" if solids else "",
                 f"{cavities} cavit{'ies' if cavities != 1 else 'y'} (a body inside another) faced outward"
                 if cavities else ""]
        bodies_named = f"{len(bodies)} bod{'ies' if len(bodies) != 1 else 'y'}"
        warnings.append(("mesh_inverted_repaired",
                         f"{name}: of its {bodies_named}, {' and '.join(part for part in found if part)}; "
                         "fixwizard turned solids to face outward and cavities inward."))
    if len(bodies) > 1:
        cavities = int(np.count_nonzero(depths % 2))
        warnings.append(("mesh_several_bodies",
                         f"{name} holds {len(bodies)} separate bodies" + (f" ({cavities} of them cavities)"
                                                                           if cavities else "")
                         + "; fixwizard takes them as one rigid fixture. If they are separate parts, solve each "
                         "with its own mesh."))
    crossing, unchecked = _faces_whose_side_misleads(mesh, plane_unsigned_faces)
    if crossing:  # the repairs said above still hold
        warnings.append(("mesh_self_intersecting",
                         f"{name} crosses itself or has faces lying over one another ({crossing} of its {len(faces)} "
                         "faces are crossed or touched inside by another face, or face outside on their inner side "
                         "or inside on their outer side), so fixwizard cannot "
                         "tell inside from outside there and uses the unsigned distance: the bounds stay guaranteed "
                         "but may be looser. Repair the mesh in CAD (a union of its solids, no faces crossing) for "
                         "tighter bounds."))
        return mesh, False, warnings, np.zeros(len(faces), bool)
    return mesh, True, warnings, plane_unsigned_faces | unchecked


def reliable_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Whether each face's normal can be trusted for a sign (``RELIABLE_NORMAL_SINE``): not a sliver."""
    corners = vertices[faces]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    twice_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    longest_pair = np.sort(edges, axis=1)[:, 1:].prod(axis=1)
    return twice_area > RELIABLE_NORMAL_SINE * longest_pair


def _faces_whose_side_misleads(mesh: trimesh.Trimesh, skipped: np.ndarray) -> tuple[int, np.ndarray]:
    """How many faces (not ``skipped``, not slivers) another face meets inside (``face_contact.faces_met``), or have
    their centroid's point ``SIDE_STEP_SHARE`` off them inside on their outer side or outside on their inner side
    (by ray parity, each disagreement with the face settled by the exact winding number); and which faces it did not
    look at (``skipped`` ones aside): slivers, and faces too crowded to check (``face_contact.CROWDED``). Their planes
    must not sign (the oracle, on the mesh moved to its internal frame, tells slivers after its own rounding). Where
    there is none, the plane of every other face signs the distance of a point nearest to it rightly
    (``face_contact``'s module doc); a surface that crosses itself, or lays faces over one another facing opposite
    ways, has them where it does, and there that plane would call a point outside inside: the true pose lost."""
    vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    reliable = reliable_normals(vertices, faces)
    checked = np.flatnonzero(~skipped & reliable)  # a sliver's plane never signs
    unchecked = ~skipped & ~reliable
    if len(checked) == 0:
        return 0, unchecked
    step_m = SIDE_STEP_SHARE * float(np.linalg.norm(np.ptp(vertices, axis=0)))
    surface = MeshDistance(vertices, faces)
    status = faces_met(surface, vertices, faces, checked, step_m)
    unchecked[checked[status == CROWDED]] = True
    unmet = checked[status == UNMET]
    normals = np.asarray(mesh.face_normals)[unmet]
    centroids = vertices[faces[unmet]].mean(axis=1)
    points = np.concatenate([centroids + step_m * normals, centroids - step_m * normals])
    # one direction per ray, as the oracle's parity passes them: the kernel's types the warm-up compiled
    inside = surface.rays(points, np.tile(SIDE_RAY, (len(points), 1)))[1] % 2 == 1
    expected = np.repeat([False, True], len(unmet))
    doubtful = np.flatnonzero(inside != expected)
    if len(doubtful):  # a ray grazing an edge may miscount: the winding number is exact
        inside[doubtful] = igl.winding_number(vertices, faces, points[doubtful]) > 0.5
    misleading = np.any((inside != expected).reshape(2, -1), axis=0)
    return int(np.count_nonzero(status == MET)) + int(np.count_nonzero(misleading)), unchecked


def _cracks_closed_message(name: str, closed: Closed) -> str:
    """The warning of a mesh closed at its cracks: what was found, and how far that moves its surface."""
    found = [f"{closed.merged} vertices of open edges within rounding of another (merged)" if closed.merged else "",
             f"{closed.junctions} T-junctions (a vertex of some faces on an edge of their neighbour, which was not "
             "split there; split now)" if closed.junctions else ""]
    moved = (f"at most {closed.offset_m * 1e6:.2g} micrometres" if closed.offset_m >= 1e-9
             else "less than a nanometre")
    return (f"{name} was open only at cracks: {' and '.join(part for part in found if part)}; fixwizard closed "
            f"them, which moves its surface by {moved} (the bounds include that).")


def clean_mesh(mesh: trimesh.Trimesh, name: str) -> CleanMesh:
    """Check and repair a mesh (see the module doc); ``name`` names it in messages. Raises ``MeshError`` for
    vertices that are not finite numbers or lie absurdly far."""
    refuse_non_finite(np.asarray(mesh.vertices), name)
    refuse_far_vertices(np.asarray(mesh.vertices), name)
    mesh, warnings = _drop_degenerate(mesh, name)
    mesh, repeated = _drop_repeated(mesh, name)
    warnings += repeated
    if not mesh.is_watertight:
        closed = _close_cracks(mesh)
        if closed is not None:
            oriented, signed, orient_warnings, plane_unsigned_faces = _orient(closed.mesh, name)
            if signed:
                warnings.append(("mesh_cracks_closed", _cracks_closed_message(name, closed)))
                return CleanMesh(oriented, True, tuple(warnings + orient_warnings), plane_unsigned_faces,
                                 closed.offset_m)
        warnings.append(("mesh_not_watertight",
                         f"{name} is not watertight (it has holes or open edges), so fixwizard cannot tell inside "
                         "from outside and uses the unsigned distance: the bounds stay guaranteed but may be "
                         "looser. Close the mesh in CAD for tighter bounds."))
        return CleanMesh(mesh, False, tuple(warnings), np.zeros(len(mesh.faces), bool))
    mesh, signed, orient_warnings, plane_unsigned_faces = _orient(mesh, name)
    return CleanMesh(mesh, signed, tuple(warnings + orient_warnings), plane_unsigned_faces)
