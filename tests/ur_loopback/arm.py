"""The fake controller's arm: a flange that moves in straight lines, holds still, follows the operator's hand
in freedrive, or complies along force-mode axes, and a tool tip that meets a flat contact surface (the table) and,
where one stands on it, a fixture's mesh.

Poses are 4x4 transforms in the robot base frame (m); UR pose vectors are ``[x, y, z, rx, ry, rz]``
(m, rotation vector in rad). All methods are called with the controller's lock held.
"""

from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation, Slerp

# contact surface stiffness (N/m) and force-mode time constant (s): near equilibrium the compliant axis
# approaches its force target exponentially, far from it at the speed limit
SURFACE_STIFFNESS_N_M = 2.0e4
# a fixture's surface is stiffer: a tap's 10 N press it in by 50 micrometres, well within a tap's sample bound
FIXTURE_STIFFNESS_N_M = 2.0e5
FORCE_MODE_TAU_S = 0.03
# a contact force above this (N) outside force mode makes the controller protective-stop (collision)
COLLISION_FORCE_N = 150.0


def pose_vector(base_T: np.ndarray) -> list[float]:
    """UR pose vector of a 4x4 transform."""
    return [*base_T[:3, 3], *Rotation.from_matrix(base_T[:3, :3]).as_rotvec()]


def transform(pose: list[float]) -> np.ndarray:
    """4x4 transform of a UR pose vector."""
    base_T = np.eye(4)
    base_T[:3, :3] = Rotation.from_rotvec(pose[3:6]).as_matrix()
    base_T[:3, 3] = pose[:3]
    return base_T


@dataclass
class ForceMode:
    """Force-mode parameters as ``force_mode(task_frame, selection_vector, wrench, type, limits)`` takes them."""

    base_T_task: np.ndarray
    selection: list[int]
    wrench: list[float]
    limits: list[float]


@dataclass
class LinearMove:
    """A ``movel`` in progress: start and target flange poses, speed (m/s), elapsed time (s)."""

    base_T_start: np.ndarray
    base_T_target: np.ndarray
    speed_m_s: float
    elapsed_s: float = 0.0

    @property
    def duration_s(self) -> float:
        return float(np.linalg.norm(self.base_T_target[:3, 3] - self.base_T_start[:3, 3])) / self.speed_m_s


def interpolate_pose(base_T_from: np.ndarray, base_T_to: np.ndarray, fraction: float) -> np.ndarray:
    """URScript's ``interpolate_pose``: the position along the straight line, the rotation along the shortest turn."""
    rotations = Rotation.from_matrix([base_T_from[:3, :3], base_T_to[:3, :3]])
    base_T_between = np.eye(4)
    base_T_between[:3, :3] = Slerp([0.0, 1.0], rotations)(fraction).as_matrix()
    base_T_between[:3, 3] = (1 - fraction) * base_T_from[:3, 3] + fraction * base_T_to[:3, 3]
    return base_T_between


class FixtureBody:
    """A rigid fixture on the table: a closed triangle mesh (``cad_p_vertices`` m, ``faces``) placed at
    ``base_T_cad``. The tool's ball meets its surface as it meets the table: a spring along the surface's outward
    direction at the point nearest the ball's centre."""

    def __init__(self, cad_p_vertices: np.ndarray, faces: np.ndarray, base_T_cad: np.ndarray) -> None:
        self.base_T_cad = np.array(base_T_cad, float)
        self._cad_T_base = np.linalg.inv(self.base_T_cad)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(np.asarray(cad_p_vertices, np.float32)),
                                  o3d.core.Tensor(np.asarray(faces, np.uint32)))
        self._last: tuple[bytes, tuple[float, np.ndarray]] | None = None  # a cycle asks several times

    def penetration(self, base_p_ball: np.ndarray, ball_radius_m: float) -> tuple[float, np.ndarray]:
        """How deep (m) a ball of ``ball_radius_m`` centred at ``base_p_ball`` reaches into the fixture, and the
        direction (base frame, unit) the surface pushes it out along; 0 and zeros when it does not touch."""
        key = np.append(base_p_ball, ball_radius_m).tobytes()
        if self._last is None or self._last[0] != key:
            self._last = key, self._penetration(base_p_ball, ball_radius_m)
        return self._last[1]

    def _penetration(self, base_p_ball: np.ndarray, ball_radius_m: float) -> tuple[float, np.ndarray]:
        cad_p_ball = self._cad_T_base[:3, :3] @ base_p_ball + self._cad_T_base[:3, 3]
        query = o3d.core.Tensor(cad_p_ball[None].astype(np.float32))
        cad_p_nearest = self._scene.compute_closest_points(query)["points"].numpy()[0].astype(float)
        inside = self._scene.compute_occupancy(query).numpy()[0] > 0
        away = cad_p_ball - cad_p_nearest
        distance_m = float(np.linalg.norm(away))
        depth_m = ball_radius_m + distance_m if inside else ball_radius_m - distance_m
        if depth_m <= 0.0 or distance_m == 0.0:
            return 0.0, np.zeros(3)
        cad_d_out = (-away if inside else away) / distance_m
        return depth_m, self.base_T_cad[:3, :3] @ cad_d_out


@dataclass
class SimulatedArm:
    """Flange pose, active tool offset, tool tip (the centre of a ball of ``ball_radius_m``; 0: a point), contact
    surface (the plane ``z = surface_z_m``), a fixture on it (none: None) and a ceiling over the flange
    (``z = ceiling_z_m``; none: inf)."""

    base_T_flange: np.ndarray
    flange_p_tip_m: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.1]))
    surface_z_m: float = 0.0
    ball_radius_m: float = 0.0
    ceiling_z_m: float = np.inf  # something over the arm: the flange meets it from below at this height (m)
    fixture: FixtureBody | None = None
    flange_T_tcp: np.ndarray = field(default_factory=lambda: np.eye(4))
    sensor_bias_n: np.ndarray = field(default_factory=lambda: np.array([1.5, -2.0, 4.0]))
    sensor_zero_n: np.ndarray = field(default_factory=lambda: np.zeros(3))
    velocity_m_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    move: LinearMove | None = None
    speed_fraction: float = 1.0  # the teach pendant's speed slider: linear moves go at this fraction of their speed
    force_mode: ForceMode | None = None
    freedrive: bool = False

    # --- what the controller reports ---

    def tcp_pose(self) -> list[float]:
        """``actual_TCP_pose``: the active TCP (flange plus tool offset) as a UR pose vector."""
        return pose_vector(self.base_T_flange @ self.flange_T_tcp)

    def tcp_speed(self) -> list[float]:
        return [*self.velocity_m_s, 0.0, 0.0, 0.0]

    def tcp_force(self) -> list[float]:
        """``actual_TCP_force``: contact force on the tool plus sensor bias, minus the last zeroing (N)."""
        return [*(self.contact_force_n() + self.sensor_bias_n - self.sensor_zero_n), 0.0, 0.0, 0.0]

    def penetration_m(self) -> float:
        """How far the tool tip's ball reaches into the contact surface or the fixture (m); 0 when it does not touch."""
        return max(self._table_penetration_m(), self._fixture_contact()[0])

    def _base_p_tip(self) -> np.ndarray:
        return self.base_T_flange[:3, :3] @ self.flange_p_tip_m + self.base_T_flange[:3, 3]

    def _table_penetration_m(self) -> float:
        return max(self.surface_z_m - (self._base_p_tip()[2] - self.ball_radius_m), 0.0)

    def _fixture_contact(self) -> tuple[float, np.ndarray]:
        if self.fixture is None:
            return 0.0, np.zeros(3)
        return self.fixture.penetration(self._base_p_tip(), self.ball_radius_m)

    def contact_force_n(self) -> np.ndarray:
        """Force of the surface on the tool (base frame, N): along the surface normal, +z, and the fixture's along
        its surface's outward direction; and of the ceiling on the flange, -z."""
        above_ceiling_m = max(self.base_T_flange[2, 3] - self.ceiling_z_m, 0.0)
        fixture_depth_m, base_d_out = self._fixture_contact()
        table_and_ceiling_n = np.array([0.0, 0.0, self._table_penetration_m() - above_ceiling_m])
        return SURFACE_STIFFNESS_N_M * table_and_ceiling_n + FIXTURE_STIFFNESS_N_M * fixture_depth_m * base_d_out

    def in_contact(self) -> bool:
        return self.penetration_m() > 0.0

    # --- what the control program commands ---

    def move_linear(self, base_T_target: np.ndarray, speed_m_s: float) -> None:
        self.force_mode = None
        self.move = LinearMove(self.base_T_flange.copy(), base_T_target, max(speed_m_s, 1e-6))

    def moving(self) -> bool:
        return self.move is not None

    def halt(self) -> None:
        """Stop any motion (stopl, protective or emergency stop) and leave force mode."""
        self.move = None
        self.force_mode = None
        self.velocity_m_s = np.zeros(3)

    def zero_sensor(self) -> None:
        self.sensor_zero_n = self.contact_force_n() + self.sensor_bias_n

    def move_by_hand(self, base_T_flange: np.ndarray) -> None:
        """The operator moves the arm; only possible in freedrive."""
        if not self.freedrive:
            raise RuntimeError("the arm is not in freedrive: the operator cannot move it by hand")
        self.base_T_flange = np.array(base_T_flange, float)

    # --- physics ---

    def step(self, dt: float) -> None:
        """Advance the motion by ``dt`` seconds."""
        start = self.base_T_flange[:3, 3].copy()
        if self.move is not None:
            self._step_move(dt)
        elif self.force_mode is not None:
            self._step_force_mode(dt)
        self.velocity_m_s = (self.base_T_flange[:3, 3] - start) / dt

    def _step_move(self, dt: float) -> None:
        move = self.move
        move.elapsed_s += dt * self.speed_fraction
        fraction = 1.0 if move.duration_s == 0.0 else min(move.elapsed_s / move.duration_s, 1.0)
        self.base_T_flange = interpolate_pose(move.base_T_start, move.base_T_target, fraction)
        if fraction >= 1.0:
            self.move = None

    def _step_force_mode(self, dt: float) -> None:
        mode = self.force_mode
        contact_n = self.contact_force_n()
        for axis in range(3):
            if not mode.selection[axis]:
                continue
            base_d_axis = mode.base_T_task[:3, axis]
            # the robot pushes the environment with wrench[axis]; the environment pushes back with -contact
            force_error_n = mode.wrench[axis] + float(contact_n @ base_d_axis)
            speed = float(np.clip(force_error_n / (SURFACE_STIFFNESS_N_M * FORCE_MODE_TAU_S),
                                  -mode.limits[axis], mode.limits[axis]))
            self.base_T_flange[:3, 3] += speed * dt * base_d_axis
