"""Face lists of OBJ and PLY files that trimesh would read as another surface, refused with the fix.

Faces of four or more corners: trimesh cuts every such polygon into a fan of triangles from its first corner, which
is its own surface only where the polygon is convex. A concave one (the top of an L-shaped plate as Blender writes
it without "Triangulate Faces") gets triangles reaching outside it, a surface the part does not have, which can
exclude the true pose. A convex polygon that is not flat (a corner off the plane of the others) is let through, but its
fan is only one of the surfaces spanning its corners (the other diagonal of a warped quad, a curved patch): each lies
within the slab of the polygon's plane that holds its corners, and over the same outline, so any two lie within the
slab's width of each other, twice the largest corner's distance from the plane. The fixture carries that width as
the distance its surface may lie from the part's (``Fixture.surface_offset_m``). OBJ corner number 0: OBJ counts
vertices from 1 (negative numbers count back), and trimesh read a 0 as some other vertex without a word. An OBJ's
lines are read as the loader hands them to trimesh (``obj_lines.plain``): ended by LF, CR LF or CR alone, comments
left out, a backslash at the end joining the next line to it."""

import io
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from trimesh.exchange import ply

from fixwizard.errors import MeshError
from fixwizard.obj_lines import joined, line_number, plain

_VERTEX_LINE = re.compile(rb"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.MULTILINE)
_POLYGON_LINE = re.compile(rb"^[ \t]*f((?:[ \t]+\S+){4,})[ \t]*$", re.MULTILINE)
_ZERO_TOKEN = re.compile(rb"[ \t][-+]?0+(?=[/ \t\n]|$)")  # a number 0 in any line
_ZERO_CORNER = re.compile(rb"^[ \t]*f[ \t][^\n]*?(?<=[ \t])[-+]?0+(?=[/ \t\n]|$)", re.MULTILINE)
PLY_INDEX_NAMES = ("vertex_indices", "vertex_index")  # what PLY exporters call a face's corner list
# A corner whose turn is below this share of its edges' and the normal's lengths is straight: the rounding of the
# turn's two products (a few units of float64's eps each), no more (it was 1e-9). A concave corner any larger is
# refused; the fan of a polygon let through leaves its outline by at most about this share of its edges (4e-15 m for
# a 1 m edge), where the turn's sign cannot be told in float64.
STRAIGHT_SHARE = 16 * float(np.finfo(np.float64).eps)


def _is_convex(corners: np.ndarray) -> bool:
    """Whether a polygon (K, 3 corners in order) turns the same way at every corner about its Newell normal, and once
    round in all (so a fan from any corner cuts it into its own pieces): a star such as a pentagram turns the same
    way at every corner but twice round, and its fan covers the points between its tips."""
    following = np.roll(corners, -1, axis=0)
    normal = np.cross(corners, following).sum(axis=0)
    incoming = corners - np.roll(corners, 1, axis=0)
    outgoing = following - corners
    turns = np.cross(incoming, outgoing) @ normal
    length = float(np.linalg.norm(normal))
    scale = np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1) * length
    # turning by the exterior angles: 2 pi once round, 4 pi or more for a star (3 pi between them is no rounding)
    turning = float(np.sum(np.arctan2(turns / length, np.einsum("ij,ij->i", incoming, outgoing)))) if length else 0.0
    return bool(np.all(turns >= -STRAIGHT_SHARE * scale)) and turning < 3.0 * np.pi


def _warp(corners: np.ndarray) -> float:
    """How far apart two surfaces spanning a convex polygon (K, 3 corners in order) may lie: twice the largest
    distance of a corner from the plane through their mean across the Newell normal, plus that distance's rounding
    (a few eps of the coordinates, taken generously)."""
    normal = np.cross(corners, np.roll(corners, -1, axis=0)).sum(axis=0)
    heights = (corners - corners.mean(axis=0)) @ (normal / np.linalg.norm(normal))
    return 2.0 * float(np.max(np.abs(heights))) + STRAIGHT_SHARE * float(np.max(np.abs(corners)))


def _checked(path: Path, vertices: np.ndarray, polygons: Iterable[tuple[str, np.ndarray]]) -> float:
    """Raise ``MeshError`` for the first of the polygons (where in the file, corner rows of ``vertices``) that has
    four or more corners and is not convex; polygons with a corner outside ``vertices`` are the reader's to refuse.
    Returns the largest ``_warp`` of the others (0.0 without any)."""
    warp = 0.0
    for where, rows in polygons:
        if len(rows) < 4 or np.any(rows < 0) or np.any(rows >= len(vertices)):
            continue
        if _is_convex(vertices[rows]):
            warp = max(warp, _warp(vertices[rows]))
        else:
            raise MeshError(f"{path}: the face {where} is a polygon of {len(rows)} corners that is not convex; "
                            "fixwizard's reader would cut it into triangles reaching outside it, a surface the part "
                            "does not have. Export the mesh with triangulated faces (in Blender: Triangulate Faces), "
                            "or as STL")
    return warp


def _obj_polygons(text: bytes, lines: bytes) -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    """The vertices of an OBJ file's text (``obj_lines.joined``) and its faces of four or more corners, named by their
    line in the file's ``obj_lines.plain`` text ``lines`` (empty where it cannot be read: the loader then says what is
    wrong)."""
    polygons = list(_POLYGON_LINE.finditer(text))
    vertex_lines = list(_VERTEX_LINE.finditer(text)) if polygons else []
    try:
        vertices = np.array([[float(value) for value in line.groups()] for line in vertex_lines]).reshape(-1, 3)
        starts = np.array([line.start() for line in vertex_lines], np.int64)
        found = []
        for polygon in polygons:
            defined = int(np.searchsorted(starts, polygon.start()))  # negative indices count back from here
            indices = [int(token.split(b"/")[0]) for token in polygon.group(1).split()]
            rows = np.array([index - 1 if index > 0 else defined + index for index in indices])
            found.append((f"on line {line_number(lines, polygon.start())}", rows))
    except ValueError:
        return np.zeros((0, 3)), []
    return vertices, found


def _ply_polygons(raw: bytes) -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    """The vertices of a PLY file (``raw``, its bytes) and its faces, read by trimesh's own parser before it cuts them
    (empty where it cannot be read: trimesh's reader then says what is wrong)."""
    try:
        file = io.BytesIO(raw)
        elements, is_ascii, _ = ply._parse_header(file)
        (ply._ply_ascii if is_ascii else ply._ply_binary)(elements, file)
        vertex_data = elements["vertex"]["data"]
        vertices = np.column_stack([np.asarray(vertex_data[axis], np.float64) for axis in "xyz"])
        face_data = elements["face"]["data"]
        names = face_data.keys() if isinstance(face_data, dict) else face_data.dtype.names
        name = next(name for name in PLY_INDEX_NAMES if name in names)
        faces = face_data[name] if isinstance(face_data, dict) else face_data[name]["f1"]
    except Exception:  # noqa: BLE001 - any file trimesh's parser cannot read is its reader's to refuse
        return np.zeros((0, 3)), []
    if getattr(faces, "ndim", 1) == 2 and faces.shape[1] < 4:
        return vertices, []  # triangles only
    return vertices, [(f"number {number}", np.asarray(rows, np.int64)) for number, rows in enumerate(faces, 1)
                      if len(rows) >= 4]


def _face_naming_vertex_zero(text: bytes, lines: bytes) -> int | None:
    """The number of the line of the file's ``obj_lines.plain`` text ``lines`` where the first face of an OBJ file's
    text (``obj_lines.joined``) with a corner numbered 0 starts, None when there is none."""
    if _ZERO_TOKEN.search(text) is None:  # most files: no number 0 anywhere, found at the speed of a plain search
        return None
    zero = _ZERO_CORNER.search(text)
    return None if zero is None else line_number(lines, zero.start())


def checked_polygon_faces(path: Path, raw: bytes) -> float:
    """Raise ``MeshError`` naming the first face of the OBJ or PLY file at ``path`` (``raw``, its bytes) that has four
    or more corners and is not convex, or an OBJ face naming vertex 0 (see the module doc); other files pass, and so
    do other formats. Returns how far (the file's units) the surface trimesh reads may lie from another surface
    spanning its polygons: the largest polygon's ``_warp`` (0.0 for a file of triangles, or of another format)."""
    suffix = path.suffix.lower()
    if suffix == ".obj":
        lines = plain(raw)  # as the loader hands it to trimesh
        text = joined(lines)
        line = _face_naming_vertex_zero(text, lines)
        if line is not None:
            raise MeshError(f"{path}: the face on line {line} names vertex 0, which an OBJ file does not have (it "
                            "counts vertices from 1); export the mesh again from CAD")
        return _checked(path, *_obj_polygons(text, lines))
    if suffix == ".ply":
        return _checked(path, *_ply_polygons(raw))
    return 0.0
