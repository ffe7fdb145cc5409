"""The ``fixwizard`` command: without a sub-command the interactive wizard (simulated demo cell, or a UR
arm with ``--robot HOST``; ``--resume`` reopens an unfinished session); the headless sub-commands solve,
import-poses, calibrate-tip, identify, verify, export and serve.

This module holds only the argument parser and imports nothing heavy: ``--help`` and bad arguments answer at
once. A chosen command's module (``COMMAND_MODULE:function``) is imported when it runs.

Exit codes (``exit_codes``): 0 unique (one pose, pinned down), 1 bad input, 2 inconsistent (no pose explains the
taps), 3 ambiguous (several distinct poses), 4 undetermined (the taps do not pin the pose down, or no pose was
found that explains them), 130 cancelled.
Only 0 means a pose a robot program can use.
"""

import argparse
import contextlib
import difflib
import importlib
import os
import re
import sys
from collections.abc import Sequence
from typing import NoReturn

from fixwizard.errors import FixwizardError, command_line_text, file_problem, likely_units
from fixwizard.exit_codes import EXIT_BAD_INPUT, EXIT_CANCELLED, EXIT_CODES, EXIT_OK, EXIT_READER_GONE
from fixwizard.units import parse_duration_s, parse_length_m

__all__ = ["EXIT_CODES", "EXIT_OK", "build_parser", "entry", "main"]
DEFAULT_MAX_CELLS = 1e7
DEFAULT_IDENTIFY_MAX_CELLS = 1e7
DEFAULT_TIME_LIMIT_S = 120.0
EXPORT_FORMATS = ("urscript", "ros2", "json")
ROS_BASE_FRAME_ID = "base"  # the UR ROS 2 driver's base frame (not base_link)
SERVE_PORT = 50000  # as UR's XML-RPC examples use
SERVE_HOST = "0.0.0.0"
SERVE_MAX_AGE = "30d"


def _cell_budget(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"the cell budget must be a number such as 1e7, not {text!r}") from None
    if not 1e3 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"the cell budget must be a number from 1e3 up, such as 1e7, not {text!r}")
    return value


def _length(text: str, allow_zero: bool) -> str:
    """A length as typed (the command parses it again), refused here when it is not a length or not positive."""
    try:
        metres = parse_length_m(text)
    except FixwizardError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    if metres < 0 or (metres == 0 and not allow_zero):
        raise argparse.ArgumentTypeError(f"{text!r} must be {'zero or ' if allow_zero else ''}a positive length, "
                                         "e.g. 1mm")
    return text


def _positive_length(text: str) -> str:
    return _length(text, allow_zero=False)


def _diameter(text: str) -> str:
    return _length(text, allow_zero=True)


def _age(text: str) -> str:
    """A largest report age as typed (serve parses it again), refused here when it is no positive duration."""
    try:
        parse_duration_s(text)
    except FixwizardError as error:
        raise argparse.ArgumentTypeError(str(error)) from None
    return text


def _port(text: str) -> int:
    """A TCP port, 1-65535, or 0 for any free one."""
    if not re.fullmatch(r"\d{1,5}", text.strip()) or int(text) > 65535:
        raise argparse.ArgumentTypeError(f"a port is a number from 1 to 65535 (0: any free one), not {text!r}")
    return int(text)


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a time in seconds such as 60, not {text!r}") from None
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"a positive time in seconds such as 60, not {text!r}")
    return value


def _ros_frame_id(text: str) -> str:
    """A frame id as tf2 and ROS names take it: names of letters, digits and '_', each starting with a letter or '_',
    joined by single '/' (a prefix, as in ``ur/base``). tf2 refuses an empty one and one starting with '/' (ROS 1's
    tf wrote ``/base``): its static transform would be published and never found."""
    if not text:
        problem = "it is empty"
    elif re.search(r"[^A-Za-z0-9_/]", text):
        problem = "it may hold only letters, digits, '_' and '/'"
    elif text.startswith("/"):
        problem = "tf2 refuses a frame id that starts with '/' (as ROS 1 wrote them); leave the '/' out"
    elif "" in text.split("/"):
        problem = "a '/' must stand between two names, as in 'ur/base'"
    elif text[0].isdigit():
        problem = "it must start with a letter or '_', not a digit"
    elif re.search(r"/\d", text):
        problem = "each name after a '/' must start with a letter or '_', not a digit"
    else:
        return text
    raise argparse.ArgumentTypeError(f"{text!r} is no ROS frame name: {problem}")


class _Parser(argparse.ArgumentParser):
    """argparse with bad usage exiting 1 (bad input), since exit code 2 means inconsistent taps, and with
    negative lengths and ages such as ``-1mm`` or ``-1d`` taken as values (so that their check can say what is
    wrong)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?\s*(?:mm|m|s|min|h|d)?$")
        self._words: list[str] = []

    def parse_known_args(self, args: Sequence[str] | None = None,  # type: ignore[override]  # typeshed: overloads
                         namespace: None = None) -> tuple[argparse.Namespace, list[str]]:
        """argparse's, keeping the words parsed (``args``, or the command line's) for ``error``."""
        self._words = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> NoReturn:
        unknown = self._unknown_options_before_command(message)
        if unknown:  # ``--robt 10.0.0.5``: argparse skipped the option and took its value for the command
            message = self._unrecognized(unknown)
        self.print_usage(sys.stderr)
        self.exit(EXIT_BAD_INPUT, f"fixwizard: {message}\n")

    def refuse_unrecognized(self, extras: list[str]) -> NoReturn:
        """The usage error for words ``extras`` this (sub-)command does not take, under its own usage (the whole
        program's hid which command they were wrong for)."""
        self.error(self._unrecognized(extras))

    def _unrecognized(self, words: list[str]) -> str:
        """That ``words`` are not taken, with the option a mistyped one likely means."""
        options = [option for action in self._actions for option in action.option_strings if option.startswith("--")]
        hints = [f"{word} (did you mean {likely[0]}?)" if word.startswith("-") and (likely := difflib.get_close_matches(
            word.split("=")[0], options, n=1, cutoff=0.6)) else word for word in words]
        return f"unrecognized arguments: {' '.join(hints)}"

    def _unknown_options_before_command(self, message: str) -> list[str]:
        """The options this parser does not know among the words before the one ``message`` calls no command."""
        choice = re.match(r"argument COMMAND: invalid choice: '(.*?)'", message)
        if choice is None or choice[1] not in self._words:
            return []
        options = [option for action in self._actions for option in action.option_strings]
        return [word for word in self._words[:self._words.index(choice[1])] if word.startswith("--") and not any(
            option.startswith(word.split("=")[0]) for option in options)]


def _add_solve(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("solve", help="find every fixture pose that explains the taps; write a report")
    parser.add_argument("mesh", metavar="MESH", help="fixture CAD mesh (STL, PLY or OBJ)")
    parser.add_argument("points", metavar="POINTS", help="taps: YAML {frame: base, points_m: [...]} or CSV x,y,z")
    parser.add_argument("--sample-bound", type=_positive_length, help="bound on each tap's error, e.g. 1mm")
    parser.add_argument("--ball-diameter", type=_diameter, help="diameter of the tip ball, e.g. 3mm (0 for a grown "
                        "mesh)")
    parser.add_argument("--calibration", help="tip calibration YAML giving the ball diameter and sample bound")
    parser.add_argument("--mesh-units", choices=("m", "mm"), default="m", help="units of the mesh file")
    parser.add_argument("--max-cells", type=_cell_budget, default=DEFAULT_MAX_CELLS,
                        help=f"cell budget (default {DEFAULT_MAX_CELLS:g})")
    parser.add_argument("--sigma", type=_positive_length, help="standard deviation of tap errors (default: sample "
                        "bound / 3)")
    parser.add_argument("--fixture-name", metavar="NAME", help="the fixture's name in the report, as `fixwizard "
                        "serve` offers it (default: the mesh file's name without its suffix)")
    parser.add_argument("-o", "--output", help="report path (default: POINTS with .report.yaml)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(handler="fixwizard.commands:solve_command")


def _add_import_poses(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("import-poses", help="turn UR flange *.pose files into ball-centre points")
    parser.add_argument("directory", metavar="DIR", help="folder of *.pose files (x y z rx ry rz)")
    parser.add_argument("--tip", required=True, help="tip as a .pose file or a tip calibration YAML")
    parser.add_argument("-o", "--output", required=True, help="POINTS YAML to write")
    parser.set_defaults(handler="fixwizard.commands:import_poses_command")


def _add_calibrate_tip(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser(
        "calibrate-tip", help="calibrate the ball tip from recorded flange poses; write calibrations/NAME.yaml",
        description="Calibrate the tool tip (ball centre in the flange frame) from folders of UR flange *.pose "
                    "files (x y z rx ry rz, m and rad), and propose the sample error bound.")
    parser.add_argument("--pivot", required=True, metavar="DIR", help="poses turning the tool about one point (3+)")
    parser.add_argument("--table", required=True, metavar="DIR", help="table taps with one fixed tool orientation")
    parser.add_argument("--tilted", required=True, metavar="DIR", help="table taps at tilts of 10 to 30 degrees")
    parser.add_argument("--table-coarse", metavar="DIR", help="three table taps A, B (corner), C for the table frame")
    parser.add_argument("--ball-diameter", required=True, type=_diameter, help="diameter of the tip ball, e.g. 3mm")
    parser.add_argument("-o", "--output", required=True, help="calibration file to write, e.g. calibrations/NAME.yaml")
    parser.add_argument("--robot", help="robot identity to record, e.g. its serial number")
    parser.set_defaults(handler="fixwizard.workflow.tip_calibration:calibrate_tip_command")


def _add_identify(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("identify", help="which of several meshes can the taps belong to?")
    parser.add_argument("points", metavar="POINTS", help="taps: YAML {frame: base, points_m: [...]} or CSV x,y,z")
    parser.add_argument("meshes", metavar="MESH", nargs="+", help="candidate fixture meshes (STL, PLY or OBJ)")
    parser.add_argument("--sample-bound", required=True, type=_positive_length, help="bound on each tap's error, "
                        "e.g. 1mm")
    parser.add_argument("--ball-diameter", required=True, type=_diameter, help="diameter of the tip ball, e.g. 3mm")
    parser.add_argument("--mesh-units", choices=("m", "mm"), default="m", help="units of the mesh files")
    parser.add_argument("--max-cells", type=_cell_budget, default=DEFAULT_IDENTIFY_MAX_CELLS,
                        help=f"largest cell budget per mesh (default {DEFAULT_IDENTIFY_MAX_CELLS:g})")
    parser.add_argument("--time-limit", type=_seconds, default=DEFAULT_TIME_LIMIT_S,
                        help=f"seconds for all meshes together (default {DEFAULT_TIME_LIMIT_S:g})")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress lines")
    parser.set_defaults(handler="fixwizard.workflow.identify:identify_command")


def _add_verify(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("verify", help="has the fixture moved? test a few new taps against a report",
                                 description="Test new taps against the poses a report's guaranteed set allows. "
                                 "Exit 0: consistent with the report; 2: the fixture has moved (a proof); 1: bad "
                                 "input.")
    parser.add_argument("report", metavar="REPORT", help="the fixture's report (fixwizard.report/1 or /2)")
    parser.add_argument("points", metavar="POINTS", help="the new taps: YAML {frame: base, points_m: [...]} or CSV "
                        "x,y,z (6-8 spread over the fixture)")
    parser.add_argument("--mesh", metavar="PATH", help="the report's mesh, if it has moved to another folder (it must "
                        "be the same file)")
    parser.add_argument("--ball-diameter", type=_diameter, help="the new taps' ball, e.g. 3mm (default: the report's)")
    parser.add_argument("--sample-bound", type=_positive_length, help="bound on the new taps' error, e.g. 1mm "
                        "(default: the report's)")
    parser.set_defaults(handler="fixwizard.workflow.verify:verify_command")


def _add_export(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("export", help="the report's pose as URScript, a ROS 2 transform or JSON",
                                 description="Write the pose to use from a report for a robot program (URScript, "
                                 "ROS 2) or anything else (JSON).")
    parser.add_argument("report", metavar="REPORT", help="a fixwizard report")
    parser.add_argument("--format", required=True, choices=EXPORT_FORMATS, help="urscript, ros2 or json")
    parser.add_argument("-o", "--output", help="file to write (default, or '-': standard output)")
    parser.add_argument("--frame-id", type=_ros_frame_id,
                        help=f"ros2 only: the parent frame (default {ROS_BASE_FRAME_ID})")
    parser.add_argument("--child-frame-id", type=_ros_frame_id, help="ros2 only: the fixture's frame (default: its "
                        "name with every character but letters, digits and '_' made '_', and fixture_ before a "
                        "leading digit: 1-a.b gives fixture_1_a_b)")
    parser.add_argument("--allow-simulated", action="store_true",
                        help="export a report of the simulated cell to urscript or ros2 (for tests; marked SIMULATED)")
    parser.set_defaults(handler="fixwizard.export:export_command")


def _refuse_frame_ids_without_ros2(args: argparse.Namespace) -> None:
    """export's frame ids name the frames of a ROS 2 transform; with another --format, which has none, they were
    ignored without a word: a usage error instead."""
    if args.command != "export" or args.format == "ros2":
        return
    given = [option for option, value in (("--frame-id", args.frame_id), ("--child-frame-id", args.child_frame_id))
             if value is not None]
    if given:
        one = len(given) == 1
        args.command_parser.error(f"{' and '.join(given)} {'is' if one else 'are'} for --format ros2 only; --format "
                                  f"{args.format} names no frames: leave {'it' if one else 'them'} out, or export "
                                  "--format ros2")


def _add_serve(commands: argparse._SubParsersAction) -> None:
    parser = commands.add_parser("serve", help="serve the newest report of each fixture to robot programs (XML-RPC)",
                                 description="An XML-RPC server for URScript's rpc_factory: get_pose, get_bounds, "
                                 "get_status, is_usable, get_status_text and list_fixtures over the newest report "
                                 "of each fixture in the reports folder.")
    parser.add_argument("--reports", default="reports", metavar="DIR", help="the reports folder (default reports)")
    parser.add_argument("--host", default=SERVE_HOST, help=f"address to listen on (default {SERVE_HOST}: all)")
    parser.add_argument("--port", type=_port, default=SERVE_PORT, help=f"port (default {SERVE_PORT})")
    parser.add_argument("--max-age", type=_age, default=SERVE_MAX_AGE, help=f"refuse older reports, e.g. 8h or 7d "
                        f"(default {SERVE_MAX_AGE})")
    parser.add_argument("--log", metavar="FILE", help="also append the log of calls to FILE")
    parser.set_defaults(handler="fixwizard.serve:serve_command")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="fixwizard", description="Fixture pose calibration with guaranteed bounds from a few "
                     "robot taps. Without a COMMAND it starts the interactive wizard.",
                     epilog="exit codes of solve: 0 unique, 1 bad input, 2 inconsistent, 3 ambiguous, 4 undetermined, "
                     "130 cancelled")
    parser.add_argument("--robot", metavar="HOST", help="wizard: the UR arm at HOST (default: the simulated demo cell)")
    parser.add_argument("--resume", nargs="?", const="", metavar="SESSION",
                        help="wizard: reopen SESSION, or the newest unfinished session, straight into sampling")
    parser.add_argument("--seed", type=int, default=0, help="wizard: seed of the simulated demo cell (default 0)")
    parser.set_defaults(handler="fixwizard.wizard_command:wizard_command")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for add in (_add_solve, _add_import_poses, _add_calibrate_tip, _add_identify, _add_verify, _add_export, _add_serve):
        add(commands)
    parser.set_defaults(command_parser=parser)
    for command_parser in commands.choices.values():
        command_parser.set_defaults(command_parser=command_parser)
    return parser


# Commands that end once their output is written: they leave without the interpreter's teardown (``entry``).
BATCH_COMMANDS = frozenset({"solve", "import-poses", "calibrate-tip", "identify", "verify", "export"})


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code (usage errors and ``--help`` included)."""
    return _run(argv)[0]


def entry() -> NoReturn:
    """The installed ``fixwizard`` command and ``python -m fixwizard.cli``: ``main``, then leave. A batch command
    leaves without the interpreter's teardown of its libraries (0.3 s after its last line on a quiet 2-core PC, up
    to 6 s on a loaded one, also after Ctrl+C): by then its files are written whole and closed (``atomic``), it
    has no child process, and only its own threads, stopped or cancelled, are left. The wizard and serve, which
    have children or connections to close, leave as usual."""
    code, batch = _run(None)
    if not batch:
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):  # a reader that went away (``| head``): nothing left to tell
            stream.flush()
    os._exit(code)


def _run(argv: list[str] | None) -> tuple[int, bool]:
    """The exit code, and whether a batch command ran."""
    try:
        args, extras = build_parser().parse_known_args(argv)
        if extras:
            args.command_parser.refuse_unrecognized(extras)
        _refuse_frame_ids_without_ros2(args)
    except SystemExit as leaving:  # argparse leaves after --help (0) or a usage error (1, said on stderr)
        return int(leaving.code or 0), False
    batch = args.command in BATCH_COMMANDS
    try:
        module, function = args.handler.split(":")
        return getattr(importlib.import_module(module), function)(args), batch
    except FixwizardError as error:
        print(f"fixwizard: {command_line_text(str(error), likely_units(error))}", file=sys.stderr)
        return EXIT_BAD_INPUT, batch
    except BrokenPipeError:  # the standard output's reader left (``| head``): nothing to tell it
        return EXIT_READER_GONE, batch
    except OSError as error:
        print(f"fixwizard: {file_problem(error)}", file=sys.stderr)
        return EXIT_BAD_INPUT, batch
    except KeyboardInterrupt:  # long work runs interruptibly (``interrupt``): this arrives within 0.1 s
        print("fixwizard: cancelled; nothing was written", file=sys.stderr)
        return EXIT_CANCELLED, batch


if __name__ == "__main__":
    entry()
