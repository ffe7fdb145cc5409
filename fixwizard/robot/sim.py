"""A simulated robot cell: a table (z = 0 in base), a fixture at a hidden pose, a ball tip and bounded
forward-kinematics error. Needs nothing but the fixture; used by the demo and the tests.

Motion is exact in the true frame; every pose the cell *reports* carries a fresh position error
drawn from a normal with sigma = bound / 3 truncated at the bound (rotation is reported exactly),
so a ball centre computed from a report errs by at most ``fk_error_bound_m``.
"""

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import invert, make_transform, rotation_angle_rad, transform_points
from fixwizard.robot.base import (
    MAX_LINEAR_SPEED_M_S,
    MOVE_FORCE_LIMIT_N,
    ConnectionLost,
    MotionStopped,
    MoveBlocked,
    NoContact,
    ProtectiveStop,
    RobotError,
    RobotStatus,
    TapResult,
    check_limit,
    check_move_travel,
    check_tap_request,
)
from fixwizard.synthetic import touching_ball_centres

Surface = Literal["fixture", "table"]
Fault = Literal["protective_stop_during_tap", "connection_loss", "no_surface"]

# The ball touches a surface when its centre is within this distance (m) of the ball-offset surface.
CONTACT_TOLERANCE_M = 1e-6
SETTLE_S = 0.2
# move_linear: the ball's path is checked every MOVE_STEP_M (m); dipping deeper than COLLISION_DEPTH_M (m) into
# the fixture or the table blocks the move (a step can pass a corner by up to about MOVE_STEP_M / 2 unseen).
MOVE_STEP_M = 0.0005
COLLISION_DEPTH_M = 0.0002
# place_tip_near: hover height range (m), largest tilt of the tool z axis from the inward normal (rad),
# smallest base-z component of a fixture face normal that counts as facing up.
HOVER_M = (0.005, 0.010)
MAX_TILT_RAD = np.radians(30.0)
UP_FACING_MIN_Z = 0.3
PLACE_ATTEMPTS = 200
# A random fixture pose rests on the table at this distance (m) from the base axis.
REACH_M = (0.35, 0.6)


@dataclass(frozen=True, eq=False)
class SimTruth:
    """What the simulation hides from the calibration: fixture pose (CAD frame in base, m), ball centre in
    the flange frame (m), ball diameter (m) and the bound of the reported position error (m)."""

    base_T_cad: np.ndarray
    tcp_p_tip_m: np.ndarray
    ball_diameter_m: float
    fk_error_bound_m: float


def resting_pose(fixture: Fixture, rng: np.random.Generator) -> np.ndarray:
    """A random ``base_T_cad`` with the fixture on the table (lowest vertex at z = 0), random yaw, in reach."""
    base_R_cad = Rotation.from_euler("z", rng.uniform(-np.pi, np.pi))
    lowest_z = base_R_cad.apply(fixture.mesh.vertices)[:, 2].min()
    angle, distance = rng.uniform(-np.pi / 2, np.pi / 2), rng.uniform(*REACH_M)
    return make_transform(base_R_cad, [distance * np.cos(angle), distance * np.sin(angle), -lowest_z])


def _tool_rotation(base_d_tool_z: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A 3x3 rotation whose z axis is ``base_d_tool_z`` (unit), with a random spin about it."""
    x_axis = np.cross(base_d_tool_z, rng.normal(size=3))
    x_axis /= np.linalg.norm(x_axis)
    return np.column_stack([x_axis, np.cross(base_d_tool_z, x_axis), base_d_tool_z])


class SimulatedCell:
    """A robot cell in software implementing ``fixwizard.robot.base.Robot``; thread safe.

    ``truth`` holds the hidden values for tests. ``place_tip_near`` stands in for the operator's hands,
    ``inject_fault`` makes the next tap fail, ``unlock`` stands in for the teach pendant.
    """

    def __init__(self, fixture: Fixture, truth: SimTruth, seed: int = 0, pace_s: float = 0.0) -> None:
        self.fixture = fixture
        self.pace_s = pace_s
        self.truth = truth
        self._rng = np.random.default_rng(seed)
        self._fix_T_base = fixture.fix_T_cad @ invert(truth.base_T_cad)
        self._lock = threading.RLock()
        self._base_T_tcp = make_transform(Rotation.from_euler("x", np.pi), [0.3, 0.0, 0.3])
        self._connected = False
        self._protective_stop = False
        self._freedrive = False
        self._fault: Fault | None = None
        self._stop_count = 0  # ``stop`` calls (see ``base.Robot.stop_count``), under ``_stopped``
        self._stopped = threading.Condition()  # notified by ``stop``; not ``_lock``, which a move holds
        self._moving = threading.Event()  # set while a tap or move takes its time (``status`` says so)

    @classmethod
    def with_fixture(cls, fixture: Fixture, seed: int = 0, base_T_cad: np.ndarray | None = None,
                     tcp_p_tip_m: np.ndarray | None = None, ball_diameter_m: float = 0.003,
                     fk_error_bound_m: float = 0.0003, pace_s: float = 0.0) -> "SimulatedCell":
        """A cell with ``fixture`` at ``base_T_cad`` (random resting pose if None) and a tip about 10 cm
        along the flange z axis (random within 2 mm if None); all randomness from ``seed``. Each tap and
        move takes ``pace_s`` seconds (0 for tests; a demo uses a fraction of a second so motion is visible)."""
        rng = np.random.default_rng(seed)
        base_T_cad = resting_pose(fixture, rng) if base_T_cad is None else np.array(base_T_cad, float)
        if tcp_p_tip_m is None:
            tcp_p_tip_m = np.array([0.0, 0.0, 0.1]) + rng.uniform(-0.002, 0.002, 3)
        truth = SimTruth(base_T_cad, np.array(tcp_p_tip_m, float), ball_diameter_m, fk_error_bound_m)
        return cls(fixture, truth, seed=int(rng.integers(2**31)), pace_s=pace_s)

    @property
    def _ball_radius_m(self) -> float:
        return self.truth.ball_diameter_m / 2.0

    # --- the Robot protocol ---

    def connect(self) -> None:
        with self._lock:
            self._connected = True

    def close(self) -> None:
        with self._lock:
            self._connected = False

    def base_T_tcp(self) -> np.ndarray:
        with self._lock:
            self._require_connected()
            return self._reported(self._base_T_tcp)

    def freedrive(self, on: bool, stop_mark: int | None = None) -> None:
        with self._stopped, self._lock:  # ``_stopped`` before ``_lock``, wherever both are held
            self._require_connected()
            if on and stop_mark is not None and self._stop_count != stop_mark:
                raise MotionStopped("freedrive")
            self._freedrive = on

    def tap(self, max_travel_m: float = 0.02, speed_m_s: float = 0.01, force_limit_n: float = 10.0,
            stop_mark: int | None = None, on_contact: Callable[[TapResult], None] | None = None) -> TapResult:
        result = self._tap(max_travel_m, speed_m_s, force_limit_n, stop_mark)
        if on_contact is not None:  # the simulated tap has no retract of its own to report the contact before
            on_contact(result)
        return result

    def _tap(self, max_travel_m: float, speed_m_s: float, force_limit_n: float, stop_mark: int | None) -> TapResult:
        check_tap_request(max_travel_m, speed_m_s, force_limit_n)
        self._move_for_pace("tap", stop_mark)
        with self._lock:
            self._require_ready()
            fault, self._fault = self._fault, None
            if fault == "protective_stop_during_tap":
                self._protective_stop = True
                raise ProtectiveStop(" during the tap")
            if fault == "connection_loss":
                self._connected = False
                raise ConnectionLost(" during the tap")
            if fault == "no_surface":
                raise NoContact(max_travel_m)
            travel_m, surface = self._first_contact(self._base_T_tcp, max_travel_m)
            if surface is None:
                raise NoContact(max_travel_m)
            base_T_contact = self._base_T_tcp.copy()
            base_T_contact[:3, 3] += travel_m * self._base_T_tcp[:3, 2]
            return TapResult(self._reported(base_T_contact), travel_m, force_limit_n, SETTLE_S)

    def move_linear(self, base_T_tcp: np.ndarray, speed_m_s: float = 0.05, stop_mark: int | None = None) -> None:
        """Move the flange straight to ``base_T_tcp``; if the ball would hit the fixture or the table on the
        way, go back to the start and raise ``MoveBlocked``, as fixwizard's move program on a UR does when the
        contact force reaches ``MOVE_FORCE_LIMIT_N``."""
        check_limit("linear speed", speed_m_s, MAX_LINEAR_SPEED_M_S, "mm/s", 1e3)
        with self._lock:  # as a UR's move program: a target too far is refused before anything moves
            check_move_travel(float(np.linalg.norm(np.asarray(base_T_tcp, float)[:3, 3] - self._base_T_tcp[:3, 3])))
        self._move_for_pace("move", stop_mark)
        with self._lock:
            self._require_ready()
            path = self._flange_path(np.array(base_T_tcp, float))
            hit = self._first_collision(path)
            if hit is None:
                self._base_T_tcp = np.array(base_T_tcp, float)
                return
            raise MoveBlocked(MOVE_FORCE_LIMIT_N)

    def status(self) -> RobotStatus:
        with self._lock:
            mode = ("disconnected" if not self._connected else "protective stop" if self._protective_stop
                    else "moving" if self._moving.is_set() else "freedrive" if self._freedrive else "idle")
            return RobotStatus(self._connected, self._protective_stop, False, False, mode)

    def stop(self) -> None:
        """Cut short a tap or move that is waiting out its pace (it raises ``MotionStopped``) and end freedrive, as
        a UR controller's stop ends the program that holds it; never waits for the lock a move holds."""
        with self._stopped:
            self._stop_count += 1
            self._freedrive = False
            self._stopped.notify_all()

    def stop_count(self) -> int:
        with self._stopped:
            return self._stop_count

    # --- stand-ins for the operator and the teach pendant ---

    def unlock(self) -> None:
        """Unlock a protective stop, as the operator does on the teach pendant."""
        with self._lock:
            self._protective_stop = False

    def guide_by_hand(self, base_T_tcp: np.ndarray) -> None:
        """Put the flange at ``base_T_tcp`` (4x4, base frame, m) as the operator does by hand in freedrive."""
        with self._lock:
            self._require_connected()
            self._base_T_tcp = np.array(base_T_tcp, float)

    def inject_fault(self, fault: Fault) -> None:
        """Make the next tap fail: a protective stop, a dropped connection, or no surface found."""
        with self._lock:
            self._fault = fault

    def place_tip_near(self, target: Surface, rng: np.random.Generator | None = None,
                       point: np.ndarray | None = None) -> None:
        """Move the flange, as the operator does in freedrive, so the ball hovers 5-10 mm above ``point``
        (base frame, m, on the target surface) or a random up-facing point of it, the tool z axis tilted at
        most 30 deg from the inward surface normal; a default ``tap()`` then touches that surface."""
        rng = self._rng if rng is None else rng
        with self._lock:
            for _ in range(PLACE_ATTEMPTS):
                base_p_touch, base_n = self._touching_centre(target, rng, point)
                if base_p_touch[2] < self._ball_radius_m - CONTACT_TOLERANCE_M:  # through the table
                    continue
                axis = np.cross(base_n, rng.normal(size=3))
                tilt = Rotation.from_rotvec(axis / np.linalg.norm(axis) * rng.uniform(0.0, MAX_TILT_RAD))
                base_d_tool_z = tilt.apply(-base_n)
                base_R_tcp = _tool_rotation(base_d_tool_z, rng)
                base_p_ball = base_p_touch - rng.uniform(*HOVER_M) * base_d_tool_z
                base_T_tcp = make_transform(base_R_tcp, base_p_ball - base_R_tcp @ self.truth.tcp_p_tip_m)
                travel_m, surface = self._first_contact(base_T_tcp, HOVER_M[1] + CONTACT_TOLERANCE_M)
                if surface == target and travel_m > 0.0:
                    self._base_T_tcp = base_T_tcp
                    return
        raise RobotError(f"could not place the tip above the {target}: give a point on its upper surface")

    # --- internals (call with the lock held, except ``_move_for_pace``) ---

    def _move_for_pace(self, motion: str, stop_mark: int | None) -> None:
        """Let ``pace_s`` pass as the motion's duration, ``status`` saying "moving" meanwhile; a motion the cell
        refuses does not start, nor one with a STOP since ``stop_mark`` (None: since now), and a ``stop()``
        meanwhile aborts it."""
        with self._lock:
            self._require_ready()
        with self._stopped:
            mark = self._stop_count if stop_mark is None else stop_mark
            if self._stop_count != mark:
                raise MotionStopped(motion)
            self._moving.set()
            try:
                if self.pace_s > 0.0 and self._stopped.wait_for(lambda: self._stop_count != mark, self.pace_s):
                    raise MotionStopped(motion)
            finally:
                self._moving.clear()

    def _require_connected(self) -> None:
        if not self._connected:
            raise ConnectionLost()

    def _require_ready(self) -> None:
        self._require_connected()
        if self._protective_stop:
            raise ProtectiveStop(" earlier and is still locked")
        if self._freedrive:
            raise RobotError("freedrive is on, so the robot cannot move by itself: turn freedrive off, then retry")

    def _reported(self, base_T_tcp: np.ndarray) -> np.ndarray:
        """The pose as the controller would report it: position off by a truncated normal error."""
        bound = self.truth.fk_error_bound_m
        error = self._rng.normal(scale=bound / 3.0, size=3)
        while np.linalg.norm(error) > bound:
            error = self._rng.normal(scale=bound / 3.0, size=3)
        reported = base_T_tcp.copy()
        reported[:3, 3] += error
        return reported

    def _touching_centre(self, target: Surface, rng: np.random.Generator,
                         point: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """A ball centre (base, m) touching ``target`` at ``point`` or at a random up-facing point, and the
        outward surface normal there (base, unit)."""
        radius = self._ball_radius_m
        if target == "table":
            base_p = rng.uniform(-0.7, 0.7, 3) if point is None else np.asarray(point, float)
            return np.array([base_p[0], base_p[1], radius]), np.array([0.0, 0.0, 1.0])
        mesh = self.fixture.mesh
        base_R_cad = self.truth.base_T_cad[:3, :3]
        if point is None:
            up_facing = (mesh.face_normals @ base_R_cad.T)[:, 2] >= UP_FACING_MIN_Z
            cad_p_ball = touching_ball_centres(mesh, 1, radius, rng, face_mask=up_facing)[0]
            _, _, (face,) = mesh.nearest.on_surface(cad_p_ball[None])
        else:
            cad_p_surface, _, (face,) = mesh.nearest.on_surface(transform_points(invert(self.truth.base_T_cad),
                                                                                 np.asarray(point, float)[None]))
            cad_p_ball = cad_p_surface[0] + radius * mesh.face_normals[face]
        return transform_points(self.truth.base_T_cad, cad_p_ball[None])[0], base_R_cad @ mesh.face_normals[face]

    def _flange_path(self, base_T_tcp_end: np.ndarray) -> np.ndarray:
        """Flange poses (K, 4, 4) along a linear move from the current pose, position linear and rotation
        slerped, with the ball advancing at most ``MOVE_STEP_M`` between poses."""
        start, end = self._base_T_tcp, base_T_tcp_end
        tip = self.truth.tcp_p_tip_m
        rotations = Rotation.from_matrix(np.stack([start[:3, :3], end[:3, :3]]))
        turn_rad = rotation_angle_rad(start[:3, :3].T @ end[:3, :3])
        length_m = np.linalg.norm(end[:3, 3] - start[:3, 3]) + turn_rad * np.linalg.norm(tip)
        fractions = np.linspace(0.0, 1.0, max(2, int(np.ceil(length_m / MOVE_STEP_M)) + 1))
        path = np.repeat(np.eye(4)[None], len(fractions), axis=0)
        path[:, :3, :3] = Slerp([0.0, 1.0], rotations)(fractions).as_matrix()
        path[:, :3, 3] = start[:3, 3] + fractions[:, None] * (end[:3, 3] - start[:3, 3])
        return path

    def _first_collision(self, path: np.ndarray) -> int | None:
        """Index of the first flange pose of ``path`` after its start where the ball dips more than
        ``COLLISION_DEPTH_M`` into the fixture or the table, or None."""
        base_p_balls = path[1:, :3, 3] + path[1:, :3, :3] @ self.truth.tcp_p_tip_m
        clearance = np.minimum(self.fixture.signed_distance_at_m(self.truth.base_T_cad, base_p_balls),
                               base_p_balls[:, 2])
        deep = np.flatnonzero(clearance - self._ball_radius_m < -COLLISION_DEPTH_M)
        return int(deep[0]) + 1 if len(deep) else None

    def _first_contact(self, base_T_tcp: np.ndarray, max_travel_m: float) -> tuple[float, Surface | None]:
        """Travel (m) of the ball along the tool z axis from ``base_T_tcp`` until it touches the fixture or
        the table, and which; ``(max_travel_m, None)`` if it touches nothing within ``max_travel_m``."""
        base_p_start = transform_points(base_T_tcp, self.truth.tcp_p_tip_m[None])[0]
        base_d = base_T_tcp[:3, 2]
        radius = self._ball_radius_m
        table_m = max(base_p_start[2] - radius, 0.0) / -base_d[2] if base_d[2] < 0 else np.inf
        fixture_m = self._fixture_travel_m(base_p_start, base_d, min(table_m, max_travel_m))
        if fixture_m <= min(table_m, max_travel_m):
            return fixture_m, "fixture"
        if table_m <= max_travel_m:
            return table_m, "table"
        return max_travel_m, None

    def _fixture_travel_m(self, base_p_start: np.ndarray, base_d: np.ndarray, limit_m: float) -> float:
        """Sphere tracing on the fixture's signed distance: travel (m) until the ball touches it, or inf
        beyond ``limit_m``. Distances are 1-Lipschitz, so each step by the clearance stays free."""
        fix_p_start = transform_points(self._fix_T_base, base_p_start[None])[0]
        fix_d = self._fix_T_base[:3, :3] @ base_d
        travel_m = 0.0
        while travel_m <= limit_m:
            clearance = self.fixture.oracle.signed_distance_m(fix_p_start + travel_m * fix_d)[0] - self._ball_radius_m
            if clearance <= CONTACT_TOLERANCE_M:
                return max(travel_m, 0.0)
            travel_m += clearance
        return np.inf
