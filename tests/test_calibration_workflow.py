"""The calibrate-tip command: folders of pose files in, figures printed, calibration file out."""

import argparse
from pathlib import Path

import pytest

from fixwizard.calibration.store import load_calibration
from fixwizard.cli import build_parser
from fixwizard.workflow.tip_calibration import calibrate_tip_command
from test_calibration_helpers import real_calib_dir


def parse(argv: list[str]) -> argparse.Namespace:
    return build_parser().parse_args(argv)


def linked_series(calib: Path, folder: Path, *ranges: range) -> Path:
    """A folder of links to the tip_pts files of the given index ranges."""
    folder.mkdir()
    for index in (index for indices in ranges for index in indices):
        name = f"base_t_tcp_pt_{index}.pose"
        (folder / name).symlink_to(calib / "tip_pts" / name)
    return folder


def real_args(tmp_path: Path, tilted: Path, *extra: str) -> argparse.Namespace:
    calib = real_calib_dir()
    return parse(["calibrate-tip", "--pivot", str(calib / "tip_manual"), "--table", str(calib / "square_pts"),
                  "--table-coarse", str(calib / "square_manual"), "--tilted", str(tilted), "--ball-diameter", "3mm",
                  "-o", str(tmp_path / "calibrations" / "logo.yaml"), *extra])


def test_the_parser_offers_the_documented_options():
    args = parse(["calibrate-tip", "--pivot", "p", "--table", "t", "--tilted", "s", "--ball-diameter", "3mm",
                  "-o", "calibrations/bench.yaml"])
    assert (args.pivot, args.table, args.tilted, args.table_coarse, args.ball_diameter, args.output, args.robot) == \
        ("p", "t", "s", None, "3mm", "calibrations/bench.yaml", None)
    assert args.handler == "fixwizard.workflow.tip_calibration:calibrate_tip_command"


def test_real_data_gives_a_loadable_calibration_and_prints_the_figures(tmp_path, capsys):
    tilted = linked_series(real_calib_dir(), tmp_path / "tilted", range(100, 200))
    assert calibrate_tip_command(real_args(tmp_path, tilted, "--robot", "UR5 of the logo cell")) == 0
    printed = capsys.readouterr().out
    for figure in ("pivot (3 poses): tip [0.185, 0.116, 49.052] mm, residual RMS 0.859 mm, max 1.078 mm",
                   "table plane (80 taps): residual RMS 0.028 mm",
                   "fine tip (100 tilted taps): [-1.539, 0.597, 49.171] mm, residual RMS 0.102 mm, max 0.341 mm",
                   "condition number 6.6", "no tap excluded",
                   "proposed sample bound 0.8 mm: the largest of 100 fine-calibration residuals was 0.34 mm"):
        assert figure in printed
    calibration = load_calibration(tmp_path / "calibrations" / "logo.yaml")
    assert (calibration.name, calibration.robot, calibration.sample_bound_m) == ("logo", "UR5 of the logo cell",
                                                                                 pytest.approx(0.8e-3))


def test_taps_off_the_table_are_named_in_the_printout(tmp_path, capsys):
    tilted = linked_series(real_calib_dir(), tmp_path / "tilted", range(11), range(100, 200))
    assert calibrate_tip_command(real_args(tmp_path, tilted)) == 0
    printed = capsys.readouterr().out
    assert "excluded tilted tap 0 (base_t_tcp_pt_0.pose): +" in printed
    assert "excluded tilted tap 10 (base_t_tcp_pt_10.pose)" in printed


def test_all_200_real_files_are_refused_naming_the_two_series(tmp_path, capsys):
    args = real_args(tmp_path, real_calib_dir() / "tip_pts")
    assert calibrate_tip_command(args) == 1
    error = capsys.readouterr().err
    assert "base_t_tcp_pt_11.pose to base_t_tcp_pt_96.pose" in error
    assert "base_t_tcp_pt_100.pose to base_t_tcp_pt_199.pose" in error and "calibrate from one series only" in error
    assert not Path(args.output).exists()


@pytest.mark.parametrize("problem, message", [
    ("missing folder", "is not a folder"),
    ("pivot poses without tilt", "the pivot poses cannot determine the tip"),
    ("ball diameter without unit", "a ball diameter of 3000 mm is implausible"),
])
def test_bad_input_returns_1_with_a_message_and_writes_nothing(tmp_path, capsys, problem, message):
    calib = real_calib_dir()
    args = real_args(tmp_path, calib / "tip_pts")
    if problem == "missing folder":
        args.tilted = str(tmp_path / "absent")
    elif problem == "pivot poses without tilt":
        args.pivot = str(calib / "square_manual")
    else:
        args.ball_diameter = "3"
    assert calibrate_tip_command(args) == 1
    captured = capsys.readouterr()
    assert message in captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    assert not Path(args.output).exists()
