"""Synthetic taps with known truth: ball centres touching a mesh, with bounded measurement noise.

Used by tests, the bundled demo and the simulated cell. Exactness is checked in float64 by
brute force over every triangle, independent of the solver's Open3D queries (trimesh's
``closest_point`` prunes candidate faces and can miss the nearest one by a fraction of a micron).
"""

import numpy as np
import trimesh

# A candidate ball centre is kept only if its float64 distance to the surface equals the
# ball radius to this tolerance (m): then the ball touches the surface without cutting it.
CONTACT_TOLERANCE_M = 1e-9


def closest_on_triangles(points: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Closest points on triangles (a, b, c) to points, all (..., 3), by Voronoi regions (Ericson 5.1.5)."""
    ab, ac, ap = b - a, c - a, points - a
    d1, d2 = np.sum(ab * ap, -1), np.sum(ac * ap, -1)
    bp = points - b
    d3, d4 = np.sum(ab * bp, -1), np.sum(ac * bp, -1)
    cp = points - c
    d5, d6 = np.sum(ab * cp, -1), np.sum(ac * cp, -1)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denominator = 1.0 / (va + vb + vc)
        v, w = vb * denominator, vc * denominator
        result = a + ab * v[..., None] + ac * w[..., None]
        edge_bc = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        result = np.where(edge_bc[..., None], b + t_bc[..., None] * (c - b), result)
        edge_ac = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        result = np.where(edge_ac[..., None], a + (d2 / (d2 - d6))[..., None] * ac, result)
        edge_ab = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        result = np.where(edge_ab[..., None], a + (d1 / (d1 - d3))[..., None] * ab, result)
    result = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, result)
    result = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, result)
    return np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, result)


def exact_distances_m(mesh: trimesh.Trimesh, points_m: np.ndarray, batch: int = 64) -> np.ndarray:
    """Unsigned float64 distance (m) from each point to the mesh surface, by brute force over all triangles."""
    triangles = mesh.triangles
    distances = np.empty(len(points_m))
    for first in range(0, len(points_m), batch):
        block = points_m[first:first + batch, None, :]
        closest = closest_on_triangles(block, triangles[None, :, 0], triangles[None, :, 1], triangles[None, :, 2])
        distances[first:first + batch] = np.sqrt(np.min(np.sum((closest - block) ** 2, axis=-1), axis=1))
    return distances


def touching_ball_centres(mesh: trimesh.Trimesh, count: int, ball_radius_m: float, rng: np.random.Generator,
                          face_mask: np.ndarray | None = None) -> np.ndarray:
    """``count`` ball centres (mesh frame, m) at exactly ``ball_radius_m`` from the surface, outside the solid.

    Contact points are uniform over the surface (or over the faces in ``face_mask``).
    """
    return touching_ball_contacts(mesh, count, ball_radius_m, rng, face_mask)[0]


def touching_ball_contacts(mesh: trimesh.Trimesh, count: int, ball_radius_m: float, rng: np.random.Generator,
                           face_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Ball centres as ``touching_ball_centres`` and the outward surface normals (unit, mesh frame) there."""
    weights = mesh.area_faces * (face_mask if face_mask is not None else 1.0)
    centres: list[np.ndarray] = []
    normals: list[np.ndarray] = []
    while len(centres) < count:
        faces = rng.choice(len(mesh.faces), size=4 * count, p=weights / weights.sum())
        corners = mesh.triangles[faces]
        u, v = rng.random((2, len(faces)))
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        contacts = (corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0])
                    + v[:, None] * (corners[:, 2] - corners[:, 0]))
        candidates = contacts + ball_radius_m * mesh.face_normals[faces]
        distance = exact_distances_m(mesh, candidates)
        good = np.abs(distance - ball_radius_m) <= CONTACT_TOLERANCE_M
        centres.extend(candidates[good])
        normals.extend(mesh.face_normals[faces][good])
    return np.array(centres[:count]), np.array(normals[:count])


def bounded_noise(count: int, bound_m: float, rng: np.random.Generator, at_bound_fraction: float = 0.3) -> np.ndarray:
    """Noise vectors (count, 3), m: uniform in the ball of radius ``bound_m``; a fraction of exactly that length."""
    directions = rng.normal(size=(count, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    lengths = bound_m * rng.random(count) ** (1.0 / 3.0)
    lengths[rng.random(count) < at_bound_fraction] = bound_m
    return directions * lengths[:, None]
