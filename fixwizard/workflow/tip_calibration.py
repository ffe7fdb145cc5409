"""Tool-tip calibration from folders of recorded flange poses: the ``calibrate-tip`` command.

Prints the figures a person needs to accept or reject the calibration and writes the
``fixwizard.tip/1`` file.
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from fixwizard.atomic import check_not_read_later, check_output
from fixwizard.calibration.calibrate import calibrate_tip
from fixwizard.calibration.residuals import ResidualStats
from fixwizard.calibration.store import TipCalibration, save_calibration
from fixwizard.calibration.taps import PoseSeries
from fixwizard.errors import FixwizardError
from fixwizard.geometry.se3 import pose_files, read_pose_dir
from fixwizard.units import parse_length_m


def read_pose_series(directory: str | Path) -> PoseSeries:
    """The ``*.pose`` files of a folder (natural name order) with their file names."""
    paths, base_T_tcp = read_pose_dir(directory)
    return PoseSeries(base_T_tcp, tuple(path.name for path in paths))


def calibrate_tip_from_dirs(pivot_dir: str | Path, table_dir: str | Path, tilted_dir: str | Path,
                            ball_diameter_m: float, table_coarse_dir: str | Path | None = None, name: str = "tip",
                            robot: str | None = None) -> TipCalibration:
    """Calibrate from folders of ``*.pose`` files: pivot poses, table taps at one orientation, tilted table
    taps and optionally the three coarse table taps A, B, C (see ``calibrate_tip``)."""
    return calibrate_tip(read_pose_series(pivot_dir), read_pose_series(table_dir), read_pose_series(tilted_dir),
                         ball_diameter_m, read_pose_series(table_coarse_dir) if table_coarse_dir else None, name,
                         robot)


def summary_lines(calibration: TipCalibration) -> list[str]:
    """The figures to accept or reject a calibration, in mm."""
    steps = calibration.steps
    tip_mm = calibration.tcp_p_tip_m * 1e3
    pivot_mm = calibration.pivot_tcp_p_tip_m * 1e3
    excluded = [f"  excluded {step} {tap.describe()}" for step, series in steps.items() for tap in series.excluded]
    return [
        f"pivot ({len(steps['pivot'].base_T_tcp)} poses): tip {_mm(pivot_mm)} mm, "
        f"{_residuals(calibration.pivot_residuals)}",
        f"table plane ({len(steps['table'].base_T_tcp)} taps): {_residuals(calibration.table_residuals)}",
        f"fine tip ({len(steps['tilted'].base_T_tcp)} tilted taps): {_mm(tip_mm)} mm, "
        f"{_residuals(calibration.tip_residuals)}",
        f"  condition number {calibration.tip_condition_number:.1f}; standard error from the scatter "
        f"{_mm(calibration.tip_standard_error_m * 1e3)} mm; {np.linalg.norm(tip_mm - pivot_mm):.2f} mm from the "
        "pivot tip",
        *(excluded or ["  no tap excluded"]),
        f"proposed sample bound {calibration.sample_bound_reason} Solving with --sample-bound overrides it.",
    ]


def _mm(values_mm: np.ndarray) -> str:
    return "[" + ", ".join(f"{value:.3f}" for value in values_mm) + "]"


def _residuals(stats: ResidualStats) -> str:
    return f"residual RMS {stats.rms_m * 1e3:.3f} mm, max {stats.max_m * 1e3:.3f} mm"


def calibrate_tip_command(args: argparse.Namespace) -> int:
    """Run ``calibrate-tip``: 0 when the calibration was written, 1 (message on stderr) for bad input."""
    output = Path(args.output)
    folders = [folder for folder in (args.pivot, args.table, args.tilted, args.table_coarse) if folder]
    recorded = [path for folder in folders if Path(folder).is_dir() for path in pose_files(Path(folder))]
    try:
        fix = "give another calibration path with -o, e.g. -o calibrations/NAME.yaml"
        # as typed: a Path drops a final '/', and '-o calibrations/' was the file 'calibrations'
        check_output(args.output, [("recorded pose file", path) for path in recorded], fix, "tip.yaml")
        check_not_read_later(output, folders, ".pose", "a recorded pose", fix)
        calibration = calibrate_tip_from_dirs(args.pivot, args.table, args.tilted, parse_length_m(args.ball_diameter),
                                              args.table_coarse, output.stem, args.robot)
        save_calibration(calibration, output)
    except FixwizardError as error:
        print(f"fixwizard calibrate-tip: {error}", file=sys.stderr)
        return 1
    print("\n".join(summary_lines(calibration)))
    print(f"tip calibration written to {output}")
    return 0
