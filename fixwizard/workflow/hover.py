"""The robot's way to a safe hover pose above a suggested tap point, so the operator only confirms the tap.

At the hover pose the ball centre is ``HOVER_M`` plus the ball radius out from the point along the face's
outward normal and the tool z axis points along the inward normal, so a default tap (which approaches along
tool z) touches the face there. The flange keeps its current spin as far as the new tool axis allows.
The way there has three straight moves: up to a safe height (``CLEARANCE_M`` above the fixture's top and
never lower than the flange already is), across at that height while turning the tool, then down to hover.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform
from fixwizard.workflow.advice import TapAdvice

HOVER_M = 0.008
CLEARANCE_M = 0.05


def _aligned(base_R_tcp: np.ndarray, base_d_tool_z: np.ndarray) -> np.ndarray:
    """The rotation nearest ``base_R_tcp`` whose z axis is ``base_d_tool_z`` (unit): the shortest turn of its z."""
    current = base_R_tcp[:, 2]
    axis = np.cross(current, base_d_tool_z)
    angle = np.arctan2(np.linalg.norm(axis), float(current @ base_d_tool_z))
    if np.linalg.norm(axis) < 1e-12:
        axis = base_R_tcp[:, 0] if angle > np.pi / 2 else np.zeros(3)  # opposite: turn about x; same: no turn
    turn = Rotation.from_rotvec(axis / max(np.linalg.norm(axis), 1e-300) * angle)
    return turn.as_matrix() @ base_R_tcp


def hover_path(advice: TapAdvice, tcp_p_tip_m: np.ndarray, ball_radius_m: float, base_T_tcp_now: np.ndarray,
               fixture_top_z_m: float) -> list[np.ndarray]:
    """Flange poses (4x4, base frame, m) of the three moves to the hover pose above ``advice``'s point.
    ``tcp_p_tip_m``: ball centre in the flange frame (m); ``fixture_top_z_m``: base z of the fixture's highest
    point under the estimate (m)."""
    base_n = advice.base_n_face / np.linalg.norm(advice.base_n_face)
    base_R_hover = _aligned(base_T_tcp_now[:3, :3], -base_n)
    base_p_ball = advice.base_p_point_m + (ball_radius_m + HOVER_M) * base_n
    hover = make_transform(base_R_hover, base_p_ball - base_R_hover @ tcp_p_tip_m)
    safe_ball_z = fixture_top_z_m + CLEARANCE_M
    lift_z = max(base_T_tcp_now[2, 3], safe_ball_z - (base_T_tcp_now[:3, :3] @ tcp_p_tip_m)[2],
                 safe_ball_z - (base_R_hover @ tcp_p_tip_m)[2])
    lifted = base_T_tcp_now.copy()
    lifted[2, 3] = lift_z
    across = hover.copy()
    across[2, 3] = lift_z
    return [lifted, across, hover]
