"""An OBJ file's lines as the format reads them, for trimesh's reader, and a count of what that reader must give back.

trimesh's OBJ reader takes a vertex or a face only from a line that starts with ``v `` or ``f `` at its first byte:
an indented line, or one with a tab after its keyword, was skipped without a word. A vertex skipped moved every later
vertex up by one, so faces named other corners (another surface, or "index out of bounds"); a face skipped left a
hole; a byte-order mark before the first line lost that line too. Its lines end at LF alone, so a file with the old
Mac line ends (CR alone) was one line, and a comment after a vertex's or a face's numbers (``f 1 2 3 # lid``) was
read as numbers; a corner counted back (``f -3 -2 -1``) was counted from the file's last vertex, not from those before
its line. ``plain`` gives the lines as the format reads them (the mark dropped, every line end an LF, comments
blanked) and ``reader_text`` hands them to trimesh (continued lines joined, corners counted back made absolute, tabs
as spaces, indents removed); the loader refuses a line whose numbers trimesh would not read as written
(``unreadable_line``) or a corner counted back past the first vertex, and checks that trimesh read as many triangles
as the faces hold (``face_triangles``).
"""

import bisect
import re
from collections.abc import Iterator

from fixwizard.mesh_format import NOT_FINITE_WORD, NUMBER, UTF8_BOM

_CONTINUATION = re.compile(rb"\\[ \t]*\n")  # a backslash ending a line joins the next one to it (the OBJ spec)
_COMMENT = re.compile(rb"#[^\n]*")  # from a '#' to the line's end
_INDENT = re.compile(rb"^[ \t]+", re.MULTILINE)
_FACE_CORNERS = re.compile(rb"^f[ \t]([^\n]*)", re.MULTILINE)
_VERTEX_NUMBERS = re.compile(rb"^v[ \t]([^\n]*)", re.MULTILINE)
_VERTEX_START = re.compile(rb"^[ \t]*v[ \t]", re.MULTILINE)
_FACE = re.compile(rb"^([ \t]*f[ \t])([^\n]*)", re.MULTILINE)
_COUNTED_BACK = re.compile(rb"^[ \t]*f[ \t][^\n]*(?<=[ \t])-\d", re.MULTILINE)  # a face with a corner such as -3
_CORNER = rb"[-+]?\d+(?:/[-+]?\d*){0,2}"  # vertex[/texture[/normal]], either of the last two may be left out
# A vertex (v), texture (vt), normal (vn) or parameter (vp) line, or a face line, with a word that is no number of its
# kind: trimesh's reader read such a line as other numbers, or stopped with numpy's words.
_UNREADABLE = re.compile(rb"^[ \t]*(?:(?:v|vt|vn|vp)[ \t](?![ \t]*(?:%s)(?:[ \t]+(?:%s))*[ \t]*$)"
                         rb"|f[ \t](?![ \t]*%s(?:[ \t]+%s)*[ \t]*$))[^\n]*" % (NUMBER, NUMBER, _CORNER, _CORNER),
                         re.MULTILINE)
# A line with NaN or infinity as Microsoft's C library writes them (``v 1.#QNAN 2 3``) before any comment: its '#'
# would start one, and the line be read as ``v 1.``
_NOT_FINITE_LINE = re.compile(rb"^[^\n#]*?(?<![^ \t])(?:%s)[^\n]*" % NOT_FINITE_WORD, re.MULTILINE | re.IGNORECASE)


def line_ended(raw: bytes) -> bytes:
    """An OBJ file's bytes with the byte-order mark dropped and every line end an LF (CR LF as a space and an LF, CR
    alone as an LF): every other byte stays where it was."""
    return raw.removeprefix(UTF8_BOM).replace(b"\r\n", b" \n").replace(b"\r", b"\n")


def plain(raw: bytes) -> bytes:
    """An OBJ file's ``line_ended`` bytes with every comment blanked (spaces): every other byte stays where it was,
    so a position's line number (``line_number``) is that of the file's line it came from."""
    return _COMMENT.sub(lambda found: b" " * len(found.group()), line_ended(raw))


def not_finite_line(raw: bytes) -> tuple[int, str] | None:
    """The number and the words of the first line of an OBJ file's bytes that holds NaN or infinity as Microsoft's C
    library writes them (``1.#QNAN``, ``-nan(ind)``) before any comment, None when there is none."""
    text = line_ended(raw)
    found = _NOT_FINITE_LINE.search(text)
    return None if found is None else (line_number(text, found.start()), found.group().decode("latin-1").strip())


def joined(text: bytes) -> bytes:
    """The ``plain`` text with each line continued by a backslash joined to the next; every byte stays where it was
    (the backslash and the line break become spaces), so a position's line is still that of the ``plain`` text."""
    return _CONTINUATION.sub(lambda found: b" " * len(found.group()), text)


def line_number(text: bytes, position: int) -> int:
    """The number (from 1) of the line of the ``plain`` text holding ``position``."""
    return text.count(b"\n", 0, position) + 1


def reader_text(text: bytes) -> bytes:
    """An OBJ file's ``plain`` text as trimesh's reader should see it (see the module doc), its corners counted back
    made absolute (``absolute_corners``)."""
    return _INDENT.sub(b"", absolute_corners(joined(text)).replace(b"\t", b" "))


def _counted_back_faces(text: bytes) -> Iterator[tuple[re.Match[bytes], int]]:
    """Each face line of a ``joined`` text, with how many vertex lines come before it, when some face has a corner
    counted back (none otherwise: most files, found at the speed of one search)."""
    if _COUNTED_BACK.search(text) is None:
        return
    starts = [vertex.start() for vertex in _VERTEX_START.finditer(text)]
    for face in _FACE.finditer(text):
        yield face, bisect.bisect_left(starts, face.start())


def _absolute(corner: bytes, defined: int) -> bytes:
    """A face's corner (``vertex[/texture[/normal]]``) with its vertex number counted back from the ``defined``
    vertices before it made the number it means."""
    vertex, slash, rest = corner.partition(b"/")
    number = int(vertex)
    return (b"%d" % (defined + number + 1) if number < 0 else vertex) + slash + rest


def absolute_corners(text: bytes) -> bytes:
    """A ``joined`` text with every corner counted back (``f -3 -2 -1``) made the vertex number it means: counted back
    from the vertices before its line, as the OBJ format counts. trimesh counted back from the file's last vertex,
    so an object's faces written after its own vertices named the last object's (two boxes read as one, twice)."""
    changed = {face.start(): face.group(1) + b" ".join(_absolute(corner, defined) for corner in face.group(2).split())
               for face, defined in _counted_back_faces(text)}
    return _FACE.sub(lambda face: changed[face.start()], text) if changed else text


def corner_before_first_vertex(text: bytes) -> tuple[int, str] | None:
    """The number and the words of the first face line of the ``plain`` text with a corner counted back past the
    first vertex (``f -9 -2 -1`` after 8 vertices), None when there is none."""
    for face, defined in _counted_back_faces(joined(text)):
        if any(int(corner.partition(b"/")[0]) < -defined for corner in face.group(2).split()):
            return line_number(text, face.start()), face.group().decode("latin-1").strip()
    return None


def unreadable_line(text: bytes) -> tuple[int, str] | None:
    """The number and the words of the first line of the ``plain`` text that is a vertex, texture, normal or
    parameter line with a word that is no number, or a face line with a corner that is no vertex number (with its
    texture and normal numbers); None when there is none."""
    found = _UNREADABLE.search(joined(text))
    if found is None:
        return None
    return line_number(text, found.start()), found.group().decode("latin-1").strip()


def face_triangles(text: bytes) -> int:
    """How many triangles the faces of ``reader_text`` hold: ``k - 2`` for a face of ``k >= 3`` corners."""
    return sum(max(len(corners.split()) - 2, 0) for corners in _FACE_CORNERS.findall(text))


def short_vertex_line(text: bytes) -> str | None:
    """The first vertex line of ``reader_text`` with fewer than three numbers (trimesh read it as some other point),
    None when there is none."""
    for numbers in _VERTEX_NUMBERS.findall(text):
        if len(numbers.split()) < 3:
            return "v " + numbers.decode("latin-1").strip()
    return None
