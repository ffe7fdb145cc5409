"""Top view of the taps: the robot base x-y plane seen from above (looking down -z), +x right, +y up.

The fixture under a pose is drawn as its silhouette outline plus its sharp edges that border
an upward-facing face; each tap is its number (1-based) at its position, a suspect tap its
number followed by ``!``. The last row holds a scale bar in mm and the axis directions.
"""

import numpy as np
import trimesh

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import transform_points
from fixwizard.plots.canvas import DOTS_PER_CELL_X, DOTS_PER_CELL_Y, BrailleCanvas, spots_on
from fixwizard.plots.picture import Picture, vstack
from fixwizard.plots.scale import draw_scale_bar, format_length, round_length
from fixwizard.solver.solve import Solution

MIN_WIDTH, MIN_HEIGHT = 20, 4
MARGIN_DOTS = (6, 4)  # free dots (x, y) around the content, so labels at the border stay readable
MIN_EXTENT_M = 0.01
SHARP_EDGE_RAD = np.radians(20.0)
UPWARD_NORMAL_Z = 0.05
SAMPLES_PER_DOT = 2  # silhouette samples per dot along triangle edges: dense enough to leave no holes
SCALE_BAR_SHARE = 0.4  # longest scale bar, as a share of the width


class TopViewFrame:
    """Mapping from base-frame points (m) to dots of a canvas: uniform scale, +x right, +y up."""

    def __init__(self, base_xy_min: np.ndarray, base_xy_max: np.ndarray, dot_width: int, dot_height: int) -> None:
        extent = np.maximum(base_xy_max - base_xy_min, MIN_EXTENT_M)
        usable = np.array([dot_width - 1 - 2 * MARGIN_DOTS[0], dot_height - 1 - 2 * MARGIN_DOTS[1]], float)
        self.metres_per_dot = float(np.max(extent / np.maximum(usable, 1.0)))
        self._base_xy_mid = (base_xy_min + base_xy_max) / 2
        self._dot_mid = np.array([(dot_width - 1) / 2, (dot_height - 1) / 2])

    def to_dots(self, base_points: np.ndarray) -> np.ndarray:
        """Dot coordinates (N, 2: x right, y down, fractional) of base-frame points (N, 2 or 3, m)."""
        offset = (np.asarray(base_points, float)[:, :2] - self._base_xy_mid) / self.metres_per_dot
        return self._dot_mid + offset * [1.0, -1.0]


def _silhouette_mask(triangles_dots: np.ndarray, dot_width: int, dot_height: int) -> np.ndarray:
    """Dots (dot_height, dot_width) covered by any of the triangles (T, 3, 2 in dot coordinates)."""
    mask = np.zeros((dot_height, dot_width), bool)
    edges = np.linalg.norm(triangles_dots - np.roll(triangles_dots, 1, axis=1), axis=2).max(axis=1)
    steps = np.ceil(SAMPLES_PER_DOT * edges).astype(int) + 1
    for step in np.unique(steps):
        corners = triangles_dots[steps == step]
        i, j = np.meshgrid(np.arange(step + 1), np.arange(step + 1), indexing="ij")
        keep = i + j <= step
        u, v = i[keep] / step, j[keep] / step
        points = (corners[:, None, 0] + u[None, :, None] * (corners[:, None, 1] - corners[:, None, 0])
                  + v[None, :, None] * (corners[:, None, 2] - corners[:, None, 0])).reshape(-1, 2)
        x, y = np.rint(points[:, 0]).astype(int), np.rint(points[:, 1]).astype(int)
        inside = (x >= 0) & (x < dot_width) & (y >= 0) & (y < dot_height)
        mask[y[inside], x[inside]] = True
    return mask


def _outline(mask: np.ndarray) -> np.ndarray:
    """Dots of the mask with a 4-neighbour outside it."""
    padded = np.pad(mask, 1)
    interior = padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
    return mask & ~interior


def _draw_fixture(canvas: BrailleCanvas, frame: TopViewFrame, mesh: trimesh.Trimesh, base_T_cad: np.ndarray) -> None:
    base_vertices = transform_points(base_T_cad, mesh.vertices)
    vertices_dots = frame.to_dots(base_vertices)
    mask = _silhouette_mask(vertices_dots[mesh.faces], canvas.dot_width, canvas.dot_height)
    rows, cols = np.nonzero(_outline(mask))
    canvas.set_dots(cols, rows, "outline")
    base_normals_z = (mesh.face_normals @ base_T_cad[:3, :3].T)[:, 2]
    upward = base_normals_z > UPWARD_NORMAL_Z
    sharp = mesh.face_adjacency_angles > SHARP_EDGE_RAD
    seen = upward[mesh.face_adjacency[:, 0]] | upward[mesh.face_adjacency[:, 1]]
    for start, end in mesh.face_adjacency_edges[sharp & seen]:
        (x0, y0), (x1, y1) = vertices_dots[start], vertices_dots[end]
        canvas.line(x0, y0, x1, y1, "outline")


def tap_label(index: int, suspect_index: int | None) -> str:
    """The text marking tap ``index`` (0-based): its 1-based number, with ``!`` if it is the suspect."""
    return f"{index + 1}!" if index == suspect_index else str(index + 1)


TARGET_LABEL = "*"


def _legend(width: int, metres_per_dot: float, suspect_index: int | None, has_target: bool) -> Picture:
    canvas = BrailleCanvas(width, 1)
    longest_m = SCALE_BAR_SHARE * canvas.dot_width * metres_per_dot
    length_m = round_length(longest_m)
    column = draw_scale_bar(canvas, 0, 0, length_m / metres_per_dot, format_length(length_m * 1e3, "mm"), "scale")
    notes = ["+x right, +y up"]
    if suspect_index is not None:
        notes.append(f"{tap_label(suspect_index, suspect_index)} suspect")
    if has_target:
        notes.append(f"{TARGET_LABEL} tap next")
    for note in notes:
        if column + 2 + len(note) <= width:
            canvas.write(0, column + 2, note, "label")
            column += 2 + len(note)
    return canvas.picture()


def taps_view(base_p_taps: np.ndarray, width: int, height: int, mesh: trimesh.Trimesh | None = None,
              base_T_cad: np.ndarray | None = None, suspect_index: int | None = None,
              base_p_target: np.ndarray | None = None) -> Picture:
    """Top view, exactly ``width`` x ``height`` characters, of taps (N, 3, base frame, m).

    With ``mesh`` (CAD frame, m) and ``base_T_cad`` the fixture is drawn at that pose;
    ``suspect_index`` (0-based) marks one tap as suspect; ``base_p_target`` (3,) (base frame, m) is where to
    tap next, marked ``*``.
    """
    if width < MIN_WIDTH or height < MIN_HEIGHT:
        raise ValueError(f"the taps view needs at least {MIN_WIDTH}x{MIN_HEIGHT} characters, not {width}x{height}")
    base_p_taps = np.asarray(base_p_taps, float).reshape(-1, 3)
    canvas = BrailleCanvas(width, height - 1)
    shown = [base_p_taps] if base_p_target is None else [base_p_taps, np.reshape(base_p_target, (1, 3))]
    if mesh is not None and base_T_cad is not None:
        shown.append(transform_points(base_T_cad, mesh.vertices))
    points = np.vstack(shown)
    frame = TopViewFrame(points[:, :2].min(axis=0), points[:, :2].max(axis=0), canvas.dot_width, canvas.dot_height)
    if mesh is not None and base_T_cad is not None:
        _draw_fixture(canvas, frame, mesh, base_T_cad)
    if base_p_target is not None:
        dot_x, dot_y = np.rint(frame.to_dots(np.reshape(base_p_target, (1, 3)))[0]).astype(int)
        canvas.place(TARGET_LABEL, spots_on(dot_y // DOTS_PER_CELL_Y, dot_x // DOTS_PER_CELL_X, 1), "target")
    taps_dots = np.rint(frame.to_dots(base_p_taps)).astype(int)
    for index, (dot_x, dot_y) in enumerate(taps_dots):
        style = "suspect" if index == suspect_index else "tap"
        label = tap_label(index, suspect_index)
        canvas.place(label, spots_on(dot_y // DOTS_PER_CELL_Y, dot_x // DOTS_PER_CELL_X, len(label)), style)
    return vstack([canvas.picture(), _legend(width, frame.metres_per_dot, suspect_index, base_p_target is not None)])


def taps_view_for_solution(solution: Solution, fixture: Fixture, base_p_taps: np.ndarray, width: int,
                           height: int) -> Picture:
    """``taps_view`` of a solve: the fixture at the expected pose (none if inconsistent) and its suspect tap."""
    suspect_index = solution.suspect_tap.index if solution.suspect_tap is not None else None
    return taps_view(base_p_taps, width, height, fixture.mesh, solution.base_T_cad, suspect_index)
