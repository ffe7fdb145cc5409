"""Nested HEALPix pixels on the unit sphere: centres, boundaries and the pixel of a direction.

The three functions the rotation grid needs, vectorised over pixels, with the float operations of the HEALPix
C++ library (``healpix_base``: ``nest2xyf``, ``xyf2loc``, ``loc2pix``), so they agree with ``healpy``'s
``pix2vec``, ``boundaries`` and ``vec2pix`` with ``nest=True`` (the tests compare them). ``healpy`` itself is not
imported: its package import pulls in astropy and takes longer than the rest of a solve's imports.

A pixel at order ``k`` (``nside = 2**k``, ``k <= 29``) is ``face * 4**k + interleave(ix, iy)``: one of the 12
base faces and a position ``(ix, iy)`` on its ``nside x nside`` lattice, ``ix`` in the even bits.
"""

import numpy as np

MAX_ORDER = 29
_FACE_RING = np.array([2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4], np.float64)  # jrll: ring of a face's south corner / nside
_FACE_PHI = np.array([1, 3, 5, 7, 0, 2, 4, 6, 1, 3, 5, 7], np.float64)  # jpll: a face's longitude in pi/4
_SPREAD_MASKS = ((16, 0x0000FFFF0000FFFF), (8, 0x00FF00FF00FF00FF), (4, 0x0F0F0F0F0F0F0F0F),
                 (2, 0x3333333333333333), (1, 0x5555555555555555))
_COMPRESS_MASKS = ((1, 0x3333333333333333), (2, 0x0F0F0F0F0F0F0F0F), (4, 0x00FF00FF00FF00FF),
                   (8, 0x0000FFFF0000FFFF), (16, 0x00000000FFFFFFFF))


def _order(nside: int) -> int:
    order = int(nside).bit_length() - 1
    if nside < 1 or 2**order != nside or order > MAX_ORDER:
        raise ValueError(f"nside must be a power of two up to 2**{MAX_ORDER}, not {nside}")
    return order


def _spread_bits(values: np.ndarray) -> np.ndarray:
    """Bit ``i`` of each value moved to bit ``2 i`` (values below 2**32)."""
    spread = values.astype(np.int64)
    for shift, mask in _SPREAD_MASKS:
        spread = (spread | (spread << shift)) & mask
    return spread


def _compress_bits(values: np.ndarray) -> np.ndarray:
    """The even bits of each value, packed: the inverse of ``_spread_bits``."""
    packed = values & 0x5555555555555555
    for shift, mask in _COMPRESS_MASKS:
        packed = (packed | (packed >> shift)) & mask
    return packed


def _pixel_faces(order: int, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ix, iy, face)`` of nested pixels."""
    pixels = np.asarray(pixels, np.int64)
    if pixels.size and (pixels.min() < 0 or pixels.max() >= 12 * 4**order):
        raise ValueError(f"pixel ids must lie in [0, {12 * 4**order}) at nside {2**order}")
    in_face = pixels & (4**order - 1)
    return _compress_bits(in_face), _compress_bits(in_face >> 1), pixels >> (2 * order)


def _face_points(x: np.ndarray, y: np.ndarray, face: np.ndarray) -> np.ndarray:
    """Unit vectors (..., 3) of points ``(x, y)`` in [0, 1]^2 on base faces (``xyf2loc``)."""
    ring = _FACE_RING[face] - x - y
    north, south = ring < 1.0, ring > 3.0
    nr = np.where(north, ring, np.where(south, 4.0 - ring, 1.0))
    polar_tmp = nr * nr / 3.0
    z = np.where(north, 1.0 - polar_tmp, np.where(south, polar_tmp - 1.0, (2.0 - ring) * 2.0 / 3.0))
    near_pole = (north & (z > 0.99)) | (south & (z < -0.99))
    sin_theta = np.where(near_pole, np.sqrt(np.abs(polar_tmp * (2.0 - polar_tmp))),
                         np.sqrt(np.abs((1.0 - z) * (1.0 + z))))
    longitude = _FACE_PHI[face] * nr + x - y
    longitude = np.where(longitude < 0.0, longitude + 8.0, longitude)
    longitude = np.where(longitude >= 8.0, longitude - 8.0, longitude)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = np.where(nr < 1e-15, 0.0, (0.25 * np.pi * longitude) / nr)
    return np.stack([sin_theta * np.cos(phi), sin_theta * np.sin(phi), z], axis=-1)


def pixel_centers(nside: int, pixels: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) of the centres of nested pixels (``healpy.pix2vec(nside, pixels, nest=True)``, stacked)."""
    ix, iy, face = _pixel_faces(_order(nside), pixels)
    return _face_points((ix + 0.5) / nside, (iy + 0.5) / nside, face)


def pixel_boundaries(nside: int, pixels: np.ndarray, step: int) -> np.ndarray:
    """Boundary points (N, 4 step, 3) of nested pixels, ``step`` per edge, counter-clockwise from the north corner
    (``healpy.boundaries(nside, pixels, step, nest=True)`` with its axes (N, 3, 4 step) swapped)."""
    ix, iy, face = _pixel_faces(_order(nside), np.atleast_1d(pixels))
    half, spacing = 0.5 / nside, 1.0 / (step * nside)
    xc, yc = ((ix + 0.5) / nside)[:, None], ((iy + 0.5) / nside)[:, None]
    along = np.arange(step) * spacing
    x = np.concatenate([xc + half - along, np.repeat(xc - half, step, axis=1),
                        xc - half + along, np.repeat(xc + half, step, axis=1)], axis=1)
    y = np.concatenate([np.repeat(yc + half, step, axis=1), yc + half - along,
                        np.repeat(yc - half, step, axis=1), yc - half + along], axis=1)
    return _face_points(x, y, np.broadcast_to(face[:, None], x.shape))


def pixels_of(nside: int, directions: np.ndarray) -> np.ndarray:
    """Nested pixels (N,) holding directions (N, 3), any length but not zero (``healpy.vec2pix``, ``nest=True``)."""
    order = _order(nside)
    x, y, z = np.asarray(directions, np.float64).reshape(-1, 3).T
    inverse_length = 1.0 / np.sqrt(x * x + y * y + z * z)
    sin_theta = np.sqrt(x * x + y * y) * inverse_length
    z = z * inverse_length
    quarter = np.arctan2(y, x) * (2.0 / np.pi)
    tt = np.where(quarter >= 0.0, quarter, np.fmod(quarter, 4.0) + 4.0)
    tt = np.where(tt >= 4.0, np.where(quarter >= 0.0, np.fmod(quarter, 4.0), 0.0), tt)
    za = np.abs(z)
    faces = np.empty(len(z), np.int64)
    ix = np.empty(len(z), np.int64)
    iy = np.empty(len(z), np.int64)
    mask = nside - 1

    equatorial = za <= 2.0 / 3.0
    t1 = nside * (0.5 + tt[equatorial])
    t2 = nside * (z[equatorial] * 0.75)
    jp = (t1 - t2).astype(np.int64)
    jm = (t1 + t2).astype(np.int64)
    ifp, ifm = jp >> order, jm >> order
    faces[equatorial] = np.where(ifp == ifm, ifp | 4, np.where(ifp < ifm, ifp, ifm + 8))
    ix[equatorial] = jm & mask
    iy[equatorial] = nside - (jp & mask) - 1

    polar = ~equatorial
    zp, zap, tp_all = z[polar], za[polar], tt[polar]
    ntt = np.minimum(3, tp_all.astype(np.int64))
    tp = tp_all - ntt
    tmp = np.where(zap < 0.99, nside * np.sqrt(3.0 * (1.0 - zap)),
                   nside * sin_theta[polar] / np.sqrt((1.0 + zap) / 3.0))
    jp = np.minimum((tp * tmp).astype(np.int64), nside - 1)
    jm = np.minimum(((1.0 - tp) * tmp).astype(np.int64), nside - 1)
    north = zp >= 0.0
    faces[polar] = np.where(north, ntt, ntt + 8)
    ix[polar] = np.where(north, nside - jm - 1, jp)
    iy[polar] = np.where(north, nside - jp - 1, jm)
    return (faces << (2 * order)) + _spread_bits(ix) + (_spread_bits(iy) << 1)
