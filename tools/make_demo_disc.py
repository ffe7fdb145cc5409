"""Regenerate the second bundled fixture: fixwizard/data/demo_disc.stl (mm), a round plate with a flat and a notch.

Run from the repository root: ``.venv/bin/python tools/make_demo_disc.py``. The flat and the off-centre
notch leave the plate without rotational symmetry, unlike a plain disc; its round edge makes poses that
turn it about its axis hard to pin down from a few taps, which is what the guidance benchmark needs.
"""

from pathlib import Path

import numpy as np
import trimesh

DATA = Path(__file__).resolve().parents[1] / "fixwizard" / "data"
RADIUS_MM = 45.0
FLAT_Y_MM = -33.0  # the flat cuts the circle along y = FLAT_Y_MM
NOTCH_DEG = (55.0, 70.0)  # the notch spans these polar angles at the rim...
NOTCH_FLOOR_DEG = (57.0, 68.0)  # ...and these at its floor (walls not radial: no flat fan triangles)...
NOTCH_DEPTH_MM = 12.0  # ...which lies this far in from the rim
THICKNESS_MM = 25.0
STEP_DEG = 5.0


def _rim_mm(angle_deg: float) -> np.ndarray:
    """The rim point at a polar angle: on the circle, or on the flat where it cuts the circle."""
    direction = np.array([np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))])
    radius = FLAT_Y_MM / direction[1] if direction[1] * RADIUS_MM < FLAT_Y_MM else RADIUS_MM
    return radius * direction


def outline_mm() -> np.ndarray:
    """The plate's outline, counter-clockwise, its polar angle strictly increasing (star-shaped about the origin)."""
    notch_floor = RADIUS_MM - NOTCH_DEPTH_MM
    points = [_rim_mm(angle) for angle in np.arange(0.0, NOTCH_DEG[0] + 1e-9, STEP_DEG)]
    points += [notch_floor / RADIUS_MM * _rim_mm(angle) for angle in NOTCH_FLOOR_DEG]
    points += [_rim_mm(angle) for angle in np.arange(NOTCH_DEG[1], 360.0 - 1e-9, STEP_DEG)]
    return np.array(points)


def disc_mm() -> trimesh.Trimesh:
    """The plate as a watertight mesh: the outline fanned from its centre, extruded."""
    outline = outline_mm()
    vertices = np.vstack([[0.0, 0.0], outline])
    count = len(outline)
    fan = np.array([[0, 1 + i, 1 + (i + 1) % count] for i in range(count)])
    mesh = trimesh.creation.extrude_triangulation(vertices, fan, height=THICKNESS_MM)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def main() -> None:
    mesh = disc_mm()
    assert mesh.is_watertight and mesh.area_faces.min() > 1.0  # mm^2: no degenerate face
    mesh.export(DATA / "demo_disc.stl")
    print(f"{len(mesh.faces)} faces, extents {mesh.extents} mm")


if __name__ == "__main__":
    main()
