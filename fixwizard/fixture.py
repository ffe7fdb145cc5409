"""The fixture model: mesh loading with explicit units, the internal frame, and the distance oracle.

Frames: ``cad`` is the mesh file's own frame; ``fix`` is the internal frame, ``cad``
shifted to the centre of the mesh's exact minimum enclosing ball. Every pose shown to
users is of the ``cad`` frame.
"""

import hashlib
import io
import struct
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import igl
import numpy as np
import trimesh

from fixwizard import stl_text
from fixwizard.errors import MeshError, MeshUnitsError, file_problem, quoted
from fixwizard.geometry.hull_cover import HullCover, hull_cover
from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.mesh_distance import FEATURE_MARGIN, MeshDistance
from fixwizard.geometry.se3 import invert, make_transform, points_in_frames
from fixwizard.mesh_format import (
    FORMAT_NAMES,
    STL_HEADER_BYTES,
    STL_TRIANGLE_BYTES,
    archive_format,
    binary_stl_size_mismatch,
    binary_stl_triangles,
    content_format,
    unreadable_line_message,
)
from fixwizard.mesh_hygiene import (
    ZIP_SHARE,
    clean_mesh,
    refuse_far_vertices,
    refuse_non_finite,
    reliable_normals,
    used_vertices,
)
from fixwizard.obj_lines import (
    corner_before_first_vertex,
    face_triangles,
    not_finite_line,
    plain,
    reader_text,
    short_vertex_line,
    unreadable_line,
)
from fixwizard.ply_text import checked_ply, float32_vertices
from fixwizard.polygon_faces import checked_polygon_faces

METRES_PER_UNIT = {"m": 1.0, "mm": 1e-3}
UNIT_NAMES = {"m": "metres", "mm": "millimetres"}
METRES_PER_INCH = 0.0254
# Rays for the parity cross-check of inside tests leave along the axis to the nearest side of the mesh's bounding
# box (the shortest way out, the fewest crossings), tilted by this off every axis and diagonal so that they graze
# the edges of axis-aligned CAD faces as rarely as possible.
PARITY_TILT = np.array([0.0117, 0.0131, 0.0093])
MESH_SUFFIXES = (".stl", ".ply", ".obj")
POINTS_SUFFIXES = (".yaml", ".yml", ".csv")  # a POINTS file given as the mesh: the arguments swapped
PLAUSIBLE_SIZE_M = (0.005, 2.5)
# A binary STL, and a PLY of float coordinates, hold float32 numbers, whose spacing grows with their size: 0.06 mm at
# 1 km. Where the spacing at the mesh's farthest coordinate exceeds FLOAT32_WARNED_M (1 % of a 0.1 mm sample bound;
# beyond 16 m from the origin) the bounds carry it and a warning says so; beyond FLOAT32_REFUSED_M, the finest sample
# bound fixwizard accepts (solver.solve.MIN_SAMPLE_BOUND_M; beyond 128 m), the file cannot place its surface as
# finely as a tap is placed, and it is refused.
FLOAT32_WARNED_M = 1e-6
FLOAT32_REFUSED_M = 1e-5
# A CAD origin farther from its part (a plant layout's frame) would lie about as far from the robot base, beyond what
# a report holds (report.MAX_POSITION_M, 1 km: farther from its robot no fixture is).
MAX_ORIGIN_OFFSET_M = 500.0


@dataclass(frozen=True)
class Fixture:
    """A fixture mesh in metres with its internal frame.

    ``mesh``: CAD-frame mesh (m), checked and repaired (``mesh_hygiene``). ``signed``: whether inside and
    outside can be told apart (closed, consistently oriented). ``cad_p_center``: minimum enclosing ball centre
    in the CAD frame (m). ``radius_m``: that ball's radius. ``warnings``: (code, message) pairs to pass on.
    ``plane_unsigned_faces``: faces whose plane does not sign the distance (``CleanMesh.plane_unsigned_faces``;
    None: none). ``surface_offset_m``: how far ``mesh``'s surface may lie from the file's (closed cracks,
    ``CleanMesh.surface_offset_m``, and polygon faces that are not flat, ``polygon_faces``).
    """

    path: Path
    units: str
    mesh: trimesh.Trimesh
    cad_p_center: np.ndarray
    radius_m: float
    sha256: str
    signed: bool = True
    warnings: tuple[tuple[str, str], ...] = field(default=())
    plane_unsigned_faces: np.ndarray | None = None
    surface_offset_m: float = 0.0

    @property
    def fix_T_cad(self) -> np.ndarray:
        """Transform from the CAD frame to the internal frame (a pure shift)."""
        return make_transform(np.eye(3), -self.cad_p_center)

    def base_T_fix(self, base_T_cad: np.ndarray) -> np.ndarray:
        """The pose of the internal frame when the CAD frame is at ``base_T_cad``."""
        return base_T_cad @ invert(self.fix_T_cad)

    def signed_distance_at_m(self, base_T_cad: np.ndarray, base_p_points: np.ndarray) -> np.ndarray:
        """Distance (N,) in m of base-frame points (N, 3) from the surface with the CAD frame at ``base_T_cad``:
        negative inside a closed mesh, unsigned on an open one (``DistanceOracle.signed_distance_m``)."""
        return self.oracle.signed_distance_at_m(self.base_T_fix(base_T_cad), base_p_points)

    @property
    def fix_vertices_m(self) -> np.ndarray:
        return self.mesh.vertices - self.cad_p_center

    @cached_property
    def oracle(self) -> "DistanceOracle":
        """Distance queries in the internal frame (signed where inside and outside can be told apart)."""
        fix_mesh = trimesh.Trimesh(self.fix_vertices_m, self.mesh.faces, process=False)
        return DistanceOracle(fix_mesh, signed=self.signed, plane_unsigned_faces=self.plane_unsigned_faces,
                              surface_offset_m=self.surface_offset_m)


class DistanceOracle:
    """Distance queries to a triangle mesh; points in the mesh's frame, metres, float64 in and out.

    Distances are guaranteed intervals from the float64 hierarchy of ``geometry.mesh_distance`` (any triangle
    shape). Signs (closed, consistently oriented meshes only) come from the angle-weighted pseudonormal of the
    closest feature (face, edge or vertex; Baerentzen and Aanaes 2005), which is exact for a closed manifold
    mesh; near edges and corners, where which feature is closest is a numerical decision, the parity of a ray's
    crossings cross-checks it, and the exact generalised winding number (libigl) settles every disagreement. A
    point closer to the surface than ``SIGN_FREE_M`` gets an interval of both signs: there the sign is not worth
    trusting and does not matter.
    """

    FEATURE_MARGIN = FEATURE_MARGIN  # the face's plane signs a closest point farther from its edges
    # Far above the intervals' widths (at most ~1e-8 m for metre-sized triangles of any shape), far below any
    # sample bound.
    SIGN_FREE_M = 1e-7

    def __init__(self, mesh_m: trimesh.Trimesh, signed: bool, plane_unsigned_faces: np.ndarray | None = None,
                 surface_offset_m: float = 0.0) -> None:
        """``plane_unsigned_faces``: faces whose plane does not sign the distance (``CleanMesh.plane_unsigned_faces``):
        their points are signed as near an edge.
        ``surface_offset_m``: how far this mesh's surface may lie from the fixture's as exported (m); the distances
        are this mesh's, and the search widens each tap's band by it (``SearchProblem.tap_bound_m``)."""
        self.signed = signed
        self.surface_offset_m = surface_offset_m
        self._vertices = np.asarray(mesh_m.vertices, np.float64)
        self._faces = np.asarray(mesh_m.faces, np.int64)
        self._distance = MeshDistance(self._vertices, self._faces)
        if signed:
            self._face_normals = np.asarray(mesh_m.face_normals, np.float64)
            self._reliable_normal = reliable_normals(self._vertices, self._faces)
            if plane_unsigned_faces is not None:
                self._reliable_normal &= ~np.asarray(plane_unsigned_faces, bool)
            edge_normals = np.zeros((len(mesh_m.edges_unique), 3))
            np.add.at(edge_normals, mesh_m.faces_unique_edges.ravel(), np.repeat(self._face_normals, 3, axis=0))
            self._edge_normals = edge_normals[mesh_m.faces_unique_edges]
            vertex_normals = np.zeros((len(self._vertices), 3))
            weights = mesh_m.face_angles[:, :, None] * self._face_normals[:, None, :]
            np.add.at(vertex_normals, self._faces.ravel(), weights.reshape(-1, 3))
            self._corner_normals = vertex_normals[self._faces]

    @property
    def triangle_rows(self) -> np.ndarray:
        """Each triangle's data for ``mesh_distance.triangle_row_high_m`` (the compiled search's face bounds)."""
        return self._distance.rows

    @cached_property
    def kernel_arguments(self) -> tuple[object, ...]:
        """The mesh as the search's compiled exact stage takes it (``interval_kernel``): triangle rows, the
        hierarchy's five arrays, whether distances are signed, each face's unit normal and whether it is
        trustworthy (none for an unsigned mesh), ``FEATURE_MARGIN`` and ``SIGN_FREE_M``. That stage signs a
        distance only where the closest point lies inside a face with a trustworthy normal; it leaves the others
        to ``distance_interval_m``."""
        normals = self._face_normals if self.signed else np.zeros((0, 3))
        reliable = self._reliable_normal if self.signed else np.zeros(0, bool)
        return (self._distance.rows, *self._distance.hierarchy, self.signed, normals, reliable, self.FEATURE_MARGIN,
                self.SIGN_FREE_M)

    @cached_property
    def hull_cover(self) -> HullCover:
        """Balls (m, the mesh's frame) covering the vertices of the mesh's convex hull: where a rigid motion moves a
        point of the fixture farthest (``geometry.hull_cover``; the hull vertices themselves unless there are
        thousands)."""
        return hull_cover(self._vertices)

    @property
    def triangle_count(self) -> int:
        return len(self._faces)

    @property
    def mesh_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh as float64 vertices (V, 3) in m and triangles (F, 3) of vertex indices."""
        return self._vertices, self._faces

    @cached_property
    def bounds_m(self) -> tuple[np.ndarray, np.ndarray]:
        """Corners (m) of the mesh's axis-aligned bounding box in its frame (once: every inside test by ray parity
        needs them, and a mesh of a million vertices took 40 ms a call)."""
        return self._vertices.min(axis=0), self._vertices.max(axis=0)

    def _pseudonormal_inside(self, points_m: np.ndarray, closest: np.ndarray, weights: np.ndarray,
                             faces: np.ndarray) -> np.ndarray:
        """Whether each point lies inside, by the pseudonormal of the feature (face, edge, vertex) its closest
        point ``closest`` lies on; ``weights``: that point's barycentric weights of the face's second and third
        vertex."""
        barycentric = np.column_stack([1.0 - weights.sum(axis=1), weights])
        near_zero = barycentric <= self.FEATURE_MARGIN
        normals = self._face_normals[faces].copy()
        # edge k of a face joins corners k and k+1, so it is the edge opposite corner k+2
        for corner, edge in ((2, 0), (0, 1), (1, 2)):
            on_edge = near_zero[:, corner] & (near_zero.sum(axis=1) == 1)
            normals[on_edge] = self._edge_normals[faces[on_edge], edge]
        at_vertex = near_zero.sum(axis=1) >= 2
        corner = np.argmax(~near_zero[at_vertex], axis=1)
        normals[at_vertex] = self._corner_normals[faces[at_vertex], corner]
        return np.einsum("ij,ij->i", points_m - closest, normals) < 0.0

    def _parity_inside(self, points_m: np.ndarray) -> np.ndarray:
        """Whether each point lies inside by the parity of its ray's crossings (see ``PARITY_TILT``)."""
        low, high = self.bounds_m
        gaps = np.hstack([points_m - low, high - points_m])  # to the -x, -y, -z, +x, +y, +z sides
        side = np.argmin(gaps, axis=1)
        directions = np.zeros_like(points_m)
        directions[np.arange(len(points_m)), side % 3] = np.where(side < 3, -1.0, 1.0)
        directions += PARITY_TILT
        return self._distance.rays(points_m, directions)[1] % 2 == 1

    def _inside(self, points_m: np.ndarray, faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """Whether each point lies inside the closed surface, from its closest point's face and weights. Where the
        closest point lies on an edge or a corner, or on a face without a trustworthy normal, the pseudonormal is
        cross-checked against ray parity, and the exact winding number settles every disagreement; inside a face
        the face's plane decides (the point lies on the normal through its closest point)."""
        corners = self._vertices[self._faces[faces]]
        closest = (corners[:, 0] + weights[:, :1] * (corners[:, 1] - corners[:, 0])
                   + weights[:, 1:] * (corners[:, 2] - corners[:, 0]))
        inside = self._pseudonormal_inside(points_m, closest, weights, faces)
        barycentric_low = np.minimum(1.0 - weights.sum(axis=1), weights.min(axis=1))
        checked = np.flatnonzero((barycentric_low <= self.FEATURE_MARGIN) | ~self._reliable_normal[faces])
        if len(checked):
            disagree = checked[inside[checked] != self._parity_inside(points_m[checked])]
            if len(disagree):
                inside[disagree] = igl.winding_number(self._vertices, self._faces, points_m[disagree]) > 0.5
        return inside

    def distance_interval_m(self, points_m: np.ndarray, signed: np.ndarray | None = None,
                            hint_faces: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """An interval (low, high; m) holding the distance from each (N, 3) point to the surface, and the face
        of the nearest point found (its distance bounds the unsigned distance from above).

        The distance is negative inside the closed surface, for the points where ``signed`` is true (all by
        default); it is unsigned for the others and everywhere on an open mesh. ``hint_faces``: a face likely
        near each point (-1 for none), for speed only.
        """
        return self._signed_interval_m(points_m, signed, hint_faces, np.inf)

    def _signed_interval_m(self, points_m: np.ndarray, signed: np.ndarray | None, hint_faces: np.ndarray | None,
                           cap_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        points_m = np.asarray(points_m, np.float64).reshape(-1, 3)
        low, high, faces, weights = self._distance.query(points_m, hint_faces, cap_m)
        if self.signed:
            rows = np.arange(len(points_m)) if signed is None else np.flatnonzero(signed)
            touching = rows[low[rows] <= self.SIGN_FREE_M]
            rows = rows[(low[rows] > self.SIGN_FREE_M) & (faces[rows] >= 0)]
            inside = rows[self._inside(points_m[rows], faces[rows], weights[rows])]
            low[inside], high[inside] = -high[inside], -low[inside]
            low[touching] = -high[touching]
        return low, high, faces

    def signed_distance_m(self, points_m: np.ndarray, signed: np.ndarray | None = None,
                          cap_m: float = np.inf) -> np.ndarray:
        """Distance (m, negative inside) where the mesh is closed, unsigned otherwise (and where ``signed`` is
        false): the middle of ``distance_interval_m``, within 1e-8 m of the truth. Points farther than ``cap_m``
        from the surface (on either side) get ``cap_m``: for weights that are nil that far, at a fraction of the
        cost."""
        low, high, _ = self._signed_interval_m(points_m, signed, None, cap_m)
        return np.where(np.isfinite(high), 0.5 * (low + high), low)

    def signed_distance_at_m(self, base_T_fix: np.ndarray, base_p_points: np.ndarray) -> np.ndarray:
        """``signed_distance_m`` (N,) of base-frame points (N, 3) with the mesh's (internal) frame at
        ``base_T_fix``: the one home of "distance of points at a pose" (``Fixture.signed_distance_at_m`` for a
        CAD-frame pose)."""
        return self.signed_distance_m(points_in_frames(base_T_fix[:3, :3], base_T_fix[:3, 3], base_p_points)[0])

    def ray_hit_distance_m(self, origins_m: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance (m) along each ray (origins (N, 3) m, unit directions (N, 3)) to the first surface it hits;
        inf where it hits none."""
        return self._distance.rays(origins_m, directions)[0]


def _surface_of(loaded: object) -> object:
    """The triangles of what trimesh read: a mesh as it is, a scene's meshes (an OBJ of several objects, an STL of
    several solids) as one, without their textures and colours (copying a textured mesh, as trimesh's own
    ``force="mesh"`` does, needs Pillow, which fixwizard does not install: every OBJ with texture coordinates was
    refused); anything else (a point cloud, lines) as it is."""
    if not isinstance(loaded, trimesh.Scene):
        return loaded
    for name, geometry in list(loaded.geometry.items()):
        if isinstance(geometry, trimesh.Trimesh):
            loaded.geometry[name] = trimesh.Trimesh(geometry.vertices, geometry.faces, process=False)
    return trimesh.util.concatenate([part for part in loaded.dump() if isinstance(part, trimesh.Trimesh)])


def _trimesh_load(path: Path, raw: bytes) -> object:
    """The triangles trimesh reads from the file at ``path`` (``raw``, its bytes; ``_surface_of``); an OBJ as
    ``obj_lines.reader_text`` gives it (trimesh skipped indented lines, tabs after a keyword and the first line after
    a byte-order mark without a word, and read no comment nor old Mac line ends), with no line of words that are no
    numbers, checked to hold every triangle of its faces."""
    if path.suffix.lower() == ".stl":
        return _surface_of(_stl_load(path, raw))
    if path.suffix.lower() != ".obj":
        return _surface_of(trimesh.load(io.BytesIO(raw), file_type=path.suffix.lower()[1:], process=False))
    lines = plain(raw)
    unreadable = not_finite_line(raw) or unreadable_line(lines)
    if unreadable is not None:
        raise MeshError(unreadable_line_message(path, *unreadable))
    before_first = corner_before_first_vertex(lines)
    if before_first is not None:
        raise MeshError(f"{path}: the face on line {before_first[0]} ({quoted(before_first[1])}) counts back past the "
                        "first vertex (a negative corner counts back from the vertices before its line); export the "
                        "mesh again from CAD")
    text = reader_text(lines)
    short = short_vertex_line(text)
    if short is not None:
        raise MeshError(f"{path} has a vertex line with fewer than three coordinates ({quoted(short)}); export the "
                        "mesh again from CAD")
    loaded = _surface_of(trimesh.load(io.BytesIO(text), file_type="obj", process=False))
    read, held = len(getattr(loaded, "faces", ())), face_triangles(text)
    if read != held:
        raise MeshError(f"{path}: its faces hold {held} triangles, of which the OBJ reader read {read}; export the "
                        "mesh again from CAD, or as STL")
    return loaded


def _stl_load(path: Path, raw: bytes) -> object:
    """What trimesh reads from an STL file at ``path`` (``raw``, its bytes); a binary one with the triangle count its
    size holds (``mesh_format.binary_stl_triangles``); an ASCII one as ``stl_text.reader_text`` gives it (trimesh
    read CR alone as no line end), with every vertex line of three numbers and every solid ended."""
    count = binary_stl_triangles(raw[:STL_HEADER_BYTES], len(raw))
    if count is not None:  # with the count its size holds in the header, where the header says 0
        counted = raw[:80] + struct.pack("<I", count) + raw[STL_HEADER_BYTES:]
        return trimesh.load(io.BytesIO(counted), file_type="stl", process=False)
    text = stl_text.reader_text(raw)
    unreadable = stl_text.unreadable_line(text)
    if unreadable is not None:
        raise MeshError(unreadable_line_message(path, *unreadable))
    unended = stl_text.unended_solid(text)
    if unended is not None:
        raise MeshError(f"{path}: the solid that starts on line {unended} has no 'endsolid' after it: the file is cut "
                        "short (an interrupted copy or download?); copy or export it again")
    return trimesh.load(io.BytesIO(text), file_type="stl", process=False)


def _mesh_bytes(path: Path) -> bytes:
    """The bytes of the mesh file at ``path``, read once: every check, the reader and the hash take these, so a file
    saved again while it loads (by a CAD tool) cannot be checked, solved and hashed as different files. ``MeshError``
    saying what to do for a path that is no mesh file (a folder, a pipe, a points file, an empty file)."""
    if path.is_dir():
        raise MeshError(f"{path} is a folder, not a mesh file; give the path of an STL, PLY or OBJ file in it")
    if not path.exists():
        raise MeshError(f"the mesh file {path} does not exist; give the path of an STL, PLY or OBJ file")
    if not path.is_file():
        raise MeshError(f"{path} is not a regular file (a pipe or a device such as /dev/null), so it holds no "
                        "mesh to read; give the path of an STL, PLY or OBJ file")
    if path.suffix.lower() in POINTS_SUFFIXES:
        raise MeshError(f"{path} is a points file (YAML or CSV of the taps), not a mesh: give the fixture's STL, PLY "
                        "or OBJ file (on the command line, are the arguments in the wrong order? solve MESH POINTS, "
                        "identify POINTS MESH...)")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{path} is not a mesh file fixwizard reads; export the fixture's CAD model as STL, "
                        "PLY or OBJ")
    raw = path.read_bytes()
    if not raw:
        raise MeshError(f"the mesh file {path} is empty; export the fixture's CAD model again")
    return raw


def _load_trimesh(path: Path, raw: bytes) -> tuple[trimesh.Trimesh, float]:
    """The triangles of the mesh file at ``path`` (``raw``, its bytes), and how far (its units) their surface may lie
    from another one spanning its polygon faces (``polygon_faces.checked_polygon_faces``); ``MeshError`` saying what
    to do for a file that is none."""
    archive = archive_format(raw)
    if archive is not None:
        raise MeshError(f"{path} is a {archive} archive, not a mesh (a compressed download; a 3MF file is a ZIP too): "
                        "unpack the mesh from it, or export the fixture's CAD model as STL, PLY or OBJ")
    found, suffix = content_format(raw), path.suffix.lower()
    if found is not None and found != suffix:
        raise MeshError(f"{path} holds a mesh in {FORMAT_NAMES[found]} format, not {FORMAT_NAMES[suffix]} as its name "
                        f"says (fixwizard reads a mesh by its suffix): rename it to {path.with_suffix(found).name}")
    if suffix == ".ply":
        checked_ply(path, raw)
    warp = checked_polygon_faces(path, raw)
    mismatch = binary_stl_size_mismatch(raw) if suffix == ".stl" else None
    if mismatch is not None:
        count, size = mismatch
        raise MeshError(f"{path} is a binary STL whose header announces {count} triangles "
                        f"({STL_HEADER_BYTES + STL_TRIANGLE_BYTES * count} bytes), but it holds {size} bytes: the "
                        "file is cut short or has bytes added (an interrupted copy or download?); copy or export it "
                        "again")
    try:
        with np.errstate(all="ignore"):  # absurd coordinates overflow in the reader; they are refused below
            mesh = _trimesh_load(path, raw)
    except MeshError:
        raise
    except Exception as error:  # trimesh raises many types for malformed files
        raise MeshError(f"{path} could not be read as a mesh ({error}); check that it is an STL, PLY or "
                        "OBJ export of the fixture") from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path} holds no triangles (a point cloud or an empty model?); export the "
                        "fixture's surface as a triangle mesh")
    _refuse_missing_corners(mesh, path)
    refuse_non_finite(np.asarray(mesh.vertices), str(path))
    refuse_far_vertices(np.asarray(mesh.vertices), str(path))
    return _identical_vertices_merged(mesh), warp


def _refuse_missing_corners(mesh: trimesh.Trimesh, path: Path) -> None:
    """MeshError for a face naming a vertex the file does not have (a damaged PLY): past the last one, or negative,
    which numpy would read as counted from the end, another vertex."""
    faces, count = np.asarray(mesh.faces, np.int64), len(mesh.vertices)
    bad = np.flatnonzero(np.any((faces < 0) | (faces >= count), axis=1))
    if len(bad):
        row = faces[bad[0]]
        corner = int(row[(row < 0) | (row >= count)][0])
        raise MeshError(f"{path}: face {bad[0] + 1} names vertex {corner}, but the file has {count} vertices, "
                        "numbered from 0 (a damaged or cut-short export); export the mesh again from CAD")


def _identical_vertices_merged(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh's faces on its referenced vertices, those at identical coordinates merged into one (an STL gives each
    face its own corners; an OBJ splits a vertex at its texture seams), in the order they first appear. Exact, so the
    surface stays the file's: trimesh's ``process`` also merged vertices up to 1e-8 of the file's unit apart (17 nm
    of a mesh in metres), which moved the surface by an amount no bound carried; vertices written apart by rounding
    are closed by ``mesh_hygiene``, which bounds how far that moves the surface. The faces' indices are in range
    (``_refuse_missing_corners``) and the coordinates finite (``refuse_non_finite``)."""
    vertices, faces = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    used = used_vertices(faces)
    first, rank = _first_of_each_point(vertices[used])
    index = np.full(len(vertices), -1, np.int64)
    index[used] = rank
    return trimesh.Trimesh(vertices[used[first]], index[faces], process=False)


def _first_of_each_point(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For finite points ``(N, 3)``: where each distinct point first occurs, in order of appearance, and each point's
    number among them. Points are the same when their coordinates are equal as numbers (0.0 and -0.0 too: an ASCII
    export writes both). The points are sorted by one 64-bit key of their coordinates' bits, several times faster
    than sorting rows of three (np.unique by rows took 6-10 s for the 3.9 million corners of a 1.3-million-triangle
    STL); where two different points share a key, the rows themselves are sorted instead."""
    bits = np.ascontiguousarray(points + 0.0).view(np.uint64)  # + 0.0 turns -0.0 into 0.0
    _, first, inverse = np.unique(_point_keys(bits), return_index=True, return_inverse=True)
    if not np.array_equal(bits[first[inverse]], bits):
        _, first, inverse = np.unique(bits, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return first[order], rank[inverse.ravel()]


def _point_keys(bits: np.ndarray) -> np.ndarray:
    """One 64-bit key per row of three 64-bit words: each word mixed with the ones after it by SplitMix64's
    finalizer, whose shifts carry every bit into every other (a multiplication alone only carries bits upwards, and
    coordinates read from float32 files share their low 29 bits)."""
    key = np.zeros(len(bits), np.uint64)
    for column in range(bits.shape[1] - 1, -1, -1):
        key = bits[:, column] ^ key
        key = (key ^ (key >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        key = (key ^ (key >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        key = key ^ (key >> np.uint64(31))
    return key


def _plausible(size_m: float) -> bool:
    low, high = PLAUSIBLE_SIZE_M
    return low <= size_m <= high


def _check_size(path: Path, mesh_m: trimesh.Trimesh, units: str) -> None:
    """Refuse a fixture whose size (m) is implausible in ``units``, naming the other unit only where it makes the size
    plausible (``MeshUnitsError.likely_units``), and inches where only they do (fixwizard reads m or mm)."""
    size_m = float(np.max(mesh_m.extents))
    if _plausible(size_m):
        return
    file_size = size_m / METRES_PER_UNIT[units]  # in the file's own unit
    other = "mm" if units == "m" else "m"
    likely = other if _plausible(file_size * METRES_PER_UNIT[other]) else None
    if likely is not None:
        hint = f"if the file is in {UNIT_NAMES[likely]}, its units are {likely}"
    elif _plausible(file_size * METRES_PER_INCH):
        hint = (f"in {UNIT_NAMES[other]} it would be implausible too; if the file is in inches (a "
                f"{file_size * METRES_PER_INCH * 1e3:.3g} mm fixture), export it again in millimetres or metres "
                "(fixwizard reads m or mm)")
    else:
        hint = "check that the file holds the fixture and its units (fixwizard reads m or mm)"
    large = size_m > PLAUSIBLE_SIZE_M[1]
    shown = size_m if large else size_m * 1e3
    digits = 3
    while digits < 9 and _plausible(float(f"{shown:.{digits}g}") / (1.0 if large else 1e3)):
        digits += 1  # 4.9996 mm is no "5 mm small fixture, which is implausible"
    size = f"{shown:.{digits}g} m large" if large else f"{shown:.{digits}g} mm small"
    low, high = PLAUSIBLE_SIZE_M
    raise MeshUnitsError(f"{path} would be a {size} fixture with units '{units}', which is implausible (fixwizard "
                         f"takes fixtures {low * 1e3:g} mm to {high:g} m across); {hint}", likely)


def _warped_polygons_warning(name: str, warp_m: float) -> tuple[str, str]:
    return ("mesh_polygons_warped",
            f"{name} has polygon faces that are not flat: their triangles, as fixwizard reads them, may lie up to "
            f"{warp_m * 1e3:.3g} mm from the part's surface (another way across them), and the bounds allow for that "
            "(they are looser). Export the mesh with triangulated faces (in Blender: Triangulate Faces), or as STL.")


def _float32_kind(path: Path, raw: bytes) -> str | None:
    """What holds the file's (``raw``, its bytes) coordinates as float32 numbers: a binary STL, a PLY of float
    coordinates; None for any other file."""
    if path.suffix.lower() == ".stl" and binary_stl_triangles(raw[:STL_HEADER_BYTES], len(raw)) is not None:
        return "a binary STL"
    return "a PLY of float coordinates" if path.suffix.lower() == ".ply" and float32_vertices(raw) else None


def _float32_spacing_m(path: Path, raw: bytes, mesh: trimesh.Trimesh, units: str) -> float:
    """The spacing (m) of float32 numbers at the farthest coordinate of a file that holds them (``_float32_kind``;
    ``mesh``, in the file's ``units``), 0 for any other file or where it is under ``FLOAT32_WARNED_M``: each vertex
    lies within half of it of the exporter's along each axis, so the surface within it. MeshError with the fix
    where it exceeds ``FLOAT32_REFUSED_M``, unless the mesh's size is implausible in ``units`` (a millimetre file
    read as metres lies far out too: ``_check_size`` names the units)."""
    kind = _float32_kind(path, raw)
    if kind is None:
        return 0.0
    farthest = float(np.max(np.abs(mesh.vertices)))
    spacing_m = float(np.spacing(np.float32(farthest))) * METRES_PER_UNIT[units]
    if spacing_m > FLOAT32_REFUSED_M and _plausible(float(np.max(mesh.extents)) * METRES_PER_UNIT[units]):
        raise MeshError(f"{path}: its coordinates reach {farthest * METRES_PER_UNIT[units]:.4g} m from the file's "
                        f"origin, too far for the precision of the numbers of {kind} (float32): the file's precision "
                        f"there is {spacing_m * 1e3:.3g} mm, coarser than the finest sample bound "
                        f"({FLOAT32_REFUSED_M * 1e3:g} mm), and small faces collapse. Export the mesh again with its "
                        "origin near the part (the reports then give that origin's pose)")
    return spacing_m if spacing_m > FLOAT32_WARNED_M else 0.0


def _float32_warning(name: str, spacing_m: float) -> tuple[str, str]:
    return ("mesh_float32_precision",
            f"{name} lies far from its origin for its float32 numbers: their precision there is "
            f"{spacing_m * 1e3:.3g} mm, so its surface may lie that far from the exported part, and the bounds allow "
            "for that (they are looser). Export the mesh with the origin near the part.")


def fixture_from_mesh(mesh_m: trimesh.Trimesh, path: Path, units: str, sha256: str,
                      polygon_warp_m: float = 0.0, float32_spacing_m: float = 0.0) -> Fixture:
    """A Fixture from a mesh already in metres (``path``, ``units`` and ``sha256`` describe its source), checked
    and repaired by ``mesh_hygiene``. ``polygon_warp_m``: how far the mesh's surface may lie from another one
    spanning the file's polygon faces (``polygon_faces.checked_polygon_faces``), added to the surface's offset and
    said where it is more than an export's rounding; ``float32_spacing_m``: how far the file's float32 numbers
    may have moved it (``_float32_spacing_m``), added and said where it is not 0."""
    clean = clean_mesh(mesh_m, path.name)
    _check_size(path, clean.mesh, units)
    ball = minimum_enclosing_ball(clean.mesh.vertices)
    if (offset_m := float(np.linalg.norm(ball.center))) > MAX_ORIGIN_OFFSET_M:
        raise MeshError(f"{path}: the fixture lies {offset_m:.0f} m from the mesh's origin; fixwizard gives the pose "
                        "of that origin, and one so far from the robot base is no pose a report holds. Export the "
                        f"mesh with its origin near the part (within {MAX_ORIGIN_OFFSET_M:g} m of it)")
    warnings = clean.warnings
    if polygon_warp_m > ZIP_SHARE * float(np.linalg.norm(clean.mesh.extents)):
        warnings += (_warped_polygons_warning(path.name, polygon_warp_m),)
    if float32_spacing_m > 0.0:
        warnings += (_float32_warning(path.name, float32_spacing_m),)
    return Fixture(path=path, units=units, mesh=clean.mesh, cad_p_center=ball.center, radius_m=ball.radius,
                   sha256=sha256, signed=clean.signed, warnings=warnings,
                   plane_unsigned_faces=(clean.plane_unsigned_faces if np.any(clean.plane_unsigned_faces)
                                         else None),
                   surface_offset_m=clean.surface_offset_m + polygon_warp_m + float32_spacing_m)


def warm_up_distance_queries() -> None:
    """Load the distance queries' compiled code now (from numba's cache, or compiled), with a signed query and a ray
    on a 1 cm box: otherwise a process's first query pays it, holding the interpreter for most of a second (in the
    wizard, its first simulated tap, while its keys wait)."""
    box = fixture_from_mesh(trimesh.creation.box((0.01, 0.01, 0.01)), Path("warm-up box"), "m", "generated")
    points_m = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.02]])
    box.oracle.signed_distance_m(points_m)
    box.oracle.ray_hit_distance_m(points_m, np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))


def load_fixture(path: str | Path, units: str = "m") -> Fixture:
    """Load a fixture mesh (STL/PLY/OBJ) in ``units`` ('m' or 'mm'); refuses implausible sizes. The file is read once
    (``_mesh_bytes``): ``sha256`` is that of the bytes checked and loaded."""
    path = Path(path)
    if units not in METRES_PER_UNIT:
        raise MeshError(f"mesh units must be 'm' or 'mm', not {units!r}")
    try:
        raw = _mesh_bytes(path)
        mesh, warp = _load_trimesh(path, raw)
    except OSError as error:  # no permission, a name too long, a disk error: a mesh that cannot be read
        raise MeshError(file_problem(error, path, "read")) from error
    spacing_m = _float32_spacing_m(path, raw, mesh, units)
    mesh = mesh.copy()
    mesh.apply_scale(METRES_PER_UNIT[units])
    return fixture_from_mesh(mesh, path, units, hashlib.sha256(raw).hexdigest(), warp * METRES_PER_UNIT[units],
                             spacing_m)
