"""The YAML report robot programs read, schema ``fixwizard.report/2``: built, written atomically, loaded with checks.

Every pose is of the fixture mesh's own CAD frame (its file's origin and axes) in the robot base frame: positions
in metres, rotations as rotation vectors in radians (axis times angle, UR's ``rx, ry, rz``) and quaternions
``x, y, z, w``; angles of bounds in degrees. ``simulated`` comes first, then ``status``.

The pose to use is ``pose``, the most probable pose (the likelihood-weighted mean; the 95/99 % intervals are about
it), with ``pose.guaranteed``: the true pose lies within those figures of it. ``bounds`` describes the guaranteed
set itself: every pose that explains the taps lies within ``bounds`` of ``bounds.center``, the centre those figures
are smallest about; that centre is a reference for the bounds, not a better pose.

Numbers are rounded for people (0.1 um, 1e-6 rad, 1e-5 deg) and guaranteed figures are rounded up, after adding
how far rounding moved the centre they are measured from, so that the written bounds still hold about the written
centre. ``schema: fixwizard.report/2`` is documented by ``fixwizard/schemas/report-2.schema.json``; ``load``
also reads ``fixwizard.report/1`` files. Taps are numbered from 1 in messages and in ``suspect_tap.tap``.
"""

import datetime as dt
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

from fixwizard.atomic import write_text_atomic
from fixwizard.errors import InputError, quoted
from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import make_transform, rotation_angle_rad
from fixwizard.geometry.so3_grid import chord
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import Solution
from fixwizard.solver.verdict import STATUSES
from fixwizard.yamlfile import load_document, parse_yaml_start

T = TypeVar("T")

SCHEMA = "fixwizard.report/2"
SCHEMA_V1 = "fixwizard.report/1"
SCHEMAS = (SCHEMA, SCHEMA_V1)
FRAME = {"pose_of": "fixture CAD frame (the mesh file's own origin and axes)", "relative_to": "robot base frame"}
UNITS = {"length": "m", "rotation_vector": "rad (axis times angle, as UR's rx, ry, rz)",
         "quaternion": "x, y, z, w", "angle": "deg"}
# Clocks of the PC that wrote a report and the one that reads it may differ by this much (s); a report dated
# further in the future says a clock is wrong.
FUTURE_TOLERANCE_S = 300.0
POSITION_DECIMALS = 7  # 0.1 um
ROTVEC_DECIMALS = 6  # 1e-6 rad
QUATERNION_DECIMALS = 7
DEGREE_DECIMALS = 5  # 1e-5 deg, about 2e-7 rad
# A rotation read from the rounded quaternion lies within this angle (rad) of the one of the unrounded quaternion:
# each of four components moves by at most half a unit of the last decimal, and the angle is at most 2 |dq|.
QUATERNION_ROUNDING_RAD = 2.0 * 2.0 * 0.5 * 10.0**-QUATERNION_DECIMALS
CLAIM_BYTES = 8192  # a report names its fixture and time in its first lines (about 1 kB)
MAX_POSITION_M = 1000.0  # farther from the robot base no fixture is: a report saying so was edited or damaged
NAME_PATTERN = re.compile(r"^[A-Za-z0-9_.-]{1,64}$")


def fixture_name(text: str) -> str:
    """A fixture name as given (ASCII letters, digits, ``_``, ``.``, ``-``; at most 64); InputError otherwise."""
    if not isinstance(text, str) or not NAME_PATTERN.match(text):
        raise InputError(f"the fixture name {quoted(text)} must be 1-64 letters, digits, '_', '.' or '-', in ASCII "
                         "(a-z, A-Z, 0-9), e.g. bracket or cell2-plate")
    return text


def name_from_stem(stem: str) -> str:
    """The fixture name derived from a mesh file's stem: every run of other characters becomes ``_``."""
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", stem).strip("_")[:64]
    return name or "fixture"


def _rounded(values, decimals: int) -> list[float]:
    return [round(float(value), decimals) for value in np.asarray(values, float).ravel()]


def round_up(value: float, decimals: int) -> float:
    """The smallest number of ``decimals`` decimals that is not below ``value``; ``value`` itself when it is too
    large to have decimals (a hand-edited report's 1e307 m, which times the scale is no longer finite)."""
    scale = 10.0**decimals
    if not math.isfinite(value * scale):
        return value
    rounded = math.ceil(value * scale) / scale
    return rounded if rounded >= value else rounded + 1.0 / scale


def rounded_up_text(value: float, decimals: int) -> str:
    """A guaranteed figure for a screen: ``round_up`` to ``decimals`` decimals, written with them (0.449 as "0.5" to
    one decimal, never "0.4", which the true pose may lie beyond)."""
    return f"{round_up(value, decimals):.{decimals}f}"


def _written_pose(base_T_cad: np.ndarray) -> tuple[list[float], list[float]]:
    """Position (m) and rotation vector (rad) of a pose as written."""
    return (_rounded(base_T_cad[:3, 3], POSITION_DECIMALS),
            _rounded(Rotation.from_matrix(base_T_cad[:3, :3]).as_rotvec(), ROTVEC_DECIMALS))


def _as_transform(position: list[float], rotvec: list[float]) -> np.ndarray:
    return make_transform(Rotation.from_rotvec(rotvec), np.array(position))


@dataclass(frozen=True)
class _Gap:
    """How far apart two poses are: CAD origins (m), rotations (rad) and any fixture point (m)."""

    position_m: float
    rotation_rad: float
    point_m: float


def _gap(first: np.ndarray, second: np.ndarray, fixture: Fixture) -> _Gap:
    """The distance of two ``base_T_cad``: any fixture point lies within ``r`` of the mesh's enclosing-ball centre,
    so it moves by at most the centre's displacement plus ``r`` times the chord of the rotation between them."""
    angle = float(rotation_angle_rad(first[:3, :3].T @ second[:3, :3]))
    centres = [pose[:3, :3] @ fixture.cad_p_center + pose[:3, 3] for pose in (first, second)]
    point_m = float(np.linalg.norm(centres[0] - centres[1])) + fixture.radius_m * float(chord(angle))
    return _Gap(float(np.linalg.norm(first[:3, 3] - second[:3, 3])), angle, point_m)


def _figures(position_m: float, rotation_rad: float, point_m: float) -> dict:
    """Guaranteed figures as written: rounded up."""
    return {"position_m": round_up(position_m, POSITION_DECIMALS),
            "rotation_deg": round_up(float(np.degrees(min(rotation_rad, np.pi))), DEGREE_DECIMALS),
            "max_point_displacement_m": round_up(point_m, POSITION_DECIMALS)}


def robot_pose_text(status: str, ur_pose: str) -> str:
    """The UR pose literal ``ur_pose`` where a robot program may take it (a unique result), else why there is none,
    for the summaries people read (the report itself says so in its header)."""
    if status == "unique":
        return ur_pose
    return f"none ({status}: robots take only a unique result's pose)"


def pose_dict(base_T_cad: np.ndarray) -> dict:
    """Report form of a pose: position (m), rotation vector (rad), quaternion (x, y, z, w) and UR literal, rounded;
    the quaternion is that of the written rotation vector."""
    position, rotvec = _written_pose(base_T_cad)
    quaternion = Rotation.from_rotvec(rotvec).as_quat()
    quaternion = quaternion if quaternion[3] >= 0 else -quaternion
    return {"position_m": position, "rotvec_rad": rotvec,
            "quaternion_xyzw": _rounded(quaternion, QUATERNION_DECIMALS),
            "ur": "p[" + ", ".join(f"{value:.{POSITION_DECIMALS}f}" for value in position) + ", "
                  + ", ".join(f"{value:.{ROTVEC_DECIMALS}f}" for value in rotvec) + "]"}


def bounds_dict(bounds: Bounds, fixture: Fixture) -> dict:
    """The guaranteed bounds about their centre as written: the centre rounded, and the figures grown by how far
    rounding moved it, then rounded up."""
    position, rotvec = _written_pose(bounds.base_T_cad_center)
    moved = _gap(bounds.base_T_cad_center, _as_transform(position, rotvec), fixture)
    return {"center": {"position_m": position, "rotvec_rad": rotvec},
            **_figures(bounds.position_m + moved.position_m, bounds.rotation_rad + moved.rotation_rad,
                       bounds.max_point_displacement_m + moved.point_m)}


def _lever_m(fixture: Fixture) -> float:
    """The farthest any fixture point lies from the CAD origin (m): a turn about that origin by an angle ``a``
    moves no point by more than this times ``a``."""
    return float(np.linalg.norm(fixture.cad_p_center)) + fixture.radius_m


def _pose_with_guarantee(base_T_cad: np.ndarray, written_bounds: dict, fixture: Fixture) -> dict:
    """``pose_dict`` with ``guaranteed``: the written bounds about the written centre, plus the written pose's
    distance from that centre (and the quaternion's rounding)."""
    pose = pose_dict(base_T_cad)
    centre = written_bounds["center"]
    gap = _gap(_as_transform(pose["position_m"], pose["rotvec_rad"]),
               _as_transform(centre["position_m"], centre["rotvec_rad"]), fixture)
    pose["guaranteed"] = _figures(written_bounds["position_m"] + gap.position_m,
                                  np.radians(written_bounds["rotation_deg"]) + gap.rotation_rad
                                  + QUATERNION_ROUNDING_RAD,
                                  written_bounds["max_point_displacement_m"] + gap.point_m
                                  + _lever_m(fixture) * QUATERNION_ROUNDING_RAD)
    return pose


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
                sample_bound_m: float, sigma_m: float, created: dt.datetime | None = None, simulated: bool = False,
                name: str | None = None) -> dict:
    """The report as plain data (see the module docstring). ``name``: the fixture's name (default: derived from
    the mesh file's stem, ``name_from_stem``); ``simulated``: the taps come from a simulated cell. The mesh is
    named by its absolute path, so that ``fixwizard verify`` finds it from any folder."""
    created = created or dt.datetime.now(dt.UTC).astimezone()
    suspect = solution.suspect_tap
    bounds = bounds_dict(solution.bounds, fixture) if solution.bounds is not None else None
    return {
        "schema": SCHEMA,
        "simulated": bool(simulated),
        "status": solution.status,
        "created": created.isoformat(timespec="seconds"),
        "fixture": {"name": fixture_name(name) if name is not None else name_from_stem(fixture.path.stem),
                    "mesh": str(fixture.path.resolve()), "mesh_sha256": fixture.sha256, "mesh_units": fixture.units},
        "frame": dict(FRAME),
        "units": dict(UNITS),
        "pose": (_pose_with_guarantee(solution.base_T_cad, bounds, fixture)
                 if solution.base_T_cad is not None and bounds is not None else None),
        "bounds": bounds,
        "intervals": [{"level": interval.level, "position_m": round_up(interval.position_m, POSITION_DECIMALS),
                       "rotation_deg": round_up(float(np.degrees(interval.rotation_rad)), DEGREE_DECIMALS)}
                      for interval in solution.intervals] or None,
        "effective_samples": round(float(solution.effective_samples), 1),
        "modes": [{"probability": round(float(mode.probability), 6), "cells": mode.cell_count,
                   "pose": pose_dict(mode.base_T_cad), "bounds": bounds_dict(mode.bounds, fixture)}
                  for mode in solution.modes],
        "warnings": [{"code": warning.code, "message": warning.message} for warning in solution.warnings],
        "suspect_tap": ({"tap": suspect.index + 1,
                         "distance_from_surface_m": round(float(suspect.distance_m), POSITION_DECIMALS)}
                        if suspect is not None else None),
        "diagnosis": _diagnosis_dict(solution),
        "inputs": {"ball_diameter_m": float(ball_diameter_m), "sample_bound_m": float(sample_bound_m),
                   "sigma_m": round(float(sigma_m), 10),
                   "points_m": [_rounded(point, POSITION_DECIMALS) for point in base_p_taps]},
        # last, every key required (``_check_complete``): a file cut short at any line is refused, not read with
        # fewer taps
        "search": {"cells": solution.stats.cells, "rotation_level": solution.stats.rotation_level,
                   "position_level": solution.stats.position_level, "elapsed_s": round(solution.stats.elapsed_s, 3),
                   "max_cells": float(solution.stats.max_cells)},
    }


def _header(report: dict) -> str:
    """The comment lines at the top of a written report: what it is, frames and units, which pose to use."""
    name = report.get("fixture", {}).get("name", "?")
    usable = report.get("status") == "unique" and not report.get("simulated")
    lines = [f"fixwizard report ({report.get('schema')}) of the fixture '{name}'.",
             "Poses: the fixture mesh's own CAD frame (its file's origin and axes) in the robot base frame.",
             ("Units: metres (_m), rotation vectors in radians (_rad, axis times angle, as UR's rx ry rz), degrees "
              "(_deg)."),
             ("Use `pose` (or `pose.ur`, a UR p[...] literal): the most probable pose; the true pose lies within "
              "`pose.guaranteed` of it."),
             ("`bounds` describe the guaranteed set about its centre `bounds.center` (where those bounds are "
              "smallest); the centre is no better pose to use."),
             ("A robot program may use only a `status: unique` report from a real cell (`simulated: false`): "
              + ("this one is." if usable else "THIS ONE IS NOT."))]
    return "".join(f"# {line}\n" for line in lines)


class _Dumper(yaml.SafeDumper):
    """YAML with mappings as blocks and lists of numbers on one line (a point per line)."""


def _represent_list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flat = all(not isinstance(item, (dict, list)) for item in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flat)


_Dumper.add_representer(list, _represent_list)


def write(path: str | Path, report: dict) -> Path:
    """Write a report dict atomically, with comment lines on top saying what it holds."""
    return write_text_atomic(path, _header(report) + yaml.dump(report, Dumper=_Dumper, sort_keys=False, width=120,
                                                                allow_unicode=True))


@dataclass(frozen=True)
class Guarantee:
    """Guaranteed figures about a pose: CAD-origin distance (m), rotation (deg), any fixture point (m)."""

    position_m: float
    rotation_deg: float
    max_point_displacement_m: float


@dataclass(frozen=True)
class Report:
    """A loaded report (``fixwizard.report/2`` or ``/1``). ``base_T_cad`` (the pose to use) and
    ``center_base_T_cad`` with the bounds about it are None for an inconsistent result; ``pose_guarantee`` is
    None for those and for ``/1`` files (which did not state it). ``created`` is timezone-aware."""

    status: str
    base_T_cad: np.ndarray | None
    center_base_T_cad: np.ndarray | None
    position_bound_m: float | None
    rotation_bound_deg: float | None
    max_point_displacement_m: float | None
    data: dict
    path: Path
    schema: str
    simulated: bool
    created: dt.datetime
    name: str
    mesh: Path
    mesh_sha256: str
    mesh_units: str
    ball_diameter_m: float
    sample_bound_m: float
    pose_guarantee: Guarantee | None

    def ur_pose_to_use(self) -> list[float] | None:
        """``pose_to_use`` as the report writes it, ``[x, y, z, rx, ry, rz]`` (m, rad), every digit kept (so that
        its guarantee holds for these numbers); None for an inconsistent report."""
        if self.pose_to_use() is None:
            return None
        section = self.data["pose"] if self.pose_guarantee is not None else self.data["bounds"]["center"]
        values = np.concatenate([np.array(section["position_m"], float).reshape(3),
                                 np.array(section["rotvec_rad"], float).reshape(3)])
        return [float(value) for value in values]

    def pose_to_use(self) -> tuple[np.ndarray, Guarantee] | None:
        """The pose a robot program uses and the guarantee of its error: ``pose`` and ``pose.guaranteed``; for a
        ``/1`` file, which states no guarantee for ``pose``, the bounds' centre and the bounds. None for an
        inconsistent report."""
        if self.base_T_cad is None or self.center_base_T_cad is None:
            return None
        if self.pose_guarantee is not None:
            return self.base_T_cad, self.pose_guarantee
        assert self.position_bound_m is not None and self.rotation_bound_deg is not None
        assert self.max_point_displacement_m is not None
        return self.center_base_T_cad, Guarantee(self.position_bound_m, self.rotation_bound_deg,
                                                 self.max_point_displacement_m)


def _not_bool(value: T) -> T:
    """``value`` unless it is or holds a YAML boolean (``true`` would be read as the number 1): ``TypeError`` then."""
    if isinstance(value, bool) or (isinstance(value, list) and any(isinstance(item, bool) for item in value)):
        raise TypeError("a boolean is no number")
    return value


def _pose_from(section: object, path: Path, where: str) -> np.ndarray:
    if not isinstance(section, dict):
        raise InputError(f"{path}: {where} needs position_m and rotvec_rad as three numbers each")
    try:
        position = np.array(_not_bool(section["position_m"]), float).reshape(3)
        rotvec = np.array(_not_bool(section["rotvec_rad"]), float).reshape(3)
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: {where} needs position_m and rotvec_rad as three numbers each") from error
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(rotvec))):
        raise InputError(f"{path}: {where} holds numbers that are not finite")
    if np.any(np.abs(position) > MAX_POSITION_M):
        raise InputError(f"{path}: {where}.position_m lies more than {MAX_POSITION_M:g} m from the robot base: was the "
                         "report edited?")
    if np.any(np.abs(rotvec) > math.pi + 1.0) or np.linalg.norm(rotvec) > math.pi + 10.0**-ROTVEC_DECIMALS:
        raise InputError(f"{path}: {where}.rotvec_rad turns by more than pi rad: fixwizard writes no such rotation "
                         "vector; was the report edited?")
    base_T_cad = make_transform(Rotation.from_rotvec(rotvec), position)
    _check_other_forms(section, base_T_cad, np.concatenate([position, rotvec]), path, where)
    return base_T_cad


def _check_other_forms(section: dict, base_T_cad: np.ndarray, values: np.ndarray, path: Path, where: str) -> None:
    """InputError unless the section's quaternion and UR literal, where it has them, are the pose of its position
    and rotation vector (``base_T_cad``; ``values``: the six numbers as written) (a robot program may read any of
    them): a report edited in one of them only. The literal is compared with the numbers written, not with a rotation
    vector of the matrix: half a turn has two, of opposite signs, and the written one may turn by a hair more than
    pi."""
    quaternion = section.get("quaternion_xyzw")
    if quaternion is not None:
        try:
            quaternion = np.array(_not_bool(quaternion), float).reshape(4)
        except (TypeError, ValueError) as error:
            raise InputError(f"{path}: {where}.quaternion_xyzw must be four numbers") from error
        if not (np.all(np.abs(quaternion) <= 1.0 + 1e-5) and abs(np.linalg.norm(quaternion) - 1.0) < 1e-5):
            raise InputError(f"{path}: {where}.quaternion_xyzw is not a unit quaternion")
        apart_rad = rotation_angle_rad(Rotation.from_quat(quaternion).as_matrix().T @ base_T_cad[:3, :3])
        if apart_rad > 2.0 * QUATERNION_ROUNDING_RAD:
            raise InputError(f"{path}: {where}.quaternion_xyzw and rotvec_rad are rotations "
                             f"{np.degrees(apart_rad):.3g} deg apart: the report was edited in one of them only")
    literal = section.get("ur")
    if literal is not None:
        written = _ur_numbers(literal)
        # every fixwizard version wrote it with at least 6 decimals (version 1: 6 for each number)
        if written is None or not np.all(np.abs(written - values) <= 0.5e-6 + 1e-12):
            raise InputError(f"{path}: {where}.ur is not p[{', '.join(f'{value:.6g}' for value in values)}], the "
                             "pose of position_m and rotvec_rad: the report was edited in one of them only")


def _ur_numbers(literal: object) -> np.ndarray | None:
    """The six numbers of a UR pose literal ``p[x, y, z, rx, ry, rz]``, or None."""
    if not isinstance(literal, str):
        return None
    match = re.fullmatch(r"\s*p\[([^\]]*)\]\s*", literal)
    texts = [text.strip() for text in match.group(1).split(",")] if match else []
    if len(texts) != 6 or not all(re.fullmatch(r"-?\d+(\.\d+)?", text) for text in texts):
        return None
    return np.array([float(text) for text in texts])


def _figures_from(section: object, path: Path, where: str) -> list[float]:
    """(position_m, rotation_deg, max_point_displacement_m) of a bounds-like section, finite and not negative."""
    try:
        figures = [float(_not_bool(section[key])) for key in ("position_m", "rotation_deg",  # type: ignore[index]
                                                              "max_point_displacement_m")]
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: {where} need position_m, rotation_deg and max_point_displacement_m") from error
    if not all(math.isfinite(value) and value >= 0 for value in figures):
        raise InputError(f"{path}: {where} must be finite numbers that are not negative")
    return figures


def _created(data: dict, path: Path) -> dt.datetime:
    value = data.get("created")
    if isinstance(value, str):
        try:
            value = dt.datetime.fromisoformat(value)
        except ValueError:
            value = None
    if not isinstance(value, dt.datetime):
        raise InputError(f"{path}: 'created' must be the time the report was written (ISO 8601, e.g. "
                         f"2026-11-24T10:15:00+00:00), not {quoted(data.get('created'))}")
    return value if value.tzinfo is not None else value.replace(tzinfo=dt.UTC)


def _positive_input(inputs: dict, key: str, path: Path, allow_zero: bool = False) -> float:
    try:
        value = float(_not_bool(inputs[key]))
    except (KeyError, TypeError, ValueError) as error:
        raise InputError(f"{path}: inputs.{key} must be a length in metres") from error
    if not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise InputError(f"{path}: inputs.{key} must be a positive length in metres, not {value}")
    return value


def _fixture_section(data: dict, path: Path) -> tuple[str, Path, str, str]:
    """Name, mesh path, its sha256 and units: ``fixture`` of a /2 report, ``inputs`` of a /1 report (named after
    the mesh file's stem)."""
    inputs = data.get("inputs")
    section = data.get("fixture") if data["schema"] == SCHEMA else inputs
    if not isinstance(section, dict):
        raise InputError(f"{path}: the report does not say which fixture it is ('fixture' with name, mesh, "
                         "mesh_sha256 and mesh_units)")
    mesh, sha256, units = section.get("mesh"), section.get("mesh_sha256"), section.get("mesh_units")
    if not (isinstance(mesh, str) and mesh and isinstance(sha256, str) and units in ("m", "mm")):
        raise InputError(f"{path}: the fixture's mesh, mesh_sha256 and mesh_units (m or mm) are missing or damaged")
    name = section.get("name") if data["schema"] == SCHEMA else name_from_stem(Path(mesh).stem)
    if not isinstance(name, str):
        raise InputError(f"{path}: fixture.name must be the fixture's name, e.g. bracket, not {quoted(name)}")
    try:
        return fixture_name(name), Path(mesh), sha256, units
    except InputError as error:
        raise InputError(f"{path}: {error}") from None


SEARCH_KEYS = ("cells", "rotation_level", "position_level", "elapsed_s", "max_cells")


def _check_complete(data: dict, path: Path) -> None:
    """InputError unless a ``/2`` report's ``search`` section, which ``report_dict`` writes last, holds all its
    numbers: a report cut short (a copy that did not finish) lacks its last line at least."""
    search = data.get("search")
    if data["schema"] != SCHEMA:
        return
    if not (isinstance(search, dict) and all(isinstance(search.get(key), int | float) for key in SEARCH_KEYS)):
        raise InputError(f"{path}: 'search' ({', '.join(SEARCH_KEYS)}) is missing or incomplete: the report may "
                         "be cut short (a copy that did not finish?); copy it again or solve again")


def load(path: str | Path) -> Report:
    """Read and check a report written by ``write`` (or a ``fixwizard.report/1`` file); InputError says what is
    wrong with a damaged or foreign file."""
    path = Path(path)
    data = load_document(path, SCHEMAS, "fixwizard report")
    _check_complete(data, path)  # first: a copy cut short lacks later sections, which is what to say about it
    status = data.get("status")
    if status not in STATUSES:
        raise InputError(f"{path}: status must be one of {', '.join(STATUSES)}, not {quoted(status)}")
    simulated = data.get("simulated", False)
    if not isinstance(simulated, bool):
        raise InputError(f"{path}: 'simulated' must be true or false, not {quoted(simulated)}")
    name, mesh, sha256, units = _fixture_section(data, path)
    inputs = data["inputs"] if isinstance(data.get("inputs"), dict) else {}
    created = _created(data, path)
    ball_diameter_m = _positive_input(inputs, "ball_diameter_m", path, allow_zero=True)
    sample_bound_m = _positive_input(inputs, "sample_bound_m", path)

    def loaded(base_T_cad: np.ndarray | None, center: np.ndarray | None, figures: list[float] | list[None],
               guarantee: Guarantee | None) -> Report:
        return Report(status, base_T_cad, center, position_bound_m=figures[0], rotation_bound_deg=figures[1],
                      max_point_displacement_m=figures[2], data=data, path=path, schema=data["schema"],
                      simulated=simulated, created=created, name=name, mesh=mesh, mesh_sha256=sha256, mesh_units=units,
                      ball_diameter_m=ball_diameter_m, sample_bound_m=sample_bound_m, pose_guarantee=guarantee)

    if status == "inconsistent":
        return loaded(None, None, [None, None, None], None)
    pose, bounds = data.get("pose"), data.get("bounds")
    if not isinstance(pose, dict) or not isinstance(bounds, dict):
        raise InputError(f"{path}: a {status} report needs 'pose' and 'bounds'")
    guarantee = (Guarantee(*_figures_from(pose.get("guaranteed"), path, "pose.guaranteed"))
                 if data["schema"] == SCHEMA else None)
    found = loaded(_pose_from(pose, path, "pose"), _pose_from(bounds.get("center"), path, "bounds.center"),
                   _figures_from(bounds, path, "bounds"), guarantee)
    _check_guarantee_covers_the_pose(found)
    return found


def _claim(path: Path) -> dict | None:
    """The start of the file at ``path`` (its first ``CLAIM_BYTES``, as far as they parse) when it says it is a
    fixwizard report of any version, damaged or not; None otherwise (also for a file that cannot be read)."""
    try:
        with path.open("rb") as stream:
            start = stream.read(CLAIM_BYTES)
    except OSError:
        return None
    text = start.decode("utf-8-sig", errors="replace")
    data = parse_yaml_start(text if len(start) < CLAIM_BYTES else text[:text.rfind("\n") + 1])
    if not (isinstance(data, dict) and isinstance(data.get("schema"), str)
            and data["schema"].startswith(SCHEMA.rsplit("/", 1)[0] + "/")):
        return None
    return data


def is_report_file(path: str | Path) -> bool:
    """Whether ``path`` is a regular file that says it is a fixwizard report (of any version, damaged or not): to
    tell an argument given in another's place. A pipe is never read (it would wait for a writer)."""
    path = Path(path)
    return path.is_file() and _claim(path) is not None


def claimed_fixture(path: Path) -> tuple[str | None, dt.datetime | None]:
    """The fixture name and creation time that a file ``load`` refuses (cut short, edited, of a newer version) says
    it is a report of, read from its first ``CLAIM_BYTES`` as far as they parse; None for what it does not say (a
    file that is no fixwizard report says neither)."""
    data = _claim(path)
    if data is None:
        return None, None
    section = data.get("inputs" if data["schema"] == SCHEMA_V1 else "fixture")
    name = section.get("name") if isinstance(section, dict) and data["schema"] != SCHEMA_V1 else None
    if isinstance(section, dict) and data["schema"] == SCHEMA_V1 and isinstance(section.get("mesh"), str):
        name = name_from_stem(Path(section["mesh"]).stem)
    if not (isinstance(name, str) and NAME_PATTERN.match(name)):
        name = None
    try:
        created: dt.datetime | None = _created(data, path)
    except InputError:
        created = None
    return name, created


def _check_guarantee_covers_the_pose(found: Report) -> None:
    """InputError unless ``pose.guaranteed`` is at least the bounds plus the pose's distance from their centre, as
    ``write`` makes it (in position and rotation; the point figure needs the mesh): a pose edited by hand keeps a
    guarantee that no longer holds about it."""
    if found.pose_guarantee is None or found.base_T_cad is None or found.center_base_T_cad is None:
        return
    assert found.position_bound_m is not None and found.rotation_bound_deg is not None
    guarantee, pose, centre = found.pose_guarantee, found.base_T_cad, found.center_base_T_cad
    apart_m = float(np.linalg.norm(pose[:3, 3] - centre[:3, 3]))
    apart_deg = math.degrees(rotation_angle_rad(centre[:3, :3].T @ pose[:3, :3]))
    if (guarantee.position_m + 1e-9 < found.position_bound_m + apart_m
            or guarantee.rotation_deg + 1e-6 < min(found.rotation_bound_deg + apart_deg, 180.0)):
        bounds_mm = found.position_bound_m * 1e3
        raise InputError(f"{found.path}: pose.guaranteed ({guarantee.position_m * 1e3:.4g} mm, "
                         f"{guarantee.rotation_deg:.4g} deg) is less than the bounds ({bounds_mm:.4g} mm, "
                         f"{found.rotation_bound_deg:.4g} deg) plus the pose's distance from bounds.center "
                         f"({apart_m * 1e3:.4g} mm, {apart_deg:.4g} deg), so it does not hold about the pose: the "
                         "report was edited; solve again")
