"""The robot's way to a safe hover pose above a suggested tap point, so the operator only confirms the tap.

At the hover pose the ball centre is the hover gap plus the ball radius out from the point along the face's
outward normal and the tool z axis points along the inward normal, so a default tap (which approaches along
tool z) touches the face there. The flange keeps its current spin as far as the new tool axis allows.
The way there has three straight moves: up until the ball is ``CLEARANCE_M`` above the highest the fixture
can reach and the flange is high enough that no turn of the tool brings the ball lower, across at that
height while turning the tool, then straight down to hover. The first move starts where the operator left
the ball and is not checked: straight up from there is free unless the ball was left under an overhang.

The point comes from an estimate, and the fixture may sit anywhere in the set of possible poses. So the way
down is planned against all of them (``plan_hover``): the ball, and the tool behind it along the normal,
keep ``MARGIN_M`` from the surface at every possible pose. The hover gap starts at ``HOVER_M`` and widens up
to ``MAX_HOVER_M`` if needed; if even that is not clear, there is no plan and the operator guides the ball.
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import Solution
from fixwizard.workflow.advice import TOOL_CLEARANCE_M, TapAdvice, next_tap

HOVER_M = 0.008  # preferred gap (m) between the ball and the surface at the hover pose
MAX_HOVER_M = 0.016  # widest gap (m): a default tap travels 20 mm, and the surface may lie beyond the estimate
HOVER_STEP_M = 0.002
CLEARANCE_M = 0.05  # the ball crosses over this far (m) above the highest point the fixture can reach
MARGIN_M = 0.002  # the ball and tool stay this far (m) from every possible surface on the way down
PATH_STEP_M = 0.001  # spacing (m) of the checked points on the way down


@dataclass(frozen=True)
class HoverPlan:
    """Go above ``advice``'s point: the ball centre to ``base_p_ball_m`` (base frame, m), ``hover_m`` (m) off the
    surface along the face normal, crossing over with the ball at base z ``safe_ball_z_m`` (m) or higher."""

    advice: TapAdvice
    hover_m: float
    base_p_ball_m: np.ndarray
    safe_ball_z_m: float


def guaranteed_gap_m(fixture: Fixture, pose_bounds: Sequence[Bounds], base_p_points: np.ndarray) -> np.ndarray:
    """The least distance (m) from each point (N, 3; base frame, m) to the fixture's surface over every pose
    within any of ``pose_bounds``. At each bound's centre pose that is the distance there less the bound's
    largest point displacement: no point of the fixture moves farther between the centre and a pose it allows.
    Unsigned on an open mesh; ``plan_hover`` only uses it along a path that starts clear above the fixture."""
    gaps = np.full(len(base_p_points), np.inf)
    for bounds in pose_bounds:
        gaps = np.minimum(gaps, fixture.signed_distance_at_m(bounds.base_T_cad_center, base_p_points)
                          - bounds.max_point_displacement_m)
    return gaps


def highest_z_m(fixture: Fixture, pose_bounds: Sequence[Bounds]) -> float:
    """The highest base z (m) any point of the fixture can have at a pose within any of ``pose_bounds``."""
    return max(float(transform_points(bounds.base_T_cad_center, fixture.mesh.vertices)[:, 2].max())
               + bounds.max_point_displacement_m for bounds in pose_bounds)


def plan_hover(advice: TapAdvice, fixture: Fixture, pose_bounds: Sequence[Bounds],
               ball_radius_m: float) -> HoverPlan | None:
    """The narrowest hover gap from ``HOVER_M`` to ``MAX_HOVER_M`` whose way down is clear at every pose within
    ``pose_bounds`` (the modes of the possible poses), or None if none is."""
    base_n = advice.base_n_face / np.linalg.norm(advice.base_n_face)
    safe_ball_z_m = highest_z_m(fixture, pose_bounds) + CLEARANCE_M
    along_tool = np.arange(0.0, TOOL_CLEARANCE_M + PATH_STEP_M, PATH_STEP_M)
    # the checked points sit PATH_STEP_M apart along two directions, so every point swept is within PATH_STEP_M
    needed_m = ball_radius_m + MARGIN_M + PATH_STEP_M
    for hover_m in np.arange(HOVER_M, MAX_HOVER_M + HOVER_STEP_M / 2, HOVER_STEP_M):
        base_p_ball = advice.base_p_point_m + (ball_radius_m + hover_m) * base_n
        rises = np.arange(0.0, max(safe_ball_z_m - base_p_ball[2], 0.0) + PATH_STEP_M, PATH_STEP_M)
        swept = (base_p_ball + rises[:, None, None] * np.array([0.0, 0.0, 1.0])
                 + along_tool[None, :, None] * base_n).reshape(-1, 3)
        if np.all(guaranteed_gap_m(fixture, pose_bounds, swept) >= needed_m):
            return HoverPlan(advice, float(hover_m), base_p_ball, safe_ball_z_m)
    return None


def next_tap_and_plan(fixture: Fixture, solution: Solution, sample_bound_m: float, ball_radius_m: float,
                      seed: int = 0) -> tuple[TapAdvice | None, HoverPlan | None]:
    """``next_tap``, taking among the candidates nearly as good as the best one the robot can safely go above,
    and the way there (None if none of them has one: the operator guides the ball)."""
    pose_bounds = [mode.bounds for mode in solution.modes]

    def has_plan(candidate: TapAdvice) -> bool:
        return plan_hover(candidate, fixture, pose_bounds, ball_radius_m) is not None

    advice = next_tap(fixture, solution, sample_bound_m, seed, prefer=has_plan)
    return advice, None if advice is None else plan_hover(advice, fixture, pose_bounds, ball_radius_m)


def _aligned(base_R_tcp: np.ndarray, base_d_tool_z: np.ndarray) -> np.ndarray:
    """The rotation nearest ``base_R_tcp`` whose z axis is ``base_d_tool_z`` (unit): the shortest turn of its z."""
    current = base_R_tcp[:, 2]
    axis = np.cross(current, base_d_tool_z)
    angle = np.arctan2(np.linalg.norm(axis), float(current @ base_d_tool_z))
    if np.linalg.norm(axis) < 1e-12:
        axis = base_R_tcp[:, 0] if angle > np.pi / 2 else np.zeros(3)  # opposite: turn about x; same: no turn
    turn = Rotation.from_rotvec(axis / max(np.linalg.norm(axis), 1e-300) * angle)
    return turn.as_matrix() @ base_R_tcp


def hover_path(plan: HoverPlan, tcp_p_tip_m: np.ndarray, base_T_tcp_now: np.ndarray) -> list[np.ndarray]:
    """Flange poses (4x4, base frame, m) of the three moves to ``plan``'s hover pose. ``tcp_p_tip_m``: ball
    centre in the flange frame (m)."""
    base_n = plan.advice.base_n_face / np.linalg.norm(plan.advice.base_n_face)
    base_R_hover = _aligned(base_T_tcp_now[:3, :3], -base_n)
    hover = make_transform(base_R_hover, plan.base_p_ball_m - base_R_hover @ tcp_p_tip_m)
    # whatever the tool's turn, the ball is at most |tcp_p_tip_m| below the flange
    lift_z = max(base_T_tcp_now[2, 3], plan.safe_ball_z_m + float(np.linalg.norm(tcp_p_tip_m)))
    lifted = base_T_tcp_now.copy()
    lifted[2, 3] = lift_z
    across = hover.copy()
    across[2, 3] = lift_z
    return [lifted, across, hover]
