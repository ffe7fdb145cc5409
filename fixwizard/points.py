"""The POINTS file: measured ball centres in the robot base frame, metres.

YAML ``{frame: base, points_m: [[x, y, z], ...]}`` or CSV with one ``x,y,z`` row per tap
(an optional header row of names is skipped).
"""

import csv
import io
from pathlib import Path

import numpy as np
import yaml

from fixwizard.atomic import write_text_atomic
from fixwizard.errors import InputError

POINTS_FRAME = "base"


def _rows_to_array(rows: list, path: Path) -> np.ndarray:
    points = []
    for number, row in enumerate(rows, start=1):
        try:
            values = [float(value) for value in row]
        except (TypeError, ValueError):
            raise InputError(f"tap {number} in {path} is not three numbers: {row!r}") from None
        if len(values) != 3:
            raise InputError(f"tap {number} in {path} has {len(values)} numbers; each tap is x, y, z in metres")
        if not np.all(np.isfinite(values)):
            raise InputError(f"tap {number} in {path} has a coordinate that is not a finite number ({row!r}); "
                             "fix or remove that tap")
        points.append(values)
    return np.array(points, dtype=float).reshape(-1, 3)


def _read_csv(text: str, path: Path) -> np.ndarray:
    rows = [row for row in csv.reader(io.StringIO(text)) if row and any(cell.strip() for cell in row)]
    if rows and not _is_number(rows[0][0]):
        rows = rows[1:]
    return _rows_to_array(rows, path)


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_yaml(text: str, path: Path) -> np.ndarray:
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise InputError(f"{path} is not valid YAML: {error}") from error
    if not isinstance(data, dict) or "points_m" not in data:
        raise InputError(f"{path} must be YAML with 'frame: base' and 'points_m: [[x, y, z], ...]' in metres")
    if data.get("frame", POINTS_FRAME) != POINTS_FRAME:
        raise InputError(f"{path} gives points in frame {data.get('frame')!r}; fixwizard needs them in the robot "
                         "base frame ('frame: base')")
    if not isinstance(data["points_m"], list):
        raise InputError(f"points_m in {path} must be a list of [x, y, z] points in metres")
    return _rows_to_array(data["points_m"], path)


def load_points(path: str | Path) -> np.ndarray:
    """Taps (N, 3) in metres from a POINTS file (YAML or CSV by suffix)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(f"cannot read the points file {path}: {error}") from error
    if path.suffix.lower() == ".csv":
        return _read_csv(text, path)
    return _read_yaml(text, path)


def write_points(path: str | Path, base_p_taps: np.ndarray, **extra) -> Path:
    """Write taps (N, 3, metres, base frame) as a POINTS YAML file, atomically; ``extra`` keys are kept."""
    data = {"frame": POINTS_FRAME, "points_m": [[float(value) for value in point] for point in base_p_taps]}
    data.update(extra)
    return write_text_atomic(path, yaml.safe_dump(data, sort_keys=False))
