"""The Mollweide equal-area projection of the sphere of directions.

Unit sphere, central meridian at longitude 0: ``x = (2 sqrt 2 / pi) lon cos t``,
``y = sqrt 2 sin t`` with the auxiliary angle ``t`` solving ``2t + sin 2t = pi sin lat``.
The map is the ellipse ``|x| <= 2 sqrt 2``, ``|y| <= sqrt 2`` of area ``4 pi`` (the sphere's).
A direction ``(dx, dy, dz)`` has latitude ``asin(dz)`` and longitude ``atan2(dy, dx)``, so
``+z`` is the top of the map, ``+x`` its centre, ``+y`` halfway to the right edge and ``-x``
both edges.
"""

import numpy as np

HALF_WIDTH = 2.0 * np.sqrt(2.0)
HALF_HEIGHT = np.sqrt(2.0)
NEWTON_TOLERANCE_RAD = 1e-13
NEWTON_MAX_ITERATIONS = 200


def auxiliary_angle(latitude_rad: np.ndarray) -> np.ndarray:
    """The angle ``t`` (rad) with ``2t + sin 2t = pi sin(latitude)``, by Newton iteration on ``u = 2t``.

    ``f(u) = u + sin u - pi sin(lat)`` is increasing and, for ``u`` of the sign of the root,
    concave away from zero; Newton steps from ``u = 0`` therefore approach the root from the
    zero side without overshooting (quadratically, and linearly only at the poles where
    ``f'`` vanishes). The poles themselves are set exactly.
    """
    latitude_rad = np.asarray(latitude_rad, float)
    target = np.pi * np.sin(latitude_rad)
    u = np.zeros_like(target)
    for _ in range(NEWTON_MAX_ITERATIONS):
        slope = 1.0 + np.cos(u)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = np.where(slope > 0.0, (target - u - np.sin(u)) / slope, 0.0)
        u = np.clip(u + step, -np.pi, np.pi)
        if np.all(np.abs(step) <= NEWTON_TOLERANCE_RAD):
            break
    u = np.where(np.abs(latitude_rad) >= np.pi / 2, np.sign(latitude_rad) * np.pi, u)
    return u / 2.0


def mollweide_xy(latitude_rad: np.ndarray, longitude_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map coordinates ``(x, y)`` of latitudes and longitudes (rad, longitude in [-pi, pi])."""
    theta = auxiliary_angle(latitude_rad)
    return 2.0 * np.sqrt(2.0) / np.pi * np.asarray(longitude_rad, float) * np.cos(theta), np.sqrt(2.0) * np.sin(theta)


def direction_xy(directions: np.ndarray) -> np.ndarray:
    """Map coordinates (N, 2) of directions (N, 3), given in any frame and normalised here."""
    directions = np.asarray(directions, float).reshape(-1, 3)
    directions = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    latitude = np.arcsin(np.clip(directions[:, 2], -1.0, 1.0))
    longitude = np.arctan2(directions[:, 1], directions[:, 0])
    return np.stack(mollweide_xy(latitude, longitude), axis=1)
