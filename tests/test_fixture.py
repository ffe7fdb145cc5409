"""Loading fixture meshes: units, bad files, open meshes; distance intervals and signs."""

import gzip
import hashlib
import re
import zipfile

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from fixwizard import fixture as fixture_module
from fixwizard.errors import MeshError, MeshUnitsError
from fixwizard.fixture import load_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.synthetic import closest_on_triangles, exact_distances_m, touching_ball_centres
from shapes import SHAPES, WARPED_BOX_QUADS, across_other_diagonals, as_fixture, polygons_obj, warped_box_vertices


def test_a_millimetre_mesh_loaded_as_metres_is_refused_with_the_fix(tmp_path):
    path = tmp_path / "bracket.stl"
    trimesh.creation.box((180.0, 120.0, 40.0)).export(path)
    with pytest.raises(MeshUnitsError, match="if the file is in millimetres, its units are mm") as caught:
        load_fixture(path, "m")
    assert caught.value.likely_units == "mm"
    assert load_fixture(path, "mm").mesh.extents == pytest.approx([0.18, 0.12, 0.04])


def test_a_metre_mesh_loaded_as_millimetres_is_refused_with_the_fix(tmp_path):
    path = tmp_path / "bracket.stl"
    trimesh.creation.box((0.18, 0.12, 0.04)).export(path)
    with pytest.raises(MeshUnitsError, match="if the file is in metres, its units are m") as caught:
        load_fixture(path, "mm")
    assert caught.value.likely_units == "m"


@pytest.mark.parametrize("units", ["m", "mm"])
def test_a_mesh_in_inches_is_refused_naming_inches_not_a_unit_that_would_be_refused_too(tmp_path, units):
    """A 120 mm part exported in inches is 4.7 mm in mm and 4.7 m in m, both implausible: the message names inches
    and no unit to switch to (it suggested the other unit, which was then refused the other way round)."""
    path = tmp_path / "bracket.stl"
    trimesh.creation.box(np.array([120.0, 80.0, 10.0]) / 25.4).export(path)
    inches = r"if the file is in inches \(a 120 mm fixture\), export it again"
    with pytest.raises(MeshUnitsError, match=inches) as caught:
        load_fixture(path, units)
    assert caught.value.likely_units is None


@pytest.mark.parametrize("size_mm, shown", [(4.9996, "a 4.9996 mm small fixture"), (4.2, "a 4.2 mm small fixture"),
                                             (2500.4, "a 2.5004 m large fixture")])
def test_a_size_just_beyond_the_plausible_range_is_said_with_the_digits_that_show_it_and_the_range(tmp_path, size_mm,
                                                                                                 shown):
    """A 4.9996 mm part was "a 5 mm small fixture, which is implausible" while 5 mm is fine."""
    path = tmp_path / "part.stl"
    trimesh.creation.box([size_mm, size_mm / 2, size_mm / 3]).export(path)
    with pytest.raises(MeshUnitsError) as caught:
        load_fixture(path, "mm")
    assert f"would be {shown} with units 'mm', which is implausible (fixwizard takes fixtures 5 mm to 2.5 m " \
        "across)" in str(caught.value)


@pytest.mark.parametrize("content, match", [(b"", "empty"), (b"hello, I am not a mesh\n" * 10, "mesh"),
                                            (b"solid x\nendsolid x\n", "no triangles")])
def test_files_that_are_not_meshes_get_a_clear_message(tmp_path, content, match):
    path = tmp_path / "fixture.stl"
    path.write_bytes(content)
    with pytest.raises(MeshError, match=match):
        load_fixture(path)


def test_a_missing_file_and_a_foreign_format_are_named(tmp_path):
    with pytest.raises(MeshError, match="does not exist"):
        load_fixture(tmp_path / "nothing.stl")
    with pytest.raises(MeshError, match="is a folder, not a mesh file"):
        load_fixture(tmp_path)
    step = tmp_path / "fixture.step"
    step.write_text("ISO-10303-21;")
    with pytest.raises(MeshError, match="STL, PLY or OBJ"):
        load_fixture(step)


EXPORTS = {"binary STL": ("stl", ".stl"), "ASCII STL": ("stl_ascii", ".stl"), "binary PLY": ("ply", ".ply"),
           "OBJ": ("obj", ".obj")}


def _exported(kind: str, header: bytes = b"") -> bytes:
    """The L-plate exported as ``kind`` (a binary STL's 80-byte header replaced by ``header`` if given)."""
    data = SHAPES["l_prism"]().export(file_type=EXPORTS[kind][0])
    data = data.encode() if isinstance(data, str) else data
    return header.ljust(80, b" ") + data[80:] if header else data


@pytest.mark.parametrize("kind", sorted(EXPORTS))
def test_a_mesh_saved_with_another_formats_suffix_is_named_for_what_it_holds(tmp_path, kind):
    """Under its own suffix it loads; under each other one the message says what it holds and the name to give."""
    fmt = EXPORTS[kind][1]
    for suffix in (".stl", ".ply", ".obj"):
        path = tmp_path / f"fixture{suffix}"
        path.write_bytes(_exported(kind))
        if suffix == fmt:
            assert len(load_fixture(path).mesh.faces) > 0
        else:
            with pytest.raises(MeshError, match=rf"in {fmt[1:].upper()} format, .* rename it to fixture\{fmt}$"):
                load_fixture(path)


@pytest.mark.parametrize("kind", ["ZIP", "gzip"])
def test_a_compressed_mesh_is_called_an_archive_not_a_binary_stl_cut_short(tmp_path, kind):
    """A zipped or gzipped export (or a 3MF, a ZIP) named .stl was "a binary STL whose header announces 1886351212
    triangles ... cut short"; a binary STL whose header starts like a ZIP still loads."""
    data = _exported("ASCII STL")
    path = tmp_path / "fixture.stl"
    if kind == "ZIP":
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("fixture.stl", data)
    else:
        path.write_bytes(gzip.compress(data))
    with pytest.raises(MeshError, match=f"fixture.stl is a {kind} archive, not a mesh .* unpack the mesh from it"):
        load_fixture(path)
    path.write_bytes(_exported("binary STL", header=b"PK\x03\x04 and more"))
    assert len(load_fixture(path).mesh.faces) == len(SHAPES["l_prism"]().faces)


@pytest.mark.parametrize("content", [b"\xef\xbb\xbf" + _exported("OBJ"),
                                     b"# exported by a CAD tool\n" + _exported("OBJ"),
                                     _exported("binary STL", header=b"solid part exported binary")])
def test_exports_that_look_odd_still_load(tmp_path, content):
    """A byte-order mark before an OBJ, comments first, a binary STL whose header starts with "solid" (as some CAD
    tools write it)."""
    path = tmp_path / ("fixture.stl" if content.startswith(b"solid") else "fixture.obj")
    path.write_bytes(content)
    assert len(load_fixture(path).mesh.faces) == len(SHAPES["l_prism"]().faces)


@pytest.mark.parametrize("spare_vertex", [False, True])
def test_an_obj_whose_first_vertex_follows_a_byte_order_mark_loads_as_its_surface(tmp_path, spare_vertex):
    """trimesh took the mark for part of the first line and lost its vertex: every face named the vertex after its
    own, refused as "index out of bounds", or, with a vertex to spare at the end, read as another surface; the
    check of polygon faces read the same wrong corners. Now the file's own box, and the warp of its quads."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    vertices = np.vstack([box.vertices, [[0.2, 0.2, 0.2]]]) if spare_vertex else np.asarray(box.vertices)
    path = tmp_path / "box.obj"
    path.write_bytes(b"\xef\xbb\xbf" + _obj_text(vertices, box.faces).encode())
    fixture = load_fixture(path)
    assert fixture.mesh.area == pytest.approx(box.area, rel=1e-12) and fixture.signed and fixture.warnings == ()
    warped = tmp_path / "warped.obj"
    warped.write_bytes(b"\xef\xbb\xbf" + polygons_obj(warped_box_vertices(), WARPED_BOX_QUADS).encode())
    assert load_fixture(warped).surface_offset_m == pytest.approx(0.001, rel=1e-3)


@pytest.mark.parametrize("line, changed", [(0, "  v "), (0, "v\t"), (8, "  f "), (8, "f\t")])
def test_an_obj_line_indented_or_with_a_tab_after_its_keyword_is_read(tmp_path, line, changed):
    """trimesh read a vertex or face only from a line starting with "v " or "f ": such a vertex was skipped (every
    later one moved up by one, the faces naming other corners: with a vertex to spare, a box read as 0.091 m2 of
    another surface), such a face left a hole. The file's own box now."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    lines = _obj_text(np.vstack([box.vertices, [[0.2, 0.2, 0.2]]]), box.faces).splitlines()
    lines[line + (line > 0)] = changed + lines[line + (line > 0)][1:].lstrip()
    path = tmp_path / "box.obj"
    path.write_text("\n".join(lines) + "\n")
    fixture = load_fixture(path)
    assert fixture.mesh.area == pytest.approx(box.area, rel=1e-12) and fixture.signed and fixture.warnings == ()


def test_an_obj_vertex_of_two_coordinates_is_refused(tmp_path):
    """trimesh read 'v 1 2' as some other point (the box's surface changed)."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    path = tmp_path / "box.obj"
    path.write_text(_obj_text(box.vertices, box.faces).replace("\nf ", "\nv 0.1 0.2\nf ", 1))
    with pytest.raises(MeshError, match=r"a vertex line with fewer than three coordinates \('v 0.1 0.2'\)"):
        load_fixture(path)


def _count_set(data: bytes, count: int) -> bytes:
    return data[:80] + count.to_bytes(4, "little") + data[84:]


@pytest.mark.parametrize("change", ["cut short", "bytes added", "no count, cut short", "count too large"])
def test_a_binary_stl_whose_size_does_not_fit_its_triangle_count_is_called_damaged(tmp_path, change):
    """An interrupted copy or bytes appended: it was refused as holding no triangles ("a point cloud or an empty
    model?"). A count of 0 fits only a whole number of triangles."""
    data = _exported("binary STL", header=b"solid part")
    count = len(SHAPES["l_prism"]().faces)
    path = tmp_path / "fixture.stl"
    path.write_bytes({"cut short": data[:-30], "bytes added": data + b"\0" * 7,
                      "no count, cut short": _count_set(data, 0)[:-30],
                      "count too large": _count_set(data, count + 3)}[change])
    with pytest.raises(MeshError, match="binary STL whose header announces .* triangles .* the file is cut short or "
                                        "has bytes added"):
        load_fixture(path)


def test_a_binary_stl_whose_header_counts_no_triangles_is_read_as_the_triangles_its_size_holds(tmp_path):
    """Some exporters write a count of 0 and leave it to the file's size: it was refused as cut short. Its triangles
    are exactly those of the same file with its count."""
    data = _exported("binary STL", header=b"solid part")
    counted, uncounted = tmp_path / "counted.stl", tmp_path / "uncounted.stl"
    counted.write_bytes(data)
    uncounted.write_bytes(_count_set(data, 0))
    expected, read = load_fixture(counted), load_fixture(uncounted)
    assert np.array_equal(read.mesh.vertices, expected.mesh.vertices)
    assert np.array_equal(read.mesh.faces, expected.mesh.faces)
    assert len(read.mesh.faces) == len(SHAPES["l_prism"]().faces) and read.warnings == expected.warnings


FLOAT32_FILES = {".stl": ("stl", "a binary STL"), ".ply": ("ply", "a PLY of float coordinates"),
                 "ascii .ply": ("ply_ascii", "a PLY of float coordinates")}


def _export_float32(mesh: trimesh.Trimesh, folder, kind: str):
    """``mesh`` exported as ``kind`` (a key of FLOAT32_FILES: float32 coordinates), its path."""
    file_type = FLOAT32_FILES[kind][0]
    path = folder / "plate.ply" if "ply" in file_type else folder / "plate.stl"
    path.write_bytes(mesh.export(file_type="ply", encoding="ascii") if file_type == "ply_ascii"
                     else mesh.export(file_type=file_type))
    return path


@pytest.mark.parametrize("kind", sorted(FLOAT32_FILES))
@pytest.mark.parametrize("offset, units", [(1000.0, "m"), (1e6, "mm"), (200.0, "m")])
def test_a_float32_mesh_too_far_from_its_origin_is_refused_naming_the_precision(tmp_path, offset, units, kind):
    """A binary STL holds float32 numbers (and trimesh reads a PLY's float coordinates as such, ASCII too): 0.06 mm
    apart at 1 km, where small faces collapse ("all faces zero area" named no cause) and the rest moved without a
    word. Beyond the finest sample bound (0.01 mm) it is refused."""
    plate = SHAPES["l_prism"]()
    plate.apply_scale(1e3 if units == "mm" else 1.0)
    plate.apply_translation([offset, 0.0, 0.0])
    path = _export_float32(plate, tmp_path, kind)
    spacing_mm = np.spacing(np.float32(offset + np.max(plate.extents))) * (1.0 if units == "mm" else 1e3)
    with pytest.raises(MeshError, match=rf"coordinates reach .* m from the file's origin, too far for the precision "
                                        rf"of the numbers of {FLOAT32_FILES[kind][1]} \(float32\): the file's "
                                        rf"precision there is {spacing_mm:.3g} mm.* Export the mesh again with its "
                                        "origin near the part"):
        load_fixture(path, units)


def test_a_millimetre_binary_stl_read_as_metres_is_a_unit_mistake_not_one_too_far_from_its_origin(tmp_path):
    """Its coordinates, read as metres, lie hundreds of metres out: the units are named, as for any such mesh."""
    plate = SHAPES["l_prism"]()
    plate.apply_scale(1e3)
    plate.apply_translation([300.0, 0.0, 0.0])
    path = tmp_path / "plate.stl"
    plate.export(path)
    with pytest.raises(MeshUnitsError, match="if the file is in millimetres, its units are mm"):
        load_fixture(path, "m")


@pytest.mark.parametrize("kind", sorted(FLOAT32_FILES))
@pytest.mark.parametrize("offset", [20.0, 100.0])
def test_a_float32_mesh_far_enough_from_its_origin_to_lose_precision_widens_the_bounds_and_says_so(tmp_path, offset,
                                                                                                   kind):
    """Between 16 and 128 m from the origin float32 numbers are 0.002-0.008 mm apart: a tenth or more of a fine sample
    bound, silently. The spacing is carried in the surface's offset (every vertex moved by half of it at most along
    each axis), and a warning says why; near the origin nothing is, nor in a PLY of double coordinates."""
    plate = SHAPES["l_prism"]()
    plate.apply_translation([offset, 0.0, 0.0])
    path = _export_float32(plate, tmp_path, kind)
    fixture = load_fixture(path)
    spacing_m = float(np.spacing(np.float32(np.max(np.abs(fixture.mesh.vertices)))))
    assert [code for code, _ in fixture.warnings] == ["mesh_float32_precision"]
    assert f"their precision there is {spacing_m * 1e3:.3g} mm" in fixture.warnings[0][1]
    assert fixture.surface_offset_m == spacing_m and fixture.oracle.surface_offset_m == spacing_m
    moved = np.abs(fixture.mesh.vertices[:, None, :] - plate.vertices[None, :, :]).max(axis=2).min(axis=1)
    assert moved.max() <= spacing_m / 2
    path.with_suffix(".ply").write_text(_ascii_ply(plate.vertices, plate.faces))  # double coordinates, as written
    assert load_fixture(path.with_suffix(".ply")).surface_offset_m == 0.0
    plate.apply_translation([-offset, 0.0, 0.0])
    path = _export_float32(plate, tmp_path, kind)
    assert load_fixture(path).warnings == () and load_fixture(path).surface_offset_m == 0.0


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj"])
def test_a_mesh_saved_again_while_it_loads_is_hashed_as_the_bytes_that_were_loaded(tmp_path, monkeypatch, suffix):
    """A CAD tool saving the mesh again while fixwizard reads it: the fixture's sha256 (the report's mesh_sha256, the
    session's) is that of the very bytes checked and loaded. Each check, the reader and the hash read the file anew,
    so the hash was of the file saved after the triangles were read: a report naming a mesh it was not solved on."""
    path = tmp_path / f"bracket{suffix}"
    first, second = (trimesh.creation.box(extents).export(file_type=suffix[1:])
                     for extents in ((0.1, 0.06, 0.04), (0.12, 0.06, 0.04)))
    first, second = (text.encode() if isinstance(text, str) else text for text in (first, second))
    path.write_bytes(first)
    read = trimesh.load

    def read_then_saved_again(*args, **kwargs):
        loaded = read(*args, **kwargs)
        path.write_bytes(second)
        return loaded

    monkeypatch.setattr(trimesh, "load", read_then_saved_again)
    fixture = load_fixture(path)
    assert path.read_bytes() == second  # the file was saved again while it loaded
    assert fixture.mesh.extents == pytest.approx([0.1, 0.06, 0.04])
    assert fixture.sha256 == hashlib.sha256(first).hexdigest()


def test_a_point_cloud_has_no_faces(tmp_path):
    path = tmp_path / "cloud.ply"
    trimesh.PointCloud(np.random.default_rng(0).random((50, 3)) * 0.1).export(path)
    with pytest.raises(MeshError, match="no triangles"):
        load_fixture(path)


def test_an_open_mesh_loads_with_a_warning_and_unsigned_distances(tmp_path):
    box = trimesh.creation.box((0.1, 0.1, 0.1))
    open_box = trimesh.Trimesh(box.vertices, box.faces[2:])
    path = tmp_path / "open.stl"
    open_box.export(path)
    fixture = load_fixture(path)
    assert [code for code, _ in fixture.warnings] == ["mesh_not_watertight"]
    assert not fixture.oracle.signed


def test_internal_frame_is_the_minimum_enclosing_ball_centre(tmp_path):
    path = tmp_path / "box.ply"
    trimesh.creation.box((0.1, 0.06, 0.02)).apply_translation([0.3, 0, 0]).export(path)
    fixture = load_fixture(path)
    assert fixture.cad_p_center == pytest.approx([0.3, 0, 0], abs=1e-7)  # PLY stores float32
    assert fixture.radius_m == pytest.approx(np.linalg.norm([0.05, 0.03, 0.01]), abs=1e-7)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_distance_intervals_hold_the_float64_brute_force_distance_and_name_a_nearest_face(name):
    fixture = as_fixture(name)
    rng = np.random.default_rng(1)
    near = touching_ball_centres(fixture.mesh, 300, 0.0015, rng) + rng.normal(size=(300, 3)) * 0.002
    far = fixture.mesh.bounds[0] + rng.random((300, 3)) * (fixture.mesh.extents * 1.5)
    points = np.vstack([near, far]) - fixture.cad_p_center
    exact = exact_distances_m(trimesh.Trimesh(fixture.fix_vertices_m, fixture.mesh.faces, process=False), points)
    low, high, faces = fixture.oracle.distance_interval_m(points, signed=np.zeros(len(points), bool))
    assert np.all(low <= exact + 1e-12) and np.all(exact <= high + 1e-12) and np.max(high - low) < 1e-9
    corners = fixture.fix_vertices_m[fixture.mesh.faces[faces]]
    on_face = closest_on_triangles(points, corners[:, 0], corners[:, 1], corners[:, 2])
    assert np.all(np.abs(np.linalg.norm(points - on_face, axis=1) - exact) <= 1e-12)


def test_signed_distance_is_negative_inside_a_closed_mesh():
    fixture = as_fixture("cube")
    points = np.array([[0.0, 0, 0], [0.0, 0, 0.05]])
    assert fixture.oracle.signed_distance_m(points) == pytest.approx([-0.03, 0.02], abs=1e-6)


def test_the_distance_of_base_frame_points_at_a_pose_is_their_distance_in_the_cad_frame():
    """``Fixture.signed_distance_at_m``: points given in the base frame with the CAD frame at ``base_T_cad``."""
    fixture = as_fixture("l_prism")
    base_T_cad = make_transform(Rotation.from_rotvec([0.3, -1.2, 2.0]), np.array([0.4, -0.1, 0.05]))
    rng = np.random.default_rng(9)
    cad_p_points = fixture.mesh.bounds[0] - 0.01 + rng.random((2000, 3)) * (fixture.mesh.extents + 0.02)
    base_p_points = transform_points(base_T_cad, cad_p_points)
    expected = fixture.oracle.signed_distance_m(cad_p_points - fixture.cad_p_center)
    assert np.any(expected < 0.0) and np.any(expected > 0.0)
    assert np.allclose(fixture.signed_distance_at_m(base_T_cad, base_p_points), expected, rtol=0.0, atol=1e-12)
    base_T_fix = fixture.base_T_fix(base_T_cad)
    assert np.allclose(transform_points(base_T_fix, cad_p_points - fixture.cad_p_center), base_p_points, atol=1e-15)
    assert np.allclose(fixture.oracle.signed_distance_at_m(base_T_fix, base_p_points), expected, rtol=0.0,
                       atol=1e-12)


def test_sign_is_right_where_ray_parity_fails():
    """Open3D's ray-parity occupancy calls this point, 3.7 mm below the L-plate, inside; it is outside."""
    fixture = as_fixture("l_prism")
    point = np.array([[-0.02890762, 0.02193329, -0.00873163]])
    assert fixture.oracle.signed_distance_m(point)[0] == pytest.approx(0.00373163, abs=1e-6)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_sign_agrees_with_the_exact_winding_number(name):
    import igl

    fixture = as_fixture(name)
    rng = np.random.default_rng(2)
    points = fixture.mesh.bounds[0] - 0.01 + rng.random((5000, 3)) * (fixture.mesh.extents + 0.02)
    points -= fixture.cad_p_center
    vertices = fixture.fix_vertices_m
    winding = igl.winding_number(vertices, np.asarray(fixture.mesh.faces, np.int64), points)
    assert np.array_equal(fixture.oracle.signed_distance_m(points) < 0.0, winding > 0.5)


def _obj_text(vertices: np.ndarray, faces: np.ndarray) -> str:
    """An OBJ file of the mesh with every digit of its vertices."""
    return "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist()) + "".join(
        f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)


def test_a_file_loads_with_its_own_surface_or_one_within_the_offset_the_bounds_carry(tmp_path):
    """A patch of faces whose shared corners a mesh in metres wrote 3 nm apart along each axis: whatever closes that
    crack, the distance intervals widened by ``surface_offset_m`` hold the distance to the file's own triangles
    (trimesh's merge of vertices up to 1e-8 of a unit apart moved them by 5 nm, uncounted)."""
    rng = np.random.default_rng(3)
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    vertices, faces = np.asarray(box.vertices), np.asarray(box.faces).copy()
    patch = np.flatnonzero(box.face_normals[:, 2] > 0.5)
    corners = np.unique(faces[patch])
    copies = vertices[corners] + rng.choice([-3e-9, 3e-9], size=(len(corners), 3))
    copy_of = np.arange(len(vertices))
    copy_of[corners] = len(vertices) + np.arange(len(corners))
    faces[patch] = copy_of[faces[patch]]
    file_vertices = np.vstack([vertices, copies])
    path = tmp_path / "cracked.obj"
    path.write_text(_obj_text(file_vertices, faces))
    fixture = load_fixture(path)
    cad_p_points = np.repeat(copies, 50, axis=0) + rng.normal(scale=0.002, size=(50 * len(copies), 3))
    low, high, _ = fixture.oracle.distance_interval_m(cad_p_points - fixture.cad_p_center,
                                                      np.zeros(len(cad_p_points), bool))
    file_triangles = file_vertices[faces]
    exact = exact_distances_m(trimesh.Trimesh(file_triangles.reshape(-1, 3), np.arange(3 * len(faces)).reshape(-1, 3),
                                              process=False), cad_p_points)
    assert np.all(low - fixture.surface_offset_m <= exact)
    assert np.all(exact <= high + fixture.surface_offset_m)


def test_an_ascii_stl_writing_minus_zero_at_some_corners_loads_as_one_closed_surface(tmp_path):
    """An exporter that writes a zero coordinate as '-0' in some facets and '0' in others gives the same corner two
    spellings of one number (two bit patterns): they are merged as identical coordinates, not left as two vertices
    (the box would come back open at its edges, with a warning about cracks closed)."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    corners = (box.vertices - box.bounds[0])[box.faces]  # every corner has a zero coordinate or more
    facets = []
    for number, triangle in enumerate(corners):
        zero = "-0" if number % 2 else "0"
        lines = ["  vertex " + " ".join(zero if value == 0.0 else repr(value) for value in corner)
                 for corner in triangle.tolist()]
        facets.append("facet normal 0 0 0\n outer loop\n" + "\n".join(lines) + "\n endloop\nendfacet\n")
    path = tmp_path / "box.stl"
    path.write_text("solid box\n" + "".join(facets) + "endsolid box\n")
    fixture = load_fixture(path)
    assert len(fixture.mesh.vertices) == 8 and fixture.signed and fixture.surface_offset_m == 0.0
    assert fixture.warnings == ()


def test_corners_whose_sort_keys_collide_are_still_merged_only_where_identical(tmp_path, monkeypatch):
    """Corners are grouped by a 64-bit key of their coordinates; where two different corners share a key (every key
    made the same here) they are told apart by their coordinates, and the surface loads as it does otherwise."""
    path = tmp_path / "part.stl"
    SHAPES["cylinder"]().export(path)
    expected = load_fixture(path)
    monkeypatch.setattr(fixture_module, "_point_keys", lambda bits: np.zeros(len(bits), np.uint64))
    collided = load_fixture(path)
    assert np.array_equal(collided.mesh.vertices, expected.mesh.vertices)
    assert np.array_equal(collided.mesh.faces, expected.mesh.faces)


def test_the_corners_of_a_float32_export_get_a_key_each():
    """Coordinates read from a binary STL's float32 numbers share their low 29 bits: the keys still tell every
    corner apart (a key made by multiplying alone did not, and every large STL fell back to the slow sort)."""
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=0.05)
    corners = np.unique(sphere.vertices.astype(np.float32).astype(np.float64), axis=0)
    corners = np.vstack([corners, corners * 1e-3, corners + 1.0])
    keys = fixture_module._point_keys(np.ascontiguousarray(corners).view(np.uint64))
    assert len(np.unique(keys)) == len(corners)


@pytest.mark.parametrize("objects", [1, 2])
def test_an_obj_with_texture_coordinates_and_materials_loads_as_its_closed_surface(tmp_path, objects):
    """CAD tools and Blender write texture coordinates (``f v/vt``, a texture seam at every face here), materials
    and several objects into an OBJ: the surface loads whole, closed and signed, with no crack to close (it was
    refused: trimesh needs Pillow to copy a textured mesh)."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    faces = [f"f {a + 1}/{3 * row + 1} {b + 1}/{3 * row + 2} {c + 1}/{3 * row + 3}"
             for row, (a, b, c) in enumerate(box.faces.tolist())]
    half = len(faces) // objects
    lines = ["mtllib fixture.mtl", *(f"v {x!r} {y!r} {z!r}" for x, y, z in box.vertices.tolist()),
             *(f"vt {row / 40} {row % 7 / 7}" for row in range(3 * len(faces)))]
    for start in range(0, len(faces), half):
        lines += [f"o part_{start}", "usemtl steel", *faces[start:start + half]]
    path = tmp_path / "fixture.obj"
    path.write_text("\n".join(lines) + "\n")
    fixture = load_fixture(path)
    assert len(fixture.mesh.vertices) == 8 and len(fixture.mesh.faces) == 12
    assert fixture.signed and fixture.warnings == () and fixture.surface_offset_m == 0.0


L_OUTLINE = [[0, 0], [0.12, 0], [0.12, 0.03], [0.05, 0.03], [0.05, 0.06], [0.035, 0.06], [0.035, 0.08], [0, 0.08]]


def _prism_obj(outline: list[list[float]], caps: list[list[int]]) -> str:
    """An OBJ of the outline extruded 10 mm: each cap polygon (corner numbers of the outline, counter-clockwise)
    once at the bottom (turned) and once at the top, and one quad per side, as Blender writes it untriangulated."""
    count = len(outline)
    lines = [f"v {x} {y} {z}" for z in (0.0, 0.01) for x, y in outline]
    lines += ["f " + " ".join(str(corner + 1) for corner in reversed(cap)) for cap in caps]
    lines += ["f " + " ".join(str(count + corner + 1) for corner in cap) for cap in caps]
    lines += [f"f {k + 1} {(k + 1) % count + 1} {count + (k + 1) % count + 1} {count + k + 1}" for k in range(count)]
    return "\n".join(lines) + "\n"


def test_an_obj_with_a_concave_polygon_face_is_refused_with_the_fix(tmp_path):
    """The L-plate's caps as one 8-corner polygon each: trimesh cuts a polygon into a fan from its first corner,
    whose triangles cover the notch (a surface the part does not have, 1.4 mm from true taps); it was loaded so."""
    path = tmp_path / "plate.obj"
    path.write_text(_prism_obj(L_OUTLINE, [list(range(8))]))
    with pytest.raises(MeshError, match="line 17 is a polygon of 8 corners that is not convex.*Triangulate Faces"):
        load_fixture(path)


def test_a_concave_polygon_face_in_a_file_with_windows_line_ends_is_refused(tmp_path):
    """CAD tools on Windows end lines with CR LF: the check of polygon faces skipped every line that ended so (its
    pattern wanted the line's end right after the last corner), and the L-plate loaded with its notch covered."""
    path = tmp_path / "plate.obj"
    path.write_bytes(_prism_obj(L_OUTLINE, [list(range(8))]).replace("\n", "\r\n").encode())
    with pytest.raises(MeshError, match="line 17 is a polygon of 8 corners that is not convex"):
        load_fixture(path)


@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_a_concave_polygon_face_continued_on_the_next_line_is_refused_too(tmp_path, newline):
    """OBJ lets a backslash continue a line, and trimesh joins them: the L-plate's caps, each written over two lines,
    passed the check line by line (no line a polygon of integers) and loaded with the notch covered."""
    lines = []
    for line in _prism_obj(L_OUTLINE, [list(range(8))]).splitlines():
        words = line.split()
        lines += [" ".join(words[:4]) + " \\", " " + " ".join(words[4:])] if len(words) > 5 else [line]
    path = tmp_path / "plate.obj"
    path.write_bytes(newline.join(lines).encode() + newline.encode())
    with pytest.raises(MeshError, match="line 17 is a polygon of 8 corners that is not convex"):
        load_fixture(path)


def test_an_obj_of_convex_polygons_loads_as_its_surface(tmp_path):
    """The same L-plate with each cap cut into convex polygons (a pentagon with a straight corner, two quads) loads
    with the plate's own area and volume."""
    outline = [*L_OUTLINE, [0.0, 0.03]]  # corner 8 on the left side; 3 is a straight corner of the first piece
    caps = [[0, 1, 2, 3, 8], [8, 3, 4, 5], [8, 5, 6, 7]]
    path = tmp_path / "plate.obj"
    path.write_text(_prism_obj(outline, caps))
    fixture = load_fixture(path)
    assert fixture.mesh.area == pytest.approx(SHAPES["l_prism"]().area, rel=1e-12)
    assert fixture.mesh.volume == pytest.approx(SHAPES["l_prism"]().volume, rel=1e-12)
    assert fixture.warnings == () and fixture.surface_offset_m < 1e-15  # flat: only the rounding of their planes


def test_an_obj_with_a_star_polygon_face_is_refused_with_the_fix(tmp_path):
    """A pentagram turns the same way at every corner, so it passed as convex; it goes twice round, and the fan
    trimesh cuts it into covers the points between its tips (a surface the part does not have)."""
    angles = np.pi / 2 + 2 * np.pi * np.arange(5) / 5
    corners = 0.05 * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(5)])
    path = tmp_path / "star.obj"
    path.write_text(polygons_obj(corners, np.array([[0, 2, 4, 1, 3]])))
    with pytest.raises(MeshError, match="line 6 is a polygon of 5 corners that is not convex.*Triangulate Faces"):
        load_fixture(path)


@pytest.mark.parametrize("raise_m", [0.002, 2e-5])
def test_polygon_faces_that_are_not_flat_widen_the_surface_offset_to_hold_every_way_across_them(tmp_path, raise_m):
    """A box whose top corner at +x +y is raised, its top and two sides quads that are not flat: trimesh cuts each
    along one diagonal, the part may be cut along the other (or curved between them), up to 1 mm off for a corner
    raised by 2 mm. The offset every tap's band is widened by holds that surface, and is said (it was 0: the true
    pose was lost in 7 of 8 descents, ``test_guarantee_features``)."""
    vertices = warped_box_vertices(raise_m)
    path = tmp_path / "warped.obj"
    path.write_text(polygons_obj(vertices, WARPED_BOX_QUADS))
    fixture = load_fixture(path)
    other = across_other_diagonals(vertices, WARPED_BOX_QUADS)
    points = other.sample(2000, seed=1)
    fan_distances = exact_distances_m(fixture.mesh, points)
    assert fan_distances.max() > 0.9 * raise_m / 2  # the two surfaces are that far apart
    assert np.all(fan_distances <= fixture.surface_offset_m) and fixture.surface_offset_m <= 0.51 * raise_m
    assert [code for code, _ in fixture.warnings] == ["mesh_polygons_warped"]
    assert f"may lie up to {raise_m / 2 * 1e3:.3g} mm from the part's surface" in fixture.warnings[0][1]


@pytest.mark.parametrize("encoding", ["ascii", "binary"])
def test_a_ply_with_a_concave_polygon_face_is_refused_with_the_fix(tmp_path, encoding):
    """PLY faces are cut into fans the same way: the L-plate's cap as one 8-corner polygon (binary PLY: every face
    such a polygon, the only kind trimesh reads) is refused naming the face."""
    vertices = np.array([[x, y, z] for z in (0.0, 0.01) for x, y in L_OUTLINE], np.float32)
    faces = [list(range(8))[::-1], list(range(8, 16))]
    header = (f"ply\nformat {'ascii' if encoding == 'ascii' else 'binary_little_endian'} 1.0\nelement vertex 16\n"
              "property float x\nproperty float y\nproperty float z\nelement face 2\n"
              "property list uchar int vertex_indices\nend_header\n").encode()
    if encoding == "ascii":
        body = "".join(" ".join(map(str, row)) + "\n" for row in vertices.tolist())
        body += "".join(f"8 {' '.join(map(str, face))}\n" for face in faces)
        content = header + body.encode()
    else:
        content = header + vertices.tobytes() + b"".join(
            np.uint8(8).tobytes() + np.array(face, "<i4").tobytes() for face in faces)
    path = tmp_path / "plate.ply"
    path.write_bytes(content)
    with pytest.raises(MeshError, match="face number 1 is a polygon of 8 corners that is not convex"):
        load_fixture(path)


@pytest.mark.parametrize("corner", [7, -1])
def test_a_ply_face_naming_a_vertex_the_file_does_not_have_is_refused(tmp_path, corner):
    """A PLY counts vertices from 0: a corner past the last one ended in an IndexError traceback, and -1 was read
    as the last vertex without a word."""
    path = tmp_path / "part.ply"
    path.write_text("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n0.1 0 0\n0 0.1 0\n"
                    f"0 0 0.1\n3 0 1 2\n3 0 1 {corner}\n")
    with pytest.raises(MeshError, match=f"face 2 names vertex {corner}, but the file has 4 vertices, numbered from 0"):
        load_fixture(path)


@pytest.mark.parametrize("face", ["f 0 1 2", "f 1 2 0/1/1", "f -0 1 2\r", "f 1 2 \\\n 0"])
def test_an_obj_face_naming_vertex_zero_is_refused(tmp_path, face):
    """OBJ counts vertices from 1: trimesh read a 0 as another vertex and dropped one without a word."""
    path = tmp_path / "part.obj"
    path.write_text(f"v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\n{face}\nf 1 2 3 # 0 in a comment is no corner\n")
    with pytest.raises(MeshError, match="the face on line 5 names vertex 0, which an OBJ file does not have"):
        load_fixture(path)


def _comment_after_each(text: str, keyword: str, comment: str) -> str:
    return "".join(line + comment + "\n" if line.startswith(keyword + " ") else line + "\n"
                   for line in text.splitlines())


OBJ_OLD_SPELLINGS = {"a comment after each face": lambda text: _comment_after_each(text, "f", " # facet 5 6"),
                     "a comment after each vertex": lambda text: _comment_after_each(text, "v", "  # corner 7"),
                     "a comment right after the numbers": lambda text: _comment_after_each(text, "f", "#0 1"),
                     "CR line ends (old Mac)": lambda text: text.replace("\n", "\r"),
                     "CR line ends and comments": lambda text: _comment_after_each(text, "f", " # 2").replace("\n",
                                                                                                             "\r")}


@pytest.mark.parametrize("spelling", sorted(OBJ_OLD_SPELLINGS))
def test_an_obj_with_comments_after_its_numbers_or_old_mac_line_ends_loads_as_the_same_file_without(tmp_path,
                                                                                                  spelling):
    """trimesh's OBJ reader took a comment after a face's corners or a vertex's numbers for more numbers, and a file
    whose lines end with CR alone for one line: refused in numpy's words ("could not be read to its end"), with
    numpy before 2.3 numbers cut short. Now exactly the vertices and faces of the file without them."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    text = _obj_text(np.vstack([box.vertices, [[0.2, 0.2, 0.2]]]), box.faces)
    (tmp_path / "clean.obj").write_text(text)
    (tmp_path / "box.obj").write_bytes(OBJ_OLD_SPELLINGS[spelling](text).encode())
    clean, read = load_fixture(tmp_path / "clean.obj"), load_fixture(tmp_path / "box.obj")
    assert np.array_equal(read.mesh.vertices, clean.mesh.vertices) and np.array_equal(read.mesh.faces, clean.mesh.faces)
    assert read.signed and read.warnings == ()


@pytest.mark.parametrize("spelling", ["a comment after each face", "CR line ends (old Mac)"])
def test_a_concave_polygon_face_with_a_comment_or_old_mac_line_ends_is_refused_naming_its_line(tmp_path, spelling):
    """The check of polygon faces reads the lines as the reader does: a comment after the corners made them no
    polygon of numbers to it, and CR alone made the file one line."""
    path = tmp_path / "plate.obj"
    path.write_bytes(OBJ_OLD_SPELLINGS[spelling](_prism_obj(L_OUTLINE, [list(range(8))])).encode())
    with pytest.raises(MeshError, match="line 17 is a polygon of 8 corners that is not convex"):
        load_fixture(path)


def _ascii_ply(vertices: np.ndarray, faces: np.ndarray, element: str = "face") -> str:
    """An ASCII PLY of the mesh, its faces (or triangle strips: ``element``) as lists of corners."""
    header = (f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty double x\nproperty double y\n"
              f"property double z\nelement {element} {len(faces)}\nproperty list uchar int vertex_indices\n"
              "end_header\n")
    return header + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in vertices.tolist()) + "".join(
        f"{len(face)} {' '.join(map(str, face))}\n" for face in faces.tolist())


DECIMAL_COMMA = "writes its numbers with a decimal comma .* Export the mesh again with decimal points"


def _ascii_stl(vertices: np.ndarray, faces: np.ndarray) -> str:
    return trimesh.Trimesh(vertices, faces, process=False).export(file_type="stl_ascii")


MESH_TEXTS = {".obj": _obj_text, ".ply": _ascii_ply, ".stl": _ascii_stl}


@pytest.mark.parametrize("suffix, line", [(".obj", 4), (".ply", 13), (".stl", 11)])
def test_numbers_with_a_decimal_comma_are_refused_naming_the_line(tmp_path, suffix, line):
    """A German-locale exporter writes 'v 1,5 2,0 3,0': refused in numpy's words, naming no line (with numpy before
    2.3 read as other numbers). Not read as decimals either: '1,500' may be fifteen hundred."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    text = MESH_TEXTS[suffix](box.vertices, box.faces)
    lines = text.splitlines()
    lines[line - 1] = lines[line - 1].replace(".", ",")
    path = tmp_path / f"box{suffix}"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MeshError, match=f"box{suffix}: line {line} \\('(v |vertex )?[-0-9, ]+'\\) {DECIMAL_COMMA}"):
        load_fixture(path)


@pytest.mark.parametrize("suffix, line", [(".obj", 4), (".ply", 13), (".stl", 11)])
@pytest.mark.parametrize("word", ["1.#QNAN", "-1.#IND", "1.#INF00", "-nan(ind)"])
def test_nan_as_microsofts_c_library_writes_it_is_refused_as_not_finite_naming_the_line(tmp_path, suffix, line, word):
    """Old exporters built with Microsoft's C library write NaN as '1.#QNAN': in an OBJ its '#' starts a comment,
    and the line was refused as 'v 1.', a vertex of too few coordinates; elsewhere as a word that is no number.
    (numpy's PLY reader reads '-nan(ind)' as NaN: that vertex is refused as not finite.)"""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    lines = MESH_TEXTS[suffix](box.vertices, box.faces).splitlines()
    words = lines[line - 1].split()
    lines[line - 1] = " ".join(words[:-3] + [word] + words[-2:])
    path = tmp_path / f"box{suffix}"
    path.write_text("\n".join(lines) + "\n")
    named = (re.escape(f"box{suffix}: line {line} ({lines[line - 1]!r}) holds a number that is not finite ({word!r}: "
                       "NaN or infinity, as Microsoft's C library writes them)"),
             re.escape(f"box{suffix} has 1 vertices that are not finite numbers (NaN or infinity; the first is vertex"))
    with pytest.raises(MeshError, match=named[1] if (suffix, word) == (".ply", "-nan(ind)") else named[0]):
        load_fixture(path)
    lines[line - 1] = " ".join(words) + (f" # was {word}" if suffix == ".obj" else "")
    path.write_text("\n".join(lines) + "\n")
    assert len(load_fixture(path).mesh.faces) == 12


@pytest.mark.parametrize("line", ["v 0.1 0.2 x", "vn 0,1 0 1", "f 1 2 3/x"])
def test_an_obj_line_with_a_word_that_is_no_number_is_refused_naming_it(tmp_path, line):
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    path = tmp_path / "box.obj"
    path.write_text(_obj_text(box.vertices, box.faces) + line + "\n")
    with pytest.raises(MeshError, match=f"box.obj: line 21 \\('{line}'\\) (holds a word that is no number|writes)"):
        load_fixture(path)


@pytest.mark.parametrize("faces_too", [False, True])
def test_a_ply_of_triangle_strips_is_refused_with_the_fix(tmp_path, faces_too):
    """trimesh reads faces, not strips: a PLY of strips loaded as a point cloud ("holds no triangles"), and strips
    beside faces were left out without a word (a surface with holes)."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    strips = np.array([[0, 1, 2, 3]]) if not faces_too else box.faces[:1]
    text = _ascii_ply(box.vertices, strips, "tristrips")
    if faces_too:
        text = text.replace("end_header", "element face 11\nproperty list uchar int vertex_indices\nend_header") + \
            "".join(f"3 {a} {b} {c}\n" for a, b, c in box.faces[1:].tolist())
    path = tmp_path / "strips.ply"
    path.write_text(text)
    with pytest.raises(MeshError, match="strips.ply: it holds triangle strips .* export the mesh with faces"):
        load_fixture(path)


@pytest.mark.parametrize("line_end", ["\r", "\r\n"])
def test_an_ascii_stl_with_old_mac_or_windows_line_ends_loads_as_the_same_file_with_lf(tmp_path, line_end):
    """trimesh's reader took each vertex's numbers up to the next LF: with CR alone a facet's 'endloop' and 'facet
    normal' were read as numbers (numpy's words; with numpy before 2.3, the numbers cut short)."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    text = _ascii_stl(box.vertices, box.faces)
    (tmp_path / "clean.stl").write_text(text)
    (tmp_path / "box.stl").write_text(text.replace("\n", line_end), newline="")
    clean, read = load_fixture(tmp_path / "clean.stl"), load_fixture(tmp_path / "box.stl")
    assert np.array_equal(read.mesh.vertices, clean.mesh.vertices) and np.array_equal(read.mesh.faces, clean.mesh.faces)


@pytest.mark.parametrize("name", ["vertex 0.5 0 0 0 0.5 0 0 0 0.5", "bracket with vertex markers", "endsolid part",
                                  "Part1 (vertex)"])
def test_an_ascii_stl_solid_name_is_free_text_and_the_surface_is_the_files(tmp_path, name):
    """trimesh's reader looked for 'vertex' and 'endsolid' in the name: the first gained a triangle without a word
    (13 faces, open), the others were refused in the reader's words ('unmatched data', '`endsolid` precedes
    `solid`!')."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    lines = _ascii_stl(box.vertices, box.faces).splitlines()
    lines[0], lines[-1] = f"solid {name}", f"endsolid {name}"
    path = tmp_path / "box.stl"
    path.write_text("\n".join(lines) + "\n")
    fixture = load_fixture(path)
    assert len(fixture.mesh.faces) == 12 and fixture.mesh.area == pytest.approx(box.area, rel=1e-12)
    assert fixture.signed and fixture.warnings == ()


def test_a_ply_whose_header_ends_its_lines_with_cr_alone_is_refused_with_the_fix(tmp_path):
    """trimesh read such a header as one line: "list index out of range"."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    path = tmp_path / "box.ply"
    path.write_text(_ascii_ply(box.vertices, box.faces).replace("\n", "\r"))
    with pytest.raises(MeshError, match="box.ply: its header's lines end with a carriage return alone"):
        load_fixture(path)


def _objects_obj(meshes: list[trimesh.Trimesh], counted_back: bool) -> str:
    """An OBJ of the meshes object by object, each its vertices then its faces; corners counted back from the
    vertices before the face (``f -8 -6 -7``), or numbered from the file's first vertex."""
    text, offset = "", 0
    for number, mesh in enumerate(meshes):
        text += f"o part_{number}\n" + "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in mesh.vertices.tolist())
        text += "".join("f " + " ".join(str(corner - len(mesh.vertices) if counted_back else offset + corner + 1)
                                         for corner in face) + "\n" for face in mesh.faces.tolist())
        offset += len(mesh.vertices)
    return text


def test_an_obj_whose_corners_count_back_loads_as_its_own_surface(tmp_path):
    """OBJ counts a negative corner back from the vertices before its line; trimesh counted back from the file's last
    vertex, so a box and a cube written object by object loaded as the cube twice (0.0024 m2 of 0.024), with only a
    warning that repeated faces were dropped. A corner counted back past the first vertex is refused naming its line
    (it was "index -9 is out of bounds")."""
    cube = trimesh.creation.box((0.02, 0.02, 0.02))
    cube.apply_translation([0.2, 0.0, 0.0])
    meshes = [trimesh.creation.box((0.1, 0.06, 0.03)), cube]
    (tmp_path / "numbered.obj").write_text(_objects_obj(meshes, counted_back=False))
    (tmp_path / "counted.obj").write_text(_objects_obj(meshes, counted_back=True))
    numbered, counted = load_fixture(tmp_path / "numbered.obj"), load_fixture(tmp_path / "counted.obj")
    assert numbered.mesh.area == pytest.approx(0.024, rel=1e-12)
    assert np.array_equal(counted.mesh.vertices, numbered.mesh.vertices)
    assert np.array_equal(counted.mesh.faces, numbered.mesh.faces)
    path = tmp_path / "past.obj"
    path.write_text(_objects_obj(meshes[:1], counted_back=True).replace("f -1 ", "f -9 ", 1))
    with pytest.raises(MeshError, match=r"past.obj: the face on line \d+ \('f -9 .*'\) counts back past the first"):
        load_fixture(path)


@pytest.mark.parametrize("damage, problem", [
    (lambda text: text[:-30], r"its header announces 12 face lines, and it holds 9 \(cut short"),
    (lambda text: text.rstrip("\n").rsplit(" ", 1)[0] + "\n", "line 29 does not hold the face values its header"),
    (lambda text: text + "3 0 1 2\n", r"line 30 and those after it are more than its header announces \(two files"),
])
def test_an_ascii_ply_cut_short_or_with_lines_added_is_refused_naming_the_line(tmp_path, damage, problem):
    """trimesh read the rows an ASCII PLY holds, not those its header announces: a file cut short by an interrupted
    copy loaded without its last faces (an open mesh, solved with the unsigned distance), and lines after the
    announced ones (two files joined) were left out, without a word."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    path = tmp_path / "box.ply"
    path.write_text(damage(_ascii_ply(box.vertices, box.faces)))
    with pytest.raises(MeshError, match=f"box.ply: {problem}"):
        load_fixture(path)


@pytest.mark.parametrize("solids", [1, 2])
@pytest.mark.parametrize("cut", ["before endsolid", "inside a facet"])
def test_an_ascii_stl_cut_short_is_refused_naming_the_solid_it_cuts(tmp_path, solids, cut):
    """trimesh's reader leaves out a solid with no 'endsolid': one cut short was said to hold no triangles ("a point
    cloud or an empty model?"), and the second of two solids was left out without a word."""
    box = trimesh.creation.box((0.1, 0.06, 0.03))
    text = _ascii_stl(box.vertices, box.faces) * solids
    text = text[:text.rfind("endsolid")] if cut == "before endsolid" else text[:text.rfind("endfacet")]
    path = tmp_path / "box.stl"
    path.write_text(text)
    line = 1 + (solids - 1) * len(_ascii_stl(box.vertices, box.faces).splitlines())
    with pytest.raises(MeshError, match=f"box.stl: the solid that starts on line {line} has no 'endsolid' after it"):
        load_fixture(path)


def _binary_ply(vertices: np.ndarray, faces: list[list[int]], order: str = "<") -> bytes:
    """A binary PLY (``order``: '<' little, '>' big endian) of float vertices and faces of any corner counts."""
    endian = "little" if order == "<" else "big"
    header = (f"ply\nformat binary_{endian}_endian 1.0\nelement vertex {len(vertices)}\nproperty float x\n"
              f"property float y\nproperty float z\nelement face {len(faces)}\nproperty list uchar int vertex_indices\n"
              "end_header\n").encode()
    return header + np.asarray(vertices, f"{order}f4").tobytes() + b"".join(
        bytes([len(face)]) + np.asarray(face, f"{order}i4").tobytes() for face in faces)


@pytest.mark.parametrize("order", ["<", ">"])
def test_a_binary_ply_of_triangles_and_quads_or_damaged_is_refused_saying_why(tmp_path, order):
    """trimesh's binary PLY reader takes every face as long as the first, and refused all three as "PLY is unexpected
    length!" (and "check that it is an STL, PLY or OBJ export"): a box as Blender writes it untriangulated, cut short
    by a copy, and with bytes after its data. The same box of quads alone loads."""
    vertices = np.array([[0, 0, 0], [0.1, 0, 0], [0.1, 0.06, 0], [0, 0.06, 0], [0, 0, 0.03], [0.1, 0, 0.03],
                         [0.1, 0.06, 0.03], [0, 0.06, 0.03]])
    quads = WARPED_BOX_QUADS.tolist()
    path = tmp_path / "box.ply"
    path.write_bytes(_binary_ply(vertices, quads, order))
    assert load_fixture(path).mesh.area == pytest.approx(0.0216, rel=1e-6)
    mixed = [[0, 3, 2], [0, 2, 1], *quads[1:]]
    damaged = {_binary_ply(vertices, mixed, order): "its faces have different numbers of corners (triangles and quads)",
               _binary_ply(vertices, quads, order)[:-10]: "it ends inside face 6 of the 6 its header announces",
               _binary_ply(vertices, quads, order) + bytes(17): "it holds 17 bytes after the data its header announces"}
    for data, problem in damaged.items():
        path.write_bytes(data)
        with pytest.raises(MeshError, match=re.escape(f"box.ply: {problem}")):
            load_fixture(path)
