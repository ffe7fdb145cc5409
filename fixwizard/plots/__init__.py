"""Text pictures of a solve for terminals: braille dots and ASCII, no colour needed and no Textual.

Every function takes data and a size in characters and returns a ``Picture`` of exactly that
size: ``rows`` (plain text) and ``styles`` (a name per character cell, for optional colour):
``grid`` graticule and frames, ``label`` axis names and legends, ``scale`` scale bars,
``expected`` the expected pose's marks in close-ups, ``mode1``, ``mode2`` ... orientations
of each mode, ``outline`` the fixture, ``tap`` and ``suspect`` tap numbers.
"""

from fixwizard.plots.picture import Picture
from fixwizard.plots.rotation_map import (
                                          RotationSet,
                                          rotation_map,
                                          rotation_map_for_solution,
                                          rotation_set_from_solution,
)
from fixwizard.plots.taps_view import taps_view, taps_view_for_solution

__all__ = ["Picture", "RotationSet", "rotation_map", "rotation_map_for_solution", "rotation_set_from_solution",
           "taps_view", "taps_view_for_solution"]
