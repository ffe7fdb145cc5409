"""`fixwizard export`: the pose to use as URScript, as a ROS 2 static transform and as JSON, each read back the
way its user reads it; reports a robot must not use are refused."""

import argparse
import datetime as dt
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from fixwizard import report
from fixwizard.cli import main
from report_edits import with_pose
from test_report import V1_REPORT

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "report.yaml"
UR_FLOAT = r"-?\d+(?:\.\d+)?"  # no exponent: fixwizard's UR programs write none either (ur_script._number)


@pytest.fixture
def real_report(tmp_path) -> Path:
    """The example report as if from a real cell, fixture named 'cell2-bracket'."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["simulated"] = False
    data["fixture"]["name"] = "cell2-bracket"
    return report.write(tmp_path / "bracket.yaml", data)


@pytest.fixture
def mesh_report(tmp_path) -> tuple[Path, Path]:
    """A real report and its mesh: a copy of the example's in tmp_path, named by its full path as `solve` does."""
    mesh = tmp_path / "mesh" / "bracket.stl"
    mesh.parent.mkdir()
    data = yaml.safe_load(EXAMPLE.read_text())
    data["simulated"] = False
    mesh.write_bytes((EXAMPLE.parents[1] / data["fixture"]["mesh"]).read_bytes())
    data["fixture"]["mesh"] = str(mesh)
    return report.write(tmp_path / "bracket.yaml", data), mesh


def exported(capsys, path: Path, *args) -> str:
    assert main(["export", str(path), *args]) == 0
    return capsys.readouterr().out


def parse_urscript(text: str) -> dict[str, list[float]]:
    """A tiny reader of what export writes: comment lines, and assignments ``name = p[six numbers]``; anything else
    is a syntax error."""
    variables = {}
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("#") or not line.strip():
            continue
        match = re.fullmatch(rf"([A-Za-z][A-Za-z0-9_]*) = p\[((?:{UR_FLOAT}, ){{5}}{UR_FLOAT})\]", line)
        assert match, f"line {number} is no URScript pose assignment: {line!r}"
        variables[match.group(1)] = [float(value) for value in match.group(2).split(", ")]
    return variables


def test_urscript_defines_the_pose_to_use_as_a_global(real_report, capsys):
    text = exported(capsys, real_report, "--format", "urscript")
    variables = parse_urscript(text)
    loaded = report.load(real_report)
    assert list(variables) == ["fixture_cell2_bracket"]
    values = variables["fixture_cell2_bracket"]
    assert values == loaded.data["pose"]["position_m"] + loaded.data["pose"]["rotvec_rad"]  # every digit of the report
    assert "SIMULATED" not in text and "pose_trans(fixture_cell2_bracket" in text
    guarantee = float(re.search(r"within (\d+\.\d\d) mm \(CAD origin\)", text).group(1))
    assert guarantee * 1e-3 >= loaded.pose_guarantee.position_m  # stated rounded up, never below the guarantee


def test_urscript_writes_small_numbers_without_exponents_every_digit_kept(real_report, tmp_path, capsys):
    data = yaml.safe_load(real_report.read_text())
    small = report.write(tmp_path / "small.yaml", with_pose(data, [0.45, -0.00002, 0.0000001],
                                                           [0.00005, -0.000003, 0.560606]))
    text = exported(capsys, small, "--format", "urscript")
    assert "fixture_cell2_bracket = p[0.45, -0.00002, 0.0000001, 0.00005, -0.000003, 0.560606]" in text  # was 2e-05
    assert parse_urscript(text)["fixture_cell2_bracket"] == [0.45, -0.00002, 0.0000001, 0.00005, -0.000003, 0.560606]


@pytest.mark.parametrize("format_name", ["urscript", "ros2"])
def test_a_report_path_with_a_line_break_or_bytes_not_utf8_stays_in_one_comment_line(real_report, tmp_path, capsys,
                                                                                      format_name):
    """A line break in the report's path started a line of code of its own in the URScript file; a Latin-1 byte in
    it made -o fail with a traceback (UnicodeEncodeError)."""
    odd = tmp_path / os.fsdecode(b"gr\xfcn\nfixture_cell2_bracket = p[1, 2, 3, 0, 0, 0]\n#.yaml")
    real_report.rename(odd)
    output = tmp_path / f"pose.{format_name}"
    assert main(["export", str(odd), "--format", format_name, "-o", str(output)]) == 0
    text = output.read_text(encoding="utf-8")
    assert "gr\ufffdn\\nfixture_cell2_bracket = p[1, 2, 3, 0, 0, 0]\\n#.yaml" in text.splitlines()[0]
    if format_name == "urscript":
        assert parse_urscript(text)["fixture_cell2_bracket"][0] != 1.0
    else:
        assert yaml.safe_load(text)["transform_stamped"]["transform"]["translation"]["x"] != 1.0


def test_a_hand_edited_guarantee_too_large_to_round_is_exported_as_it_is(real_report, tmp_path, capsys):
    data = yaml.safe_load(real_report.read_text())
    data["pose"]["guaranteed"]["position_m"] = 1e307  # in mm, 1e310: no longer a finite float (it was a traceback)
    huge = report.write(tmp_path / "huge.yaml", data)
    assert "guaranteed: the true pose lies within inf mm (CAD origin)" in exported(capsys, huge, "--format", "urscript")


def _static_transform_publisher_arguments() -> argparse.ArgumentParser:
    """tf2_ros static_transform_publisher's named arguments (ROS 2 Humble and later)."""
    parser = argparse.ArgumentParser()
    for name in ("--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw"):
        parser.add_argument(name, type=float, required=True)
    parser.add_argument("--frame-id", required=True)
    parser.add_argument("--child-frame-id", required=True)
    return parser


def test_ros2_gives_a_transform_stamped_and_the_static_transform_publisher_arguments(real_report, capsys):
    document = yaml.safe_load(exported(capsys, real_report, "--format", "ros2"))
    loaded = report.load(real_report)
    message = document["transform_stamped"]
    assert set(message) == {"header", "child_frame_id", "transform"}
    assert message["header"] == {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "base"}
    assert message["child_frame_id"] == "cell2_bracket"
    translation, rotation = message["transform"]["translation"], message["transform"]["rotation"]
    assert [translation[axis] for axis in "xyz"] == loaded.data["pose"]["position_m"]
    quaternion = np.array([rotation[axis] for axis in "xyzw"])
    assert np.linalg.norm(quaternion) == pytest.approx(1.0, abs=1e-12) and quaternion[3] >= 0
    assert (Rotation.from_quat(quaternion).inv() * Rotation.from_matrix(loaded.base_T_cad[:3, :3])).magnitude() < 1e-9
    publisher = document["static_transform_publisher"]
    arguments = publisher["arguments"]
    assert arguments[::2] == ["--x", "--y", "--z", "--qx", "--qy", "--qz", "--qw", "--frame-id", "--child-frame-id"]
    assert all(isinstance(argument, str) for argument in arguments)  # launch files pass text
    parsed = _static_transform_publisher_arguments().parse_args(arguments)
    assert [parsed.x, parsed.y, parsed.z] == [translation[axis] for axis in "xyz"]
    assert [parsed.qx, parsed.qy, parsed.qz, parsed.qw] == list(quaternion)
    assert (parsed.frame_id, parsed.child_frame_id) == ("base", "cell2_bracket")
    assert publisher["command"] == "ros2 run tf2_ros static_transform_publisher " + " ".join(arguments)


def test_ros2_frames_can_be_named_and_bad_names_are_refused(real_report, capsys):
    document = yaml.safe_load(exported(capsys, real_report, "--format", "ros2", "--frame-id", "ur/base",
                                       "--child-frame-id", "jig"))
    assert document["transform_stamped"]["header"]["frame_id"] == "ur/base"
    assert document["static_transform_publisher"]["arguments"][-3:] == ["ur/base", "--child-frame-id", "jig"]
    assert main(["export", str(real_report), "--format", "ros2", "--frame-id", "my base"]) == 1
    assert "no ROS frame name" in capsys.readouterr().err


def test_json_is_the_whole_report(real_report, capsys):
    data = json.loads(exported(capsys, real_report, "--format", "json"))
    assert data == yaml.safe_load(real_report.read_text())


def test_an_output_of_dash_is_standard_output_not_a_file_named_dash(real_report, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert json.loads(exported(capsys, real_report, "--format", "json", "-o", "-")) == yaml.safe_load(
        real_report.read_text())
    assert not (tmp_path / "-").exists()


@pytest.mark.parametrize("value", [".inf", ".nan", f"1{'0' * 400}"])
def test_json_of_a_hand_edited_report_with_a_number_json_cannot_hold_is_a_message(real_report, capsys, value):
    text = real_report.read_text()
    real_report.write_text(re.sub(r"(\n\s*cells: )\d+", rf"\g<1>{value}", text, count=1))
    assert main(["export", str(real_report), "--format", "json"]) == 1
    err = capsys.readouterr().err
    assert "holds a number that is not finite" in err and "Traceback" not in err


def test_a_report_a_robot_must_not_use_is_refused_but_json_exports_it(real_report, tmp_path, capsys):
    for change, message in ((lambda data: data.update(simulated=True), "--allow-simulated"),
                            (lambda data: data.update(status="ambiguous"), "is ambiguous")):
        data = yaml.safe_load(real_report.read_text())
        change(data)
        path = report.write(tmp_path / "other.yaml", data)
        for format_name in ("urscript", "ros2"):
            assert main(["export", str(path), "--format", format_name]) == 1
            err = capsys.readouterr().err
            assert message in err and "Traceback" not in err
        assert json.loads(exported(capsys, path, "--format", "json"))["status"] == data["status"]


def test_a_simulated_report_is_exported_for_tests_marked_simulated(capsys):
    text = exported(capsys, EXAMPLE, "--format", "urscript", "--allow-simulated")
    assert text.startswith("# SIMULATED") and list(parse_urscript(text)) == ["fixture_bracket"]


def test_a_version_1_report_exports_the_bounds_centre_the_bounds_hold_about(capsys):
    variables = parse_urscript(exported(capsys, V1_REPORT, "--format", "urscript"))
    centre = yaml.safe_load(V1_REPORT.read_text())["bounds"]["center"]
    assert variables["fixture_demo_bracket"] == centre["position_m"] + centre["rotvec_rad"]


def test_the_output_file_is_written_and_never_the_report(real_report, tmp_path, capsys):
    target = tmp_path / "out" / "bracket.script"
    assert main(["export", str(real_report), "--format", "urscript", "-o", str(target)]) == 0
    assert "fixture_cell2_bracket" in parse_urscript(target.read_text())
    before = real_report.read_text()
    assert main(["export", str(real_report), "--format", "json", "-o", str(real_report)]) == 1
    assert "is the report" in capsys.readouterr().err and real_report.read_text() == before


@pytest.mark.parametrize("format_name, suffix", [("urscript", ".script"), ("ros2", ".yaml"), ("json", ".json")])
@pytest.mark.parametrize("made", [False, True])
def test_a_folder_as_the_output_is_refused_suggesting_a_file_of_the_formats_kind(real_report, tmp_path, capsys,
                                                                                 format_name, suffix, made):
    """It suggested report.yaml for URScript and ROS 2 too."""
    folder = tmp_path / "programs"
    if made:
        folder.mkdir()
    output = str(folder) if made else f"{folder}/"
    assert main(["export", str(real_report), "--format", format_name, "-o", output]) == 1
    err = capsys.readouterr().err
    assert f"give the path of a file in it, e.g. {folder / ('cell2-bracket' + suffix)}\n" in err


@pytest.mark.parametrize("format_name", ["urscript", "ros2", "json"])
def test_the_output_file_is_never_the_reports_mesh_nor_a_link_to_it(mesh_report, tmp_path, capsys, format_name):
    path, mesh = mesh_report
    before = mesh.read_bytes()
    symlink, hard_link = tmp_path / "symlink.stl", tmp_path / "hard_link.stl"
    symlink.symlink_to(mesh)
    hard_link.hardlink_to(mesh)
    for output in (mesh, symlink, hard_link):
        assert main(["export", str(path), "--format", format_name, "-o", str(output)]) == 1
        err = capsys.readouterr().err
        assert f"is the report's mesh ({mesh})" in err and "another output path with -o" in err
        assert "Traceback" not in err and mesh.read_bytes() == before
    assert symlink.is_symlink()


def test_a_mesh_the_report_names_relative_to_the_current_folder_is_not_written_either(mesh_report, monkeypatch,
                                                                                      capsys):
    path, mesh = mesh_report
    data = yaml.safe_load(path.read_text())
    data["fixture"]["mesh"] = "mesh/bracket.stl"  # as examples/report.yaml and /1 reports name it
    report.write(path, data)
    before = mesh.read_bytes()
    monkeypatch.chdir(mesh.parents[1])
    assert main(["export", str(path), "--format", "urscript", "-o", str(mesh)]) == 1
    assert "is the report's mesh" in capsys.readouterr().err and mesh.read_bytes() == before


def test_a_fixture_name_starting_with_a_digit_gives_a_ros_frame_name_with_fixture_before_it(real_report, capsys):
    data = yaml.safe_load(real_report.read_text())
    data["fixture"]["name"] = "1-a.b"
    report.write(real_report, data)
    document = yaml.safe_load(exported(capsys, real_report, "--format", "ros2"))
    assert document["transform_stamped"]["child_frame_id"] == "fixture_1_a_b"
    assert document["static_transform_publisher"]["arguments"][-2:] == ["--child-frame-id", "fixture_1_a_b"]
    assert list(parse_urscript(exported(capsys, real_report, "--format", "urscript"))) == ["fixture_1_a_b"]


@pytest.mark.parametrize("format_name", ["urscript", "json"])
@pytest.mark.parametrize("options, said", [
    (["--frame-id", "ur/base"], "--frame-id is for --format ros2 only; --format {} names no frames: leave it out"),
    (["--child-frame-id", "jig"], "--child-frame-id is for --format ros2 only; --format {} names no frames: leave it "
                                  "out"),
    (["--frame-id", "base", "--child-frame-id", "jig"], "--frame-id and --child-frame-id are for --format ros2 only; "
                                                        "--format {} names no frames: leave them out")])
def test_frame_ids_with_a_format_that_names_no_frames_are_bad_usage(real_report, tmp_path, capsys, format_name,
                                                                    options, said):
    """They were ignored without a word: a URScript pose exported 'in ur/base' was in the UR base frame all the
    same. Refused before anything is written; with ros2 they are taken as before."""
    output = tmp_path / "out.txt"
    assert main(["export", str(real_report), "--format", format_name, *options, "-o", str(output)]) == 1
    out, err = capsys.readouterr()
    assert out == "" and err.startswith("usage: fixwizard export ") and not output.exists()
    assert err.endswith(f"fixwizard: {said.format(format_name)}, or export --format ros2\n")
    assert "transform_stamped" in exported(capsys, real_report, "--format", "ros2", *options)  # where they belong


FRAME_RULES = {  # what is said of a frame id given, and frame ids that break that rule
    "tf2 refuses a frame id that starts with '/' (as ROS 1 wrote them); leave the '/' out": ["/", "/base"],
    "it is empty": [""],
    "it may hold only letters, digits, '_' and '/'": ["my base", " base", "jig\n"],
    "a '/' must stand between two names, as in 'ur/base'": ["ur//base", "base/"],
    "it must start with a letter or '_', not a digit": ["1jig"],
    "each name after a '/' must start with a letter or '_', not a digit": ["cell/2jig"],
}


@pytest.mark.parametrize(("option", "frame", "rule"), [
    (option, frame, rule) for rule, frames in FRAME_RULES.items() for frame in frames
    for option in ("--frame-id", "--child-frame-id")])
def test_a_frame_name_that_is_given_is_refused_with_the_rule_it_breaks(real_report, capsys, option, frame, rule):
    """As every other argument error: the usage, then the argument and the rule (tf2's own: not empty, no leading
    '/'; ROS names': letters, digits and '_', no name starting with a digit), before the report is read (exit 1)."""
    assert main(["export", str(real_report), "--format", "ros2", option, frame]) == 1
    err = capsys.readouterr().err
    assert err.startswith("usage: fixwizard export") and "Traceback" not in err
    assert f"fixwizard: argument {option}: {frame!r} is no ROS frame name: {rule}" in err
    assert main(["export", "no-such-report.yaml", "--format", "ros2", option, frame]) == 1
    assert "no ROS frame name" in capsys.readouterr().err


def test_a_report_dated_in_the_future_is_exported_with_a_note_on_the_clocks(real_report, tmp_path, capsys):
    data = yaml.safe_load(real_report.read_text())
    assert main(["export", str(real_report), "--format", "urscript"]) == 0
    assert "note:" not in capsys.readouterr().err
    data["created"] = (dt.datetime.now(dt.UTC) + dt.timedelta(hours=3)).isoformat(timespec="seconds")
    ahead = report.write(tmp_path / "ahead.yaml", data)
    assert main(["export", str(ahead), "--format", "urscript"]) == 0
    err = capsys.readouterr().err
    assert f"note: the report {ahead} is dated 3.0 h in the future: check the clocks" in err
