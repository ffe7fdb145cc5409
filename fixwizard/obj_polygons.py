"""OBJ faces of four or more corners that trimesh would cut wrongly: it cuts every such polygon into a fan of
triangles from its first corner, which is its own surface only where the polygon is convex. A concave one (the top
of an L-shaped plate as Blender writes it without "Triangulate Faces") gets triangles reaching outside it, a
surface the part does not have, which can exclude the true pose. Such a file is refused with the fix."""

import re
from pathlib import Path

import numpy as np

from fixwizard.errors import MeshError

_VERTEX_LINE = re.compile(rb"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)", re.MULTILINE)
_POLYGON_LINE = re.compile(rb"^[ \t]*f((?:[ \t]+\S+){4,})[ \t]*$", re.MULTILINE)
# A corner whose turn is below this share of its edges' and the normal's lengths is straight (rounding), not concave.
STRAIGHT_SHARE = 1e-9


def _is_convex(corners: np.ndarray) -> bool:
    """Whether a polygon (K, 3 corners in order) turns the same way at every corner about its Newell normal (so a fan
    from any corner cuts it into its own pieces)."""
    following = np.roll(corners, -1, axis=0)
    normal = np.cross(corners, following).sum(axis=0)
    incoming = corners - np.roll(corners, 1, axis=0)
    outgoing = following - corners
    turns = np.cross(incoming, outgoing) @ normal
    scale = np.linalg.norm(incoming, axis=1) * np.linalg.norm(outgoing, axis=1) * float(np.linalg.norm(normal))
    return bool(np.all(turns >= -STRAIGHT_SHARE * scale))


def refuse_concave_polygons(path: Path) -> None:
    """Raise ``MeshError`` naming the first face of the OBJ file at ``path`` that has four or more corners and is not
    convex (see the module doc); files of triangles and convex polygons pass."""
    text = path.read_bytes()
    polygons = list(_POLYGON_LINE.finditer(text))
    if not polygons:
        return
    vertex_lines = list(_VERTEX_LINE.finditer(text))
    try:
        vertices = np.array([[float(value) for value in line.groups()] for line in vertex_lines]).reshape(-1, 3)
    except ValueError:
        return  # trimesh's reader says what is wrong with the vertices
    vertex_starts = np.array([line.start() for line in vertex_lines], np.int64)
    for polygon in polygons:
        defined = int(np.searchsorted(vertex_starts, polygon.start()))  # vertices before this line
        try:
            indices = [int(token.split(b"/")[0]) for token in polygon.group(1).split()]
        except ValueError:
            return
        rows = np.array([index - 1 if index > 0 else defined + index for index in indices])
        if np.any(rows < 0) or np.any(rows >= len(vertices)):
            return
        if not _is_convex(vertices[rows]):
            line = text.count(b"\n", 0, polygon.start()) + 1
            raise MeshError(f"{path}: the face on line {line} is a polygon of {len(rows)} corners that is not convex; "
                            "fixwizard's reader would cut it into triangles reaching outside it, a surface the part "
                            "does not have. Export the mesh with triangulated faces (in Blender: Triangulate Faces), "
                            "or as STL")
