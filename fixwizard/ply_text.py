"""PLY files trimesh would read as another surface, or refuse in its own words: refused here with the fix.

trimesh's PLY reader reads the header up to each LF: a header whose lines end with CR alone (classic Mac OS) is one
line to it ("list index out of range"). It reads the surface from ``element face`` alone: triangle strips
(``element tristrips``, as Stanford's range scanning tools wrote them) were skipped without a word, leaving a point
cloud or, beside faces, a surface with holes. An ASCII PLY's numbers go to numpy's parser, which reads ``0,05`` (a
decimal comma) as 0 and stops, or refuses in words naming no line, by its version.
"""

import re
from pathlib import Path

from fixwizard.errors import MeshError
from fixwizard.mesh_format import NUMBER, UTF8_BOM, unreadable_line_message

_HEADER_END = re.compile(rb"^end_header[ \t]*(?:\r\n|\r|\n)", re.MULTILINE)
_LINE_END = re.compile(rb"\r\n|\r|\n")
_NOT_A_NUMBER = re.compile(rb"(?<!\S)(?!(?:%s)(?!\S))\S+" % NUMBER)
_STRIPS = re.compile(rb"^element[ \t]+(tristrips?)\b", re.MULTILINE | re.IGNORECASE)
_ASCII = re.compile(rb"^format[ \t]+ascii\b", re.MULTILINE)
HEAD_BYTES = 1024


def _ends_lines_with_cr_alone(head: bytes) -> bool:
    """Whether the header (``head``: the file's first bytes) ends its first line with CR alone."""
    first = head.removeprefix(UTF8_BOM).split(b"\n", 1)[0]
    return b"\r" in first.rstrip(b"\r")


def _unreadable_line(raw: bytes, start: int) -> tuple[int, str] | None:
    """The number and the text of the first line of an ASCII PLY's ``raw`` bytes, from its data's ``start`` on, that
    holds a word that is no number; None when there is none."""
    word = _NOT_A_NUMBER.search(raw, start)
    if word is None:
        return None
    line_start = max(raw.rfind(b"\n", 0, word.start()), raw.rfind(b"\r", 0, word.start())) + 1
    line = _LINE_END.split(raw[line_start:], maxsplit=1)[0]
    return len(_LINE_END.findall(raw, 0, line_start)) + 1, line.decode("latin-1").strip()


def checked_ply(path: Path) -> None:
    """Raise ``MeshError`` saying what to do for a PLY file at ``path`` whose header ends its lines with CR alone,
    that holds triangle strips, or, ASCII, a word that is no number (a decimal comma), naming its line; other files
    pass (trimesh's reader says what else is wrong)."""
    raw = path.read_bytes()
    if _ends_lines_with_cr_alone(raw[:HEAD_BYTES]):
        raise MeshError(f"{path}: its header's lines end with a carriage return alone (CR, as classic Mac OS wrote "
                        "text), which fixwizard's PLY reader does not read; export the mesh again, or convert its "
                        "line ends to LF")
    end = _HEADER_END.search(raw)
    if end is None:
        return
    strips = _STRIPS.search(raw, 0, end.start())
    if strips is not None:
        raise MeshError(f"{path}: it holds triangle strips (element {strips.group(1).decode()}), which fixwizard's PLY "
                        "reader does not read (it reads element face); export the mesh with faces (triangles), or "
                        "as binary STL")
    unreadable = _unreadable_line(raw, end.end()) if _ASCII.search(raw, 0, end.start()) else None
    if unreadable is not None:
        raise MeshError(unreadable_line_message(path, *unreadable))
