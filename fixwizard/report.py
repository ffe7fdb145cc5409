"""The YAML report robot programs read, schema ``fixwizard.report/1``: written atomically, loaded with checks.

Poses are of the fixture's CAD frame in the robot base frame. Taps are numbered from 1 in
messages and in ``suspect_tap.tap``.
"""

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from fixwizard.atomic import write_text_atomic
from fixwizard.errors import InputError
from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import format_ur_pose, make_transform
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import Solution
from fixwizard.solver.verdict import STATUSES
from fixwizard.yamlfile import load_document

SCHEMA = "fixwizard.report/1"



def _floats(values) -> list[float]:
    return [float(value) for value in np.asarray(values).ravel()]


def pose_dict(base_T_cad: np.ndarray) -> dict:
    """Report form of a pose: position (m), rotation vector (rad), quaternion (x, y, z, w) and UR literal."""
    rotation = Rotation.from_matrix(base_T_cad[:3, :3])
    return {"position_m": _floats(base_T_cad[:3, 3]), "rotvec_rad": _floats(rotation.as_rotvec()),
            "quaternion_xyzw": _floats(rotation.as_quat()), "ur": format_ur_pose(base_T_cad)}


def bounds_dict(bounds: Bounds) -> dict:
    center = bounds.base_T_cad_center
    return {"center": {"position_m": _floats(center[:3, 3]),
                       "rotvec_rad": _floats(Rotation.from_matrix(center[:3, :3]).as_rotvec())},
            "position_m": float(bounds.position_m),
            "rotation_deg": float(np.degrees(bounds.rotation_rad)),
            "max_point_displacement_m": float(bounds.max_point_displacement_m)}


def _diagnosis_dict(solution: Solution) -> dict | None:
    """Why no pose explains the taps (inconsistent only): causes most likely first, the smallest sample bound's
    bracket (ruled out, not ruled out; m) and a ball diameter (m) that explains the taps, if one was found."""
    diagnosis = solution.diagnosis
    if diagnosis is None:
        return None
    return {"causes": [{"code": cause.code, "message": cause.message} for cause in diagnosis.causes],
            "smallest_sample_bound_m": (None if diagnosis.smallest_bound_m is None
                                        else [float(value) for value in diagnosis.smallest_bound_m]),
            "ball_diameter_m": None if diagnosis.ball_diameter_m is None else float(diagnosis.ball_diameter_m)}


def report_dict(solution: Solution, fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float,
                sample_bound_m: float, sigma_m: float, created: dt.datetime | None = None) -> dict:
    """The report as plain data (see the module docstring for the schema)."""
    created = created or dt.datetime.now(dt.timezone.utc).astimezone()
    suspect = solution.suspect_tap
    return {
        "schema": SCHEMA,
        "created": created.isoformat(timespec="seconds"),
        "status": solution.status,
        "pose": pose_dict(solution.base_T_cad) if solution.base_T_cad is not None else None,
        "bounds": bounds_dict(solution.bounds) if solution.bounds is not None else None,
        "intervals": [{"level": interval.level, "position_m": float(interval.position_m),
                       "rotation_deg": float(np.degrees(interval.rotation_rad))}
                      for interval in solution.intervals] or None,
        "effective_samples": round(float(solution.effective_samples), 1),
        "modes": [{"probability": mode.probability, "cells": mode.cell_count, "pose": pose_dict(mode.base_T_cad),
                   "bounds": bounds_dict(mode.bounds)} for mode in solution.modes],
        "warnings": [{"code": warning.code, "message": warning.message} for warning in solution.warnings],
        "suspect_tap": ({"tap": suspect.index + 1, "distance_from_surface_m": suspect.distance_m}
                        if suspect is not None else None),
        "diagnosis": _diagnosis_dict(solution),
        "search": {"cells": solution.stats.cells, "rotation_level": solution.stats.rotation_level,
                   "position_level": solution.stats.position_level, "elapsed_s": round(solution.stats.elapsed_s, 3),
                   "max_cells": float(solution.stats.max_cells)},
        "inputs": {"mesh": str(fixture.path), "mesh_sha256": fixture.sha256, "mesh_units": fixture.units,
                   "ball_diameter_m": float(ball_diameter_m), "sample_bound_m": float(sample_bound_m),
                   "sigma_m": float(sigma_m), "points_m": [_floats(point) for point in base_p_taps]},
    }


def write(path: str | Path, report: dict) -> Path:
    """Write a report dict atomically."""
    return write_text_atomic(path, yaml.safe_dump(report, sort_keys=False, width=120))


@dataclass(frozen=True)
class Report:
    """A loaded report. ``base_T_cad`` and ``center_base_T_cad`` are None for an inconsistent result."""

    status: str
    base_T_cad: np.ndarray | None
    center_base_T_cad: np.ndarray | None
    position_bound_m: float | None
    rotation_bound_deg: float | None
    max_point_displacement_m: float | None
    data: dict


def _pose_from(section: dict, path: Path, where: str) -> np.ndarray:
    try:
        position = np.array(section["position_m"], float).reshape(3)
        rotvec = np.array(section["rotvec_rad"], float).reshape(3)
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: {where} needs position_m and rotvec_rad as three numbers each") from error
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(rotvec))):
        raise InputError(f"{path}: {where} holds numbers that are not finite")
    return make_transform(Rotation.from_rotvec(rotvec), position)


def load(path: str | Path) -> Report:
    """Read and check a report written by ``write``; raises InputError for a damaged or foreign file."""
    path = Path(path)
    data = load_document(path, SCHEMA, "fixwizard report")
    if data.get("status") not in STATUSES:
        raise InputError(f"{path}: status must be one of {', '.join(STATUSES)}")
    if data["status"] == "inconsistent":
        return Report("inconsistent", None, None, None, None, None, data)
    bounds = data.get("bounds")
    if not isinstance(data.get("pose"), dict) or not isinstance(bounds, dict):
        raise InputError(f"{path}: a {data['status']} report needs 'pose' and 'bounds'")
    try:
        figures = [float(bounds[key]) for key in ("position_m", "rotation_deg", "max_point_displacement_m")]
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: bounds need position_m, rotation_deg and max_point_displacement_m") from error
    return Report(data["status"], _pose_from(data["pose"], path, "pose"),
                  _pose_from(bounds.get("center") or {}, path, "bounds.center"), *figures, data)
