"""How far from a pose a fixture may be while a few taps still fit it, to first order: what ``verify`` may promise.

A small move ``m = (v, R w)`` of the fixture about the centre ``c`` of its enclosing ball (``v``: slide, m; ``w``:
turn vector, rad; ``R``: the ball's radius, so both parts are in metres) changes the distance of a fixed tap ``p_i``
from the surface by ``J_i m``, ``J_i = -[n_i, ((p_i - c) / R) x n_i]`` (``n_i``: the distance field's gradient at
``p_i``, base frame), to first order. The true pose explains every tap within the sample bound ``b``, so its move
from the checked pose lies in the polytope ``P = {m : |r_i + J_i m| <= b}`` (``r_i``: tap ``i``'s distance from
touching at the checked pose). Any fixture point lies within ``R`` of ``c`` and moves by at most ``|v| + R |w|``
(a turn of angle ``a`` by ``R chord(a) <= R a``), so every point of the fixture lies within
``max_P |v| + R max_P |w|`` of where the checked pose puts it. Each maximum, of a norm over a polytope, is bounded
from above on a net of unit directions ``u_j`` that comes within ``NET_ANGLE_RAD`` of every unit vector:
``|v| <= max_j (max_P u_j . v) / cos(NET_ANGLE_RAD)``, one linear program per direction.

``P`` is unbounded where the taps cannot see some move at all (fewer than six taps; taps on faces that all face one
way): a move along ``J``'s null space changes no tap's distance. First order: the bound is for moves small against
the fixture's features (a move that carries a tap over an edge changes its distance otherwise); where the
first-order ``P`` is empty although poses explain the taps (taps at edges, where the surface bends), no bound is
given.
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from fixwizard.fixture import Fixture

GRADIENT_STEP_M = 1e-6  # central differences of the distance field at the taps
NET_SIDE = 5  # the direction net: cell centres of a NET_SIDE x NET_SIDE grid on each face of the cube [-1, 1]^3
# A unit vector's ray meets the cube's surface within half a cell diagonal (sqrt(2) / NET_SIDE) of a net point, and
# the projection onto the unit sphere shortens paths outside the unit ball, so the angle is at most that.
NET_ANGLE_RAD = math.sqrt(2.0) / NET_SIDE
RANK_SHARE = 1e-9  # a singular value of J below this share of the largest one: a move the taps cannot see at all


@dataclass(frozen=True)
class MissableMove:
    """How far (first order) the fixture may be from the checked pose while every tap fits within the sample bound:
    ``slide_m`` of its centre, ``turn_rad`` about it, and ``point_m``: of any of its points (``slide_m`` plus the
    radius times ``turn_rad``); inf for a move the taps cannot see at all; None each where the first-order model
    fits no pose to the taps (taps at edges). ``base_m_move``: (6,) the farthest move found (slide m, turn vector
    times the radius m; base frame; for an unseen move, a unit one the taps cannot see); ``base_p_centre``: the
    fixture's centre ``c`` at the checked pose (m); ``radius_m``: ``R``."""

    slide_m: float | None
    turn_rad: float | None
    base_m_move: np.ndarray
    base_p_centre: np.ndarray
    radius_m: float

    @property
    def point_m(self) -> float | None:
        if self.slide_m is None or self.turn_rad is None:
            return None
        return self.slide_m + self.radius_m * self.turn_rad

    @property
    def mostly_turn(self) -> bool:
        """Whether the farthest move is more a turn than a slide (its turn moves points at the radius farther)."""
        return bool(np.linalg.norm(self.base_m_move[3:]) > np.linalg.norm(self.base_m_move[:3]))


def net_directions() -> np.ndarray:
    """Unit vectors (6 NET_SIDE^2, 3) within NET_ANGLE_RAD of every unit vector (see the module doc)."""
    ticks = -1.0 + (np.arange(NET_SIDE) + 0.5) * 2.0 / NET_SIDE
    first, second = (grid.ravel() for grid in np.meshgrid(ticks, ticks))
    ones = np.ones_like(first)
    faces = [np.column_stack([ones, first, second]), np.column_stack([first, ones, second]),
             np.column_stack([first, second, ones])]
    points = np.vstack(faces + [-face for face in faces])
    return points / np.linalg.norm(points, axis=1, keepdims=True)


def tap_jacobian(fixture: Fixture, base_T_cad: np.ndarray, base_p_taps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``J`` (N, 6): how each tap's distance from the surface changes with a move ``(v, R w)`` (m) of the fixture
    about its centre, to first order (see the module doc); and that centre (3,), base frame, m."""
    steps = np.vstack([np.eye(3), -np.eye(3)]) * GRADIENT_STEP_M
    stepped = (base_p_taps[:, None, :] + steps[None]).reshape(-1, 3)
    distances = fixture.signed_distance_at_m(base_T_cad, stepped).reshape(len(base_p_taps), 6)
    gradients = (distances[:, :3] - distances[:, 3:]) / (2.0 * GRADIENT_STEP_M)
    base_n = gradients / np.maximum(np.linalg.norm(gradients, axis=1, keepdims=True), 1e-12)
    base_p_centre = fixture.base_T_fix(base_T_cad)[:3, 3]
    moments = np.cross((base_p_taps - base_p_centre) / fixture.radius_m, base_n)
    return -np.hstack([base_n, moments]), base_p_centre


def _farthest(jacobian: np.ndarray, residuals_m: np.ndarray, bound_m: float,
              objectives: np.ndarray) -> tuple[float, np.ndarray] | None:
    """The largest ``objective . m`` over ``P`` among ``objectives`` (K, 6) and the move reaching it; inf with
    the direction reached for an unbounded ``P``; None for an empty one."""
    rows = np.vstack([jacobian, -jacobian])
    limits = np.concatenate([bound_m - residuals_m, bound_m + residuals_m])
    best, best_move = -np.inf, np.zeros(6)
    for objective in objectives:
        found = linprog(-objective, A_ub=rows, b_ub=limits, bounds=[(None, None)] * 6, method="highs")
        if found.status == 2:
            return None
        if found.status == 3 or not found.success:
            return math.inf, objective
        if -found.fun > best:
            best, best_move = -float(found.fun), np.asarray(found.x, float)
    return best, best_move


def missable_move(fixture: Fixture, base_T_cad: np.ndarray, base_p_taps: np.ndarray, ball_diameter_m: float,
                  sample_bound_m: float) -> MissableMove:
    """How far from ``base_T_cad`` the fixture may be while every tap (N, 3, base frame, m) fits within
    ``sample_bound_m``, to first order (see the module doc)."""
    jacobian, base_p_centre = tap_jacobian(fixture, base_T_cad, base_p_taps)
    singular, right = np.linalg.svd(jacobian)[1:]  # right: (6, 6), its last rows span the moves seen least
    if len(jacobian) < len(right) or singular[-1] <= RANK_SHARE * singular[0]:
        return MissableMove(math.inf, math.inf, right[-1], base_p_centre, fixture.radius_m)
    residuals = fixture.signed_distance_at_m(base_T_cad, base_p_taps) - ball_diameter_m / 2.0
    net = net_directions()
    zeros = np.zeros_like(net)
    slide = _farthest(jacobian, residuals, sample_bound_m, np.hstack([net, zeros]))
    turn = _farthest(jacobian, residuals, sample_bound_m, np.hstack([zeros, net]))
    if slide is None or turn is None:
        return MissableMove(None, None, right[-1], base_p_centre, fixture.radius_m)
    (slide_m, slide_move), (turn_m, turn_move) = slide, turn
    scale = 1.0 / math.cos(NET_ANGLE_RAD)
    move = turn_move if turn_m > slide_m else slide_move
    return MissableMove(slide_m * scale, turn_m * scale / fixture.radius_m, move, base_p_centre, fixture.radius_m)
