"""The ``fixwizard`` sub-commands' work: each takes the parsed arguments and returns the exit code. Imported only
once a command has been chosen (the heavy libraries load here, not for ``--help``)."""

import argparse
import sys
import time
from pathlib import Path

from fixwizard import report
from fixwizard.atomic import check_not_read_later, check_output
from fixwizard.errors import InputError
from fixwizard.exit_codes import EXIT_CANCELLED, EXIT_CODES, EXIT_OK
from fixwizard.geometry.se3 import pose_files
from fixwizard.interrupt import run_interruptibly
from fixwizard.points import write_points
from fixwizard.solver.search import SearchProgress
from fixwizard.solver.solve import SolveStage, Stage
from fixwizard.units import parse_length_m
from fixwizard.workflow.import_poses import import_pose_dir, load_tip
from fixwizard.workflow.solve_run import SolveRequest, run_solve, summary_lines
from fixwizard.workflow.stage_words import stage_words


def _print_progress(step: SearchProgress) -> None:
    print(f"  level rotation {step.rotation_level} / position {step.position_level}: {step.survivors} of "
          f"{step.evaluated} cells survive ({step.elapsed_s:.1f} s)", file=sys.stderr)


def _stage_printer() -> Stage:
    """Prints each phase after the search with the seconds since the printer was made (about the search's start)."""
    started = time.perf_counter()

    def print_stage(stage: SolveStage) -> None:
        print(f"  {stage_words(stage)} ({time.perf_counter() - started:.1f} s)", file=sys.stderr)

    return print_stage


def _lengths_from(args: argparse.Namespace) -> tuple[float, float]:
    """Ball diameter and sample bound (m) from the flags, else from the tip calibration."""
    tip = load_tip(args.calibration) if args.calibration else None
    ball = parse_length_m(args.ball_diameter) if args.ball_diameter else (tip.ball_diameter_m if tip else None)
    bound = parse_length_m(args.sample_bound) if args.sample_bound else (tip.sample_bound_m if tip else None)
    if ball is None or bound is None:
        raise InputError("give --ball-diameter and --sample-bound (e.g. --ball-diameter 3mm --sample-bound 1mm), "
                         "or --calibration with a tip calibration that holds them")
    if tip is not None:
        for flag, given, calibrated in (("--ball-diameter", ball, tip.ball_diameter_m),
                                        ("--sample-bound", bound, tip.sample_bound_m)):
            if calibrated is not None and abs(given - calibrated) > 1e-9:
                print(f"fixwizard: note: {flag} {given * 1e3:g} mm is used, not the {calibrated * 1e3:g} mm of the "
                      f"tip calibration {args.calibration}", file=sys.stderr)
    return ball, bound


def _report_path(args: argparse.Namespace) -> str | Path:
    """``-o`` as given (a final '/' kept for ``check_output`` to refuse), or POINTS with ``.report.yaml`` (refused
    for a POINTS that is no file, e.g. /dev/stdin)."""
    if args.output:
        return str(args.output)
    points = Path(args.points)
    if points.exists() and not points.is_file():
        raise InputError(f"POINTS {points} is not a regular file, so there is no folder beside it for the report: "
                         "give the report path with -o, e.g. -o report.yaml")
    return points.with_suffix(".report.yaml")


def solve_command(args: argparse.Namespace) -> int:
    ball_diameter_m, sample_bound_m = _lengths_from(args)
    request = SolveRequest(Path(args.mesh), Path(args.points), ball_diameter_m, sample_bound_m, args.mesh_units,
                           parse_length_m(args.sigma) if args.sigma else None, args.max_cells,
                           report.fixture_name(args.fixture_name) if args.fixture_name is not None else None)
    output = _report_path(args)
    check_output(output, [("mesh", args.mesh), ("POINTS file", args.points), ("tip calibration", args.calibration)],
                 "give another report path with -o, e.g. -o report.yaml")
    stage = None if args.quiet else _stage_printer()
    outcome = run_interruptibly(lambda cancel: run_solve(request, None if args.quiet else _print_progress, cancel,
                                                         stage))
    try:
        report.write(output, outcome.report)  # first: a reader that leaves early (`| head`) costs no report
    except KeyboardInterrupt:
        print(f"fixwizard: cancelled while the report was written: {output} holds the whole new report or what it held "
              "before", file=sys.stderr)
        return EXIT_CANCELLED
    try:
        print("\n".join(summary_lines(outcome)))
        print(f"report written to {output}")
    except KeyboardInterrupt:
        print(f"fixwizard: cancelled; the report was written to {output}", file=sys.stderr)
        return EXIT_CANCELLED
    return EXIT_CODES[outcome.solution.status]


def import_poses_command(args: argparse.Namespace) -> int:
    recorded = pose_files(Path(args.directory)) if Path(args.directory).is_dir() else []
    fix = "give another POINTS path with -o, e.g. -o points.yaml"
    check_output(args.output, [("tip file", args.tip), *(("recorded pose file", path) for path in recorded)], fix,
                 "points.yaml")
    check_not_read_later(args.output, [args.directory], ".pose", "a recorded pose", fix)
    paths, base_p_taps = import_pose_dir(args.directory, load_tip(args.tip), args.tip)
    write_points(args.output, base_p_taps, source=[path.name for path in paths], tip=str(args.tip))
    print(f"{len(base_p_taps)} ball centres written to {args.output}")
    return EXIT_OK
