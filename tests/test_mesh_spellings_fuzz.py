"""One surface, written the many ways exporters write it (binary and ASCII STL with any solid name, binary and ASCII
PLY with comments, OBJ with comments, tabs, indentation, a byte-order mark, corners counted back, polygons split
into triangles; LF, CR LF or CR alone at the line ends), loads as the same surface every time: every triangle, with
its winding, exactly. The readers behind it (trimesh's and fixwizard's own line handling) must agree, since the
guaranteed bound is a bound for the file's surface."""

import os
import random
import struct
from collections import Counter

import numpy as np
import pytest
import trimesh

from fixwizard.fixture import load_fixture

TRIALS = int(os.environ.get("FUZZ_TRIALS", "12"))


def random_solid(rng: random.Random) -> trimesh.Trimesh:
    """A closed convex solid with integer millimetre corners (exact in every format: float32 and short decimals)."""
    while True:
        points = np.array([[rng.randint(-60, 60), rng.randint(-40, 40), rng.randint(0, 50)] for _ in range(14)], float)
        hull = trimesh.convex.convex_hull(points)
        if len(hull.faces) >= 8 and hull.volume > 1000.0:
            return hull


def triangles(mesh: trimesh.Trimesh) -> Counter:
    """The triangles as corner coordinates (mm), each turned to start at its least corner: winding kept."""
    found: Counter = Counter()
    for corners in np.round(mesh.vertices[mesh.faces] * 1000.0, 6):
        rows = [tuple(corner) for corner in corners]
        start = rows.index(min(rows))
        found[tuple(rows[start:] + rows[:start])] += 1
    return found


def number(value: float, rng: random.Random) -> str:
    return rng.choice([f"{value:g}", f"{value:.1f}", f"{value:.6e}", f"{value:+.3f}"])


def binary_stl(mesh: trimesh.Trimesh, rng: random.Random) -> bytes:
    count = 0 if rng.random() < 0.3 else len(mesh.faces)  # some exporters leave the count to the size
    body = b"".join(struct.pack("<12fH", *mesh.face_normals[i], *mesh.vertices[face].ravel(), 0)
                    for i, face in enumerate(mesh.faces))
    return b"exported by a CAD tool".ljust(80, b" ") + struct.pack("<I", count) + body


def ascii_stl(mesh: trimesh.Trimesh, rng: random.Random) -> str:
    name = rng.choice(["", "part", "vertex 1 2 3 facet normal", "Body 1 (mm)"])
    indent = rng.choice(["", "  ", "\t"])
    lines = [f"solid {name}".rstrip()]
    for i, face in enumerate(mesh.faces):
        lines += [f"{indent}facet normal {' '.join(number(v, rng) for v in mesh.face_normals[i])}",
                  f"{indent}{indent}outer loop"]
        lines += [f"{indent * 3}vertex {' '.join(number(v, rng) for v in mesh.vertices[c])}" for c in face]
        lines += [f"{indent}{indent}endloop", f"{indent}endfacet"]
    return "\n".join([*lines, f"endsolid {name}".rstrip()]) + "\n"


def ascii_ply(mesh: trimesh.Trimesh, rng: random.Random) -> str:
    kind = rng.choice(["float", "double"])
    header = ["ply", "format ascii 1.0", "comment made by a CAD tool", f"element vertex {len(mesh.vertices)}",
              *(f"property {kind} {axis}" for axis in "xyz"), f"element face {len(mesh.faces)}",
              "property list uchar int vertex_indices", "end_header"]
    return "\n".join([*header, *(" ".join(number(v, rng) for v in vertex) for vertex in mesh.vertices),
                      *(f"3 {a} {b} {c}" for a, b, c in mesh.faces)]) + "\n"


def binary_ply(mesh: trimesh.Trimesh, rng: random.Random) -> bytes:
    kind, code = rng.choice([("float", "f"), ("double", "d")])
    header = ("ply\nformat binary_little_endian 1.0\ncomment made by a CAD tool\n"
              f"element vertex {len(mesh.vertices)}\n" + "".join(f"property {kind} {axis}\n" for axis in "xyz")
              + f"element face {len(mesh.faces)}\nproperty list uchar int vertex_indices\nend_header\n")
    vertices = b"".join(struct.pack(f"<3{code}", *vertex) for vertex in mesh.vertices)
    faces = b"".join(struct.pack("<B3i", 3, *face) for face in mesh.faces)
    return header.encode() + vertices + faces


def obj(mesh: trimesh.Trimesh, rng: random.Random) -> str:
    back = rng.random() < 0.5  # corners counted back from the face's line
    tab = rng.choice([" ", "\t", "  "])
    lines = ["# exported by a CAD tool", "o part"]
    lines += [f"v{tab}{' '.join(number(v, rng) for v in vertex)}" + rng.choice(["", " # corner"])
              for vertex in mesh.vertices]
    count = len(mesh.vertices)
    for face in mesh.faces:
        corners = [str(int(c) - count) if back else str(int(c) + 1) for c in face]
        lines.append(rng.choice(["", " "]) + f"f{tab}{' '.join(corners)}" + rng.choice(["", " # face"]))
    return "\ufeff" * (rng.random() < 0.3) + "\n".join(lines) + "\n"


WRITERS = {".stl": (binary_stl, ascii_stl), ".ply": (binary_ply, ascii_ply), ".obj": (obj,)}


def line_ends(text: str, suffix: str, rng: random.Random) -> bytes:
    """LF, CR LF or CR alone (not for PLY, whose header fixwizard refuses with CR alone, saying so)."""
    return text.replace("\n", rng.choice(["\n", "\r\n"] + (["\r"] if suffix != ".ply" else []))).encode()


@pytest.mark.slow
def test_one_surface_in_any_spelling_loads_as_the_same_triangles(tmp_path):
    seed = random.randrange(1 << 30)
    rng = random.Random(seed)
    for trial in range(TRIALS):
        solid = random_solid(rng)
        canonical = tmp_path / f"canonical-{trial}.stl"
        solid.export(canonical)
        expected = triangles(load_fixture(canonical, "mm").mesh)
        assert sum(expected.values()) == len(solid.faces)
        for suffix, writers in WRITERS.items():
            for writer in writers:
                written = writer(solid, rng)
                path = tmp_path / f"trial-{trial}-{writer.__name__}{suffix}"
                path.write_bytes(written if isinstance(written, bytes) else line_ends(written, suffix, rng))
                found = triangles(load_fixture(path, "mm").mesh)
                assert found == expected, f"seed {seed}, trial {trial}, {writer.__name__}: {path.read_bytes()[:300]!r}"
