"""Tap plans: flange hover poses ``base_T_tcp`` for the robot-driven calibration steps.

Each plan places the ball centre ``approach_height_m`` above a point of the table frame's plane (the
plane of ball centres touching the table, so height 0 is contact), with the tool z axis pointing down
into the table; the robot then moves along tool z until it touches. Points form a grid of cells of
``spacing_m`` starting at the table origin (the corner B) towards +x and +y, visited in serpentine order
so that every move is one cell long.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform

# Tilts up to 40 deg: the tip's component along the tool axis is fixed by how much cos(tilt) varies
# (10-30 deg leaves its standard error about twice as large); at 45 deg a 30 mm approach no longer
# fits the tap's travel limit.
DEFAULT_TILTS_DEG = (10.0, 20.0, 30.0, 35.0, 40.0)
DEFAULT_AZIMUTHS = 8
_TOOL_DOWN = np.diag([1.0, -1.0, -1.0])


def grid_hover_poses(base_T_table: np.ndarray, tcp_p_tip_m: np.ndarray, rows: int, cols: int, spacing_m: float,
                     approach_height_m: float) -> np.ndarray:
    """Hover poses (rows * cols, 4, 4) over a grid, all with the tool pointing straight down (tool x along
    table x): the fixed orientation of the table plane step."""
    cells = _serpentine(rows, cols)
    table_R_tool = np.broadcast_to(_TOOL_DOWN, (len(cells), 3, 3))
    return _hover_poses(base_T_table, tcp_p_tip_m, cells, spacing_m, table_R_tool, approach_height_m)


def tilted_hover_poses(base_T_table: np.ndarray, tcp_p_tip_m: np.ndarray, spacing_m: float, approach_height_m: float,
                       tilts_deg: tuple[float, ...] = DEFAULT_TILTS_DEG,
                       azimuths: int = DEFAULT_AZIMUTHS) -> np.ndarray:
    """Hover poses (azimuths * len(tilts_deg), 4, 4) for the fine tip: the tool axis tilted from the downward
    normal by each tilt (deg) in each of ``azimuths`` evenly spread directions.

    Grid row r holds azimuth r and, in column c, tilt (r + c) mod len(tilts_deg): each row has every tilt once,
    and every column holds several tilts, so a table height error that varies across the table does not
    line up with the tilt. The serpentine order moves one cell at a time. The approach along tool z lands
    on the grid point.
    """
    cells = _serpentine(azimuths, len(tilts_deg))
    azimuth_rad = 2 * np.pi * cells[:, 0] / azimuths
    axes = np.column_stack([-np.sin(azimuth_rad), np.cos(azimuth_rad), np.zeros(len(cells))])
    tilt_index = (cells[:, 0] + cells[:, 1]) % len(tilts_deg)
    leans = Rotation.from_rotvec(axes * np.radians(np.asarray(tilts_deg, float)[tilt_index])[:, None])
    return _hover_poses(base_T_table, tcp_p_tip_m, cells, spacing_m, leans.as_matrix() @ _TOOL_DOWN,
                        approach_height_m)


def _serpentine(rows: int, cols: int) -> np.ndarray:
    """Grid cells (rows * cols, 2) as (row, column), every other row reversed."""
    return np.array([(row, col) for row in range(rows)
                     for col in (range(cols) if row % 2 == 0 else reversed(range(cols)))])


def _hover_poses(base_T_table: np.ndarray, tcp_p_tip_m: np.ndarray, cells: np.ndarray, spacing_m: float,
                 table_R_tool: np.ndarray, approach_height_m: float) -> np.ndarray:
    """Flange poses whose ball centre hovers at ``approach_height_m`` on the tool-z line through each cell centre."""
    table_p_target = np.column_stack([(cells[:, ::-1] + 0.5) * spacing_m, np.zeros(len(cells))])
    table_z_tool = table_R_tool[:, :, 2]
    table_p_tip = table_p_target - (approach_height_m / -table_z_tool[:, 2])[:, None] * table_z_tool
    table_p_tcp = table_p_tip - table_R_tool @ tcp_p_tip_m
    return np.array([base_T_table @ make_transform(rotation, position)
                     for rotation, position in zip(table_R_tool, table_p_tcp, strict=True)])
