"""The operator's hands on a simulated cell: what a person does in freedrive during tip calibration and
sampling (hold the ball on a table point and turn the tool, bring the ball above a table point or a
fixture point). Demos, the wizard's SIMULATED mode and tests use it; a real cell has real hands.

Frames: the table is z = 0 of the robot base; points are in the base frame, metres.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.robot.base import RobotError
from fixwizard.robot.sim import SimulatedCell

# Tool tilts (rad) about base axes for the pivot poses: straight down, then leaning four ways.
PIVOT_TILTS = ((0.0, 0.0), (np.radians(25.0), 0.0), (0.0, np.radians(25.0)), (-np.radians(25.0), 0.0),
               (0.0, -np.radians(25.0)))
# Distances (m) from the base axis, on the side away from the fixture, of the pivot point and table corner B;
# A and C lie along the table edges from B (m).
PIVOT_REACH_M = 0.3
CORNER_REACH_M = 0.45
TABLE_POINT_OFFSETS_M = {"A": np.array([0.12, 0.0, 0.0]), "B": np.zeros(3), "C": np.array([0.0, 0.18, 0.0])}
TOOL_DOWN = Rotation.from_euler("x", np.pi)
# A fixture face counts as reachable from above when its base-frame normal has at least this z component.
REACHABLE_MIN_NORMAL_Z = -0.2
FACE_POINT_ATTEMPTS = 20


class SimulatedHands:
    """Moves a ``SimulatedCell`` as the operator would in freedrive; randomness from ``seed``."""

    def __init__(self, cell: SimulatedCell, seed: int = 0) -> None:
        self.cell = cell
        self._rng = np.random.default_rng(seed)
        base_p_fixture = cell.truth.base_T_cad[:2, 3]
        self._base_d_away = -base_p_fixture / max(float(np.linalg.norm(base_p_fixture)), 1e-9)

    @property
    def pivot_count(self) -> int:
        """How many distinct pivot poses ``pivot`` can take."""
        return len(PIVOT_TILTS)

    def pivot(self, index: int) -> None:
        """Hold the ball on one fixed table point away from the fixture, the tool turned to pose ``index``."""
        tilt_x, tilt_y = PIVOT_TILTS[index % len(PIVOT_TILTS)]
        base_R_tcp = Rotation.from_rotvec([tilt_x, tilt_y, 0.0]) * TOOL_DOWN
        base_p_ball = np.array([*(PIVOT_REACH_M * self._base_d_away), self.cell.truth.ball_diameter_m / 2.0])
        self.cell.guide_by_hand(make_transform(base_R_tcp, base_p_ball - base_R_tcp.apply(self.cell.truth.tcp_p_tip_m)))

    def table_point(self, label: str) -> None:
        """Bring the ball a few mm above table point ``label`` (A, B the corner, or C), away from the fixture."""
        base_p_corner = np.array([*(CORNER_REACH_M * self._base_d_away), 0.0])
        self.cell.place_tip_near("table", self._rng, point=base_p_corner + TABLE_POINT_OFFSETS_M[label])

    def near_fixture(self, base_p_point: np.ndarray | None = None) -> None:
        """Bring the ball a few mm above ``base_p_point`` on the fixture, or above a random up-facing point."""
        self.cell.place_tip_near("fixture", self._rng, point=base_p_point)

    def near_spread_point(self, index: int) -> None:
        """Bring the ball above a random point of the fixture's ``index``-th flat face the tool reaches from above
        (largest first, cycling), as a careful operator spreads taps; tries other points of that face where
        the tool does not fit."""
        faces = self._reachable_faces()
        face = faces[index % len(faces)]
        for _ in range(FACE_POINT_ATTEMPTS):
            try:
                self.near_fixture(transform_points(self.cell.truth.base_T_cad, self._point_on(face)[None])[0])
                return
            except RobotError:
                continue
        raise RobotError(f"could not place the tip above fixture face {index % len(faces)}: choose another face")

    def _reachable_faces(self) -> list[np.ndarray]:
        """Triangle indices of each flat face of the fixture mesh the tool reaches from above, largest first."""
        mesh = self.cell.fixture.mesh
        base_R_cad = self.cell.truth.base_T_cad[:3, :3]
        in_facet = np.zeros(len(mesh.faces), bool)
        for facet in mesh.facets:
            in_facet[facet] = True
        faces = [np.asarray(facet) for facet in mesh.facets] + [np.array([face]) for face in np.flatnonzero(~in_facet)]
        reachable = [face for face in faces if (base_R_cad @ mesh.face_normals[face[0]])[2] >= REACHABLE_MIN_NORMAL_Z]
        return sorted(reachable, key=lambda face: -mesh.area_faces[face].sum())

    def _point_on(self, faces: np.ndarray) -> np.ndarray:
        """A uniform random point (CAD frame, m) on the fixture mesh's triangles ``faces``."""
        mesh = self.cell.fixture.mesh
        areas = mesh.area_faces[faces]
        triangle = mesh.vertices[mesh.faces[self._rng.choice(faces, p=areas / areas.sum())]]
        u, v = self._rng.uniform(size=2)
        if u + v > 1.0:
            u, v = 1.0 - u, 1.0 - v
        return triangle[0] + u * (triangle[1] - triangle[0]) + v * (triangle[2] - triangle[0])
