"""The headless command line, as an operator would use it: good runs, and every kind of bad input."""

import errno
import json
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fixwizard import report
from fixwizard.cli import main
from fixwizard.demo import DEMO_MESH, DEMO_TAPS
from fixwizard.geometry.se3 import make_transform, transform_points
from fixwizard.points import write_points
from fixwizard.synthetic import bounded_noise, touching_ball_centres
from shapes import l_prism

REPO = Path(__file__).resolve().parents[1]
REPORT_EXAMPLE = REPO / "examples" / "report.yaml"


@pytest.fixture(scope="module")
def bracket(tmp_path_factory):
    """An L-plate exported in millimetres, 20 taps at a known pose, and that pose."""
    folder = tmp_path_factory.mktemp("bracket")
    mesh_m = l_prism()
    mesh_mm = mesh_m.copy()
    mesh_mm.apply_scale(1000.0)
    mesh_mm.export(folder / "plate.stl")
    rng = np.random.default_rng(11)
    base_T_cad = make_transform(Rotation.from_euler("z", 40, degrees=True), [0.5, 0.1, 0.0])
    taps = transform_points(base_T_cad, touching_ball_centres(mesh_m, 20, 0.0015, rng)) + bounded_noise(20, 0.0005, rng)
    write_points(folder / "taps.yaml", taps)
    return folder, taps, base_T_cad


def replaced(args: list[str], old: str, new: str) -> list[str]:
    """The arguments with one value swapped."""
    return [new if arg == old else arg for arg in args]


def solve_args(folder, points="taps.yaml", *extra):
    return ["solve", str(folder / "plate.stl"), str(folder / points), "--mesh-units", "mm", "--sample-bound", "0.5mm",
            "--ball-diameter", "3mm", "--max-cells", "1e6", "-q", "-o", str(folder / "report.yaml"), *extra]


@pytest.mark.slow
def test_solve_prints_a_summary_and_writes_a_loadable_report(bracket, capsys):
    folder, taps, base_T_cad = bracket
    assert main(solve_args(folder)) == 0
    out = capsys.readouterr().out
    assert "status: unique" in out and "guaranteed about this pose:" in out and "p[" in out
    loaded = report.load(folder / "report.yaml")
    assert loaded.status == "unique"
    assert np.linalg.norm(loaded.center_base_T_cad[:3, 3] - base_T_cad[:3, 3]) <= loaded.position_bound_m
    assert np.array(loaded.data["inputs"]["points_m"]) == pytest.approx(taps, abs=1e-7)  # 0.1 um


@pytest.mark.slow
@pytest.mark.parametrize("offset_m", [400.0, 600.0])
def test_a_mesh_whose_origin_lies_far_from_the_part_gives_a_report_every_reader_takes_or_is_refused(tmp_path, capsys,
                                                                                                    offset_m):
    """A plant layout's frame as the mesh's origin: within 500 m the report holds the pose and export reads it;
    farther, the CAD origin would be more than a report holds from the robot base (its readers refused the report
    solve had just written, as if edited), so the mesh is refused naming the fix."""
    plate = l_prism()
    offset = np.array([offset_m, 0.0, 0.0])
    plate.apply_translation(offset)
    plate.export(tmp_path / "plate.obj")  # text: float64 coordinates, placed to the micrometre so far out
    base_T_part = make_transform(Rotation.from_euler("z", 40, degrees=True), [0.5, 0.1, 0.0])
    rng = np.random.default_rng(11)
    taps = transform_points(base_T_part, touching_ball_centres(l_prism(), 20, 0.0015, rng))
    write_points(tmp_path / "taps.yaml", taps)
    args = ["solve", str(tmp_path / "plate.obj"), str(tmp_path / "taps.yaml"), "--mesh-units", "m", "--sample-bound",
            "0.5mm", "--ball-diameter", "3mm", "--max-cells", "1e6", "-q", "-o", str(tmp_path / "report.yaml")]
    code = main(args)
    if offset_m > 500.0:
        assert code == 1 and not (tmp_path / "report.yaml").exists()
        assert capsys.readouterr().err.strip().endswith(
            f"plate.obj: the fixture lies {offset_m:.0f} m from the mesh's origin; fixwizard gives the pose of that "
            "origin, and one so far from the robot base is no pose a report holds. Export the mesh with its origin "
            "near the part (within 500 m of it)")
        return
    assert code in (0, 4)  # or undetermined: bounds centred among CAD origins that swing so far out are loose
    assert main(["export", str(tmp_path / "report.yaml"), "--format", "json", "-o", str(tmp_path / "pose.json")]) == 0
    cad_origin_m = transform_points(base_T_part, -offset[None])[0]  # the CAD origin: about 400 m from the base
    exported_m = np.array(json.loads((tmp_path / "pose.json").read_text())["bounds"]["center"]["position_m"])
    assert np.linalg.norm(exported_m - cad_origin_m) <= report.load(tmp_path / "report.yaml").position_bound_m


def test_without_quiet_the_phases_after_the_search_are_shown_as_they_come(bracket, capsys):
    """With many taps the refinement can take minutes after the last search level: each round is a line."""
    folder, _, _ = bracket
    args = [arg for arg in solve_args(folder) if arg != "-q"]
    assert main(args) == 0
    err = capsys.readouterr().err.splitlines()
    phases = [line.split(" (")[0].strip() for line in err if not line.strip().startswith("level")]
    assert phases[:2] == ["grouping the possible poses", "computing the guaranteed bounds"]
    assert "computing the guaranteed bounds, round 1" in phases
    assert phases[-1] == "computing the 95 % and 99 % intervals"


@pytest.mark.parametrize("repeated", [1, 20])
def test_taps_that_repeat_an_earlier_one_exactly_are_named_in_a_warning(bracket, capsys, repeated):
    """A points file with rows pasted twice would narrow the intervals without a word."""
    folder, taps, _ = bracket
    write_points(folder / "twice.yaml", np.vstack([taps, taps[:repeated]]))
    assert main(solve_args(folder, "twice.yaml")) == 0
    out = capsys.readouterr().out
    count = "A tap repeats an earlier one" if repeated == 1 else f"{repeated} taps repeat an earlier one"
    assert f"warning: {count} exactly (tap 21 is tap 1" in out and ("..." in out) == (repeated > 3)
    assert "repeated_taps" in (folder / "report.yaml").read_text()


def test_a_csv_points_file_works_like_yaml(bracket, capsys):
    folder, taps, _ = bracket
    np.savetxt(folder / "taps.csv", taps, delimiter=",", header="x,y,z", comments="")
    assert main(solve_args(folder, "taps.csv")) == 0


def test_wrong_units_name_the_fix(bracket, capsys):
    folder, _, _ = bracket
    args = replaced(solve_args(folder), "mm", "m")
    assert main(args) == 1
    assert "--mesh-units mm" in capsys.readouterr().err


@pytest.mark.parametrize("name", ["", "left plate", "../plate"])
def test_a_fixture_name_serve_could_not_offer_is_refused_before_the_solve(bracket, tmp_path, capsys, name):
    """An empty name (a shell variable left unset) named the report after the mesh without a word: with two fixtures
    made from one mesh, serve would offer the one calibrated last under both names."""
    folder, _, _ = bracket
    assert main(solve_args(folder, "taps.yaml", "--fixture-name", name, "-o", str(tmp_path / "named.yaml"))) == 1
    assert f"the fixture name {name!r} must be 1-64 letters" in capsys.readouterr().err
    assert not (tmp_path / "named.yaml").exists()


def test_points_and_mesh_swapped_say_so(bracket, capsys):
    """The mesh is read first: the POINTS file given as the mesh was 'not a mesh file fixwizard reads; export the
    fixture's CAD model as STL, PLY or OBJ'."""
    folder, _, _ = bracket
    args = solve_args(folder)
    args[1:3] = args[2:0:-1]
    assert main(args) == 1
    assert "taps.yaml is a points file (YAML or CSV of the taps), not a mesh" in capsys.readouterr().err


SWAPPED = "the arguments seem swapped; give the report first: fixwizard verify REPORT POINTS"


@pytest.mark.parametrize("points_text, points_name", [
    (None, "taps.yaml"), (None, "taps.csv"), ("frame: base\npoints_m: [[0.1, .nan, 0.2]]\n", "damaged.yaml")])
def test_verify_with_the_points_given_for_the_report_says_the_arguments_seem_swapped(tmp_path, capsys, points_text,
                                                                                      points_name):
    """'verify POINTS REPORT' said '... is not a fixwizard report: expected 'schema: ...', found None' and not a word
    of the order; a points file with a damaged tap is one all the same."""
    points = tmp_path / points_name
    if points_text is None:
        write_points(points, np.array(yaml.safe_load(DEMO_TAPS.read_text())["points_m"]))
    else:
        points.write_text(points_text)
    assert main(["verify", str(points), str(REPORT_EXAMPLE)]) == 1
    assert capsys.readouterr().err == (f"fixwizard: {points} is a points file (the taps), not a fixwizard report: "
                                       f"{SWAPPED}\n")


def test_verify_with_a_report_given_for_the_points_says_the_arguments_seem_swapped(bracket, capsys):
    folder, _, _ = bracket
    assert main(["verify", str(folder / "plate.stl"), str(REPORT_EXAMPLE)]) == 1
    assert capsys.readouterr().err == (f"fixwizard: {folder / 'plate.stl'} is not a fixwizard report, and "
                                       f"{REPORT_EXAMPLE}, given as POINTS, is one: {SWAPPED}\n")
    (folder / "notes.yaml").write_text("schema: something else\n")  # no report, no taps: nothing seems swapped
    assert main(["verify", str(folder / "notes.yaml"), str(folder / "taps.yaml")]) == 1
    err = capsys.readouterr().err
    assert "is not a fixwizard report: expected 'schema: fixwizard.report/2'" in err and "swapped" not in err


def test_a_non_mesh_file_is_refused(bracket, tmp_path, capsys):
    folder, _, _ = bracket
    (tmp_path / "plate.stl").write_text("this is a shopping list, not a mesh\n" * 20)
    write_points(tmp_path / "taps.yaml", np.zeros((5, 3)))
    assert main(solve_args(tmp_path)) == 1
    err = capsys.readouterr().err
    assert "mesh" in err and "Traceback" not in err


def test_two_taps_are_not_enough(bracket, capsys):
    folder, taps, _ = bracket
    write_points(folder / "two.yaml", taps[:2])
    assert main(solve_args(folder, "two.yaml")) == 1
    assert "at least 3" in capsys.readouterr().err


def test_nan_in_the_points_file_is_refused_with_the_tap_number(bracket, capsys):
    folder, _, _ = bracket
    (folder / "nan.csv").write_text("0.1,0.2,0.3\n0.1,nan,0.3\n0.2,0.2,0.2\n")
    assert main(solve_args(folder, "nan.csv")) == 1
    assert "tap 2" in capsys.readouterr().err


@pytest.mark.slow
def test_a_tap_5cm_off_the_fixture_is_inconsistent_and_named(bracket, capsys):
    folder, taps, _ = bracket
    off = taps.copy()
    off[6] += np.array([0.0, 0.0, 0.05])
    write_points(folder / "off.yaml", off)
    args = replaced(solve_args(folder, "off.yaml"), "1e6", "8e6")
    assert main(args) == 2
    out = capsys.readouterr().out
    assert "status: inconsistent" in out and "Tap 7" in out
    loaded = report.load(folder / "report.yaml")
    assert loaded.status == "inconsistent" and loaded.base_T_cad is None
    assert loaded.data["suspect_tap"]["tap"] == 7
    assert loaded.data["pose"] is None and loaded.data["bounds"] is None and loaded.data["intervals"] is None


def test_a_bad_length_is_refused(bracket, capsys):
    folder, _, _ = bracket
    args = replaced(solve_args(folder), "0.5mm", "half a millimetre")
    assert main(args) == 1
    assert "cannot read the length" in capsys.readouterr().err


def test_import_poses_turns_flange_poses_into_ball_centres(tmp_path, capsys):
    poses = tmp_path / "poses"
    poses.mkdir()
    for index, pose in enumerate([[0.4, 0.0, 0.2, 0.0, 3.14159, 0.0], [0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]]):
        (poses / f"base_t_tcp_{index}.pose").write_text("\n".join(str(value) for value in pose))
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    assert main(["import-poses", str(poses), "--tip", str(tmp_path / "tip.pose"), "-o", str(tmp_path / "p.yaml")]) == 0
    points = yaml.safe_load((tmp_path / "p.yaml").read_text())
    assert points["frame"] == "base"
    assert np.array(points["points_m"]) == pytest.approx(np.array([[0.4, 0.0, 0.15], [0.5, 0.1, 0.15]]), abs=1e-5)


def _write_poses(folder: Path, poses: list[list[float]]) -> None:
    folder.mkdir(exist_ok=True)
    for index, pose in enumerate(poses):
        (folder / f"base_t_tcp_{index}.pose").write_text("\n".join(str(value) for value in pose))


def test_import_poses_takes_the_tip_file_in_the_folder_for_no_tap(tmp_path, capsys):
    """The tip's .pose kept beside the tapped poses was read as one more tap (3 ball centres for 2 taps)."""
    _write_poses(tmp_path, [[0.4, 0.0, 0.2, 0.0, 3.14159, 0.0], [0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]])
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    assert main(["import-poses", str(tmp_path), "--tip", str(tmp_path / "tip.pose"), "-o",
                 str(tmp_path / "p.yaml")]) == 0
    assert capsys.readouterr().out.startswith("2 ball centres written")
    points = yaml.safe_load((tmp_path / "p.yaml").read_text())
    assert points["source"] == ["base_t_tcp_0.pose", "base_t_tcp_1.pose"]


def test_import_poses_reads_pose_files_whatever_the_case_of_their_suffix(tmp_path, capsys):
    """A tool that writes upper-case suffixes (tap_1.POSE) gave 'no *.pose files'; -o onto such a name is still
    refused as a file the next run reads as a recorded pose."""
    _write_poses(tmp_path / "poses", [[0.4, 0.0, 0.2, 0.0, 3.14159, 0.0], [0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]])
    (tmp_path / "poses" / "base_t_tcp_1.pose").rename(tmp_path / "poses" / "base_t_tcp_1.POSE")
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    args = ["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o"]
    assert main([*args, str(tmp_path / "p.yaml")]) == 0
    assert yaml.safe_load((tmp_path / "p.yaml").read_text())["source"] == ["base_t_tcp_0.pose", "base_t_tcp_1.POSE"]
    capsys.readouterr()
    assert main([*args, str(tmp_path / "poses" / "new.Pose")]) == 1
    assert "which the next run reads as a recorded pose" in capsys.readouterr().err


def test_import_poses_refuses_poses_in_millimetres(tmp_path, capsys):
    """.pose files hold metres; poses written in millimetres made ball centres 400 m from the base, silently."""
    _write_poses(tmp_path / "poses", [[412.0, -95.0, 151.0, 2.1, -2.2, 0.1], [420.0, -90.0, 152.0, 2.1, -2.2, 0.1]])
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    assert main(["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o",
                 str(tmp_path / "p.yaml")]) == 1
    assert "beyond any robot's reach: .pose files hold metres and radians" in capsys.readouterr().err
    assert not (tmp_path / "p.yaml").exists()


@pytest.mark.parametrize("tip", ["0\n0\n50\n0\n0\n0\n", "1e308\n0\n0\n0\n0\n0\n"])
def test_import_poses_refuses_a_tip_farther_than_a_tool_holds_it(tmp_path, capsys, tip):
    """A tip in millimetres (50 for 50 mm), or an absurd one, wrote ball centres metres off; solve refused them only
    later, saying the taps looked like millimetres."""
    _write_poses(tmp_path / "poses", [[0.4, 0.0, 0.2, 0.0, 3.14159, 0.0], [0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]])
    (tmp_path / "tip.pose").write_text(tip)
    assert main(["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o",
                 str(tmp_path / "p.yaml")]) == 1
    err = capsys.readouterr().err
    assert "from the flange, farther than any tool holds it" in err and "Traceback" not in err
    assert not (tmp_path / "p.yaml").exists()


SAVETXT_POSE = ("-4.859099782104382703e-02\n-3.432098340450873697e-01\n1.075154231592212462e-02\n"
                "-2.755081915890459143e+00\n2.943487357886771516e-01\n8.995426777384196715e-01\n")


@pytest.mark.parametrize("text, read", [
    ("\ufeff0.4\n0\n0.2\n0\n3.14159\n0\n", None),  # saved by Notepad with a byte-order mark: read
    ("0.4\r\n0\r\n0.2\r\n0\r\n3.14159\r\n0\r\n", None),  # Windows line ends: read
    ("0.4\n0\n0.2\n0\n3.14159\n", "must hold exactly six numbers x y z rx ry rz (metres, radians); it holds 5 "
                                   "(cut short? record that pose again)"),
    ("0.4\n0\n0.2\n0\n1\n0\n0\n", "it holds 7 (a position and a quaternion, as ABB or ROS write a pose? "
                                    "fixwizard reads UR's rotation vector rx ry rz)"),
    ("0.4\n0\n0.2\n0\n180\n0\n", "turns by 180 rad (rx ry rz [0.0, 180.0, 0.0]), more than a full turn: a .pose "
                                   "file holds UR's rotation vector in radians, and these look like degrees"),
    ("0.4\n0\n0.2\n-179.5\n0.3\n90\n", "turns by 200.8 rad"),
    ("0.4\nnan\n0.2\n0\n3.14159\n0\n", "holds a number that is not finite ([0.4, nan, 0.2, 0.0, 3.14159, 0.0])"),
    ("0x10\n0\n0.2\n0\n3.14159\n0\n", "'0x10' is no number. A .pose file holds six numbers"),
    ("p[0.4, 0, 0.2, 0, 3.14159, 0]\n", "'p[0.4,' is no number. A .pose file holds six numbers x y z rx ry rz "
                                      "(metres, radians), one per line or apart by spaces, with '.' as the decimal "
                                      "point"),
    pytest.param("x" * 10_000 + "\n", "'xxxxxxxx", id="one long word"),
    (SAVETXT_POSE, None),  # as numpy's savetxt writes a pose (the paper's data): read
    (SAVETXT_POSE.rstrip(), None),  # the same without its last line end: whole, read
    pytest.param(SAVETXT_POSE[:-5], "ends inside its last number: '8.995426777384196715' lacks digits or the "
                 "exponent the numbers before it were written with, so the file was cut short", id="cut before e-01"),
    pytest.param(SAVETXT_POSE[:-2], "'8.995426777384196715e-0' lacks digits or the exponent", id="cut in e-01"),
    pytest.param(SAVETXT_POSE[:-12], "'8.99542677738' lacks digits", id="cut in the digits")])
def test_a_pose_file_as_editors_save_it_is_read_and_a_damaged_one_named(tmp_path, capsys, text, read):
    """Angles in degrees (a tool pointing down is 180) were read as radians, another rotation without a word; a file
    cut short inside its last number (a copy broken off) was read with that number 10 times too large."""
    _write_poses(tmp_path / "poses", [[0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]])
    (tmp_path / "poses" / "base_t_tcp_1.pose").write_text(text, encoding="utf-8", newline="")
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    code = main(["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o",
                 str(tmp_path / "p.yaml")])
    err = capsys.readouterr().err
    if read is None:
        assert code == 0 and len(yaml.safe_load((tmp_path / "p.yaml").read_text())["points_m"]) == 2
    else:
        assert code == 1 and f"the pose file {tmp_path / 'poses' / 'base_t_tcp_1.pose'}" in err
        assert read in err and "Traceback" not in err and err.count("\n") == 1 and len(err) < 600


def test_a_pose_file_too_large_for_a_pose_is_refused_without_reading_it_all(tmp_path, capsys):
    """40 MB of numbers took 5 s and 470 MB to be told it held 20 million numbers."""
    _write_poses(tmp_path / "poses", [[0.5, 0.1, 0.2, 0.0, 3.14159, 0.0]])
    with (tmp_path / "poses" / "base_t_tcp_1.pose").open("w") as file:
        file.write("1 " * 5_000_000)
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    started = time.monotonic()
    assert main(["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o",
                 str(tmp_path / "p.yaml")]) == 1
    assert time.monotonic() - started < 1.5  # reading it all took 5 s
    assert "base_t_tcp_1.pose holds more than 64 kB, so it is no pose" in capsys.readouterr().err


def test_import_poses_reads_a_tip_calibration(tmp_path, real_data):
    output = tmp_path / "points.yaml"
    calibration = REPO / "calibrations" / "example_matlab_logo.yaml"
    assert main(["import-poses", str(real_data / "samples" / "expert"), "--tip", str(calibration), "-o",
                 str(output)]) == 0
    assert len(yaml.safe_load(output.read_text())["points_m"]) == 20


@pytest.mark.slow
def test_the_bundled_demo_solves(tmp_path, capsys):
    args = ["solve", str(DEMO_MESH), str(DEMO_TAPS),
            "--mesh-units", "mm", "--sample-bound", "1mm", "--ball-diameter", "3mm", "--max-cells", "2e5", "-q",
            "-o", str(tmp_path / "demo.yaml")]
    assert main(args) == 0
    hidden = yaml.safe_load(DEMO_TAPS.read_text())["hidden_pose_ur"]
    loaded = report.load(tmp_path / "demo.yaml")
    values = [float(value) for value in hidden.strip("p[]").split(",")]
    assert np.linalg.norm(loaded.center_base_T_cad[:3, 3] - values[:3]) <= loaded.position_bound_m


@pytest.mark.slow
def test_solve_takes_ball_diameter_and_sample_bound_from_a_tip_calibration(tmp_path, real_data, capsys):
    calibration = REPO / "calibrations" / "example_matlab_logo.yaml"
    points = tmp_path / "expert.yaml"
    assert main(["import-poses", str(real_data / "samples" / "expert"), "--tip", str(calibration), "-o",
                 str(points)]) == 0
    assert main(["solve", str(real_data / "meshes" / "matlab_logo.ply"), str(points), "--calibration",
                 str(calibration), "--max-cells", "1e5", "-q", "-o", str(tmp_path / "report.yaml")]) == 0
    inputs = report.load(tmp_path / "report.yaml").data["inputs"]
    assert inputs["ball_diameter_m"] == pytest.approx(0.003)
    assert inputs["sample_bound_m"] == pytest.approx(0.0008)
    assert "note:" not in capsys.readouterr().err
    assert main(["solve", str(real_data / "meshes" / "matlab_logo.ply"), str(points), "--calibration",
                 str(calibration), "--ball-diameter", "6mm", "--sample-bound", "0.8mm", "--max-cells", "1e5", "-q",
                 "-o", str(tmp_path / "report.yaml")]) in (2, 3, 4)  # a flag wins, and says what it overrides
    err = capsys.readouterr().err
    assert f"note: --ball-diameter 6 mm is used, not the 3 mm of the tip calibration {calibration}" in err
    assert "--sample-bound" not in err


def test_a_length_without_unit_that_means_metres_is_caught(bracket, capsys):
    folder, _, _ = bracket
    args = replaced(solve_args(folder), "0.5mm", "1")
    assert main(args) == 1
    assert "--sample-bound 1mm" in capsys.readouterr().err


@pytest.mark.parametrize("bound", ["1e-9", "0.001mm", "1e-6"])
def test_a_sample_bound_finer_than_any_robot_tap_is_refused_with_the_fix(bracket, capsys, bound):
    """1e-6 for 1 mm, or 1 um: it was solved, undetermined or inconsistent after seconds, with cells and
    likelihoods finer than the report's 0.1 um."""
    folder, _, _ = bracket
    assert main(replaced(solve_args(folder), "0.5mm", bound)) == 1
    err = capsys.readouterr().err
    assert "is implausible for a robot tap: no robot taps to within 0.01 mm" in err and "--sample-bound 1mm" in err


@pytest.mark.parametrize("sigma", ["1", "0.6mm", "5"])
def test_a_sigma_beyond_the_sample_bound_is_refused_with_the_fix(bracket, capsys, sigma):
    """A bare number is metres: '--sigma 1' would widen the intervals a thousandfold without a word."""
    folder, _, _ = bracket
    assert main(solve_args(folder, "taps.yaml", "--sigma", sigma)) == 1
    err = capsys.readouterr().err
    assert "larger than the sample bound of 0.5 mm" in err and "--sigma 0.17mm" in err and "Traceback" not in err


def test_a_negative_length_is_refused_by_its_check_not_taken_for_a_flag(bracket, capsys):
    folder, _, _ = bracket
    assert main(replaced(solve_args(folder), "0.5mm", "-1mm")) == 1
    err = capsys.readouterr().err
    assert "'-1mm' must be a positive length" in err and "expected one argument" not in err


def test_a_folder_given_as_the_mesh_is_called_a_folder(bracket, capsys):
    folder, _, _ = bracket
    assert main(replaced(solve_args(folder), str(folder / "plate.stl"), str(folder))) == 1
    assert "is a folder, not a mesh file" in capsys.readouterr().err


def test_one_tap_is_counted_in_the_singular(bracket, capsys):
    folder, taps, _ = bracket
    write_points(folder / "one.yaml", taps[:1])
    assert main(solve_args(folder, "one.yaml")) == 1
    assert "1 tap is not enough" in capsys.readouterr().err


def test_bad_usage_exits_1_not_2(bracket, capsys):
    folder, _, _ = bracket
    assert main(replaced(solve_args(folder), "1e6", "lots")) == 1
    assert "the cell budget must be a number such as 1e7, not 'lots'" in capsys.readouterr().err


def test_a_word_a_command_does_not_take_is_named_under_that_commands_usage_with_the_likely_option(bracket, capsys):
    """``solve ... --units mm`` printed the whole program's usage (which hid that solve has ``--mesh-units``)."""
    folder, _, _ = bracket
    assert main([*solve_args(folder), "--units", "mm"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("usage: fixwizard solve ") and "--mesh-units {m,mm}" in err
    assert "unrecognized arguments: --units (did you mean --mesh-units?) mm" in err
    assert main(["export", str(folder / "report.yaml"), "--format", "json", "--frame-idd=world"]) == 1
    assert "unrecognized arguments: --frame-idd=world (did you mean --frame-id?)" in capsys.readouterr().err
    assert main([*solve_args(folder), "--zzz", "extra"]) == 1
    assert capsys.readouterr().err.endswith("unrecognized arguments: --zzz extra\n")


def test_a_mistyped_wizard_option_is_named_not_its_value_called_no_command(capsys):
    """``fixwizard --robt 10.0.0.5`` said "invalid choice: '10.0.0.5' (choose from 'solve', ...)"."""
    assert main(["--robt", "10.0.0.5"]) == 1
    assert capsys.readouterr().err.endswith("unrecognized arguments: --robt (did you mean --robot?)\n")
    assert main(["--rob=10.0.0.5", "--sed", "3"]) == 1  # an abbreviation argparse takes is no mistake
    assert capsys.readouterr().err.endswith("unrecognized arguments: --sed (did you mean --seed?)\n")
    assert main(["sovle"]) == 1
    assert "invalid choice: 'sovle' (choose from 'solve', " in capsys.readouterr().err


def test_an_unwritable_report_path_is_a_message_not_a_traceback(bracket, capsys):
    folder, _, _ = bracket
    blocker = folder / "not_a_folder"
    blocker.write_text("a file where a folder should be")
    assert main(replaced(solve_args(folder), str(folder / "report.yaml"), str(blocker / "report.yaml"))) == 1
    err = capsys.readouterr().err
    assert "is a file, not a folder" in err and "Traceback" not in err


@pytest.fixture
def unreadable(monkeypatch) -> set[Path]:
    """Paths opened as files of mode 000 are for a user other than root (root reads them all the same): ``open``
    refuses them with the PermissionError naming the file. Add a path to the set to make it so."""
    blocked: set[Path] = set()
    opened = Path.open

    def open_unless_blocked(path, *args, **kwargs):
        if path in blocked:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return opened(path, *args, **kwargs)

    monkeypatch.setattr(Path, "open", open_unless_blocked)
    return blocked


@pytest.mark.parametrize("command, unreadable_input", [
    ("solve", "plate.stl"), ("solve", "taps.yaml"), ("verify", "report.yaml"), ("import-poses", "poses/tap.pose"),
    ("import-poses", "tip.pose")])
def test_an_input_that_cannot_be_read_is_said_to_need_read_permission_not_another_folder(
        bracket, tmp_path, capsys, unreadable, command, unreadable_input):
    """Every input is only read: a file of mode 000 was told 'no permission to read or write it; check its
    permissions, or choose a folder you can write to', as if it were an output."""
    folder, _, _ = bracket
    inputs = {"plate.stl": folder / "plate.stl", "taps.yaml": folder / "taps.yaml",
              "report.yaml": tmp_path / "report.yaml", "poses/tap.pose": tmp_path / "poses" / "tap.pose",
              "tip.pose": tmp_path / "tip.pose"}
    inputs["report.yaml"].write_text("schema: fixwizard.report/3\n")  # never read: it cannot be
    inputs["poses/tap.pose"].parent.mkdir()
    inputs["poses/tap.pose"].write_text("0.5 0.1 0.2 0 3.14 0\n")
    inputs["tip.pose"].write_text("0 0 0.05 0 0 0\n")
    args = {"solve": replaced(solve_args(folder), str(folder / "report.yaml"), str(tmp_path / "out.yaml")),
            "verify": ["verify", str(inputs["report.yaml"]), str(inputs["taps.yaml"])],
            "import-poses": ["import-poses", str(tmp_path / "poses"), "--tip", str(inputs["tip.pose"]), "-o",
                             str(tmp_path / "out.yaml")]}
    path = inputs[unreadable_input]
    unreadable.add(path)
    assert main(args[command]) == 1
    err = capsys.readouterr().err
    assert f"no permission to read {path}; check that you may read it (its permissions, and its folders')" in err
    assert "write" not in err and "Traceback" not in err


def test_an_output_folder_that_cannot_be_written_is_said_to_need_write_permission(bracket, tmp_path, capsys,
                                                                                   monkeypatch):
    """It said 'no permission to read or write' a hidden probe file, gone by then, of a name the operator never
    gave."""
    folder, _, _ = bracket
    (tmp_path / "locked").mkdir()

    def refused(*args, dir, **kwargs):  # a folder of mode 555 for a user: no file can be made in it
        raise PermissionError(errno.EACCES, "Permission denied", str(Path(dir) / ".fixwizard-probe.tmp"))

    monkeypatch.setattr("fixwizard.atomic.tempfile.mkstemp", refused)
    assert main(replaced(solve_args(folder), str(folder / "report.yaml"), str(tmp_path / "locked" / "r.yaml"))) == 1
    err = capsys.readouterr().err
    assert err == (f"fixwizard: cannot write in the folder {tmp_path / 'locked'}: no permission to write "
                   f"{tmp_path / 'locked'}; check its permissions, or choose a folder you can write to\n")


def test_help_and_argument_errors_answer_without_loading_the_heavy_libraries():
    """``fixwizard --help`` took 4 s of imports; the parser imports none of numpy, Open3D, the solver or Textual. A
    ``serve --max-age`` that is no positive duration was refused only by serve itself, after SciPy's import (6 s on a
    busy PC)."""
    import subprocess
    import sys

    probe = ("import sys; from fixwizard.cli import main\n"
             "try:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
             "heavy = [name for name in ('numpy', 'open3d', 'scipy', 'textual', 'fixwizard.solver')\n"
             "         if name in sys.modules]\n"
             "print(heavy)")
    for argv in (["--help"], ["solve", "--help"], ["solve", "m.stl", "p.yaml", "--sample-bound", "-1mm"],
                 ["identify", "p.yaml", "m.stl", "--sample-bound", "1mm", "--ball-diameter", "3mm",
                  "--time-limit", "soon"], ["serve", "--max-age", "forever"], ["serve", "--max-age", "-1d"]):
        result = subprocess.run([sys.executable, "-c", probe, *argv], capture_output=True, text=True, timeout=60)
        assert result.stdout.strip().endswith("[]"), (argv, result.stdout, result.stderr)
    result = subprocess.run([sys.executable, "-m", "fixwizard.cli", "solve", "m.stl", "p.yaml", "--sample-bound",
                             "-1mm"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1 and "'-1mm' must be a positive length" in result.stderr


@pytest.mark.slow
def test_a_solve_in_its_own_process_tells_everything_before_it_leaves(bracket, tmp_path):
    """A batch command leaves without the interpreter's teardown (``cli.entry``): what it printed into a pipe's
    buffer reaches the reader all the same, and the report is whole."""
    import os
    import subprocess
    import sys

    folder, _, _ = bracket
    environment = {name: value for name, value in os.environ.items() if name != "PYTHONUNBUFFERED"}
    result = subprocess.run([sys.executable, "-m", "fixwizard.cli", *solve_args(folder)[:-2], "-o",
                             str(tmp_path / "r.yaml")], capture_output=True, text=True, timeout=120, env=environment)
    assert result.returncode == 0 and result.stderr == ""
    lines = result.stdout.splitlines()
    assert lines[0].startswith("status: unique (20 taps") and lines[-1] == f"report written to {tmp_path / 'r.yaml'}"
    assert report.load(tmp_path / "r.yaml").status == "unique"


@pytest.mark.slow
def test_a_solve_whose_reader_left_still_writes_its_report_and_says_nothing_untrue(bracket, tmp_path):
    """`fixwizard solve ... | head -1` with unbuffered output: the summary came before the report, so the report was
    never written, and the broken pipe was told as 'cannot read or write the file ...; check the path and the
    disk' (exit 1). The report comes first; a reader that left gets nothing more, with a shell's 141."""
    import os
    import subprocess
    import sys

    folder, _, _ = bracket
    process = subprocess.Popen([sys.executable, "-m", "fixwizard.cli", *solve_args(folder)[:-2], "-o",
                                str(tmp_path / "r.yaml")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, "PYTHONUNBUFFERED": "1"})
    process.stdout.close()  # the reader leaves before the first line
    err = process.stderr.read()
    assert process.wait(timeout=120) == 141 and err == ""
    assert report.load(tmp_path / "r.yaml").status == "unique"


@pytest.mark.slow
@pytest.mark.parametrize("stage", ["writing", "summary"])
def test_ctrl_c_once_the_solve_is_done_says_what_became_of_the_report(bracket, tmp_path, capsys, monkeypatch, stage):
    """Ctrl+C after the work, as the report is written or the summary printed, was told 'cancelled; nothing was
    written' while the report stood written."""
    from fixwizard import commands

    def interrupted(*_args):
        raise KeyboardInterrupt

    written = tmp_path / "r.yaml"
    if stage == "writing":
        real_write = report.write
        monkeypatch.setattr(commands.report, "write", lambda *args: (real_write(*args), interrupted()))
    else:
        monkeypatch.setattr(commands, "summary_lines", interrupted)
    assert main([*solve_args(bracket[0])[:-2], "-o", str(written)]) == 130
    err = capsys.readouterr().err
    assert "nothing was written" not in err and "Traceback" not in err
    assert err == (f"fixwizard: cancelled while the report was written: {written} holds the whole new report or what "
                   "it held before\n" if stage == "writing" else f"fixwizard: cancelled; the report was written to "
                   f"{written}\n")
    assert report.load(written).status == "unique"


@pytest.mark.slow
def test_ctrl_c_during_a_solve_exits_130_promptly_without_a_traceback(bracket, tmp_path):
    import signal
    import subprocess
    import sys
    import time

    folder, _, _ = bracket
    command = [sys.executable, "-m", "fixwizard.cli", *replaced(solve_args(folder), "1e6", "1e8")[:-3],
               "-o", str(tmp_path / "r.yaml")]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first_level = process.stderr.readline()  # after the imports, the mesh and the lattice: the search is under way
    assert "level rotation" in first_level, first_level
    sent = time.monotonic()
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=30)
    assert time.monotonic() - sent < 1.5  # about 0.1 s, 0.25 s under a load of 8 (the teardown it skips took 2-6 s)
    assert process.returncode == 130 and "cancelled" in err and "Traceback" not in err
    assert not (tmp_path / "r.yaml").exists()


def test_the_summary_states_the_guarantee_about_the_pose_it_prints(bracket, capsys, tmp_path):
    """The summary printed the pose and its UR literal, then 'guaranteed: CAD origin within ...' of the bounds about
    their centre, which is less than the guarantee about the printed pose (the report's pose.guaranteed, as export
    states it): the pose a robot takes looked better bounded than it is."""
    folder, _, _ = bracket
    main(replaced(replaced(solve_args(folder), "1e6", "1e4"), str(folder / "report.yaml"), str(tmp_path / "r.yaml")))
    out = capsys.readouterr().out
    loaded = report.load(tmp_path / "r.yaml")
    about_pose = loaded.pose_guarantee
    assert (f"guaranteed about this pose: CAD origin within {report.round_up(about_pose.position_m * 1e3, 2):.2f} mm, "
            f"rotation within {report.round_up(about_pose.rotation_deg, 2):.2f} deg, any fixture point within "
            f"{report.round_up(about_pose.max_point_displacement_m * 1e3, 2):.2f} mm") in out
    assert "guaranteed about the centre of the set (bounds.center): CAD origin within" in out
