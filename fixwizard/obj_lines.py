"""An OBJ file's lines as the format reads them, for trimesh's reader, and a count of what that reader must give back.

trimesh's OBJ reader takes a vertex or a face only from a line that starts with ``v `` or ``f `` at its first byte:
an indented line, or one with a tab after its keyword, was skipped without a word. A vertex skipped moved every later
vertex up by one, so faces named other corners (another surface, or "index out of bounds"); a face skipped left a
hole; a byte-order mark before the first line lost that line too. ``reader_text`` hands trimesh the lines as the
format reads them (the mark dropped, continued lines joined, tabs as spaces, indents removed), and the loader checks
that trimesh read as many triangles as the faces hold (``face_triangles``) and refuses a vertex line of fewer than
three numbers (``short_vertex_line``).
"""

import re

from fixwizard.mesh_format import UTF8_BOM

_CONTINUATION = re.compile(rb"\\[ \t]*\r?\n")  # a backslash ending a line joins the next one to it (the OBJ spec)
_INDENT = re.compile(rb"^[ \t]+", re.MULTILINE)
_FACE_CORNERS = re.compile(rb"^f[ \t]([^\n#]*)", re.MULTILINE)
_VERTEX_NUMBERS = re.compile(rb"^v[ \t]([^\n#]*)", re.MULTILINE)


def joined(text: bytes) -> bytes:
    """The text with each line continued by a backslash joined to the next; every byte stays where it was (the
    backslash and the line break become spaces), so a position's line number is that of the text it came from."""
    return _CONTINUATION.sub(lambda found: b" " * len(found.group()), text)


def reader_text(raw: bytes) -> bytes:
    """An OBJ file's bytes as trimesh's reader should see them (see the module doc)."""
    return _INDENT.sub(b"", joined(raw.removeprefix(UTF8_BOM)).replace(b"\t", b" "))


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
