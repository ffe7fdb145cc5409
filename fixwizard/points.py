"""The POINTS file: measured ball centres in the robot base frame, metres.

YAML ``{frame: base, points_m: [[x, y, z], ...]}`` or CSV with one ``x,y,z`` row per tap
(an optional header row, none of whose cells is a number, is skipped; any other first row is a tap).
"""

import contextlib
import csv
import io
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fixwizard.atomic import write_text_atomic
from fixwizard.errors import InputError, file_problem, quoted
from fixwizard.fixture import MESH_SUFFIXES
from fixwizard.yamlfile import parse_yaml, yaml_problem

POINTS_FRAME = "base"
# 1000 taps (the solver's most) take under 100 kB; a larger file is a point cloud, refused before it is parsed.
MAX_POINTS_FILE_BYTES = 1_000_000
CSV_HEADER = "x_m,y_m,z_m"  # the header row of the CSV files fixwizard writes
_NUMBER_START = re.compile(r"\s*[-+]?(?:\d|\.\d|nan|inf)", re.IGNORECASE)


def _rows_to_array(rows: Sequence[tuple[str, Any]], row_problem: Callable[[Any], str | None] | None = None
                   ) -> np.ndarray:
    """Taps (N, 3) from ``(where, row)`` pairs; ``where`` names the row in messages ("tap 3 in taps.yaml");
    ``row_problem``: what the file's format finds wrong with a row (with the fix), checked first."""
    points = []
    for where, row in rows:
        problem = row_problem(row) if row_problem is not None else None
        if problem is not None:
            raise InputError(f"{where} {problem}")
        try:
            if isinstance(row, bool) or any(isinstance(value, bool) for value in row):
                raise TypeError("true or false is no coordinate")
            values = [float(value) for value in row]
        except (TypeError, ValueError):
            raise InputError(f"{where} is not three numbers: {quoted(row)}") from None
        if len(values) != 3:
            raise InputError(f"{where} has {len(values)} numbers; each tap is x, y, z in metres")
        if not np.all(np.isfinite(values)):
            raise InputError(f"{where} has a coordinate that is not a finite number ({quoted(row)}); "
                             "fix or remove that tap")
        points.append(values)
    return np.array(points, dtype=float).reshape(-1, 3)


def _read_csv(text: str, path: Path) -> np.ndarray:
    """One ``x,y,z`` row per tap, lines ended by LF, CR LF or CR alone (Excel for Mac before 2016); a first row is a
    header only when none of its cells is or starts like a number (a typo in a first row of numbers is an error like
    in any other row)."""
    reader = csv.reader(io.StringIO(text, newline=""))
    try:
        lines = [(reader.line_num, row) for row in reader if any(cell.strip() for cell in row)]
    except csv.Error as error:  # a cell over the reader's field limit (128 kB)
        raise InputError(f"line {reader.line_num} of {path} cannot be read as CSV ({error}): each line is a tap, "
                         "x,y,z in metres") from None
    if lines and not any(_NUMBER_START.match(cell) for cell in lines[0][1]):
        lines = lines[1:]
    rows = [(f"tap {number} (line {line} of {path})", row) for number, (line, row) in enumerate(lines, start=1)]
    return _rows_to_array(rows, _csv_row_problem)


def _separator(row: list[str]) -> str | None:
    """The separator a CSV row that is not three cells seems to use instead of commas (a semicolon, as spreadsheets
    set to a German or French number format save it, tabs or spaces), None when none."""
    text = ",".join(row)
    if ";" in text:
        return "';'"
    if "\t" in text.strip():
        return "tabs"
    return "spaces" if len(row) == 1 and " " in text.strip() else None


def _csv_row_problem(row: list[str]) -> str | None:
    """What is wrong with a CSV row that a spreadsheet or an editor wrote otherwise than fixwizard reads it, with the
    fix (a comment, another separator than commas); None for any other row (its numbers are checked apart). Nothing
    is guessed: ``0,1;0,2;0,3`` may be decimal commas or not."""
    if row and row[0].lstrip().startswith("#"):
        return (f"is a comment ({quoted(','.join(row))}): a points CSV has no comments; delete the line (a first row "
                "of column names, such as x,y,z, may stay)")
    separator = _separator(row) if len(row) != 3 else None
    if separator is None:
        return None
    return (f"separates the numbers with {separator} ({quoted(','.join(row))}): fixwizard reads CSV with commas "
            "between x, y and z, one tap per line, and '.' as the decimal point; save the file so")


def _looks_like_csv(text: str) -> bool:
    """Whether the first line that holds anything is three cells apart by commas (CSV in a file not named .csv)."""
    first = next((line for line in text.splitlines() if line.strip()), "")
    return len(next(csv.reader([first]), [])) == 3


def _read_yaml(text: str, path: Path) -> np.ndarray:
    try:
        data = parse_yaml(text)
    except yaml.YAMLError as error:
        raise InputError(f"{path} is not valid YAML: {yaml_problem(error)}") from error
    if not isinstance(data, dict) or "points_m" not in data:
        csv_hint = (": it looks like CSV, which fixwizard reads from a file named .csv (any other name, standard input "
                    "too, is read as YAML)" if _looks_like_csv(text) else "")
        raise InputError(f"{path} must be YAML with 'frame: base' and 'points_m: [[x, y, z], ...]' in metres"
                         f"{csv_hint}")
    if data.get("frame", POINTS_FRAME) != POINTS_FRAME:
        raise InputError(f"{path} gives points in frame {quoted(data.get('frame'))}; fixwizard needs them in the "
                         "robot base frame ('frame: base')")
    if not isinstance(data["points_m"], list):
        raise InputError(f"points_m in {path} must be a list of [x, y, z] points in metres")
    return _rows_to_array([(f"tap {number} in {path}", row) for number, row in enumerate(data["points_m"], start=1)])


def load_points(path: str | Path) -> np.ndarray:
    """Taps (N, 3) in metres from a POINTS file (YAML or CSV by suffix; a UTF-8 byte-order mark is skipped)."""
    path = Path(path)
    if path.is_dir():
        raise InputError(f"{path} is a folder, not a points file; give the YAML or CSV file of the taps")
    if path.suffix.lower() in MESH_SUFFIXES:
        raise InputError(f"{path} is a mesh, not a points file (YAML or CSV of the taps): are the arguments in the "
                         "wrong order? (solve MESH POINTS, identify POINTS MESH...)")
    too_large = ("a points file holds the taps (at most 1000, under 100 kB), not a point cloud; give the file of the "
                 "tapped ball centres")
    try:
        size = path.stat().st_size
        if size > MAX_POINTS_FILE_BYTES:
            raise InputError(f"{path} holds {size / 1e6:.1f} MB: {too_large}")
        with path.open("rb") as stream:  # a pipe has no size to look at: read no more than the most a file holds
            data = stream.read(MAX_POINTS_FILE_BYTES + 1)
        if len(data) > MAX_POINTS_FILE_BYTES:
            raise InputError(f"{path} holds more than {MAX_POINTS_FILE_BYTES / 1e6:g} MB: {too_large}")
        text = data.decode("utf-8-sig")
    except OSError as error:
        raise InputError(f"cannot read the points file: {file_problem(error, path, 'read')}") from error
    except UnicodeDecodeError as error:
        raise InputError(f"cannot read the points file {path}: it is not UTF-8 text ({error.reason}); save it as "
                         "UTF-8 (or plain ASCII) CSV or YAML") from error
    if path.suffix.lower() == ".csv":
        return _read_csv(text, path)
    return _read_yaml(text, path)


def holds_taps(path: str | Path) -> bool:
    """Whether ``path`` is a regular file of taps: one ``load_points`` reads, or YAML with 'points_m' (some taps
    damaged); to tell an argument given in another's place. A pipe is never read (it would wait for a writer)."""
    path = Path(path)
    if not path.is_file():
        return False
    if path.suffix.lower() == ".csv":
        with contextlib.suppress(InputError):
            load_points(path)
            return True
        return False
    try:
        with path.open("rb") as stream:
            data = parse_yaml(stream.read(MAX_POINTS_FILE_BYTES).decode("utf-8-sig"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return False
    return isinstance(data, dict) and "points_m" in data


def write_points(path: str | Path, base_p_taps: np.ndarray, **extra) -> Path:
    """Write taps (N, 3, metres, base frame) as a POINTS file, atomically: CSV where ``path`` ends in ``.csv`` (a
    header row and one ``x,y,z`` row per tap, every digit kept; ``extra`` is left out), YAML otherwise, ``extra``
    keys kept. A YAML file named .csv was refused by every reader of POINTS."""
    if Path(path).suffix.lower() == ".csv":
        rows = [CSV_HEADER, *(",".join(repr(float(value)) for value in point) for point in base_p_taps)]
        return write_text_atomic(path, "\n".join(rows) + "\n")
    data = {"frame": POINTS_FRAME, "points_m": [[float(value) for value in point] for point in base_p_taps]}
    data.update(extra)
    return write_text_atomic(path, yaml.safe_dump(data, sort_keys=False))
