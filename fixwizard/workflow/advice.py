"""Where to tap next to tell two candidate poses of the fixture apart.

A tap at a surface point of the most probable pose lands on the surface if that pose is true and
misses the surface of the second pose by that point's distance to it. So the best point is the surface
point (of a face the tool reaches from above) whose distance to the other pose's surface is largest.
The distance to the surface, not the displacement of the material point, is what a tap sees: on a
symmetric part a point can move far and still land on the surface.
"""

from dataclasses import dataclass

import numpy as np
import trimesh

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import invert, transform_points

SURFACE_SAMPLES = 4000
# A face counts as reachable from above when its outward normal has at least this base-z component.
REACHABLE_MIN_NORMAL_Z = -0.2
UPWARD_MIN_NORMAL_Z = 0.7  # a face this close to horizontal is "upward-facing"
BASE_DIRECTIONS = {"+x": np.array([1.0, 0.0, 0.0]), "-x": np.array([-1.0, 0.0, 0.0]),
                   "+y": np.array([0.0, 1.0, 0.0]), "-y": np.array([0.0, -1.0, 0.0])}


@dataclass(frozen=True)
class TapAdvice:
    """Tap at ``base_p_point_m`` (base frame, m; ``cad_p_point_m`` on the CAD model), on a face whose outward
    normal is ``base_n_face``: the second pose's surface is ``separation_m`` from there."""

    base_p_point_m: np.ndarray
    cad_p_point_m: np.ndarray
    base_n_face: np.ndarray
    separation_m: float

    @property
    def face(self) -> str:
        """The face in words, by where its normal points in the robot base frame."""
        if self.base_n_face[2] >= UPWARD_MIN_NORMAL_Z:
            return "the upward-facing face"
        side = max(BASE_DIRECTIONS, key=lambda name: float(BASE_DIRECTIONS[name] @ self.base_n_face))
        return f"the side face towards base {side}"

    def sentence(self) -> str:
        x, y, z = self.base_p_point_m * 1e3
        return (f"Tap {self.face} near x {round(x)}, y {round(y)}, z {round(z)} mm (robot base): the two most likely "
                f"poses put the surface {self.separation_m * 1e3:.1f} mm apart there.")


def distinguishing_tap(fixture: Fixture, first_base_T_cad: np.ndarray, second_base_T_cad: np.ndarray,
                       seed: int = 0) -> TapAdvice | None:
    """The reachable surface point of ``first_base_T_cad`` farthest from the surface at ``second_base_T_cad``;
    None when no face of the first pose is reachable from above."""
    cad_p_points, faces = trimesh.sample.sample_surface(fixture.mesh, SURFACE_SAMPLES, seed=seed)
    base_n_faces = fixture.mesh.face_normals[faces] @ first_base_T_cad[:3, :3].T
    reachable = base_n_faces[:, 2] >= REACHABLE_MIN_NORMAL_Z
    if not np.any(reachable):
        return None
    cad_p_points, base_n_faces = cad_p_points[reachable], base_n_faces[reachable]
    base_p_points = transform_points(first_base_T_cad, cad_p_points)
    fix_p_second = transform_points(fixture.fix_T_cad @ invert(second_base_T_cad), base_p_points)
    separation_m = np.abs(fixture.oracle.signed_distance_m(fix_p_second))
    best = int(np.argmax(separation_m))
    return TapAdvice(base_p_points[best], cad_p_points[best], base_n_faces[best], float(separation_m[best]))
