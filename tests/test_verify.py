"""`fixwizard verify`: new taps tested against the poses a report's guaranteed set allows. On the paper's real expert
run its own taps are consistent and the same taps moved by 3 mm or turned by 2 deg are proved moved; on the
simulated cell a moved fixture is found from four suggested taps; the start cells cover the bounds region, a true
pose is never called moved, and a user's mistake gets a message."""

import datetime as dt
import re
import shutil

import numpy as np
import pytest
import trimesh
import yaml
from scipy.spatial.transform import Rotation

from conftest import real_taps
from fixwizard import report
from fixwizard.calibration.taps import ball_centres_m
from fixwizard.cli import main
from fixwizard.demo import DEMO_MESH, DEMO_TAPS, demo_fixture
from fixwizard.errors import InputError
from fixwizard.fixture import load_fixture
from fixwizard.geometry.se3 import invert, make_transform, transform_points
from fixwizard.points import write_points
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.solver.solve import solve
from fixwizard.solver.verify_search import AllowedRegion, search_region, start_cells
from fixwizard.synthetic import bounded_noise, touching_ball_centres
from fixwizard.workflow.missable_move import missable_move, tap_jacobian
from fixwizard.workflow.verify import (
    SUPPORT_CLEARANCE_M,
    UP_FACING_NORMAL_Z,
    fixture_of,
    suggest_check_points,
    verdict_lines,
    verify,
)
from shapes import as_fixture
from test_report import V1_REPORT
from tui_cell import spread_taps

pytestmark = pytest.mark.slow  # the expert run solved and verified (27 s to set up), 5-35 s a test

BALL_M, BOUND_M = 0.003, 0.001


@pytest.fixture(scope="module")
def expert(real_data, tmp_path_factory):
    """The expert run's report (1e7 cells) in a folder, its taps, and the fixture centre in the base frame."""
    folder = tmp_path_factory.mktemp("expert")
    fixture = load_fixture(real_data / "meshes" / "matlab_logo.ply")
    taps = real_taps(real_data, "expert")
    solution = solve(fixture, taps, BALL_M, BOUND_M, max_cells=1e7)
    assert solution.status == "unique"
    path = report.write(folder / "logo.yaml", report.report_dict(solution, fixture, taps, BALL_M, BOUND_M, BOUND_M / 3))
    centre = transform_points(solution.base_T_cad, fixture.cad_p_center[None])[0]
    return folder, path, taps, centre


def run_verify(folder, report_path, taps, *extra) -> int:
    points = folder / "new.yaml"
    write_points(points, taps)
    return main(["verify", str(report_path), str(points), *extra])


def within_mm(out: str) -> tuple[float, float]:
    """How far (mm) a consistent verdict says the taps let the fixture's points be from the report's pose, and the
    report's guarantee it compares that with."""
    found = re.search(r"within ([0-9.]+) mm of the report's pose(?: only)?, (?:no )?more than the ([0-9.]+) mm", out)
    assert found, out
    return float(found[1]), float(found[2])


def test_the_expert_runs_own_taps_are_consistent_with_its_report_and_say_to_keep_using_its_pose(expert, capsys):
    """Its 20 taps spread over the logo see every move well: to first order they put every point of the fixture
    within the report's own guarantee of its pose (3.22 mm at a 1 mm sample bound), so the pose is to be kept."""
    folder, path, taps, _ = expert
    assert run_verify(folder, path, taps) == 0
    out = capsys.readouterr().out
    assert "consistent with the report" in out and "with the report's own taps" in out and "MOVED" not in out
    figure_mm, guaranteed_mm = within_mm(out)
    assert guaranteed_mm == pytest.approx(report.load(path).pose_to_use()[1].max_point_displacement_m * 1e3, abs=0.01)
    assert 2 * BOUND_M * 1e3 < figure_mm <= guaranteed_mm  # two sample bounds apart at least: the taps' own slack
    assert "to first order (small moves)" in out and "Keep using the report's pose." in out
    assert "sample bound 1.00 mm." in out  # the report's, as given by default: nothing to say


def test_a_sample_bound_below_the_reports_is_raised_to_it_and_said_so(expert, capsys):
    """One bound serves the report's taps and the new ones: --sample-bound 0.5mm against a report of 1 mm was raised
    to 1 mm without a word (the line showed 1.00 mm, as if given)."""
    folder, path, taps, _ = expert
    assert run_verify(folder, path, taps[:8], "--sample-bound", "0.5mm") == 0
    assert ("sample bound 1.00 mm (the report's: one bound serves its taps and the new ones; 0.50 mm was given)."
            in capsys.readouterr().out)


def test_taps_just_above_the_old_seen_threshold_do_not_say_to_keep_using_the_pose(expert, real_data, capsys):
    """Six of the expert's taps whose weakest singular value (0.0505) just passed the old yes/no threshold (0.05):
    a move along that direction must be about 2 b / 0.05 before it takes a tap off its band, far more than the
    report guarantees. The verdict said "Keep using the report's pose"; it now gives how far the taps let the
    fixture be, names the move seen least and where to tap to see it."""
    folder, path, taps, _ = expert
    chosen = taps[[4, 8, 9, 10, 11, 19]]
    pose = report.load(path).pose_to_use()[0]
    jacobian = tap_jacobian(load_fixture(real_data / "meshes" / "matlab_logo.ply"), pose, chosen)[0]
    weakest = np.linalg.svd(jacobian, compute_uv=False)[-1]
    assert 0.05 <= weakest < 0.052
    assert run_verify(folder, path, chosen) == 0
    out = capsys.readouterr().out
    assert "Keep using" not in out
    figure_mm, guaranteed_mm = within_mm(out)
    assert figure_mm > 2 * BOUND_M * 1e3 / 0.0505 > 10 * guaranteed_mm
    assert "the report's pose may be off by up to" in out and "least (up to" in out
    assert re.search(r"they see a (slide along|turn about) .* least", out) and "tap a face pointing" in out


@pytest.mark.parametrize("offset_mm", [(3, 0, 0), (0, 3, 0), (0, 0, 3), (-2.1, 2.1, 0)])
def test_the_expert_taps_moved_by_3_mm_prove_the_fixture_moved(expert, capsys, offset_mm):
    folder, path, taps, _ = expert
    assert run_verify(folder, path, taps + np.array(offset_mm) * 1e-3) == 2
    out = capsys.readouterr().out
    assert "MOVED: no pose the report allows explains the 20 taps (this is a proof)" in out
    assert "no allowed pose explains them (proved)" in out


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_the_expert_taps_turned_by_2_deg_prove_the_fixture_moved(expert, capsys, axis):
    folder, path, taps, centre = expert
    turned = Rotation.from_euler(axis, 2.0, degrees=True).apply(taps - centre) + centre
    assert run_verify(folder, path, turned) == 2
    assert "MOVED" in capsys.readouterr().out


def test_four_spread_taps_are_enough_to_check(expert, capsys):
    folder, path, taps, _ = expert
    spread = taps[[0, 6, 12, 18]]
    assert run_verify(folder, path, spread) == 0
    assert run_verify(folder, path, spread + [0.0, 0.0, 0.003]) == 2
    assert "4 taps" in capsys.readouterr().out


def test_a_changed_or_missing_mesh_is_refused_and_a_copy_elsewhere_is_taken(expert, real_data, tmp_path, capsys):
    _, path, taps, _ = expert
    copy = shutil.copy(real_data / "meshes" / "matlab_logo.ply", tmp_path / "logo.ply")
    data = yaml.safe_load(path.read_text())
    data["fixture"]["mesh"] = str(tmp_path / "logo.ply")
    moved_report = report.write(tmp_path / "r.yaml", data)
    assert run_verify(tmp_path, moved_report, taps[:4]) == 0
    with open(copy, "ab") as stream:
        stream.write(b"\n")
    assert run_verify(tmp_path, moved_report, taps[:4]) == 1
    assert "not the one the report" in capsys.readouterr().err
    (tmp_path / "logo.ply").unlink()
    assert run_verify(tmp_path, moved_report, taps[:4]) == 1
    err = capsys.readouterr().err
    assert "is missing" in err and "--mesh" in err and "Traceback" not in err
    assert run_verify(tmp_path, moved_report, taps[:4], "--mesh", str(real_data / "meshes")) == 1
    assert "meshes you gave is a folder or a special file, not a mesh file" in capsys.readouterr().err
    assert run_verify(tmp_path, moved_report, taps[:4], "--mesh", str(real_data / "meshes" / "matlab_logo.ply")) == 0


def test_a_mesh_saved_again_between_its_check_and_its_loading_is_refused(tmp_path, monkeypatch):
    """The report's mesh was hashed, then read again to load: a CAD tool saving it in between had the taps checked
    against another mesh than the report's. The bytes loaded are checked too."""
    mesh = tmp_path / "bracket.stl"
    shutil.copy(DEMO_MESH, mesh)

    def saved_again_then_loaded(path, units):
        trimesh.creation.box((100.0, 60.0, 40.0)).export(mesh)  # another fixture, in the report's millimetres
        return load_fixture(path, units)

    monkeypatch.setattr("fixwizard.workflow.verify.load_fixture", saved_again_then_loaded)
    with pytest.raises(InputError, match="is not the one the report .* was made with"):
        fixture_of(report.load(V1_REPORT), mesh)


def test_a_version_1_report_is_checked_with_its_mesh_given(tmp_path, capsys):
    taps = np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"])
    assert run_verify(tmp_path, V1_REPORT, taps[:5]) == 1
    assert "fixtures/demo_bracket.stl" in capsys.readouterr().err
    assert run_verify(tmp_path, V1_REPORT, taps[:5], "--mesh", str(DEMO_MESH)) == 0
    assert run_verify(tmp_path, V1_REPORT, taps[:5] + [0.004, 0.0, 0.0], "--mesh", str(DEMO_MESH)) == 2


def test_a_report_without_its_own_taps_is_said_to_be_tested_by_its_bounds_alone_for_that_reason(tmp_path, capsys):
    data = yaml.safe_load(V1_REPORT.read_text())
    data["inputs"]["points_m"] = []  # a hand-edited copy: it blamed the ball, which was the same
    report_path = tmp_path / "no-taps.yaml"
    report_path.write_text(yaml.safe_dump(data))
    taps = np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"])[:4]
    assert run_verify(tmp_path, report_path, taps, "--mesh", str(DEMO_MESH)) == 0
    out = capsys.readouterr().out
    assert "Tested against the report's bounds only (the report lists no taps of its own" in out and "ball" not in out


def test_taps_in_millimetres_are_refused_not_called_a_moved_fixture(tmp_path, capsys):
    taps = np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"])[:4]
    assert run_verify(tmp_path, V1_REPORT, taps * 1e3, "--mesh", str(DEMO_MESH)) == 1  # was 2, "MOVED"
    out, err = capsys.readouterr()
    assert "MOVED" not in out and "Traceback" not in err
    assert err.startswith("fixwizard: tap 1 lies 571 m from the robot base") and "millimetres read as metres" in err


def test_mistakes_get_a_message_not_a_traceback(expert, tmp_path, capsys):
    folder, path, taps, _ = expert
    (tmp_path / "empty.csv").write_text("")
    assert main(["verify", str(path), str(tmp_path / "empty.csv")]) == 1
    assert "at least one tap" in capsys.readouterr().err
    (tmp_path / "nan.csv").write_text("0.1,0.2,0.3\n0.1,nan,0.3\n")
    assert main(["verify", str(path), str(tmp_path / "nan.csv")]) == 1
    assert main(["verify", str(tmp_path / "nan.csv"), str(tmp_path / "nan.csv")]) == 1
    assert run_verify(folder, path, taps[:3], "--sample-bound", "1") == 1
    err = capsys.readouterr().err
    assert "a sample bound of 1000 mm is implausible" in err and "ball" not in err
    assert run_verify(folder, path, taps[:3], "--ball-diameter", "60mm") == 1
    assert "a 60 mm tip ball is implausible" in capsys.readouterr().err
    data = yaml.safe_load(path.read_text())
    data.update(status="inconsistent", pose=None, bounds=None, intervals=None)
    inconsistent = report.write(tmp_path / "bad.yaml", data)
    assert run_verify(tmp_path, inconsistent, taps[:3]) == 1
    err = capsys.readouterr().err
    assert "no pose to check taps against" in err and "Traceback" not in err


def test_another_ball_is_tested_against_the_bounds_alone_and_says_so(expert, capsys):
    folder, path, taps, _ = expert
    assert run_verify(folder, path, taps, "--ball-diameter", "3.2mm") == 0
    assert "a weaker test" in capsys.readouterr().out


def _random_region(rng, base_T_cad: np.ndarray) -> AllowedRegion:
    """A region that holds ``base_T_cad`` (anywhere in it, often near its edge)."""
    position_m, rotation_rad = rng.uniform(1e-4, 5e-3), rng.uniform(1e-4, 0.1)
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    turn = Rotation.from_rotvec(axis / np.linalg.norm(axis) * rotation_rad * rng.uniform(0, 1) ** 0.3)
    centre = make_transform(turn * Rotation.from_matrix(base_T_cad[:3, :3]), base_T_cad[:3, 3]
                            + position_m * rng.uniform(0, 1) ** 0.3 * direction / np.linalg.norm(direction))
    return AllowedRegion(centre, position_m, rotation_rad)


def test_the_start_cells_hold_every_pose_of_the_region():
    """Random regions and poses inside them (many at their edge): each pose's internal frame lies in a start cell."""
    fixture = as_fixture("l_prism")
    rng = np.random.default_rng(5)
    fix_T_cad = fixture.fix_T_cad
    for _ in range(60):
        region = _random_region(rng, make_transform(Rotation.random(random_state=rng), rng.uniform(-0.5, 0.5, 3)))
        cells = start_cells(region, fixture)
        for _ in range(30):
            edge = rng.random() < 0.5
            pose = _random_region(rng, region.base_T_cad_center)  # a pose near the centre, at up to its bounds
            turn = Rotation.from_matrix(pose.base_T_cad_center[:3, :3] @ region.base_T_cad_center[:3, :3].T)
            angle = region.rotation_rad * (1.0 if edge else rng.uniform(0, 1))
            rotation = Rotation.from_rotvec(turn.as_rotvec() / max(turn.magnitude(), 1e-12) * angle)
            shift = rng.normal(size=3)
            position = region.base_T_cad_center[:3, 3] + shift / np.linalg.norm(shift) * region.position_m * (
                1.0 if edge else rng.uniform(0, 1))
            base_T_cad = make_transform(rotation * Rotation.from_matrix(region.base_T_cad_center[:3, :3]), position)
            assert cells.contains(base_T_cad @ invert(fix_T_cad))


def test_taps_at_a_pose_the_region_holds_are_never_called_moved():
    """Random shapes, regions holding the true pose, taps with errors up to the bound (some exactly at it):
    consistent, every time; the same taps 4 bounds off along the fixture's normal directions are proved moved."""
    rng = np.random.default_rng(9)
    moved = 0
    for trial in range(24):
        fixture = as_fixture(["l_prism", "polytope", "brick", "cone"][trial % 4])
        truth = make_transform(Rotation.random(random_state=rng), rng.uniform(-0.3, 0.3, 3))
        bound = rng.uniform(3e-4, 1.5e-3)
        count = int(rng.integers(1, 9))
        taps = transform_points(truth, touching_ball_centres(fixture.mesh, count, BALL_M / 2, rng))
        taps += bounded_noise(count, bound, rng)
        region = _random_region(rng, truth)
        assert not search_region(fixture, region, taps, BALL_M, bound, max_cells=2e5).moved
        shifted = taps + [0.0, 0.0, 4 * bound + region.position_m + fixture.radius_m * region.rotation_rad]
        moved += search_region(fixture, region, shifted, BALL_M, bound, max_cells=2e5).moved
    assert moved >= 12  # a shift far beyond the region is found most of the time, even from one tap


def test_on_the_simulated_cell_the_suggested_taps_tell_a_moved_fixture_or_to_keep_using_the_pose(tmp_path):
    """Calibrate the demo cell, then check it with the seven suggested taps: untouched they are consistent and see
    every move well enough to keep using the report's pose (four, as suggested before, never could: six ways to
    move); the fixture pushed by 4 mm or turned by 3 deg on the table is found moved."""
    fixture = demo_fixture()
    cell = SimulatedCell.with_fixture(fixture, seed=3)
    cell.connect()
    taps = spread_taps(cell, 14)
    solution = solve(fixture, taps, BALL_M, 0.00035, max_cells=2e6, max_samples=2000)
    assert solution.status == "unique"
    path = report.write(tmp_path / "r.yaml", report.report_dict(solution, fixture, taps, BALL_M, 0.00035, 0.00035 / 3,
                                                                simulated=True))
    loaded = report.load(path)
    checked = fixture_of(loaded)
    points = suggest_check_points(checked, loaded.base_T_cad, BALL_M)
    assert len(points) == 7 and all("face pointing" in point.where for point in points)
    truth = cell.truth.base_T_cad
    pushed = truth.copy()
    pushed[:3, 3] += [0.004, 0.0, 0.0]
    turn = make_transform(Rotation.from_euler("z", 3, degrees=True), np.zeros(3))
    centre = transform_points(truth, fixture.cad_p_center[None])[0]
    turned = make_transform(np.eye(3), centre) @ turn @ make_transform(np.eye(3), -centre) @ truth
    for base_T_cad, expected in ((truth, False), (pushed, True), (turned, True)):
        moved_cell = SimulatedCell.with_fixture(fixture, seed=4, base_T_cad=base_T_cad,
                                                tcp_p_tip_m=cell.truth.tcp_p_tip_m)
        moved_cell.connect()
        moved_hands = SimulatedHands(moved_cell, seed=2)
        contacts = []
        for point in points:
            moved_hands.near_fixture(point.base_p_ball_m)
            contacts.append(moved_cell.tap().base_T_tcp_contact)
        new_taps = ball_centres_m(np.array(contacts), cell.truth.tcp_p_tip_m)
        result = verify(loaded, checked, new_taps, BALL_M, 0.00035)
        assert result.moved is expected
        assert result.with_report_taps and (result.bracket is not None) is expected
        if not expected:  # consistent, and seven taps on faces facing different ways bound every move
            said = verdict_lines(result)[0]
            assert said.startswith("consistent with the report: poses the report allows explain the 7 taps, and to "
                                   "first order (small moves) they put every point of the fixture within ")
            assert said.endswith("Keep using the report's pose.")
            assert result.missable.point_m <= loaded.pose_to_use()[1].max_point_displacement_m
    assert dt.datetime.now(dt.UTC) - loaded.created < dt.timedelta(minutes=10)


def test_taps_bound_the_move_only_when_six_or_more_face_different_ways():
    """A move of the fixture that keeps every tapped point on its face changes no tap's distance: four taps always
    leave such moves (six ways to move), eight on the top face leave slides along it and a turn about its normal:
    no bound; eight and fourteen taps spread over the demo bracket's faces bound every move, more taps more
    tightly."""
    fixture = demo_fixture()
    cell = SimulatedCell.with_fixture(fixture, seed=3)
    cell.connect()
    base_T_cad = cell.truth.base_T_cad
    spread = spread_taps(cell, 14)
    facing_up = (fixture.mesh.face_normals @ base_T_cad[:3, :3].T)[:, 2] > 0.99
    on_top = touching_ball_centres(fixture.mesh, 8, BALL_M / 2.0, np.random.default_rng(0), facing_up)
    def point_m(taps):
        return missable_move(fixture, base_T_cad, taps, BALL_M, 0.00035).point_m

    assert 0.0 < point_m(spread) < point_m(spread[:8]) < fixture.radius_m
    assert point_m(spread[:4]) == np.inf
    on_top_move = missable_move(fixture, base_T_cad, transform_points(base_T_cad, on_top), BALL_M, 0.00035)
    assert on_top_move.point_m == np.inf
    assert np.abs(on_top_move.base_m_move[2:5]) == pytest.approx(0.0, abs=1e-3)  # keeps the top face in its plane


@pytest.mark.parametrize("seed", range(6))
def test_no_suggested_tap_puts_the_ball_where_the_fixture_rests(seed):
    """At any pose on the table (a random turn and offset; resting on any of its faces), every suggested ball clears
    the fixture's lowest point: the foot of a side face is where the table is, a ball there cannot be tapped."""
    fixture = demo_fixture()
    rng = np.random.default_rng(seed)
    base_R_cad = Rotation.random(random_state=seed).as_matrix()
    lowest_m = np.min(fixture.mesh.vertices @ base_R_cad.T, axis=0)[2]
    base_T_cad = make_transform(base_R_cad, np.array([*rng.uniform(-0.5, 0.5, 2), -lowest_m]))
    ball_m = rng.uniform(0.002, 0.01)
    points = suggest_check_points(fixture, base_T_cad, ball_m, count=5)
    assert len(points) == 5
    for point in points:
        assert point.base_p_ball_m[2] - ball_m / 2 >= SUPPORT_CLEARANCE_M - 1e-12, point.where


@pytest.mark.parametrize("seed", range(4))
def test_on_a_sheet_too_thin_to_clear_the_table_every_suggestion_is_on_its_upper_face(seed):
    """A sheet 0.5-1.9 mm thick lying flat, at a random turn and offset: no ball clears its lowest point by
    SUPPORT_CLEARANCE_M, and none is suggested at its edge, where the ball would meet the table; every suggestion
    is on the upper face."""
    rng = np.random.default_rng(seed)
    thickness_m = rng.uniform(0.0005, 0.0019)
    sheet = trimesh.creation.box((rng.uniform(0.05, 0.15), rng.uniform(0.03, 0.1), thickness_m))
    base_T_cad = make_transform(Rotation.from_euler("z", rng.uniform(0, 360), degrees=True),
                                np.array([*rng.uniform(-0.5, 0.5, 2), thickness_m / 2]))
    ball_m = rng.uniform(0.002, 0.01)
    points = suggest_check_points(as_fixture("sheet", sheet), base_T_cad, ball_m, count=4)
    assert len(points) == 4
    for point in points:
        assert point.base_n[2] >= UP_FACING_NORMAL_Z and "pointing up" in point.where, point.where
        assert point.base_p_ball_m[2] == pytest.approx(thickness_m + ball_m / 2, abs=1e-9)


def test_a_mistaken_argument_to_verify_is_an_input_error(expert):
    path = expert[1]
    loaded = report.load(path)
    with pytest.raises(InputError, match="at least one tap"):
        verify(loaded, None, np.zeros((0, 3)))
    with pytest.raises(InputError, match="far more"):
        verify(loaded, None, np.zeros((500, 3)))


@pytest.mark.parametrize("status", ["undetermined", "ambiguous"])
def test_taps_consistent_with_a_report_that_is_not_unique_never_say_to_keep_using_its_pose(tmp_path, capsys, status):
    """Consistent taps prove no move, but the pose of an undetermined or ambiguous report is none a robot program may
    use (export and serve refuse it): the verdict says so instead of "Keep using the report's pose"."""
    data = yaml.safe_load(V1_REPORT.read_text())
    data["status"] = status
    report_path = tmp_path / f"{status}.yaml"
    report_path.write_text(yaml.safe_dump(data))
    taps = np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"])[:4]
    assert run_verify(tmp_path, report_path, taps, "--mesh", str(DEMO_MESH)) == 0
    out = capsys.readouterr().out
    assert "Keep using" not in out
    assert f"The report is {status}, so its pose is none a robot program may use" in out
