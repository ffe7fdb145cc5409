"""Terminal pictures of a solve: Mollweide maths, the rotation map with its close-ups, and the taps top view.

Pictures are read back the way a person reads them: braille characters are decoded into dots
(by the Unicode braille layout, independently of the canvas), labels are found as text.
"""

import dataclasses
import re

import numpy as np
import pytest
import trimesh
from healpy.projector import MollweideProj
from scipy.spatial.transform import Rotation

from fixwizard.demo import DEMO_TAPS, demo_fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.plots import (
    Picture,
    RotationSet,
    rotation_map,
    rotation_map_for_solution,
    rotation_set_from_solution,
    taps_view,
    taps_view_for_solution,
)
from fixwizard.plots.canvas import BrailleCanvas, spots_beside, spots_on
from fixwizard.plots.mollweide import auxiliary_angle, direction_xy, mollweide_xy
from fixwizard.plots.rotation_map import mollweide_panel, zoom_coordinates_deg
from fixwizard.plots.scale import round_length
from fixwizard.points import load_points
from fixwizard.solver.solve import solve

SQRT2 = np.sqrt(2.0)
# Unicode braille: dot (x, y) of a cell (x 0..1 rightwards, y 0..3 downwards) and its bit.
BRAILLE_DOT_BITS = {(0, 0): 0x01, (0, 1): 0x02, (0, 2): 0x04, (1, 0): 0x08, (1, 1): 0x10, (1, 2): 0x20,
                    (0, 3): 0x40, (1, 3): 0x80}


def is_braille(char: str) -> bool:
    return 0x2800 <= ord(char) <= 0x28FF


def dots(picture: Picture, style: str | None = None, rows: range | None = None) -> set[tuple[int, int]]:
    """Picture-wide dot coordinates (x right, y down) of braille cells, optionally of one style and rows only."""
    found = set()
    for row in rows if rows is not None else range(picture.height):
        for col, char in enumerate(picture.rows[row]):
            if is_braille(char) and (style is None or picture.styles[row][col] == style):
                found |= {(2 * col + x, 4 * row + y) for (x, y), bit in BRAILLE_DOT_BITS.items()
                          if (ord(char) - 0x2800) & bit}
    return found


def find(picture: Picture, text: str, columns: range | None = None) -> list[tuple[int, int]]:
    """(row, col) of every occurrence of a text as a whole token: between spaces, braille or the edges."""
    pattern = re.compile(rf"(?<![^\s\u2800-\u28ff]){re.escape(text)}(?![^\s\u2800-\u28ff])")
    return [(row, match.start()) for row, line in enumerate(picture.rows) for match in pattern.finditer(line)
            if columns is None or match.start() in columns]


def assert_plain_and_sized(picture: Picture, width: int, height: int) -> None:
    assert picture.height == height and len(picture.styles) == height
    assert all(len(row) == width for row in picture.rows)
    assert all(len(styles) == width for styles in picture.styles)
    assert all(32 <= ord(char) < 127 or is_braille(char) for char in "".join(picture.rows)), picture.text
    assert "\x1b" not in picture.text


def rotation_set(base_R_cad: Rotation, mode_index=None, mode_base_R_cad: Rotation | None = None) -> RotationSet:
    mode_index = np.zeros(len(base_R_cad), int) if mode_index is None else np.asarray(mode_index)
    mode_base_R_cad = base_R_cad[:1] if mode_base_R_cad is None else mode_base_R_cad
    return RotationSet(base_R_cad, mode_index, mode_base_R_cad)


# --- Mollweide projection -------------------------------------------------------------------------


def test_the_auxiliary_angle_solves_the_mollweide_equation_everywhere():
    latitudes = np.concatenate([np.linspace(-np.pi / 2, np.pi / 2, 2001), np.pi / 2 - np.logspace(-9, -1, 50)])
    theta = auxiliary_angle(latitudes)
    assert np.max(np.abs(2 * theta + np.sin(2 * theta) - np.pi * np.sin(latitudes))) < 1e-12
    assert np.all(np.diff(theta[:2001]) > 0)
    assert auxiliary_angle(np.array([0.0, np.pi / 2, -np.pi / 2])) == pytest.approx([0.0, np.pi / 2, -np.pi / 2])


@pytest.mark.parametrize("latitude_deg, longitude_deg, expected_xy", [
    (0, 0, (0, 0)),  # centre
    (90, 37, (0, SQRT2)),  # north pole, whatever the longitude
    (-90, -120, (0, -SQRT2)),  # south pole
    (0, 180, (2 * SQRT2, 0)),  # right end of the equator
    (0, -180, (-2 * SQRT2, 0)),  # left end
    (0, 90, (SQRT2, 0)),  # halfway along the equator
])
def test_known_points_land_on_the_textbook_positions(latitude_deg, longitude_deg, expected_xy):
    x, y = mollweide_xy(np.radians([latitude_deg]), np.radians([longitude_deg]))
    assert (x[0], y[0]) == pytest.approx(expected_xy, abs=1e-12)


def test_healpys_closed_form_inverse_recovers_every_direction():
    """The inverse needs no iteration (healpy's ``xy2vec``); its map is ours scaled to unit height and
    mirrored (astronomers put east on the left). Directions near the poles are included."""
    rng = np.random.default_rng(0)
    directions = np.vstack([rng.normal(size=(500, 3)), [[0.3, 0.4, 1e4], [-0.2, 0.1, -1e5]]])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    xy = direction_xy(directions)
    recovered = np.stack(MollweideProj().xy2vec(-xy[:, 0] / SQRT2, xy[:, 1] / SQRT2), axis=1)
    assert recovered == pytest.approx(directions, abs=1e-9)


def test_uniform_directions_fill_equal_area_bins_evenly():
    count = 400_000
    directions = np.random.default_rng(1).normal(size=(count, 3))
    xy = direction_xy(directions)
    assert np.all(xy[:, 0] ** 2 / 8 + xy[:, 1] ** 2 / 2 <= 1 + 1e-12)  # inside the ellipse x^2/8 + y^2/2 = 1
    edges_x, edges_y = np.linspace(-2 * SQRT2, 2 * SQRT2, 17), np.linspace(-SQRT2, SQRT2, 9)
    counts = np.histogram2d(xy[:, 0], xy[:, 1], [edges_x, edges_y])[0]
    corner_x, corner_y = np.meshgrid(edges_x, edges_y, indexing="ij")
    corner_inside = corner_x**2 / 8 + corner_y**2 / 2 <= 1
    whole = corner_inside[:-1, :-1] & corner_inside[1:, :-1] & corner_inside[:-1, 1:] & corner_inside[1:, 1:]
    bin_area = (edges_x[1] - edges_x[0]) * (edges_y[1] - edges_y[0])
    expected = count * bin_area / (4 * np.pi)  # the ellipse's area equals the sphere's, 4 pi
    assert np.count_nonzero(whole) >= 60
    assert np.all(np.abs(counts[whole] - expected) < 5 * np.sqrt(expected))


# --- Rotation map ---------------------------------------------------------------------------------


def map_lines(picture: Picture) -> tuple[int, int]:
    """Row of the equator (the row with most braille) and column of the central meridian."""
    braille = np.array([[is_braille(char) for char in row] for row in picture.rows])
    return int(np.argmax(braille.sum(axis=1))), int(np.argmax(braille.sum(axis=0)))


def test_a_known_rotation_puts_its_axes_where_they_point():
    """CAD x along base +x (map centre), CAD z along base +y (equator, halfway to the right edge)."""
    base_R_cad = Rotation.from_euler("x", [[-90]], degrees=True)
    picture = mollweide_panel(rotation_set(base_R_cad), 40, 11)
    equator_row, meridian_col = map_lines(picture)
    ellipse_right = max(x for x, y in dots(picture, "grid")) // 2
    assert find(picture, "x") == [(equator_row, meridian_col + 1)]  # the tag sits right of its point
    assert picture.styles[equator_row][meridian_col] == "mode1"
    [(z_row, z_col)] = find(picture, "z")
    assert z_row == equator_row and abs(z_col - 1 - (meridian_col + ellipse_right) / 2) <= 1


def test_an_upright_fixture_has_its_z_axis_at_the_top_of_the_map():
    picture = mollweide_panel(rotation_set(Rotation.from_euler("z", [[90]], degrees=True)), 40, 11)
    equator_row, meridian_col = map_lines(picture)
    assert find(picture, "z") == [(0, meridian_col + 1)]
    assert picture.styles[0][meridian_col] == "mode1"
    [(x_row, x_col)] = find(picture, "x")  # base +y: on the equator, right of the centre
    assert x_row == equator_row and x_col > meridian_col


def test_close_ups_are_seen_from_outside_with_up_towards_base_z_or_y():
    """An upright axis is seen from above (base +x right, +y up); a level one with base +z up and east right."""
    tilted_to_x = Rotation.from_euler("y", 2, degrees=True).apply([0.0, 0.0, 1.0])
    assert zoom_coordinates_deg(tilted_to_x, np.array([0.0, 0.0, 1.0]))[0] == pytest.approx([2.0, 0.0])
    tilted_up = Rotation.from_euler("y", -2, degrees=True).apply([1.0, 0.0, 0.0])
    assert zoom_coordinates_deg(tilted_up, np.array([1.0, 0.0, 0.0]))[0] == pytest.approx([0.0, 2.0])
    turned_east = Rotation.from_euler("z", 2, degrees=True).apply([1.0, 0.0, 0.0])
    assert zoom_coordinates_deg(turned_east, np.array([1.0, 0.0, 0.0]))[0] == pytest.approx([2.0, 0.0])


def test_the_map_names_the_base_directions_and_the_poles():
    picture = rotation_map(rotation_set(Rotation.identity(1)), 60, 12)
    assert re.search(r"-x +-y +\+x +\+y +-x", picture.text)
    assert "+z" in picture.rows[0] and "-z" in picture.text


def three_mode_set() -> RotationSet:
    """Three groups of tilted orientations 120 deg apart about base z, with mode 2 the most spread."""
    rng = np.random.default_rng(2)
    centres = Rotation.from_euler("ZX", [[0, 30], [120, 30], [240, 30]], degrees=True)
    members = [centres[mode] * Rotation.from_rotvec(rng.normal(scale=0.01, size=(40, 3))) for mode in range(3)]
    return RotationSet(Rotation.concatenate(members), np.repeat(np.arange(3), 40), centres)


def close_up_title_columns(picture: Picture) -> dict[str, int]:
    """Column of each close-up's title (``z close-up``, ``z1 close-up``), by axis."""
    titles = {}
    for row, col in find(picture, "close-up"):
        tag = picture.rows[row][:col].split()[-1]
        titles[tag[0]] = col - len(tag) - 1
    return titles


def map_columns(picture: Picture) -> range:
    """Columns of the map: left of the first close-up panel (titles sit at most 2 columns into a panel)."""
    return range(min(close_up_title_columns(picture).values()) - 3)


def close_up_columns(picture: Picture, axis: str) -> range:
    """Columns of the z close-up (up to the x panel) or of the x close-up (to the right edge)."""
    titles = close_up_title_columns(picture)
    return range(titles["z"] - 3, titles["x"] - 3) if axis == "z" else range(titles["x"] - 3, picture.width)


def test_each_mode_gets_its_own_label_and_style():
    picture = rotation_map(three_mode_set(), 78, 14)
    on_map = map_columns(picture)
    for mode in (1, 2, 3):
        for axis in "zx":
            [(row, col)] = find(picture, f"{axis}{mode}", on_map)
            assert picture.styles[row][col:col + 2] == (f"mode{mode}",) * 2
        assert dots(picture, f"mode{mode}")
    assert not find(picture, "x4", on_map) and not find(picture, "z", on_map) and not find(picture, "x", on_map)
    assert "mode N of 3" in picture.rows[-1]
    assert find(picture, "z1") and find(picture, "x1")  # the close-ups show mode 1


def test_modes_sit_at_their_longitudes():
    """The x axes of modes rotated 0, 120 and 240 deg about base z point to longitudes 0, 120 and -120 deg."""
    picture = rotation_map(three_mode_set(), 78, 14)
    on_map = map_columns(picture)
    [(_, x1)], [(_, x2)], [(_, x3)] = (find(picture, f"x{mode}", on_map) for mode in (1, 2, 3))
    assert x3 < x1 < x2


def test_a_one_degree_set_is_shown_close_up_with_a_degree_scale():
    """Two orientations 1 deg apart about base x: the z close-up shows two dots as far apart as the 1 deg bar."""
    base_R_cad = Rotation.from_euler("x", [[0.0], [1.0]], degrees=True)
    picture = rotation_map(rotation_set(base_R_cad), 78, 14)
    assert find(picture, "close-up") and len(find(picture, "close-up")) == 2
    [(scale_row, label_col)] = [spot for spot in find(picture, "1 deg")]
    bar = [x for x, _ in dots(picture, "scale", range(scale_row, scale_row + 1)) if x < 2 * label_col]
    bar_dots = max(bar) - min(bar)
    z_columns = close_up_columns(picture, "z")
    z_dots = {(x, y) for x, y in dots(picture, "mode1", range(scale_row)) if x // 2 in z_columns}
    assert len(z_dots) == 2
    (x_first, y_first), (x_second, y_second) = sorted(z_dots)
    assert x_first == x_second  # a tilt about base x moves an upright z axis along base y: up/down in the view
    assert abs(abs(y_second - y_first) - bar_dots) <= 1
    x_dots = {(x, y) for x, y in dots(picture, "mode1", range(scale_row))
              if x // 2 in close_up_columns(picture, "x")}
    assert len(x_dots) == 1  # the x axis does not move under a rotation about itself


def test_a_unique_small_set_spreads_over_several_cells_close_up():
    rng = np.random.default_rng(3)
    base_R_cad = Rotation.from_euler("z", 30, degrees=True) * Rotation.from_rotvec(
        rng.normal(scale=np.radians(0.3), size=(300, 3)))
    picture = rotation_map(rotation_set(base_R_cad), 78, 14)
    close_up_cells = {(row, col) for row in range(picture.height) for col in close_up_columns(picture, "z")
                      if picture.styles[row][col] == "mode1"}
    assert len(close_up_cells) >= 4
    [scale_deg] = re.findall(r"(\d+(?:\.\d+)?) deg", picture.text)
    assert 0.1 <= float(scale_deg) <= 2


@pytest.mark.parametrize("width, height", [(40, 7), (60, 10), (78, 14), (80, 24), (120, 30)])
def test_the_rotation_map_has_exactly_the_requested_size_in_plain_text(width, height):
    picture = rotation_map(three_mode_set(), width, height)
    assert_plain_and_sized(picture, width, height)


def test_too_small_a_rotation_map_is_refused():
    with pytest.raises(ValueError, match="at least"):
        rotation_map(three_mode_set(), 30, 10)


# --- Taps view ------------------------------------------------------------------------------------


BOX_SIZE_M = (0.10, 0.06, 0.03)
# The box turned 90 deg about base z: its 100 mm side runs along base y.
BOX_POSE = make_transform(Rotation.from_euler("z", 90, degrees=True), [0.4, -0.1, 0.015])
# Top corners in the CAD frame, and where they end up in the base frame (x right, y up in the view).
CAD_TOP_CORNERS = np.array([[0.05, 0.03, 0.015], [-0.05, 0.03, 0.015], [-0.05, -0.03, 0.015], [0.05, -0.03, 0.015]])
VIEW_CORNERS = ("top-left", "bottom-left", "bottom-right", "top-right")


def box_taps_view(width: int, height: int, suspect_index: int | None = None) -> Picture:
    return taps_view(transform_points(BOX_POSE, CAD_TOP_CORNERS), width, height, trimesh.creation.box(BOX_SIZE_M),
                     BOX_POSE, suspect_index)


def outline_cells(picture: Picture) -> tuple[int, int, int, int]:
    cells = [(row, col) for row in range(picture.height) for col in range(picture.width)
             if picture.styles[row][col] == "outline"]
    rows, cols = zip(*cells, strict=True)
    return min(rows), max(rows), min(cols), max(cols)


@pytest.mark.parametrize("width, height", [(40, 12), (60, 16), (30, 20)])
def test_taps_on_the_box_corners_are_numbered_at_the_outline_corners(width, height):
    picture = box_taps_view(width, height)
    top, bottom, left, right = outline_cells(picture)
    corner_cells = {"top-left": (top, left), "bottom-left": (bottom, left), "bottom-right": (bottom, right),
                    "top-right": (top, right)}
    for number, corner in enumerate(VIEW_CORNERS, start=1):
        assert find(picture, str(number)) == [corner_cells[corner]], picture.text


def test_the_top_view_keeps_the_aspect_ratio():
    """The 60 x 100 mm footprint (x by y) is 0.6 times as wide as tall in square braille dots."""
    picture = box_taps_view(60, 20)
    outline = dots(picture, "outline")
    width_dots = max(x for x, _ in outline) - min(x for x, _ in outline)
    height_dots = max(y for _, y in outline) - min(y for _, y in outline)
    assert width_dots / height_dots == pytest.approx(0.6, abs=0.05)


def test_the_scale_bar_is_as_long_as_its_label_says():
    """The box is 60 mm wide in base x: the bar's dots per mm match the outline's."""
    picture = box_taps_view(60, 20)
    outline = dots(picture, "outline")
    outline_dots_per_mm = (max(x for x, _ in outline) - min(x for x, _ in outline)) / 60.0
    [(row, label_col)] = find(picture, "mm")
    length_mm = float(picture.rows[row][:label_col].split()[-1])
    bar = [x for x, _ in dots(picture, "scale", range(row, row + 1))]
    assert (max(bar) - min(bar)) / length_mm == pytest.approx(outline_dots_per_mm, rel=0.1)
    assert length_mm == round_length(length_mm)
    assert "+x right, +y up" in picture.rows[-1]


def test_the_suspect_tap_is_marked_and_explained():
    picture = box_taps_view(60, 16, suspect_index=2)
    _, bottom, _, right = outline_cells(picture)
    assert find(picture, "3!")[0] == (bottom, right)
    assert picture.styles[bottom][right:right + 2] == ("suspect", "suspect")
    assert find(picture, "3") == []
    assert "3! suspect" in picture.rows[-1]
    assert sum(row.count("!") for row in picture.rows[:-1]) == 1


def test_without_a_pose_only_the_taps_are_drawn():
    taps = np.array([[0.4, 0.0, 0.0], [0.5, 0.1, 0.0], [0.45, 0.05, 0.0]])
    picture = taps_view(taps, 40, 10, suspect_index=0)
    assert_plain_and_sized(picture, 40, 10)
    assert not dots(picture, "outline")
    [(row1, col1)], [(row2, col2)], [(row3, col3)] = find(picture, "1!"), find(picture, "2"), find(picture, "3")
    assert row2 < row3 < row1 and col1 < col3 < col2


@pytest.mark.parametrize("width, height", [(20, 4), (38, 10), (80, 24)])
def test_the_taps_view_has_exactly_the_requested_size_in_plain_text(width, height):
    assert_plain_and_sized(box_taps_view(width, height, suspect_index=1), width, height)


# --- Canvas ---------------------------------------------------------------------------------------


def test_canvas_dots_follow_the_unicode_braille_layout():
    canvas = BrailleCanvas(2, 1)
    canvas.set_dots([0, 1, 3], [0, 3, 1], "a")
    canvas.line(2, 3, 3, 3, "b")
    picture = canvas.picture()
    assert picture.rows == ("\u2881\u28d0",)
    assert dots(picture) == {(0, 0), (1, 3), (3, 1), (2, 3), (3, 3)}
    assert picture.styles == (("a", "b"),)


def test_text_replaces_dots_and_labels_keep_apart():
    canvas = BrailleCanvas(10, 2)
    canvas.line(0, 0, 19, 7)
    assert canvas.place("12", spots_on(0, 0, 2)) == (0, 0)
    assert canvas.place("13", spots_on(0, 1, 2)) == (1, 1)  # (0, 1) would touch "12": one row down
    assert canvas.place("7", spots_beside(1, 8, 1)) == (1, 9)
    picture = canvas.picture()
    assert picture.rows[0].startswith("12") and "1213" not in picture.text
    assert picture.style_runs(0) == []


# --- From a solve ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo_solution():
    return solve(demo_fixture(), load_points(DEMO_TAPS), 0.003, 0.001, max_cells=2.4e6)


def test_the_demo_solution_draws_both_pictures(demo_solution):
    rotations = rotation_set_from_solution(demo_solution)
    assert len(rotations.base_R_cad) == len(demo_solution.cells.distinct_rotations()[0])
    assert np.all(rotations.mode_index == 0)
    picture = rotation_map_for_solution(demo_solution, 78, 14)
    assert_plain_and_sized(picture, 78, 14)
    assert len(find(picture, "z", map_columns(picture))) == 1 and len(find(picture, "x", map_columns(picture))) == 1
    taps = load_points(DEMO_TAPS)
    view = taps_view_for_solution(demo_solution, demo_fixture(), taps, 60, 16)
    assert_plain_and_sized(view, 60, 16)
    assert all(len(find(view, str(number))) == 1 for number in range(1, len(taps) + 1)), view.text
    assert dots(view, "outline")


def test_orientations_join_the_mode_whose_pose_is_nearest(demo_solution):
    mode = demo_solution.modes[0]
    turned = dataclasses.replace(mode, base_T_cad=make_transform(Rotation.from_euler("z", 90, degrees=True)
                                                                 * Rotation.from_matrix(mode.base_T_cad[:3, :3]),
                                                                 mode.base_T_cad[:3, 3]))
    assert np.all(rotation_set_from_solution(dataclasses.replace(demo_solution, modes=[mode, turned])).mode_index == 0)
    assert np.all(rotation_set_from_solution(dataclasses.replace(demo_solution, modes=[turned, mode])).mode_index == 1)


def test_an_inconsistent_solution_has_no_rotation_map(demo_solution):
    inconsistent = dataclasses.replace(demo_solution, status="inconsistent", base_T_cad=None, tree=None, modes=[])
    with pytest.raises(ValueError, match="inconsistent"):
        rotation_map_for_solution(inconsistent, 78, 14)
