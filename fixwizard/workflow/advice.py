"""Where to tap next: the reachable surface point where a tap shrinks the set of possible poses most.

A tap at a surface point of the estimated pose measures where the surface lies along its normal there.
A possible pose that puts the surface more than the sample bound away from there along the normal is
ruled out by that tap (if the estimate is right). So for a unique set the best point is the one where
the most possible poses (the centres of the surviving cells) put the surface farther than the sample
bound from where the estimate puts it (``next_tap``). For two candidate poses (an ambiguous result) it
is the point of the most probable pose farthest from the other pose's surface
(``distinguishing_tap``). The distance to the surface, not the displacement of the material point, is
what a tap sees: on a symmetric part a point can move far and still land on the surface.

Candidates are points the tool can reach: on faces whose outward normal does not point down, clear of
the table, with a free line along the normal for the tool and free space straight above that line
(the robot comes down to the hover pose from above, see ``hover``), and on a patch flat over the
ball's footprint (so the ball touches the face aimed at, not an edge beside it).
"""

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import trimesh

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import transform_points
from fixwizard.solver.solve import Solution

SURFACE_SAMPLES = 4000
MAX_POSES = 3000  # surviving cells a suggestion weighs (a random subset of larger sets)
# A face counts as reachable from above when its outward normal has at least this base-z component.
REACHABLE_MIN_NORMAL_Z = -0.2
UPWARD_MIN_NORMAL_Z = 0.7  # a face this close to horizontal is "upward-facing"
TABLE_CLEARANCE_M = 0.01  # a point this close above the table (the fixture's lowest point) is not offered
TOOL_CLEARANCE_M = 0.08  # free length along the normal that the tip and tool need
ABOVE_SAMPLES_M = (0.01, 0.045, 0.08)  # points along that line from which the way up must be free
FLAT_RADIUS_M = 0.003  # the surface must stay within FLAT_TOLERANCE_M of the tangent plane this far around
FLAT_TOLERANCE_M = 0.0002
CORNER_SPREAD = 0.15  # a vertex is a corner when its faces' normals span 3D: third singular value over the first
PREFER_TRIES = 8  # candidates, best first, from which a caller's preference may pick
PREFER_SHARE = 0.8  # ... each scoring at least this share of the best one's
BASE_DIRECTIONS = {"+x": np.array([1.0, 0.0, 0.0]), "-x": np.array([-1.0, 0.0, 0.0]),
                   "+y": np.array([0.0, 1.0, 0.0]), "-y": np.array([0.0, -1.0, 0.0])}


@dataclass(frozen=True)
class TapAdvice:
    """Tap at ``base_p_point_m`` (base frame, m; ``cad_p_point_m`` on the CAD model), on a face whose outward
    normal is ``base_n_face`` (base frame). Two-pose advice: the second pose's surface is ``separation_m``
    from there. Set advice (``ruled_out`` given): the possible poses put the surface up to ``separation_m``
    from there along the normal, and a tap there rules out that share of them. ``base_p_corner_m``: the
    fixture corner nearest the point (base frame, m), to find it by."""

    base_p_point_m: np.ndarray
    cad_p_point_m: np.ndarray
    base_n_face: np.ndarray
    separation_m: float
    ruled_out: float | None = None
    base_p_corner_m: np.ndarray | None = None

    @property
    def face(self) -> str:
        """The face in words, by where its normal points in the robot base frame."""
        if self.base_n_face[2] >= UPWARD_MIN_NORMAL_Z:
            return "the upward-facing face"
        side = max(BASE_DIRECTIONS, key=lambda name: float(BASE_DIRECTIONS[name] @ self.base_n_face))
        return f"the side face towards base {side}"

    def sentence(self) -> str:
        x, y, z = self.base_p_point_m * 1e3
        where = f"Tap {self.face} near x {round(x)}, y {round(y)}, z {round(z)} mm (robot base)"
        if self.base_p_corner_m is not None:
            corner_x, corner_y, corner_z = self.base_p_corner_m * 1e3
            distance_mm = np.linalg.norm(self.base_p_point_m - self.base_p_corner_m) * 1e3
            where += (f", {distance_mm:.0f} mm from the corner at x {round(corner_x)}, y {round(corner_y)}, "
                      f"z {round(corner_z)} mm")
        if self.ruled_out is None:
            return f"{where}: the two most likely poses put the surface {self.separation_m * 1e3:.1f} mm apart there."
        return (f"{where}: the possible poses put the surface up to {self.separation_m * 1e3:.1f} mm from there; "
                f"a tap there rules out about {self.ruled_out:.0%} of them.")


def corners_cad_m(fixture: Fixture) -> np.ndarray:
    """The mesh's corners (K, 3; CAD frame, m): vertices whose faces' normals span all three directions."""
    mesh = fixture.mesh
    vertex_faces = mesh.vertex_faces
    normals = np.where(vertex_faces[:, :, None] >= 0, mesh.face_normals[np.maximum(vertex_faces, 0)], 0.0)
    spread = np.linalg.svd(normals, compute_uv=False)
    return mesh.vertices[spread[:, 2] > CORNER_SPREAD * spread[:, 0]]


def _with_corner(advice: TapAdvice, fixture: Fixture, base_T_cad: np.ndarray) -> TapAdvice:
    """The advice with the fixture corner nearest its point (at ``base_T_cad``) to find it by, if there is one."""
    corners = corners_cad_m(fixture)
    if len(corners) == 0:
        return advice
    nearest = corners[np.argmin(np.linalg.norm(corners - advice.cad_p_point_m, axis=1))]
    return replace(advice, base_p_corner_m=transform_points(base_T_cad, nearest[None])[0])


def reachable_points(fixture: Fixture, base_T_cad: np.ndarray, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Reachable surface points (CAD frame, m) and their outward normals (base frame) at ``base_T_cad``."""
    mesh = fixture.mesh
    cad_p_points, faces = trimesh.sample.sample_surface(mesh, SURFACE_SAMPLES, seed=seed)
    cad_n_points = mesh.face_normals[faces]
    base_n_points = cad_n_points @ base_T_cad[:3, :3].T
    base_z = transform_points(base_T_cad, cad_p_points)[:, 2]
    table_z = transform_points(base_T_cad, mesh.vertices)[:, 2].min()
    keep = (base_n_points[:, 2] >= REACHABLE_MIN_NORMAL_Z) & (base_z >= table_z + TABLE_CLEARANCE_M)
    fix_p_points = cad_p_points[keep] - fixture.cad_p_center
    cad_n_points = cad_n_points[keep]
    free = fixture.oracle.ray_hit_distance_m(fix_p_points + 1e-4 * cad_n_points, cad_n_points) > TOOL_CLEARANCE_M
    cad_d_up = np.broadcast_to(base_T_cad[:3, :3].T @ [0.0, 0.0, 1.0], fix_p_points.shape)
    for along_m in ABOVE_SAMPLES_M:
        free &= np.isinf(fixture.oracle.ray_hit_distance_m(fix_p_points + along_m * cad_n_points, cad_d_up))
    tangent = np.cross(cad_n_points, np.where(np.abs(cad_n_points[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    bitangent = np.cross(cad_n_points, tangent)
    around = np.concatenate([fix_p_points + FLAT_RADIUS_M * sign * direction
                             for direction in (tangent, bitangent) for sign in (1.0, -1.0)])
    flat = np.all(np.abs(fixture.oracle.signed_distance_m(around)).reshape(4, -1) <= FLAT_TOLERANCE_M, axis=0)
    chosen = np.flatnonzero(keep)[free & flat]
    return cad_p_points[chosen], base_n_points[chosen]


def _first_preferred(ranked: list[TapAdvice], prefer: Callable[[TapAdvice], bool] | None) -> TapAdvice:
    """The first advice of ``ranked`` (best first) that ``prefer`` accepts, else the best."""
    if prefer is not None:
        for advice in ranked:
            if prefer(advice):
                return advice
    return ranked[0]


def _near_best(order: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """The first ``PREFER_TRIES`` candidates of ``order`` (best first) that score within ``PREFER_SHARE`` of the
    best."""
    top = order[:PREFER_TRIES]
    return top[scores[top] >= PREFER_SHARE * scores[order[0]]]


def next_tap(fixture: Fixture, solution: Solution, sample_bound_m: float, seed: int = 0,
             prefer: Callable[[TapAdvice], bool] | None = None) -> TapAdvice | None:
    """The reachable point of the estimated pose where a tap rules out the most surviving cells (see module doc);
    for an ambiguous result, ``distinguishing_tap`` of its two most probable modes. None without an estimate or
    without a reachable candidate. ``prefer``: among the few candidates nearly as good as the best, the first it
    accepts is taken instead (the robot's safe way there, say)."""
    if solution.base_T_cad is None or solution.cells is None:
        return None
    if len(solution.modes) > 1:
        return distinguishing_tap(fixture, solution.modes[0].base_T_cad, solution.modes[1].base_T_cad, seed, prefer)
    cad_p_points, base_n_points = reachable_points(fixture, solution.base_T_cad, seed)
    if len(cad_p_points) == 0:
        return None
    cells = solution.cells
    rng = np.random.default_rng(seed)
    rows = np.arange(len(cells)) if len(cells) <= MAX_POSES else rng.choice(len(cells), MAX_POSES, replace=False)
    base_R_fix, _ = cells.distinct_rotation_matrices()
    base_R_fix = base_R_fix[cells.rotation_index[rows]]
    base_t_fix = cells.positions_m(rows)
    fix_p_points = cad_p_points - fixture.cad_p_center
    base_p_points = transform_points(solution.base_T_cad, cad_p_points)
    # (R_k fix_p + t_k - base_p) . n for every cell pose k and candidate p: R_k fix_p . n = sum_ij R_kij n_i fix_pj
    outer = (base_n_points[:, :, None] * fix_p_points[:, None, :]).reshape(len(fix_p_points), 9)
    along_normal = np.abs(base_R_fix.reshape(-1, 9) @ outer.T + base_t_fix @ base_n_points.T
                          - np.sum(base_p_points * base_n_points, axis=1))
    ruled_out = np.mean(along_normal > sample_bound_m, axis=0)
    order = np.lexsort((along_normal.max(axis=0), ruled_out))[::-1]
    ranked = [TapAdvice(base_p_points[i], cad_p_points[i], base_n_points[i], float(along_normal[:, i].max()),
                        float(ruled_out[i])) for i in _near_best(order, ruled_out)]
    return _with_corner(_first_preferred(ranked, prefer), fixture, solution.base_T_cad)


def distinguishing_tap(fixture: Fixture, first_base_T_cad: np.ndarray, second_base_T_cad: np.ndarray,
                       seed: int = 0, prefer: Callable[[TapAdvice], bool] | None = None) -> TapAdvice | None:
    """The reachable surface point of ``first_base_T_cad`` farthest from the surface at ``second_base_T_cad``;
    None when no point of the first pose is reachable. ``prefer``: as for ``next_tap``."""
    cad_p_points, base_n_points = reachable_points(fixture, first_base_T_cad, seed)
    if len(cad_p_points) == 0:
        return None
    base_p_points = transform_points(first_base_T_cad, cad_p_points)
    separation_m = np.abs(fixture.signed_distance_at_m(second_base_T_cad, base_p_points))
    order = np.argsort(-separation_m, kind="stable")
    ranked = [TapAdvice(base_p_points[i], cad_p_points[i], base_n_points[i], float(separation_m[i]))
              for i in _near_best(order, separation_m)]
    return _with_corner(_first_preferred(ranked, prefer), fixture, first_base_T_cad)
