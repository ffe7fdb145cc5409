"""The fixture model: mesh loading with explicit units, the internal frame, and the distance oracle.

Frames: ``cad`` is the mesh file's own frame; ``fix`` is the internal frame, ``cad``
shifted to the centre of the mesh's exact minimum enclosing ball. Every pose shown to
users is of the ``cad`` frame.
"""

import hashlib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import igl
import numpy as np
import open3d as o3d
import trimesh

from fixwizard.errors import MeshError, MeshUnitsError
from fixwizard.geometry.meb import minimum_enclosing_ball
from fixwizard.geometry.se3 import make_transform

METRES_PER_UNIT = {"m": 1.0, "mm": 1e-3}
MESH_SUFFIXES = (".stl", ".ply", ".obj")
PLAUSIBLE_SIZE_M = (0.005, 2.5)

# Open3D answers distance queries in float32. Casting a coordinate of magnitude M errs by
# at most M * 2^-24; the closest-point arithmetic adds a few rounding steps on values of
# the same magnitude. FLOAT32_ULPS units of 2^-24 per metre of coordinate magnitude (query
# plus vertex, per axis, times sqrt(3) for the norm) cover both with a wide margin;
# tests compare against float64 distances to confirm the margin.
FLOAT32_ULPS = 64.0
UNIT_ROUNDOFF_F32 = 2.0**-24


@dataclass(frozen=True)
class Fixture:
    """A fixture mesh in metres with its internal frame.

    ``mesh``: CAD-frame mesh (m). ``cad_p_center``: minimum enclosing ball centre in the CAD
    frame (m). ``radius_m``: that ball's radius. ``warnings``: (code, message) pairs to pass on.
    """

    path: Path
    units: str
    mesh: trimesh.Trimesh
    cad_p_center: np.ndarray
    radius_m: float
    sha256: str
    warnings: tuple[tuple[str, str], ...] = field(default=())

    @property
    def watertight(self) -> bool:
        return bool(self.mesh.is_watertight)

    @property
    def fix_T_cad(self) -> np.ndarray:
        """Transform from the CAD frame to the internal frame (a pure shift)."""
        return make_transform(np.eye(3), -self.cad_p_center)

    @property
    def fix_vertices_m(self) -> np.ndarray:
        return self.mesh.vertices - self.cad_p_center

    @cached_property
    def oracle(self) -> "DistanceOracle":
        """Distance queries in the internal frame (signed where the mesh is watertight)."""
        fix_mesh = trimesh.Trimesh(self.fix_vertices_m, self.mesh.faces, process=False)
        return DistanceOracle(fix_mesh, signed=self.watertight)


class DistanceOracle:
    """Open3D distance queries to a triangle mesh; points in the mesh's frame, metres, float64 in and out.

    Signs (closed meshes only) come from the angle-weighted pseudonormal of the closest feature
    (face, edge or vertex; Baerentzen and Aanaes 2005), which is exact for a closed manifold
    mesh. Open3D's ray-parity occupancy, which errs for rays grazing edges, cross-checks it,
    and the exact generalised winding number (libigl) settles every disagreement.
    """

    # A closest point within this barycentric margin of an edge or vertex takes that feature's
    # pseudonormal (that is safe for points whose true closest feature is the face itself);
    # elsewhere the face normal is the pseudonormal. Open3D's float32 barycentrics err far less.
    FEATURE_MARGIN = 1e-3

    def __init__(self, mesh_m: trimesh.Trimesh, signed: bool) -> None:
        self.signed = signed
        self._vertices = np.asarray(mesh_m.vertices, np.float64)
        self._faces = np.asarray(mesh_m.faces, np.int64)
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(o3d.core.Tensor(self._vertices.astype(np.float32)),
                                  o3d.core.Tensor(self._faces.astype(np.uint32)))
        self._vertex_magnitude_m = float(np.abs(self._vertices).max())
        if signed:
            self._face_normals = np.asarray(mesh_m.face_normals, np.float64)
            edge_normals = np.zeros((len(mesh_m.edges_unique), 3))
            np.add.at(edge_normals, mesh_m.faces_unique_edges.ravel(), np.repeat(self._face_normals, 3, axis=0))
            self._edge_normals = edge_normals[mesh_m.faces_unique_edges]
            vertex_normals = np.zeros((len(self._vertices), 3))
            weights = mesh_m.face_angles[:, :, None] * self._face_normals[:, None, :]
            np.add.at(vertex_normals, self._faces.ravel(), weights.reshape(-1, 3))
            self._corner_normals = vertex_normals[self._faces]

    @property
    def mesh_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The mesh as float64 vertices (V, 3) in m and triangles (F, 3) of vertex indices."""
        return self._vertices, self._faces

    @property
    def bounds_m(self) -> tuple[np.ndarray, np.ndarray]:
        """Corners (m) of the mesh's axis-aligned bounding box in its frame."""
        return self._vertices.min(axis=0), self._vertices.max(axis=0)

    def _query(self, points_m: np.ndarray) -> o3d.core.Tensor:
        return o3d.core.Tensor(np.asarray(points_m, np.float32).reshape(-1, 3))

    def _pseudonormal_inside(self, points_m: np.ndarray, closest: np.ndarray, faces: np.ndarray) -> np.ndarray:
        corners = self._vertices[self._faces[faces]]
        edge1, edge2, offset = corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], closest - corners[:, 0]
        d11, d12, d22 = (np.sum(edge1 * edge1, 1), np.sum(edge1 * edge2, 1), np.sum(edge2 * edge2, 1))
        o1, o2 = np.sum(offset * edge1, 1), np.sum(offset * edge2, 1)
        denominator = d11 * d22 - d12**2
        weight1 = (d22 * o1 - d12 * o2) / denominator
        weight2 = (d11 * o2 - d12 * o1) / denominator
        barycentric = np.stack([1.0 - weight1 - weight2, weight1, weight2], axis=1)
        near_zero = barycentric <= self.FEATURE_MARGIN
        normals = self._face_normals[faces].copy()
        # edge k of a face joins corners k and k+1, so it is the edge opposite corner k+2
        for corner, edge in ((2, 0), (0, 1), (1, 2)):
            on_edge = near_zero[:, corner] & (near_zero.sum(axis=1) == 1)
            normals[on_edge] = self._edge_normals[faces[on_edge], edge]
        at_vertex = near_zero.sum(axis=1) >= 2
        corner = np.argmax(~near_zero[at_vertex], axis=1)
        normals[at_vertex] = self._corner_normals[faces[at_vertex], corner]
        return np.sum((points_m - closest) * normals, axis=1) < 0.0

    def _inside(self, points_m: np.ndarray, closest: np.ndarray, normals: np.ndarray, uvs: np.ndarray,
                faces: np.ndarray) -> np.ndarray:
        """Whether each point lies inside the closed surface, from its closest point, that face's normal and
        barycentrics; cross-checked against ray parity, with the winding number settling disagreements."""
        inside = np.einsum("ij,ij->i", points_m - closest, normals) < 0.0
        near_feature = np.flatnonzero((uvs.min(axis=1) <= self.FEATURE_MARGIN)
                                      | (uvs.sum(axis=1) >= 1.0 - self.FEATURE_MARGIN))
        inside[near_feature] = self._pseudonormal_inside(points_m[near_feature], closest[near_feature],
                                                         faces[near_feature])
        disagree = inside != (self._scene.compute_occupancy(self._query(points_m)).numpy() > 0.5)
        if np.any(disagree):
            winding = igl.winding_number(self._vertices, self._faces, points_m[disagree])
            inside[disagree] = winding > 0.5
        return inside

    def distance_and_face(self, points_m: np.ndarray,
                          signed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) from each (N, 3) point to the surface, and the face holding its closest point.

        The distance is negative inside the closed surface, for the points where ``signed`` is true (all by
        default); it is unsigned for the others and everywhere on an open mesh.
        """
        points_m = np.asarray(points_m, np.float64).reshape(-1, 3)
        result = self._scene.compute_closest_points(self._query(points_m))
        closest = result["points"].numpy().astype(np.float64)
        offsets = points_m - closest
        distance = np.sqrt(np.einsum("ij,ij->i", offsets, offsets))
        faces = result["primitive_ids"].numpy().astype(np.int64)
        if self.signed:
            rows = np.arange(len(points_m)) if signed is None else np.flatnonzero(signed)
            inside = self._inside(points_m[rows], closest[rows], result["primitive_normals"].numpy()[rows],
                                  result["primitive_uvs"].numpy()[rows], faces[rows])
            distance[rows[inside]] *= -1.0
        return distance, faces

    def ray_hit_distance_m(self, origins_m: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Distance (m) along each ray (origins (N, 3) m, unit directions (N, 3)) to the first surface it hits;
        inf where it hits none."""
        rays = np.hstack([np.asarray(origins_m, np.float32).reshape(-1, 3), np.asarray(directions, np.float32)])
        return self._scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)

    def signed_distance_m(self, points_m: np.ndarray) -> np.ndarray:
        """Signed distance (m, negative inside) where the mesh is closed; unsigned otherwise."""
        return self.distance_and_face(points_m)[0]

    def error_bound_m(self, points_m: np.ndarray) -> np.ndarray:
        """Bound ``b_eps`` (m) on the float32 error of each point's distance, from coordinate magnitudes."""
        magnitude = np.abs(points_m).max(axis=1) + self._vertex_magnitude_m
        return FLOAT32_ULPS * UNIT_ROUNDOFF_F32 * np.sqrt(3.0) * magnitude


def _load_trimesh(path: Path) -> trimesh.Trimesh:
    if path.is_dir():
        raise MeshError(f"{path} is a folder, not a mesh file; give the path of an STL, PLY or OBJ file in it")
    if not path.is_file():
        raise MeshError(f"the mesh file {path} does not exist; give the path of an STL, PLY or OBJ file")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise MeshError(f"{path} is not a mesh file fixwizard reads; export the fixture's CAD model as STL, "
                        "PLY or OBJ")
    if path.stat().st_size == 0:
        raise MeshError(f"the mesh file {path} is empty; export the fixture's CAD model again")
    try:
        mesh = trimesh.load(path, force="mesh", process=True)
    except Exception as error:  # trimesh raises many types for malformed files
        raise MeshError(f"{path} could not be read as a mesh ({error}); check that it is an STL, PLY or "
                        "OBJ export of the fixture") from error
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path} holds no triangles (a point cloud or an empty model?); export the "
                        "fixture's surface as a triangle mesh")
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshError(f"{path} has vertices that are not finite numbers; export the mesh again")
    return mesh


def _check_size(path: Path, mesh_m: trimesh.Trimesh, units: str) -> None:
    size_m = float(np.max(mesh_m.extents))
    low, high = PLAUSIBLE_SIZE_M
    if size_m > high:
        likely = "mm" if units == "m" else None
        hint = "if the file is in millimetres, its units are mm" if likely else \
            "check that the file holds the fixture and its units"
        raise MeshUnitsError(f"{path} would be a {size_m:.3g} m large fixture with units '{units}', which is "
                             f"implausible; {hint}", likely)
    if size_m < low:
        likely = "m" if units == "mm" else None
        hint = "if the file is in metres, its units are m" if likely else \
            "check the units of the file (fixwizard reads m or mm)"
        raise MeshUnitsError(f"{path} would be a {size_m * 1e3:.3g} mm small fixture with units '{units}', "
                             f"which is implausible; {hint}", likely)


def fixture_from_mesh(mesh_m: trimesh.Trimesh, path: Path, units: str, sha256: str) -> Fixture:
    """A Fixture from a mesh already in metres (``path``, ``units`` and ``sha256`` describe its source)."""
    _check_size(path, mesh_m, units)
    warnings = []
    if not mesh_m.is_watertight:
        warnings.append(("mesh_not_watertight",
                         f"{path.name} is not watertight (it has holes or open edges), so fixwizard cannot "
                         "tell inside from outside and uses the unsigned distance: the bounds stay "
                         "guaranteed but may be looser. Close the mesh in CAD for tighter bounds."))
    ball = minimum_enclosing_ball(mesh_m.vertices)
    return Fixture(path=path, units=units, mesh=mesh_m, cad_p_center=ball.center, radius_m=ball.radius,
                   sha256=sha256, warnings=tuple(warnings))


def load_fixture(path: str | Path, units: str = "m") -> Fixture:
    """Load a fixture mesh (STL/PLY/OBJ) in ``units`` ('m' or 'mm'); refuses implausible sizes."""
    path = Path(path)
    if units not in METRES_PER_UNIT:
        raise MeshError(f"mesh units must be 'm' or 'mm', not {units!r}")
    mesh = _load_trimesh(path).copy()
    mesh.apply_scale(METRES_PER_UNIT[units])
    return fixture_from_mesh(mesh, path, units, hashlib.sha256(path.read_bytes()).hexdigest())
