"""fixwizard's nested HEALPix pixels are healpy's: the same centres, boundaries and pixel of every direction."""

import healpy
import numpy as np
import pytest

from fixwizard.geometry.healpix import pixel_boundaries, pixel_centers, pixels_of

ORDERS = [0, 1, 2, 3, 7, 12, 18, 23, 28, 29]


def _pixels(order: int, rng: np.random.Generator) -> np.ndarray:
    count = 12 * 4**order
    return np.arange(count) if count <= 20000 else rng.integers(0, count, size=20000)


@pytest.mark.parametrize("order", ORDERS)
def test_pixel_centres_and_boundaries_are_healpys(order: int) -> None:
    rng = np.random.default_rng(order)
    nside, pixels = 2**order, _pixels(order, rng)
    expected = np.stack(healpy.pix2vec(nside, pixels, nest=True), axis=1)
    assert np.abs(pixel_centers(nside, pixels) - expected).max() < 4e-15
    some = pixels[:3000]
    expected_boundary = np.moveaxis(healpy.boundaries(nside, some, step=7, nest=True).reshape(len(some), 3, -1), 1, 2)
    assert np.abs(pixel_boundaries(nside, some, 7) - expected_boundary).max() < 4e-15


@pytest.mark.parametrize("order", ORDERS)
def test_every_direction_lies_in_healpys_pixel(order: int) -> None:
    """Random directions of any length, the poles, the equator and pixel centres: healpy's pixel."""
    rng = np.random.default_rng(100 + order)
    nside, pixels = 2**order, _pixels(order, rng)
    random = rng.normal(size=(100000, 3)) * rng.choice([1e-6, 1.0, 1e6], size=(100000, 1))
    special = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [1, 1, 0], [1, -1, 0],
                        [0, 0.5, 1e-300], [1e-300, 0, 1], [-1e-300, -0.0, -1], [-1, -1e-300, 0.1]], np.float64)
    directions = np.concatenate([random, special, pixel_centers(nside, pixels)])
    assert np.array_equal(pixels_of(nside, directions), healpy.vec2pix(nside, *directions.T, nest=True))
    assert np.array_equal(pixels_of(nside, pixel_centers(nside, pixels)), pixels)


@pytest.mark.parametrize("order", ORDERS)
def test_a_direction_on_pixel_edges_lies_in_a_pixel_that_touches_it(order: int) -> None:
    """Face corners and pixel edges: rounding decides between the pixels that meet there, but a step from the
    direction a thousandth of the way towards its pixel's centre lies inside that pixel (by healpy)."""
    rng = np.random.default_rng(200 + order)
    nside, pixels = 2**order, _pixels(order, rng)
    on_edges = np.concatenate([pixel_boundaries(1, np.arange(12), 4).reshape(-1, 3),
                               pixel_boundaries(nside, pixels[:1000], 3).reshape(-1, 3)])
    found = pixels_of(nside, on_edges)
    inward = on_edges + 1e-3 * (pixel_centers(nside, found) - on_edges)
    assert np.array_equal(healpy.vec2pix(nside, *inward.T, nest=True), found)


def test_nside_and_pixel_ids_out_of_range_are_refused() -> None:
    for nside in (0, 3, 2**30):
        with pytest.raises(ValueError, match="power of two"):
            pixel_centers(nside, np.arange(3))
    with pytest.raises(ValueError, match="pixel ids"):
        pixel_centers(2, np.array([48]))
    with pytest.raises(ValueError, match="pixel ids"):
        pixel_boundaries(2, np.array([-1]), 4)
