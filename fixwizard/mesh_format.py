"""What kind of mesh a file holds, by its first bytes: to tell the user of a file saved with the wrong suffix (an
OBJ export named ``.stl``) what it is, instead of reading it as the suffix says and finding no triangles."""

import re
import struct
from pathlib import Path

from fixwizard.errors import quoted

FORMAT_NAMES = {".stl": "STL", ".ply": "PLY", ".obj": "OBJ"}
HEAD_BYTES = 4096
STL_HEADER_BYTES, STL_TRIANGLE_BYTES = 84, 50  # binary STL: 80-byte header, uint32 count, 50 bytes per triangle
UTF8_BOM = b"\xef\xbb\xbf"  # a byte-order mark some Windows tools put before a text file
OBJ_KEYWORDS = {"v", "vn", "vt", "vp", "f", "l", "o", "g", "s", "mtllib", "usemtl"}
# A number as an OBJ or ASCII PLY file writes it, and as numpy reads it: a decimal point, an exponent, or nan or inf
# (those are refused once read, naming the vertex)
NUMBER = rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|[-+]?(?i:nan|inf(?:inity)?)"
_DECIMAL_COMMA = re.compile(r"\d,\d")
# NaN or infinity as Microsoft's C library printed them before 2015 (1.#QNAN, -1.#IND, 1.#INF) and since (-nan(ind))
NOT_FINITE_WORD = rb"[-+]?(?:\d+\.\d*#(?:qnan|snan|ind|inf)\w*|nan\(\w*\))"
_NOT_FINITE = re.compile(NOT_FINITE_WORD.decode(), re.IGNORECASE)
ARCHIVE_MAGIC = {b"PK\x03\x04": "ZIP", b"\x1f\x8b": "gzip", b"7z\xbc\xaf\x27\x1c": "7z"}  # a 3MF is a ZIP too


def binary_stl_triangles(head: bytes, size: int) -> int | None:
    """How many triangles a file of ``size`` bytes starting with ``head`` holds as a binary STL: the count in its
    header when its size is that count's (whatever the header's text: it may start with "solid" too), or, when the
    header's count is 0 (some exporters write 0 and leave the count to the size), the whole number of triangles its
    size holds; None for a file of any other size (no binary STL, or one cut short or with bytes added)."""
    if size < STL_HEADER_BYTES:
        return None
    count = struct.unpack("<I", head[80:84])[0]
    if size == STL_HEADER_BYTES + STL_TRIANGLE_BYTES * count:
        return count
    held, rest = divmod(size - STL_HEADER_BYTES, STL_TRIANGLE_BYTES)
    return held if count == 0 and held > 0 and rest == 0 else None


def is_binary_stl(head: bytes, size: int) -> bool:
    """Whether a file of ``size`` bytes starting with ``head`` is a binary STL (``binary_stl_triangles``)."""
    return binary_stl_triangles(head, size) is not None


def archive_format(raw: bytes) -> str | None:
    """The kind of archive (``ZIP``, ``gzip``, ``7z``) a file of bytes ``raw`` is by its first bytes, None for any
    other file (a binary STL of that size whatever its header says)."""
    if is_binary_stl(raw[:STL_HEADER_BYTES], len(raw)):
        return None
    return next((kind for magic, kind in ARCHIVE_MAGIC.items() if raw.startswith(magic)), None)


def content_format(raw: bytes) -> str | None:
    """The suffix (``.stl``, ``.ply`` or ``.obj``) of the format a file's content (``raw``, its bytes) is in, None
    when its first bytes match none of them (then the reader of its suffix says what is wrong)."""
    head = raw[:HEAD_BYTES]
    if is_binary_stl(head, len(raw)):
        return ".stl"  # binary, whatever its header says (it may start with "solid" too)
    text = head.removeprefix(UTF8_BOM).lstrip()
    if text.startswith(b"ply") and text[3:4] in (b"\n", b"\r"):
        return ".ply"
    if text[:5].lower() == b"solid":
        return ".stl"
    for line in text.splitlines()[:-1] if len(head) == HEAD_BYTES else text.splitlines():
        words = line.split()
        if not words or words[0].startswith(b"#"):
            continue
        return ".obj" if words[0].decode("latin-1") in OBJ_KEYWORDS else None
    return None


def binary_stl_size_mismatch(raw: bytes) -> tuple[int, int] | None:
    """(triangles its header announces, bytes it holds) of a binary STL (``raw``, its bytes) whose size does not fit
    that count (cut short, or bytes added after it; a count of 0 fits any whole number of triangles,
    ``binary_stl_triangles``); None for any other file. Binary by a NUL byte after the header: float32 coordinates
    and the attribute bytes are full of them, and an ASCII STL has none."""
    head, size = raw[:HEAD_BYTES], len(raw)
    if size < STL_HEADER_BYTES or b"\0" not in head[STL_HEADER_BYTES:]:
        return None
    return None if is_binary_stl(head, size) else (struct.unpack("<I", head[80:84])[0], size)


def unreadable_line_message(path: Path, number: int, line: str) -> str:
    """What to say of line ``number`` (``line``, its text) of a mesh file that holds a word that is no number where
    the format has numbers: NaN or infinity in Microsoft's spelling (``1.#QNAN``) is named as such, and a decimal
    comma is refused, not read, since ``1,500`` may be one and a half (a German number format) or fifteen hundred
    (an English one)."""
    not_finite = _NOT_FINITE.search(line)
    if not_finite is not None:
        problem = (f"holds a number that is not finite ({quoted(not_finite.group())}: NaN or infinity, as Microsoft's "
                   "C library writes them): the exporter could not compute a vertex; repair the model in CAD and "
                   "export it again")
    elif _DECIMAL_COMMA.search(line):
        problem = ("writes its numbers with a decimal comma (an exporter set to a German or French number format), "
                   "which fixwizard does not read: '1,500' may be one and a half or fifteen hundred. Export the mesh "
                   "again with decimal points (an English number format), or as binary STL")
    else:
        problem = "holds a word that is no number where the format has numbers; export the mesh again from CAD"
    return f"{path}: line {number} ({quoted(line)}) {problem}"
