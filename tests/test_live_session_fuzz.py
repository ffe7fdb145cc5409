"""Randomized tapping sessions on symmetric fixtures through the live pipeline, as the solver process runs it: each
check goes on from the last one the session got (the first look, the quick check or the refined one; a newer tap
may cut the pipeline short), with taps added, undone, dropped, re-added and repeated.

A symmetric fixture makes the guarantee checkable without a search of one's own: every symmetric copy of the true
pose puts the surface exactly where the true pose does, so it explains the taps exactly as well. After every tap,
at every stage:

1. every copy lies in the set's cells, within its bounds and within some mode's bounds (a miss is the worst bug);
2. the verdict is never ``unique`` (the copies lie far apart) nor ``inconsistent``;
3. after an undo or a drop of a tap the last search counted, the first look is that of the remaining taps from
   scratch (nothing of the tap gone narrows it);
4. the way above a suggested point keeps the ball ``hover.MARGIN_M`` clear of the surface at every copy.

Taps are noisy up to the sample bound, most of them exactly at it along the face normal (the worst case), one or
two at a corner, with the ball of 0, 3 or 6 mm. FUZZ_RUNS (default 1) sessions from FUZZ_SEED (default 0) for longer
local runs.
"""

import os

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from fixwizard.workflow.hover import MARGIN_M, PATH_STEP_M
from fixwizard.workflow.live import LiveCheck, first_look
from fixwizard.workflow.live_pipeline import NextTap, live_pipeline
from shapes import as_fixture, brick, cube, cylinder
from test_verdict_fuzz import contacts, hex_prism, outside

RUNS = int(os.environ.get("FUZZ_RUNS", "1"))
FIRST_SEED = int(os.environ.get("FUZZ_SEED", "0"))
UNDO_SHARE = 0.2
DROP_SHARE = 0.1  # a tap other than the last dropped (the results screen's drop of a suspect tap)
CUT_SHORT_SHARE = 0.25  # checks a newer tap cuts short after their first stages


def plate() -> trimesh.Trimesh:
    """A 120 x 80 x 4 mm plate: four turns and their flips map it onto itself."""
    return trimesh.creation.box([0.12, 0.08, 0.004])


# each fixture, centred on the CAD origin, with the turns about z (k 2 pi / n) that, with their flips, map it onto
# itself besides the cube's
SYMMETRIC = {"plate": (plate, 1), "brick": (brick, 1), "cube": (cube, 1), "hex_prism": (hex_prism, 6),
             "cylinder": (cylinder, 32)}


def symmetries(mesh: trimesh.Trimesh, turns_about_z: int) -> list[np.ndarray]:
    """The rotations (3x3, about the CAD origin) that map the mesh's vertices onto themselves."""
    candidates = list(Rotation.create_group("O").as_matrix())
    for k in range(turns_about_z):
        turn = Rotation.from_rotvec([0.0, 0.0, 2.0 * np.pi * k / turns_about_z]).as_matrix()
        candidates += [turn, turn @ np.diag([1.0, -1.0, -1.0])]
    vertices = np.asarray(mesh.vertices)
    tree = cKDTree(vertices)
    kept: list[np.ndarray] = []
    for rotation in candidates:
        maps_onto = tree.query(vertices @ rotation.T)[0].max() < 1e-9
        if maps_onto and not any(np.allclose(rotation, other) for other in kept):
            kept.append(rotation)
    return kept


def corner_taps(solid: trimesh.Trimesh, count: int, ball_radius_m: float, bound_m: float,
                rng: np.random.Generator) -> np.ndarray:
    """Ball centres (count, 3, CAD frame) at corners of a convex solid: out from a vertex along a positive
    combination of its faces' normals (in its normal cone, so the vertex is the closest point) by the ball radius,
    give or take up to the sample bound (at most that far inside)."""
    vertices = rng.choice(len(solid.vertices), count, replace=False)
    centres = []
    for vertex in vertices:
        faces = solid.vertex_faces[vertex]
        normals = solid.face_normals[faces[faces >= 0]]
        direction = rng.random(len(normals)) @ normals
        offset_m = ball_radius_m + bound_m * rng.uniform(-1.0, 1.0)
        centres.append(solid.vertices[vertex] + max(offset_m, 0.0) * direction / np.linalg.norm(direction))
    return np.array(centres)


def swept_points_m(plan, ball_radius_m: float) -> np.ndarray:
    """The ball's way down to the hover point and the tool along the normal behind it (base frame, m), at half
    the planner's spacing."""
    base_n = plan.advice.base_n_face / np.linalg.norm(plan.advice.base_n_face)
    along_tool = np.arange(0.0, 0.08 + PATH_STEP_M / 4, PATH_STEP_M / 2)
    rises = np.arange(0.0, max(plan.safe_ball_z_m - plan.base_p_ball_m[2], 0.0) + PATH_STEP_M, PATH_STEP_M / 2)
    return (plan.base_p_ball_m + rises[:, None, None] * np.array([0.0, 0.0, 1.0])
            + along_tool[None, :, None] * base_n).reshape(-1, 3)


def session(seed: int) -> list[str]:
    """Run one session; what went wrong (empty: nothing)."""
    rng = np.random.default_rng(seed)
    name = sorted(SYMMETRIC)[seed % len(SYMMETRIC)]
    make, turns = SYMMETRIC[name]
    solid = make()
    fixture = as_fixture(name, solid)
    ball_radius_m = float(rng.choice([0.0, 0.0015, 0.003]))
    bound_m = float(rng.choice([0.0003, 0.0005, 0.001, 0.002]))
    base_T_cad = np.eye(4)
    base_T_cad[:3, :3] = Rotation.random(random_state=rng.integers(2**31)).as_matrix()
    base_T_cad[:3, 3] = rng.uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 0.3])
    copies = []
    for rotation in symmetries(solid, turns):
        turned = np.eye(4)
        turned[:3, :3] = rotation
        copies.append(base_T_cad @ turned)
    count = int(rng.integers(5, 9))
    centres, normals = contacts(solid, np.arange(len(solid.faces)), count, ball_radius_m, rng)
    directions = rng.normal(size=centres.shape)
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    at_bound = rng.random(count) < 0.6
    directions[at_bound] = normals[at_bound] * rng.choice([-1.0, 1.0], (np.count_nonzero(at_bound), 1))
    lengths = bound_m * np.where(at_bound, 1.0, rng.random(count))
    cad_p_taps = np.vstack([centres + lengths[:, None] * directions,
                            corner_taps(solid, int(rng.integers(1, 3)), ball_radius_m, bound_m, rng)])
    cad_p_taps = cad_p_taps[rng.permutation(len(cad_p_taps))]
    pool = list(cad_p_taps @ base_T_cad[:3, :3].T + base_T_cad[:3, 3])
    said = (f"seed {seed}: {name} ({len(copies)} symmetries), ball {2e3 * ball_radius_m:g} mm, "
            f"bound {bound_m * 1e3:g} mm")
    vertices = np.asarray(solid.vertices)
    found: list[str] = []
    taps: list[np.ndarray] = []
    live: LiveCheck | None = None
    while pool:
        if len(taps) > 3 and rng.random() < UNDO_SHARE:
            pool.insert(0, taps.pop())
            done = "undo"
        elif len(taps) > 3 and rng.random() < DROP_SHARE:
            pool.insert(0, taps.pop(int(rng.integers(len(taps) - 1))))
            done = "drop"
        elif len(taps) > 3 and rng.random() < 0.1:
            taps.append(taps[-1])
            done = "repeat"
        else:
            taps.append(pool.pop(0))
            done = "tap"
        if len(taps) < 3:
            continue
        base_p_taps = np.array(taps)
        where = f"{said}, {len(taps)} taps after a {done}"
        stop_after = int(rng.integers(1, 4)) if rng.random() < CUT_SHORT_SHARE else None
        searched = None if live is None else live.filtered_from or live  # the search a new check goes on from
        fresh_expected = searched is not None and not is_prefix(searched.solution.problem.base_p_taps, base_p_taps)
        for number, stage in enumerate(live_pipeline(fixture, base_p_taps, 2 * ball_radius_m, bound_m, live,
                                                     seed=len(taps)), start=1):
            if isinstance(stage, LiveCheck):
                found += [f"{where}, {stage.verdict} {'first look' if stage.rough else 'check'}: {problem}"
                          for problem in check_problems(stage, copies, vertices)]
                if number == 1 and fresh_expected:
                    fresh = first_look(fixture, base_p_taps, 2 * ball_radius_m, bound_m)
                    if (stage.verdict, len(stage.solution.cells)) != (fresh.verdict, len(fresh.solution.cells)):
                        found.append(f"{where}: the first look ({stage.verdict}, {len(stage.solution.cells)} cells) "
                                     f"is not the fresh one ({fresh.verdict}, {len(fresh.solution.cells)} cells)")
                live = stage
            elif isinstance(stage, NextTap) and stage.plan is not None:
                swept = swept_points_m(stage.plan, ball_radius_m)
                gap_m = min(float(fixture.signed_distance_at_m(copy, swept).min()) for copy in copies)
                if gap_m < ball_radius_m + MARGIN_M:
                    found.append(f"{where}: the way above the suggested point passes {gap_m * 1e3:.2f} mm from the "
                                 "surface at a possible pose")
            if number == stop_after:
                break
    return found


def is_prefix(first: np.ndarray, taps: np.ndarray) -> bool:
    return len(first) <= len(taps) and np.array_equal(taps[:len(first)], first)


def check_problems(check: LiveCheck, copies: list[np.ndarray], vertices: np.ndarray) -> list[str]:
    """How a check gets the symmetric copies of the true pose wrong (empty: it does not)."""
    solution = check.solution
    if solution.bounds is None:
        return ["no pose explains the taps, but the true one does"]
    found = ["unique, but the symmetric copies lie far apart"] if check.verdict == "unique" else []
    for index, copy in enumerate(copies):
        if not solution.contains(copy):
            found.append(f"copy {index} is in no cell")
        found += [f"copy {index} outside the bounds: {why}" for why in outside(solution.bounds, copy, vertices)]
        if all(outside(mode.bounds, copy, vertices) for mode in solution.modes):
            found.append(f"copy {index} is in no mode's bounds")
    return found


@pytest.mark.slow  # a session of live checks: about a minute
@pytest.mark.parametrize("seed", range(FIRST_SEED, FIRST_SEED + RUNS))
def test_every_symmetric_copy_of_the_true_pose_stays_in_every_live_check_of_a_session(seed):
    found = session(seed)
    assert not found, "\n".join(found)
