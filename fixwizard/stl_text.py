"""An ASCII STL's text as trimesh's reader should see it, and its vertex lines that reader would not read as written.

trimesh's ASCII STL reader takes each vertex's numbers up to the next LF: with CR alone at each line end (classic
Mac OS) the words after a facet's last vertex (``endloop``, ``endfacet``, ``facet normal``) were read as numbers,
refused in numpy's words or, with numpy before 2.3, cut short without a word. Numbers written with a decimal comma
(``vertex 1,5 2,0 3,0``) are refused naming their line, as in OBJ and PLY files (``mesh_format``), and so is a
``solid`` that no ``endsolid`` ends (cut short). The solids' names are left out: trimesh read keywords in them.
"""

import re

from fixwizard.mesh_format import NUMBER

# A vertex line whose words after ``vertex`` are not three numbers (the reader lowercases the text, so any case).
_UNREADABLE_VERTEX = re.compile(rb"^[ \t]*vertex\b(?![ \t]+(?:%s)[ \t]+(?:%s)[ \t]+(?:%s)[ \t]*$)[^\n]*"
                                % (NUMBER, NUMBER, NUMBER), re.MULTILINE | re.IGNORECASE)
_SOLID_LINE = re.compile(rb"^[ \t]*(end)?solid", re.MULTILINE | re.IGNORECASE)  # a solid's start or end
_SOLID_NAME = re.compile(rb"^([ \t]*(?:end)?solid)[^\n]*", re.MULTILINE | re.IGNORECASE)  # the keyword, then the name


def reader_text(raw: bytes) -> bytes:
    """An ASCII STL's bytes with every line end an LF (CR LF and CR alone too) and each solid's name left out: its
    lines, and their count, as written. A name is free text, and trimesh's reader looked for its keywords in it: a
    solid named 'vertex 0.5 0 0 ...' gained a triangle, and one named 'endsolid part' or 'Part1 (vertex)' was
    refused in the reader's words."""
    return _SOLID_NAME.sub(rb"\1", raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n"))


def unended_solid(text: bytes) -> int | None:
    """The number of the line of ``reader_text`` where a ``solid`` starts that no ``endsolid`` ends (a file cut short:
    trimesh's reader left that solid out, said as "no triangles" when it was the only one), None when each is
    ended."""
    started = None
    for line in _SOLID_LINE.finditer(text):
        if line.group(1):
            started = None
        elif started is None:
            started = text.count(b"\n", 0, line.start()) + 1
    return started


def unreadable_line(text: bytes) -> tuple[int, str] | None:
    """The number and the words of the first vertex line of ``reader_text`` whose coordinates are not three numbers
    (a decimal comma, a word), None when there is none."""
    found = _UNREADABLE_VERTEX.search(text)
    if found is None:
        return None
    return text.count(b"\n", 0, found.start()) + 1, found.group().decode("latin-1").strip()
