"""The ``fixwizard`` command: without a sub-command the interactive wizard (simulated demo cell, or a UR
arm with ``--robot HOST``; ``--resume`` reopens an unfinished session); the headless sub-commands solve,
import-poses, calibrate-tip, identify, verify, export and serve.

Exit codes (``EXIT_CODES``): 0 unique (one pose, pinned down), 1 bad input, 2 inconsistent (no pose explains the
taps), 3 ambiguous (several distinct poses), 4 undetermined (the taps do not pin the pose down), 130 cancelled.
Only 0 means a pose a robot program can use.
"""

import argparse
import re
import sys
from pathlib import Path

from fixwizard import report
from fixwizard.atomic import check_output
from fixwizard.errors import FixwizardError, InputError, MeshUnitsError, file_problem
from fixwizard.export import register_export_parser
from fixwizard.points import write_points
from fixwizard.serve import register_serve_parser
from fixwizard.solver.search import SearchCancelled, SearchProgress
from fixwizard.units import parse_length_m
from fixwizard.workflow.identify import register_identify_parser
from fixwizard.workflow.import_poses import import_pose_dir, load_tip
from fixwizard.workflow.solve_run import SolveRequest, run_solve, summary_lines
from fixwizard.workflow.tip_calibration import register_calibrate_tip_parser
from fixwizard.workflow.verify import register_verify_parser

EXIT_OK, EXIT_BAD_INPUT, EXIT_INCONSISTENT, EXIT_CANCELLED = 0, 1, 2, 130
EXIT_CODES = {"unique": EXIT_OK, "inconsistent": EXIT_INCONSISTENT, "ambiguous": 3, "undetermined": 4}


def _parse_cell_budget(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"the cell budget must be a number such as 1e7, not {text!r}") from None


def _print_progress(step: SearchProgress) -> None:
    print(f"  level rotation {step.rotation_level} / position {step.position_level}: {step.survivors} of "
          f"{step.evaluated} cells survive ({step.elapsed_s:.1f} s)", file=sys.stderr)


def _lengths_from(args: argparse.Namespace) -> tuple[float, float]:
    """Ball diameter and sample bound (m) from the flags, else from the tip calibration."""
    tip = load_tip(args.calibration) if args.calibration else None
    ball = parse_length_m(args.ball_diameter) if args.ball_diameter else (tip.ball_diameter_m if tip else None)
    bound = parse_length_m(args.sample_bound) if args.sample_bound else (tip.sample_bound_m if tip else None)
    if ball is None or bound is None:
        raise InputError("give --ball-diameter and --sample-bound (e.g. --ball-diameter 3mm --sample-bound 1mm), "
                         "or --calibration with a tip calibration that holds them")
    return ball, bound


def _report_path(args: argparse.Namespace) -> Path:
    """``-o``, or POINTS with ``.report.yaml`` (refused for a POINTS that is no file, e.g. /dev/stdin)."""
    if args.output:
        return Path(args.output)
    points = Path(args.points)
    if points.exists() and not points.is_file():
        raise InputError(f"POINTS {points} is not a regular file, so there is no folder beside it for the report: "
                         "give the report path with -o, e.g. -o report.yaml")
    return points.with_suffix(".report.yaml")


def solve_command(args: argparse.Namespace) -> int:
    ball_diameter_m, sample_bound_m = _lengths_from(args)
    request = SolveRequest(Path(args.mesh), Path(args.points), ball_diameter_m, sample_bound_m, args.mesh_units,
                           parse_length_m(args.sigma) if args.sigma else None, args.max_cells,
                           report.fixture_name(args.fixture_name) if args.fixture_name else None)
    output = _report_path(args)
    check_output(output, [("mesh", args.mesh), ("POINTS file", args.points), ("tip calibration", args.calibration)],
                 "give another report path with -o, e.g. -o report.yaml")
    outcome = run_solve(request, progress=None if args.quiet else _print_progress)
    print("\n".join(summary_lines(outcome)))
    report.write(output, outcome.report)
    print(f"report written to {output}")
    return EXIT_CODES[outcome.solution.status]


def wizard_command(args: argparse.Namespace) -> int:
    if not (sys.stdin.isatty() and sys.stdout.isatty()):
        raise InputError("the wizard needs an interactive terminal (its input or output is not one here); run "
                         "fixwizard in a terminal or over SSH, or use a command such as `fixwizard solve` in scripts "
                         "(see fixwizard --help)")
    from fixwizard.tui.app import FixwizardApp
    from fixwizard.tui.launch import simulated_context, ur_context

    context = ur_context(args.robot) if args.robot else simulated_context(args.seed)
    FixwizardApp(context, args.resume).run()
    context.robot.close()
    return EXIT_OK


def import_poses_command(args: argparse.Namespace) -> int:
    pose_files = sorted(Path(args.directory).glob("*.pose")) if Path(args.directory).is_dir() else []
    check_output(args.output, [("tip file", args.tip), *(("recorded pose file", path) for path in pose_files)],
                 "give another POINTS path with -o, e.g. -o points.yaml")
    paths, base_p_taps = import_pose_dir(args.directory, load_tip(args.tip))
    write_points(args.output, base_p_taps, source=[path.name for path in paths], tip=str(args.tip))
    print(f"{len(base_p_taps)} ball centres written to {args.output}")
    return EXIT_OK


class _Parser(argparse.ArgumentParser):
    """argparse with bad usage exiting 1 (bad input), since exit code 2 means inconsistent taps, and with
    negative lengths such as ``-1mm`` taken as values (so that their check can say what is wrong)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(?:mm|m)?$")

    def error(self, message: str) -> None:
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"fixwizard: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="fixwizard", description="Fixture pose calibration with guaranteed bounds from a few "
                     "robot taps. Without a COMMAND it starts the interactive wizard.",
                     epilog="exit codes of solve: 0 unique, 1 bad input, 2 inconsistent, 3 ambiguous, 4 undetermined, "
                     "130 cancelled")
    parser.add_argument("--robot", metavar="HOST", help="wizard: the UR arm at HOST (default: the simulated demo cell)")
    parser.add_argument("--resume", nargs="?", const="", metavar="SESSION",
                        help="wizard: reopen SESSION, or the newest unfinished session, straight into sampling")
    parser.add_argument("--seed", type=int, default=0, help="wizard: seed of the simulated demo cell (default 0)")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)

    solve_parser = commands.add_parser("solve", help="find every fixture pose that explains the taps; write a report")
    solve_parser.add_argument("mesh", metavar="MESH", help="fixture CAD mesh (STL, PLY or OBJ)")
    solve_parser.add_argument("points", metavar="POINTS", help="taps: YAML {frame: base, points_m: [...]} or CSV x,y,z")
    solve_parser.add_argument("--sample-bound", help="bound on each tap's error, e.g. 1mm")
    solve_parser.add_argument("--ball-diameter", help="diameter of the tip ball, e.g. 3mm (0 for a grown mesh)")
    solve_parser.add_argument("--calibration", help="tip calibration YAML giving the ball diameter and sample bound")
    solve_parser.add_argument("--mesh-units", choices=("m", "mm"), default="m", help="units of the mesh file")
    solve_parser.add_argument("--max-cells", type=_parse_cell_budget, default=1e7, help="cell budget (default 1e7)")
    solve_parser.add_argument("--sigma", help="standard deviation of tap errors (default: sample bound / 3)")
    solve_parser.add_argument("--fixture-name", metavar="NAME", help="the fixture's name in the report, as "
                              "`fixwizard serve` offers it (default: the mesh file's name without its suffix)")
    solve_parser.add_argument("-o", "--output", help="report path (default: POINTS with .report.yaml)")
    solve_parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    solve_parser.set_defaults(func=solve_command)

    import_parser = commands.add_parser("import-poses", help="turn UR flange *.pose files into ball-centre points")
    import_parser.add_argument("directory", metavar="DIR", help="folder of *.pose files (x y z rx ry rz)")
    import_parser.add_argument("--tip", required=True, help="tip as a .pose file or a tip calibration YAML")
    import_parser.add_argument("-o", "--output", required=True, help="POINTS YAML to write")
    import_parser.set_defaults(func=import_poses_command)

    register_calibrate_tip_parser(commands)
    register_identify_parser(commands, _parse_cell_budget)
    register_verify_parser(commands)
    register_export_parser(commands)
    register_serve_parser(commands)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args) if args.command else wizard_command(args)
    except FixwizardError as error:
        units_fix = f" (--mesh-units {error.likely_units})" if isinstance(error, MeshUnitsError) and \
            error.likely_units else ""
        print(f"fixwizard: {error}{units_fix}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:
        print(f"fixwizard: {file_problem(error)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (SearchCancelled, KeyboardInterrupt):
        print("fixwizard: cancelled; nothing was written", file=sys.stderr)
        return EXIT_CANCELLED


if __name__ == "__main__":
    sys.exit(main())
