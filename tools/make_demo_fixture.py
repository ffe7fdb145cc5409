"""Regenerate the bundled demo: fixwizard/data/demo_bracket.stl (mm) and simulated taps at a hidden pose,
two on every face the robot can reach from above and four on the top face.

Run from the repository root: ``.venv/bin/python tools/make_demo_fixture.py``. The hidden
pose is written beside the taps so the demo's result can be checked by eye.
"""

from pathlib import Path

import numpy as np
import trimesh
import yaml
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import format_ur_pose, make_transform, transform_points
from fixwizard.points import write_points
from fixwizard.synthetic import bounded_noise, touching_ball_centres

DATA = Path(__file__).resolve().parents[1] / "fixwizard" / "data"
OUTLINE_MM = np.array([[0, 0], [160, 0], [160, 20], [40, 20], [40, 30], [25, 30], [25, 90], [0, 90]], float)
FAN = np.array([[0, i, i + 1] for i in range(1, len(OUTLINE_MM) - 1)])
DEPTH_MM = 60.0
BALL_DIAMETER_M = 0.003
NOISE_BOUND_M = 0.0008
TAPS_PER_FACE = 2
TAPS_ON_LARGEST_FACE = 4  # the top face: three or more spread taps fix the tilt


def bracket_mm() -> trimesh.Trimesh:
    """An L-shaped bracket with a step, 160 x 90 x 60 mm; no rotational symmetry."""
    mesh = trimesh.creation.extrude_triangulation(OUTLINE_MM, FAN, height=DEPTH_MM)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


def main() -> None:
    mesh_mm = bracket_mm()
    mesh_mm.export(DATA / "demo_bracket.stl")
    rng = np.random.default_rng(2024)
    base_T_cad = make_transform(Rotation.from_euler("zyx", [32.0, 0.0, 0.0], degrees=True), [0.45, -0.12, 0.02])
    mesh_m = mesh_mm.copy()
    mesh_m.apply_scale(1e-3)
    reachable = (mesh_m.face_normals @ base_T_cad[:3, :3].T)[:, 2] > -0.5
    centres = []
    for rank, facet in enumerate(sorted(mesh_m.facets, key=lambda faces: -mesh_m.area_faces[faces].sum())):
        mask = np.zeros(len(mesh_m.faces))
        mask[facet] = reachable[facet]
        if mask.any():
            count = TAPS_ON_LARGEST_FACE if rank == 0 else TAPS_PER_FACE
            centres.append(touching_ball_centres(mesh_m, count, BALL_DIAMETER_M / 2, rng, face_mask=mask))
    centres = np.vstack(centres)
    taps = transform_points(base_T_cad, centres) + bounded_noise(len(centres), NOISE_BOUND_M, rng)
    write_points(DATA / "demo_bracket_taps.yaml", taps,
                 note="simulated taps on fixwizard/data/demo_bracket.stl (mm), two per reachable face, four on top, "
                      "3 mm ball, noise <= 0.8 mm",
                 hidden_pose_ur=format_ur_pose(base_T_cad))
    print(yaml.safe_dump({"hidden_pose_ur": format_ur_pose(base_T_cad)}))


if __name__ == "__main__":
    main()
