"""Picture of a set of fixture orientations: where the fixture's z and x axes point in the base frame.

Left, a Mollweide (equal-area) map of all directions with the graticule outline (border,
equator, central meridian), every orientation's z and x axis as dots, and each mode's
expected axes as tags ``z``/``x`` (``z1``/``x1``, ``z2``/``x2`` ... when there are several
modes) beside their point, which keeps its dots. Right, close-ups of the expected pose's z
and x axis (mode 1) at a common scale in degrees, so a set of a degree still shows its size
and shape.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import rotation_angle_rad
from fixwizard.plots.canvas import DOTS_PER_CELL_X, DOTS_PER_CELL_Y, BrailleCanvas, spots_beside
from fixwizard.plots.mollweide import HALF_HEIGHT, HALF_WIDTH, direction_xy
from fixwizard.plots.picture import Picture, hstack, pad, text_line, vstack
from fixwizard.plots.scale import draw_scale_bar, format_length, round_length
from fixwizard.solver.solve import Solution

AXES = (("z", 2), ("x", 0))  # fixture axis name and its column in base_R_cad
MIN_WIDTH, MIN_HEIGHT = 40, 7
MAP_WIDTH_SHARE = 0.6
MIN_ZOOM_HALF_RANGE_DEG = 0.05
ZOOM_MARGIN = 1.3  # half range of a close-up over the largest deviation in it
STEEP_AXIS_COS = np.cos(np.radians(45.0))
ELLIPSE_SAMPLES_PER_DOT = 4
# Where base-frame directions lie on the equator (longitude, deg) and their labels.
EQUATOR_LABELS = ((-180.0, "-x"), (-90.0, "-y"), (0.0, "+x"), (90.0, "+y"), (180.0, "-x"))


@dataclass(frozen=True)
class RotationSet:
    """Orientations of the CAD frame in the base frame, grouped in modes.

    ``base_R_cad`` (N,): the orientations; ``mode_index`` (N,): each one's mode, 0..K-1;
    ``mode_base_R_cad`` (K,): each mode's expected orientation, most probable first, so the
    first is the expected pose's.
    """

    base_R_cad: Rotation
    mode_index: np.ndarray
    mode_base_R_cad: Rotation

    @property
    def mode_count(self) -> int:
        return len(self.mode_base_R_cad)

    def axes(self, column: int, mode: int | None = None) -> np.ndarray:
        """Directions (M, 3, base frame) of one CAD axis (column 0, 1, 2 = x, y, z), of one mode or all."""
        rotations = self.base_R_cad if mode is None else self.base_R_cad[np.flatnonzero(self.mode_index == mode)]
        return rotations.as_matrix().reshape(-1, 3, 3)[:, :, column]

    def mode_axis(self, column: int, mode: int) -> np.ndarray:
        """Direction (3,) of one CAD axis at a mode's expected orientation."""
        return self.mode_base_R_cad[mode].as_matrix()[:, column]


def rotation_set_from_solution(solution: Solution) -> RotationSet:
    """The distinct rotation cells of a solution as CAD orientations, each in the mode whose pose is closest."""
    if solution.cells is None or not solution.modes:
        raise ValueError("an inconsistent solution has no orientations to draw")
    base_R_cad = solution.cells.distinct_rotations()[0] * Rotation.from_matrix(solution.fix_T_cad[:3, :3])
    mode_base_R_cad = Rotation.from_matrix(np.stack([mode.base_T_cad[:3, :3] for mode in solution.modes]))
    base_R_cad_matrices = base_R_cad.as_matrix()
    angles = np.stack([rotation_angle_rad(mode.base_T_cad[:3, :3].T @ base_R_cad_matrices) for mode in solution.modes])
    return RotationSet(base_R_cad, np.argmin(angles, axis=0), mode_base_R_cad)


def _tag(axis: str, mode: int, mode_count: int) -> str:
    return axis if mode_count == 1 else f"{axis}{mode + 1}"


def mollweide_panel(rotations: RotationSet, width: int, height: int) -> Picture:
    """The map, ``width`` x ``height`` characters; its last row labels where base axes lie on the equator."""
    canvas = BrailleCanvas(width, height - 1)
    centre_x, centre_y = (canvas.dot_width - 1) // 2, (canvas.dot_height - 1) // 2  # on a dot, not between two
    scale = min(centre_x / HALF_WIDTH, centre_y / HALF_HEIGHT)

    def to_dots(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return centre_x + scale * xy[:, 0], centre_y - scale * xy[:, 1]

    angles = np.linspace(0.0, 2 * np.pi, int(ELLIPSE_SAMPLES_PER_DOT * 2 * np.pi * scale * HALF_WIDTH))
    canvas.set_dots(centre_x + scale * HALF_WIDTH * np.cos(angles), centre_y - scale * HALF_HEIGHT * np.sin(angles),
                    "grid")
    canvas.line(centre_x - scale * HALF_WIDTH, centre_y, centre_x + scale * HALF_WIDTH, centre_y, "grid")
    canvas.line(centre_x, centre_y - scale * HALF_HEIGHT, centre_x, centre_y + scale * HALF_HEIGHT, "grid")
    for mode in range(rotations.mode_count):
        for _, column in AXES:
            canvas.set_dots(*to_dots(direction_xy(rotations.axes(column, mode))), f"mode{mode + 1}")
    for mode in range(rotations.mode_count):
        for axis, column in AXES:
            dot_x, dot_y = to_dots(direction_xy(rotations.mode_axis(column, mode)))
            tag = _tag(axis, mode, rotations.mode_count)
            canvas.place(tag, spots_beside(int(np.rint(dot_y[0])) // DOTS_PER_CELL_Y,
                                           int(np.rint(dot_x[0])) // DOTS_PER_CELL_X, len(tag)), f"mode{mode + 1}")
    for row, label in ((0, "+z top"), (canvas.height - 1, "-z bottom")):
        for text in (label, label[:2]):
            if canvas.is_empty(row, 0, len(text)):
                canvas.write(row, 0, text, "label")
                break
    return vstack([canvas.picture(), _equator_labels(width, centre_x, scale)])


def _equator_labels(width: int, centre_x: float, scale: float) -> Picture:
    """A row naming the base directions at longitudes -180, -90, 0, 90, 180 deg, each centred on its column."""
    row = [" "] * width
    for longitude, label in EQUATOR_LABELS:
        column = int((centre_x + scale * HALF_WIDTH * longitude / 180.0) // 2)
        start = min(max(column - len(label) // 2, 0), width - len(label))
        row[start:start + len(label)] = label
    text = "".join(row)
    return Picture((text,), (tuple("label" if char != " " else None for char in text),))


def zoom_basis(direction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (right, up) of a close-up around a direction, seen from outside the sphere.

    Up is towards base +z, or towards base +y for directions within 45 deg of vertical; right is
    ``up x direction`` (east, as on the map; base +x for a direction pointing straight up).
    """
    direction = direction / np.linalg.norm(direction)
    reference = np.array([0.0, 1.0, 0.0]) if abs(direction[2]) > STEEP_AXIS_COS else np.array([0.0, 0.0, 1.0])
    up = reference - (reference @ direction) * direction
    up /= np.linalg.norm(up)
    return np.cross(up, direction), up


def zoom_coordinates_deg(directions: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """Azimuthal equidistant coordinates (N, 2, deg) of directions around ``centre``: (right, up)."""
    centre = centre / np.linalg.norm(centre)
    directions = np.asarray(directions, float).reshape(-1, 3)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    right, up = zoom_basis(centre)
    along = directions @ centre
    tangent = directions - along[:, None] * centre
    length = np.linalg.norm(tangent, axis=1)
    angle_deg = np.degrees(np.arctan2(length, along))
    unit = np.divide(tangent, length[:, None], out=np.zeros_like(tangent), where=length[:, None] > 0)
    return np.stack([unit @ right, unit @ up], axis=1) * angle_deg[:, None]


def zoom_half_range_deg(rotations: RotationSet) -> float:
    """Half the width (deg) of the close-ups: a margin over the largest deviation of mode 1's z and x axes."""
    largest = max(float(np.max(np.abs(zoom_coordinates_deg(rotations.axes(column, 0), rotations.mode_axis(column, 0))),
                               initial=0.0))
                  for _, column in AXES)
    return max(ZOOM_MARGIN * largest, MIN_ZOOM_HALF_RANGE_DEG)


def zoom_dots_per_degree(width: int, height: int, half_range_deg: float) -> float:
    """Scale (dots/deg) of a close-up canvas of ``width`` x ``height`` characters."""
    return (min(2 * width, 4 * height) - 3) / (2 * half_range_deg)


def zoom_panel(rotations: RotationSet, axis: str, half_range_deg: float, width: int, height: int) -> Picture:
    """Close-up of one fixture axis (``"z"`` or ``"x"``) around mode 1's expected direction.

    ``width`` x ``height`` characters: a title row, then a framed canvas with the expected
    direction at the centre (marked by ticks on the frame and a dot) and every orientation's
    axis as a dot, at ``zoom_dots_per_degree`` (azimuthal equidistant, see ``zoom_basis``).
    """
    column = dict(AXES)[axis]
    canvas = BrailleCanvas(width, height - 1)
    dots_per_degree = zoom_dots_per_degree(width, height - 1, half_range_deg)
    centre_x, centre_y = (canvas.dot_width - 1) // 2, (canvas.dot_height - 1) // 2
    right, bottom = canvas.dot_width - 1, canvas.dot_height - 1
    canvas.rectangle(0, 0, right, bottom, "grid")
    for x0, y0, x1, y1 in ((centre_x, 0, centre_x, 2), (centre_x, bottom, centre_x, bottom - 2),
                           (0, centre_y, 2, centre_y), (right, centre_y, right - 2, centre_y)):
        canvas.line(x0, y0, x1, y1, "expected")
    centre = rotations.mode_axis(column, 0)
    canvas.set_dots(np.array([centre_x]), np.array([centre_y]), "expected")
    for mode in range(rotations.mode_count):
        offsets = zoom_coordinates_deg(rotations.axes(column, mode), centre) * dots_per_degree
        inside = (np.abs(offsets[:, 0]) < centre_x - 1) & (np.abs(offsets[:, 1]) < centre_y - 1)
        canvas.set_dots(centre_x + offsets[inside, 0], centre_y - offsets[inside, 1], f"mode{mode + 1}")
    tag = _tag(axis, 0, rotations.mode_count)
    title = f"{tag} close-up" if len(tag) + 9 <= width else f"{tag} zoom"
    return vstack([text_line(title, width, "label", "centre"), canvas.picture()])


def _zoom_scale_row(width: int, dots_per_degree: float, half_range_deg: float) -> Picture:
    """A scale bar in degrees for the close-ups."""
    canvas = BrailleCanvas(width, 1)
    length_deg = round_length(min(half_range_deg, (2 * width - 12) / dots_per_degree))
    draw_scale_bar(canvas, 0, 1, length_deg * dots_per_degree, format_length(length_deg, "deg"), "scale")
    return canvas.picture()


def _legend(rotations: RotationSet, width: int) -> Picture:
    if rotations.mode_count == 1:
        text = "z/x: fixture z/x axis at the expected pose; dots: all poses in the set"
    else:
        text = f"zN/xN: fixture z/x axis in mode N of {rotations.mode_count} (1: most probable, close up)"
    return text_line(text, width, "label")


def rotation_map(rotations: RotationSet, width: int, height: int) -> Picture:
    """The map and the two close-ups side by side with a legend, exactly ``width`` x ``height`` characters."""
    if width < MIN_WIDTH or height < MIN_HEIGHT:
        raise ValueError(f"the rotation map needs at least {MIN_WIDTH}x{MIN_HEIGHT} characters, not {width}x{height}")
    body_height = height - 1
    map_width = min(round(MAP_WIDTH_SHARE * width), 4 * (body_height - 1))
    map_rows = min(body_height - 1, round(map_width / 4))
    world = mollweide_panel(rotations, map_width, map_rows + 1)
    zoom_width = (width - map_width - 2) // 2
    zoom_height = min(body_height - 1, zoom_width // 2 + 1)
    half_range = zoom_half_range_deg(rotations)
    zooms = hstack([zoom_panel(rotations, axis, half_range, zoom_width, zoom_height) for axis, _ in AXES])
    scale_row = _zoom_scale_row(zooms.width, zoom_dots_per_degree(zoom_width, zoom_height - 1, half_range),
                                half_range)
    close_ups = vstack([zooms, scale_row])
    body = hstack([pad(world, map_width, body_height), pad(close_ups, width - map_width - 1, body_height)])
    return vstack([body, _legend(rotations, width)])


def rotation_map_for_solution(solution: Solution, width: int, height: int) -> Picture:
    """``rotation_map`` of a unique or ambiguous solution (ValueError for an inconsistent one)."""
    return rotation_map(rotation_set_from_solution(solution), width, height)
