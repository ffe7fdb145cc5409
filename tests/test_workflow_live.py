"""The sampling screen's live figures: each tap's distance from the surface under a pose, and the quick solve
that says after each tap whether the pose is open, unique, ambiguous or inconsistent."""

import threading

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from fixwizard.demo import demo_cell
from fixwizard.geometry.se3 import make_transform
from fixwizard.solver.search import SearchCancelled
from fixwizard.workflow.live import LiveCheck, first_look, quick_check, refine_check, tap_surface_distances_m
from fixwizard.workflow.live_pipeline import NextTap, live_pipeline
from shapes import as_fixture
from tui_cell import SAMPLE_BOUND_M, spread_taps

BALL_DIAMETER_M = 0.003


@pytest.fixture(scope="module")
def tapped():
    """The demo cell and 12 spread taps on it."""
    cell = demo_cell(0)
    cell.connect()
    return cell, spread_taps(cell, 12)


def test_distance_is_from_where_the_ball_would_touch_the_surface():
    brick = as_fixture("brick")  # 100 x 60 x 30 mm box centred on the CAD origin
    base_T_cad = make_transform(np.eye(3), [0.4, 0.1, 0.015])
    base_p_taps = np.array([[0.4, 0.1, 0.03 + 0.0015],  # ball resting on the top face
                            [0.4, 0.1, 0.03 + 0.0065],  # 5 mm above that
                            [0.4 + 0.05 + 0.0015 - 0.002, 0.1, 0.01]])  # 2 mm into the +x side face
    distances = tap_surface_distances_m(brick, base_p_taps, BALL_DIAMETER_M, base_T_cad)
    np.testing.assert_allclose(distances, [0.0, 0.005, -0.002], atol=1e-6)


def test_taps_of_the_simulated_cell_touch_the_surface_under_the_true_pose(tapped):
    cell, base_p_taps = tapped
    distances = tap_surface_distances_m(cell.fixture, base_p_taps, BALL_DIAMETER_M, cell.truth.base_T_cad)
    assert np.all(np.abs(distances) <= cell.truth.fk_error_bound_m + 1e-6)


@pytest.mark.slow
def test_quick_check_needs_three_taps_and_pins_the_pose_down_with_enough_taps(tapped):
    cell, base_p_taps = tapped
    assert quick_check(cell.fixture, base_p_taps[:2], BALL_DIAMETER_M, SAMPLE_BOUND_M) is None
    few = quick_check(cell.fixture, base_p_taps[:3], BALL_DIAMETER_M, SAMPLE_BOUND_M)
    assert few.verdict == "undetermined" and few.estimate_base_T_cad is None and few.tap_count == 3
    assert few.solution.contains(cell.truth.base_T_cad)
    many = quick_check(cell.fixture, base_p_taps, BALL_DIAMETER_M, SAMPLE_BOUND_M)
    assert many.verdict == "unique"
    assert many.solution.contains(cell.truth.base_T_cad)
    distances = tap_surface_distances_m(cell.fixture, base_p_taps, BALL_DIAMETER_M, many.estimate_base_T_cad)
    assert np.all(np.abs(distances) < 0.005)


@pytest.mark.slow
def test_refining_a_check_tightens_its_bounds_on_the_same_set_and_keeps_the_true_pose(tapped):
    cell, base_p_taps = tapped
    quick = quick_check(cell.fixture, base_p_taps, BALL_DIAMETER_M, SAMPLE_BOUND_M)
    refined = refine_check(cell.fixture, quick)
    assert refined.refined and not quick.refined
    assert refined.verdict == "unique" and refined.tap_count == quick.tap_count
    assert refined.solution.cells is quick.solution.cells  # the set is taken as it is, not searched again
    assert refined.solution.bounds.position_m <= quick.solution.bounds.position_m
    assert refined.solution.bounds.rotation_rad <= quick.solution.bounds.rotation_rad
    truth, centre = cell.truth.base_T_cad, refined.solution.bounds.base_T_cad_center
    assert np.linalg.norm(truth[:3, 3] - centre[:3, 3]) <= refined.solution.bounds.position_m
    assert Rotation.from_matrix(centre[:3, :3].T @ truth[:3, :3]).magnitude() <= refined.solution.bounds.rotation_rad


@pytest.mark.slow
def test_quick_check_says_inconsistent_for_a_tap_in_the_air(tapped):
    cell, base_p_taps = tapped
    in_the_air = base_p_taps[np.argmax(base_p_taps[:, 2])] + [0.0, 0.0, 0.05]
    check = quick_check(cell.fixture, np.vstack([base_p_taps, in_the_air]), BALL_DIAMETER_M, SAMPLE_BOUND_M)
    assert check.verdict == "inconsistent" and check.estimate_base_T_cad is None
    assert check.solution.suspect_tap.index == 12


def test_quick_check_stops_when_cancelled(tapped):
    cell, base_p_taps = tapped
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(SearchCancelled):
        quick_check(cell.fixture, base_p_taps, BALL_DIAMETER_M, SAMPLE_BOUND_M, cancel)


def test_the_live_pipeline_gives_the_first_look_the_check_the_next_tap_and_the_refined_check_in_turn(tapped):
    cell, base_p_taps = tapped
    stages = list(live_pipeline(cell.fixture, base_p_taps, BALL_DIAMETER_M, SAMPLE_BOUND_M))
    first, quick, next_tap, refined = stages[:4]
    assert isinstance(first, LiveCheck) and first.rough and not first.refined and first.verdict == "unique"
    assert first.solution.contains(cell.truth.base_T_cad)
    assert isinstance(quick, LiveCheck) and not quick.rough and not quick.refined and quick.verdict == "unique"
    assert quick.solution.contains(cell.truth.base_T_cad)
    assert isinstance(next_tap, NextTap) and next_tap.advice is not None
    assert isinstance(refined, LiveCheck) and refined.refined and refined.solution.contains(cell.truth.base_T_cad)
    assert all(isinstance(stage, NextTap) and stage.plan is not None for stage in stages[4:])


def test_the_live_pipeline_stops_at_the_check_while_the_pose_is_not_pinned_down(tapped):
    cell, base_p_taps = tapped
    assert list(live_pipeline(cell.fixture, base_p_taps[:2], BALL_DIAMETER_M, SAMPLE_BOUND_M)) == []
    stages = list(live_pipeline(cell.fixture, base_p_taps[:3], BALL_DIAMETER_M, SAMPLE_BOUND_M))
    assert [(stage.rough, stage.verdict) for stage in stages] == [(True, "undetermined"), (False, "undetermined")]


def test_the_live_pipeline_stops_at_the_first_look_when_no_pose_fits(tapped):
    cell, base_p_taps = tapped
    stretched = base_p_taps[:6] * 1.3  # no rigid motion maps the fixture onto these
    stages = list(live_pipeline(cell.fixture, stretched, BALL_DIAMETER_M, SAMPLE_BOUND_M))
    assert len(stages) == 1 and stages[0].rough and stages[0].verdict == "inconsistent"


def test_the_first_look_filters_the_previous_finest_level_and_the_quick_check_goes_on_from_the_previous_search(
        tapped):
    """The first look filters only the finest level of the previous check's search against the new tap (the coarse
    levels of a set not yet pinned down hold far more cells); checks after it go on from that search, whose levels
    are all filtered, never from the first look's partly filtered tree."""
    cell, base_p_taps = tapped
    before = quick_check(cell.fixture, base_p_taps[:9], BALL_DIAMETER_M, SAMPLE_BOUND_M)
    first = first_look(cell.fixture, base_p_taps[:10], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=before)
    depth = len(before.solution.tree.levels)
    assert first.rough and first.filtered_from is before and len(first.solution.tree.levels) == depth
    assert all(mine is theirs for mine, theirs in zip(first.solution.tree.levels[:-1],
                                                      before.solution.tree.levels[:-1], strict=True))
    kept, earlier = first.solution.cells, before.solution.cells
    assert kept.rotation_level == earlier.rotation_level and kept.position_level == earlier.position_level
    assert {(int(r), *map(int, p)) for r, p in zip(kept.rotation_cells, kept.position_cells, strict=True)} <= {
        (int(r), *map(int, p)) for r, p in zip(earlier.rotation_cells, earlier.position_cells, strict=True)}
    assert len(kept) < len(earlier)  # the tenth tap removes poses
    assert first.solution.contains(cell.truth.base_T_cad)
    quick = quick_check(cell.fixture, base_p_taps[:10], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=first)
    from_before = quick_check(cell.fixture, base_p_taps[:10], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=before)
    assert len(quick.solution.cells) == len(from_before.solution.cells) and len(quick.solution.tree.levels) >= depth
    assert quick.filtered_from is None and quick.solution.contains(cell.truth.base_T_cad)
    scratch = quick_check(cell.fixture, base_p_taps[:10], BALL_DIAMETER_M, SAMPLE_BOUND_M)
    assert quick.solution.cells.rotation_level == scratch.solution.cells.rotation_level


def test_a_first_look_after_a_first_look_filters_the_same_full_search(tapped):
    """A tap while the quick check still runs cancels it: the next first look goes on from the search the last
    first look filtered, with both new taps."""
    cell, base_p_taps = tapped
    before = quick_check(cell.fixture, base_p_taps[:9], BALL_DIAMETER_M, SAMPLE_BOUND_M)
    first = first_look(cell.fixture, base_p_taps[:10], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=before)
    second = first_look(cell.fixture, base_p_taps[:11], BALL_DIAMETER_M, SAMPLE_BOUND_M, previous=first)
    assert second.filtered_from is before and second.solution.tree.final.low_m.shape[1] == 11
    assert len(second.solution.cells) <= len(first.solution.cells)
    assert second.solution.contains(cell.truth.base_T_cad)


@pytest.mark.slow
def test_a_live_check_whose_set_no_found_pose_explains_says_so_and_offers_no_estimate(real_data):
    """The expert's taps at a 0.1 mm bound they do not keep, at a budget too small to prove the set empty: the live
    line says no pose was found (not "unique so far", nor "keep tapping"), and there is no estimate to show."""
    from conftest import real_taps
    from fixwizard.fixture import load_fixture
    from fixwizard.tui.sampling.text import live_text
    from fixwizard.workflow.live import LiveView

    fixture = load_fixture(real_data / "meshes" / "matlab_logo.ply")
    check = quick_check(fixture, real_taps(real_data, "expert"), BALL_DIAMETER_M, 1e-4, max_cells=3e5)
    view = LiveView.of(check, fixture)
    assert view.verdict == "undetermined" and view.estimate_base_T_cad is None
    assert live_text(view, 20, None).startswith("Live check of 20 taps: NO POSE FOUND that explains every tap")
