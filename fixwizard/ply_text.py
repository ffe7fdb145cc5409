"""PLY files trimesh would read as another surface, or refuse in its own words: refused here with the fix.

trimesh's PLY reader reads the header up to each LF: a header whose lines end with CR alone (classic Mac OS) is one
line to it ("list index out of range"). It reads the surface from ``element face`` alone: triangle strips
(``element tristrips``, as Stanford's range scanning tools wrote them) were skipped without a word, leaving a point
cloud or, beside faces, a surface with holes. An ASCII PLY's numbers go to numpy's parser, which reads ``0,05`` (a
decimal comma) as 0 and stops, or refuses in words naming no line, by its version; and its reader takes the rows the
file holds, not those the header announces: a file cut short lost its last faces, lines added after them were left
out, without a word. A binary PLY's faces are all taken as long as the first: triangles and quads together (Blender
untriangulated), a file cut short and bytes added were all "PLY is unexpected length!"; each is said for what it is.
"""

import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fixwizard.errors import MeshError
from fixwizard.mesh_format import NUMBER, UTF8_BOM, unreadable_line_message

_HEADER_END = re.compile(rb"^end_header[ \t]*(?:\r\n|\r|\n)", re.MULTILINE)
_LINE_END = re.compile(rb"\r\n|\r|\n")
_NOT_A_NUMBER = re.compile(rb"(?<!\S)(?!(?:%s)(?!\S))\S+" % NUMBER)
_ASCII = re.compile(rb"^format[ \t]+ascii\b", re.MULTILINE)
_BIG_ENDIAN = re.compile(rb"^format[ \t]+binary_big_endian\b", re.MULTILINE)
HEAD_BYTES = 1024
_WHITESPACE = np.zeros(256, bool)  # by byte value: what separates an ASCII PLY's words
_WHITESPACE[list(b" \t\n\r\x0b\x0c")] = True


# Bytes and struct codes of PLY's types (a list's length is one of the integer types)
_TYPES = {b"char": (1, "b"), b"int8": (1, "b"), b"uchar": (1, "B"), b"uint8": (1, "B"), b"short": (2, "h"),
          b"int16": (2, "h"), b"ushort": (2, "H"), b"uint16": (2, "H"), b"int": (4, "i"), b"int32": (4, "i"),
          b"uint": (4, "I"), b"uint32": (4, "I"), b"float": (4, "f"), b"float32": (4, "f"), b"double": (8, "d"),
          b"float64": (8, "d")}


@dataclass(frozen=True)
class _Element:
    """An element of a PLY header: its name, how many rows it announces, and each property's type words (``float``,
    or ``list uchar int``)."""

    name: str
    count: int
    types: tuple[tuple[bytes, ...], ...]

    @property
    def lists(self) -> tuple[bool, ...]:
        return tuple(words[0] == b"list" for words in self.types)


def _elements(header: bytes) -> list[_Element]:
    """The header's elements with their properties, in order (an unreadable count is trimesh's to refuse: -1)."""
    elements: list[_Element] = []
    for words in (line.split() for line in header.splitlines()):
        if len(words) >= 3 and words[0] == b"element":
            count = int(words[2]) if words[2].isdigit() else -1
            elements.append(_Element(words[1].decode("latin-1"), count, ()))
        elif len(words) >= 3 and words[0] == b"property" and elements:
            last = elements[-1]
            elements[-1] = _Element(last.name, last.count, (*last.types, tuple(words[1:-1])))
    return elements


def float32_vertices(raw: bytes) -> bool:
    """Whether a PLY file's (``raw``, its bytes) vertex coordinates are float32 (``property float x``): stored so in a
    binary file, and read so from an ASCII one (trimesh's reader rounds the text's further digits off)."""
    end = _HEADER_END.search(raw)
    vertex = next((element for element in _elements(raw[:end.start()]) if element.name == "vertex"), None) \
        if end is not None else None
    return vertex is not None and any(words in ((b"float",), (b"float32",)) for words in vertex.types[:3])


def _row_end(raw: bytes, position: int, element: _Element, order: str) -> tuple[int, tuple[int, ...]]:
    """Where a binary row starting at ``position`` ends, and its lists' lengths (``order``: struct's byte order);
    past the end of ``raw`` when it is cut short there."""
    lengths: list[int] = []
    for words in element.types:
        if words[0] != b"list":
            position += _TYPES[words[0]][0]
            continue
        size, code = _TYPES[words[1]]
        if position + size > len(raw):
            return len(raw) + 1, tuple(lengths)
        lengths.append(struct.unpack_from(order + code, raw, position)[0])
        position += size + lengths[-1] * _TYPES[words[2]][0]
    return position, tuple(lengths)


def _known(words: tuple[bytes, ...]) -> bool:
    """Whether a property's type words name types PLY has (``float``; ``list uchar int``)."""
    if words[:1] == (b"list",):
        return len(words) == 3 and words[1] in _TYPES and words[2] in _TYPES
    return len(words) == 1 and words[0] in _TYPES


def _size_if_uniform(raw: bytes, start: int, elements: list[_Element], order: str) -> int:
    """The bytes of a binary PLY's data if every list were as long as the first of its element (as trimesh's reader
    takes them)."""
    position = start
    for element in elements:
        row_end = _row_end(raw, position, element, order)[0] if element.count else position
        position += element.count * (row_end - position)
    return position - start


def _binary_problem(raw: bytes, start: int, elements: list[_Element], order: str) -> str | None:
    """What is wrong when a binary PLY's data (from ``start``) is not the rows its header announces with every list as
    long as the first of its element (the only data trimesh's reader takes: "PLY is unexpected length!", which said
    nothing of why): cut short, bytes after them, or faces of different corner counts. None when it is such, or its
    types are trimesh's to refuse."""
    if not all(_known(words) for element in elements for words in element.types) or \
            any(element.count < 0 for element in elements) or \
            start + _size_if_uniform(raw, start, elements, order) == len(raw):
        return None
    position, uniform = start, True
    for element in elements:
        first: tuple[int, ...] | None = None
        for row in range(element.count):
            position, lengths = _row_end(raw, position, element, order)
            if position > len(raw):
                return (f"it ends inside {element.name} {row + 1} of the {element.count} its header announces (cut "
                        "short by an interrupted copy or download, or damaged); copy or export it again")
            uniform &= first is None or lengths == first
            first = lengths if first is None else first
    if position < len(raw):
        return (f"it holds {len(raw) - position} bytes after the data its header announces (two files joined, or "
                "damaged); export the mesh again")
    return ("its faces have different numbers of corners (triangles and quads), which fixwizard's reader does not "
            "read from a binary PLY; export the mesh with triangulated faces (in Blender: Triangulate Mesh), as ASCII "
            "PLY, or as binary STL") if not uniform else None


def _numbers(body: bytes) -> np.ndarray | None:
    """Every word of an ASCII PLY's body as a number, each word one value, as numpy reads them (trimesh's reader
    does); None when some word is none (numpy refuses it, or, before 2.3, warns and stops there)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            values = np.fromstring(body, sep=" ")
        except (ValueError, DeprecationWarning):
            return None
    return values if len(values) == len(body.split()) else None


def _lines_and_words(body: bytes, first: int) -> tuple[np.ndarray, np.ndarray]:
    """The numbers (in the file, ``first`` being the body's first line) of the body's lines that hold words, and how
    many words each holds; a line ends at LF, CR LF or CR alone."""
    data = np.frombuffer(body, np.uint8)
    space = _WHITESPACE[data]
    follows = np.append(data[1:], 0)
    line_of = np.cumsum((data == ord("\n")) | ((data == ord("\r")) & (follows != ord("\n"))))
    line_of = np.concatenate(([0], line_of[:-1]))  # a line end belongs to the line it ends
    starts = ~space & np.concatenate(([True], space[:-1]))
    words = np.bincount(line_of[starts], minlength=int(line_of[-1]) + 1 if len(line_of) else 1)
    held = np.flatnonzero(words)
    return held + first, words[held]


def _wrong_rows(values: np.ndarray, offsets: np.ndarray, words: np.ndarray, lists: tuple[bool, ...]) -> np.ndarray:
    """Which rows (their first value at ``offsets`` of ``values``, ``words`` values each) do not hold what their
    properties say: one value per property, a list's length first."""
    position, ends = offsets.copy(), offsets + words
    wrong = np.zeros(len(offsets), bool)
    for is_list in lists:
        if is_list:
            inside = position < ends
            length = np.where(inside, values[np.minimum(position, len(values) - 1)], -1.0)
            wrong |= ~inside | (length < 0) | (length != np.round(length))
            position = position + np.where(wrong, 0, length).astype(np.int64)
        position = position + 1
    return wrong | (position != ends)


def _rows_problem(raw: bytes, start: int, elements: list[_Element], values: np.ndarray) -> str | None:
    """What is wrong when an ASCII PLY's body (from ``start`` of its ``raw`` bytes; ``values``, its numbers) does not
    hold the rows its header announces, one per line, each as long as its properties say: a file cut short lost its
    last faces without a word, and the lines after the announced ones (two files joined) were left out. None when it
    holds them."""
    lines, words = _lines_and_words(raw[start:], len(_LINE_END.findall(raw, 0, start)) + 1)
    offsets = np.cumsum(words) - words
    cut_short = "(cut short by an interrupted copy or download, or damaged); copy or export it again"
    done = 0
    for element in elements:
        if element.count < 0:
            return None
        rows = slice(done, done + element.count)
        if len(lines[rows]) < element.count:
            return f"its header announces {element.count} {element.name} lines, and it holds {len(lines[rows])} " \
                + cut_short
        wrong = np.flatnonzero(_wrong_rows(values, offsets[rows], words[rows], element.lists))
        if len(wrong):
            return f"line {lines[rows][wrong[0]]} does not hold the {element.name} values its header announces " \
                + cut_short
        done += element.count
    if len(lines) > done:
        return (f"line {lines[done]} and those after it are more than its header announces (two files joined into "
                "one?); export the mesh again")
    return None


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


def checked_ply(path: Path, raw: bytes) -> None:
    """Raise ``MeshError`` saying what to do for a PLY file at ``path`` (``raw``, its bytes) whose header ends its
    lines with CR alone, that holds triangle strips, or, ASCII, a word that is no number (a decimal comma) or other
    rows than its header announces, naming the line, or, binary, other data than its header announces or faces of
    different corner counts; other files pass (trimesh's reader says what else is wrong)."""
    if _ends_lines_with_cr_alone(raw[:HEAD_BYTES]):
        raise MeshError(f"{path}: its header's lines end with a carriage return alone (CR, as classic Mac OS wrote "
                        "text), which fixwizard's PLY reader does not read; export the mesh again, or convert its "
                        "line ends to LF")
    end = _HEADER_END.search(raw)
    if end is None:
        return
    elements = _elements(raw[:end.start()])
    strips = next((element.name for element in elements if element.name.lower() in ("tristrips", "tristrip")), None)
    if strips is not None:
        raise MeshError(f"{path}: it holds triangle strips (element {strips}), which fixwizard's PLY reader does not "
                        "read (it reads element face); export the mesh with faces (triangles), or as binary STL")
    if not _ASCII.search(raw, 0, end.start()):
        binary = _binary_problem(raw, end.end(), elements, ">" if _BIG_ENDIAN.search(raw, 0, end.start()) else "<")
        if binary is not None:
            raise MeshError(f"{path}: {binary}")
        return
    values = _numbers(raw[end.end():])
    if values is None:
        unreadable = _unreadable_line(raw, end.end())
        if unreadable is None:
            raise MeshError(f"{path}: its data holds a word that is no number; export the mesh again from CAD")
        raise MeshError(unreadable_line_message(path, *unreadable))
    problem = _rows_problem(raw, end.end(), elements, values)
    if problem is not None:
        raise MeshError(f"{path}: {problem}")
