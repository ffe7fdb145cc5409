"""The stored tool-tip calibration: ``calibrations/<name>.yaml`` with schema ``fixwizard.tip/1``.

The file holds the tip (m, flange frame), the ball diameter, the proposed sample bound with its reason,
residual statistics (mm), the table frame as a UR pose (m, rad), and the raw flange poses of every step
(UR poses, m and rad) with the taps that were excluded, so that anyone can recompute or audit it.
"""

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from fixwizard.atomic import write_text_atomic
from fixwizard.calibration.errors import CalibrationFileError
from fixwizard.calibration.residuals import ExcludedTap, ResidualStats
from fixwizard.calibration.taps import PoseSeries, readonly_array
from fixwizard.geometry.se3 import from_ur_pose, to_ur_pose
from fixwizard.yamlfile import load_document

SCHEMA = "fixwizard.tip/1"
STEPS = ("pivot", "table_coarse", "table", "tilted")
OPTIONAL_STEPS = ("table_coarse",)


@dataclass(frozen=True, eq=False)
class TipCalibration:
    """A tool-tip calibration. Lengths in metres; ``created`` is ISO 8601; ``robot`` None when unknown.

    ``tcp_p_tip_m`` is the ball centre in the flange frame, ``sample_bound_m`` the proposed bound on a
    tap's error, ``base_T_table`` the table frame (4, 4), ``pivot_tcp_p_tip_m`` the coarse tip.
    ``tip_standard_error_m`` comes from the scatter of the fine taps alone: systematic robot errors are
    not in it. ``steps`` maps "pivot", "table", "tilted" and, when taken, "table_coarse" to their
    recorded poses.
    """

    name: str
    created: str
    robot: str | None
    tcp_p_tip_m: np.ndarray
    ball_diameter_m: float
    sample_bound_m: float
    sample_bound_reason: str
    base_T_table: np.ndarray
    pivot_tcp_p_tip_m: np.ndarray
    pivot_residuals: ResidualStats
    table_residuals: ResidualStats
    tip_residuals: ResidualStats
    tip_condition_number: float
    tip_standard_error_m: np.ndarray
    steps: dict[str, PoseSeries]

    def __post_init__(self) -> None:
        for name in ("tcp_p_tip_m", "base_T_table", "pivot_tcp_p_tip_m", "tip_standard_error_m"):
            object.__setattr__(self, name, readonly_array(getattr(self, name)))


def save_calibration(calibration: TipCalibration, path: str | Path) -> Path:
    """Write the calibration atomically (temporary file in the same folder, then rename)."""
    text = yaml.safe_dump(_document(calibration), sort_keys=False, default_flow_style=None, width=120)
    try:
        return write_text_atomic(path, text)
    except OSError as error:
        raise CalibrationFileError(f"cannot write the tip calibration {path}: {error}") from error


def load_calibration(path: str | Path) -> TipCalibration:
    """Read and check a ``fixwizard.tip/1`` file; CalibrationFileError says what is wrong with a bad one."""
    path = Path(path)
    data = load_document(path, SCHEMA, "tip calibration", CalibrationFileError,
                         " Give a file written by `fixwizard calibrate-tip`.")
    try:
        return _calibration(data)
    except _Damaged as problem:
        raise CalibrationFileError(f"the tip calibration {path} is damaged: {problem}. Recompute it with "
                                   "`fixwizard calibrate-tip`.") from None


def _document(calibration: TipCalibration) -> dict:
    steps = {name: _series_document(series) for name, series in calibration.steps.items()}
    return {
        "schema": SCHEMA,
        "name": calibration.name,
        "created": calibration.created,
        "robot": calibration.robot,
        "tcp_p_tip_m": calibration.tcp_p_tip_m.tolist(),
        "ball_diameter_m": float(calibration.ball_diameter_m),
        "sample_bound_m": float(calibration.sample_bound_m),
        "sample_bound_reason": calibration.sample_bound_reason,
        "base_T_table_ur_m_rad": to_ur_pose(calibration.base_T_table).tolist(),
        "fit": {
            "pivot": {"tcp_p_tip_m": calibration.pivot_tcp_p_tip_m.tolist(),
                      **_stats_document(calibration.pivot_residuals)},
            "table_plane": _stats_document(calibration.table_residuals),
            "fine_tip": {**_stats_document(calibration.tip_residuals),
                         "condition_number": float(calibration.tip_condition_number),
                         "standard_error_mm": (calibration.tip_standard_error_m * 1e3).tolist()},
        },
        "steps": {name: steps[name] for name in STEPS if name in steps},
    }


def _stats_document(stats: ResidualStats) -> dict:
    return {"rms_mm": stats.rms_m * 1e3, "max_mm": stats.max_m * 1e3}


def _series_document(series: PoseSeries) -> dict:
    return {"base_T_tcp_ur_m_rad": [to_ur_pose(base_T_tcp).tolist() for base_T_tcp in series.base_T_tcp],
            "files": list(series.files),
            "excluded": [{"index": tap.index, "file": tap.file, "residual_mm": tap.residual_m * 1e3,
                          "threshold_mm": tap.threshold_m * 1e3} for tap in series.excluded]}


class _Damaged(Exception):
    """A value of the file is missing or unusable; the message names it."""


def _calibration(data: dict) -> TipCalibration:
    fit = _get(data, "fit", "")
    pivot = _get(fit, "pivot", "fit.")
    fine_tip = _get(fit, "fine_tip", "fit.")
    steps_data = _get(data, "steps", "")
    if not isinstance(steps_data, dict):
        raise _Damaged("'steps' must map step names to their poses")
    steps = {name: _series(_get(steps_data, name, "steps."), f"steps.{name}")
             for name in STEPS if name not in OPTIONAL_STEPS or name in steps_data}
    return TipCalibration(
        name=_text(_get(data, "name", ""), "name"),
        created=_text(_get(data, "created", ""), "created"),
        robot=_optional_text(_get(data, "robot", ""), "robot"),
        tcp_p_tip_m=_numbers(_get(data, "tcp_p_tip_m", ""), (3,), "tcp_p_tip_m"),
        ball_diameter_m=_positive(_get(data, "ball_diameter_m", ""), "ball_diameter_m"),
        sample_bound_m=_positive(_get(data, "sample_bound_m", ""), "sample_bound_m"),
        sample_bound_reason=_text(_get(data, "sample_bound_reason", ""), "sample_bound_reason"),
        base_T_table=from_ur_pose(_numbers(_get(data, "base_T_table_ur_m_rad", ""), (6,), "base_T_table_ur_m_rad")),
        pivot_tcp_p_tip_m=_numbers(_get(pivot, "tcp_p_tip_m", "fit.pivot."), (3,), "fit.pivot.tcp_p_tip_m"),
        pivot_residuals=_stats(pivot, "fit.pivot."),
        table_residuals=_stats(_get(fit, "table_plane", "fit."), "fit.table_plane."),
        tip_residuals=_stats(fine_tip, "fit.fine_tip."),
        tip_condition_number=_positive(_get(fine_tip, "condition_number", "fit.fine_tip."),
                                       "fit.fine_tip.condition_number"),
        tip_standard_error_m=_numbers(_get(fine_tip, "standard_error_mm", "fit.fine_tip."), (3,),
                                      "fit.fine_tip.standard_error_mm") / 1e3,
        steps=steps)


def _get(section: Any, key: str, where: str) -> Any:
    if not isinstance(section, dict) or key not in section:
        raise _Damaged(f"'{where}{key}' is missing")
    return section[key]


def _numbers(value: Any, shape: tuple[int | None, ...], where: str) -> np.ndarray:
    """Finite float array of the given shape (None: any length)."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise _Damaged(f"'{where}' must hold numbers") from None
    if array.ndim != len(shape) or any(want is not None and have != want
                                        for have, want in zip(array.shape, shape, strict=True)):
        wanted = " x ".join("N" if want is None else str(want) for want in shape) or "one number"
        raise _Damaged(f"'{where}' must be {wanted}, not of shape {array.shape}")
    if not np.all(np.isfinite(array)):
        raise _Damaged(f"'{where}' holds numbers that are not finite")
    return array


def _number(value: Any, where: str) -> float:
    return float(_numbers(value, (), where))


def _positive(value: Any, where: str) -> float:
    number = _number(value, where)
    if number <= 0:
        raise _Damaged(f"'{where}' must be positive, not {number}")
    return number


def _text(value: Any, where: str) -> str:
    if isinstance(value, str):
        return value
    raise _Damaged(f"'{where}' must be text")


def _optional_text(value: Any, where: str) -> str | None:
    return None if value is None else _text(value, where)


def _stats(section: Any, where: str) -> ResidualStats:
    return ResidualStats(*(_number(_get(section, key, where), where + key) / 1e3 for key in ("rms_mm", "max_mm")))


def _series(section: Any, where: str) -> PoseSeries:
    ur_poses = _numbers(_get(section, "base_T_tcp_ur_m_rad", f"{where}."), (None, 6), f"{where}.base_T_tcp_ur_m_rad")
    files = _get(section, "files", f"{where}.")
    if not isinstance(files, list) or not all(isinstance(name, str) for name in files) \
            or len(files) not in (0, len(ur_poses)):
        raise _Damaged(f"'{where}.files' must list one file name per pose (or none)")
    excluded_data = _get(section, "excluded", f"{where}.")
    if not isinstance(excluded_data, list):
        raise _Damaged(f"'{where}.excluded' must be a list")
    return PoseSeries(np.array([from_ur_pose(pose) for pose in ur_poses]).reshape(-1, 4, 4), tuple(files),
                      tuple(_excluded(tap, len(ur_poses), f"{where}.excluded.") for tap in excluded_data))


def _excluded(section: Any, count: int, where: str) -> ExcludedTap:
    index = _get(section, "index", where)
    if not isinstance(index, int) or not 0 <= index < count:
        raise _Damaged(f"'{where}index' must be a tap index from 0 to {count - 1}")
    return ExcludedTap(index, _optional_text(_get(section, "file", where), where + "file"),
                       _number(_get(section, "residual_mm", where), where + "residual_mm") / 1e3,
                       _positive(_get(section, "threshold_mm", where), where + "threshold_mm") / 1e3)
