"""Rigid transforms as 4x4 float64 arrays; conversion to and from UR poses at the edges.

Convention: ``a_T_b @ b_p = a_p``. A UR pose is ``[x, y, z, rx, ry, rz]`` in metres and a
rotation vector in radians.
"""

import re
from pathlib import Path

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from fixwizard.errors import InputError, file_problem, quoted


def make_transform(rotation: np.ndarray | Rotation, translation_m: npt.ArrayLike) -> np.ndarray:
    """4x4 transform from a rotation (matrix or scipy Rotation) and a translation (m)."""
    matrix = rotation.as_matrix() if isinstance(rotation, Rotation) else np.asarray(rotation, float)
    a_T_b = np.eye(4)
    a_T_b[:3, :3] = matrix
    a_T_b[:3, 3] = np.asarray(translation_m, float)
    return a_T_b


def invert(a_T_b: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform: returns ``b_T_a``."""
    b_T_a = np.eye(4)
    b_T_a[:3, :3] = a_T_b[:3, :3].T
    b_T_a[:3, 3] = -a_T_b[:3, :3].T @ a_T_b[:3, 3]
    return b_T_a


def transform_points(a_T_b: np.ndarray, b_points: np.ndarray) -> np.ndarray:
    """Apply ``a_T_b`` to an (N, 3) array of points in frame b; returns points in frame a."""
    return np.asarray(b_points, float) @ a_T_b[:3, :3].T + a_T_b[:3, 3]


def points_in_frames(a_R_b: np.ndarray, a_p_b: np.ndarray, a_points: np.ndarray) -> np.ndarray:
    """Points (N, 3) given in frame a, in each of K frames b with ``a_T_b = (a_R_b (K, 3, 3), a_p_b (K, 3))``:
    ``b_points`` (K, N, 3), i.e. ``a_R_b^T (a_p - a_p_b)``."""
    a_R_b = np.asarray(a_R_b, float).reshape(-1, 3, 3)
    offsets = np.asarray(a_points, float).reshape(1, -1, 3) - np.asarray(a_p_b, float).reshape(-1, 1, 3)
    return np.einsum("kji,knj->kni", a_R_b, offsets)


def from_ur_pose(ur_pose: np.ndarray) -> np.ndarray:
    """4x4 transform from a UR pose ``[x, y, z, rx, ry, rz]`` (m, rad)."""
    ur_pose = np.asarray(ur_pose, float)
    return make_transform(Rotation.from_rotvec(ur_pose[3:6]), ur_pose[:3])


def to_ur_pose(a_T_b: np.ndarray) -> np.ndarray:
    """UR pose ``[x, y, z, rx, ry, rz]`` (m, rad) of a 4x4 transform."""
    return np.concatenate([a_T_b[:3, 3], Rotation.from_matrix(a_T_b[:3, :3]).as_rotvec()])


def format_ur_pose(a_T_b: np.ndarray) -> str:
    """The UR script literal ``p[x, y, z, rx, ry, rz]`` of a transform (m, rad)."""
    return "p[" + ", ".join(f"{value:.6f}" for value in to_ur_pose(a_T_b)) + "]"


def rotation_angle_rad(a_R_b: np.ndarray) -> np.ndarray:
    """Angle (rad, in [0, pi]) of each rotation matrix (..., 3, 3); shape (...). The one home of this figure: for
    the angle between two rotations pass ``a_R_b.T @ a_R_c`` (it broadcasts over stacks).

    ``atan2`` of the sine (half the norm of the skew part) and the cosine (half the trace less one): accurate to
    rounding at every angle, where ``arccos`` of the trace loses half the digits near 0 and near pi."""
    a_R_b = np.asarray(a_R_b, float)
    skew = np.stack([a_R_b[..., 2, 1] - a_R_b[..., 1, 2], a_R_b[..., 0, 2] - a_R_b[..., 2, 0],
                     a_R_b[..., 1, 0] - a_R_b[..., 0, 1]], axis=-1)
    trace = a_R_b[..., 0, 0] + a_R_b[..., 1, 1] + a_R_b[..., 2, 2]
    angle: np.ndarray = np.arctan2(0.5 * np.linalg.norm(skew, axis=-1), 0.5 * (trace - 1.0))
    return angle


def quaternion_angle_rad(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Angle (rad, in [0, pi]) between the rotations of unit quaternions ``q_a`` and ``q_b`` (..., 4; either sign
    convention); shape (...). ``4 asin(c / 2)`` of the chord ``c = |q_a -+ q_b|`` to the nearer sign of ``q_b``
    (``|q_a - q_b|^2 = 2 - 2 cos(angle / 2)``): accurate to rounding at every angle and a dot product per pair,
    where composing the rotations costs a product of quaternions."""
    q_a, q_b = np.asarray(q_a, float), np.asarray(q_b, float)
    sign = np.where(np.sum(q_a * q_b, axis=-1) < 0.0, -1.0, 1.0)[..., None]
    half_chord = 0.5 * np.linalg.norm(q_a - sign * q_b, axis=-1)
    angle: np.ndarray = np.minimum(4.0 * np.arcsin(np.minimum(half_chord, np.sqrt(0.5))), np.pi)
    return angle


POSE_FILE_HOLDS = ("A .pose file holds six numbers x y z rx ry rz (metres, radians), one per line or apart by spaces, "
                   "with '.' as the decimal point")
MAX_POSE_FILE_BYTES = 65_536  # six numbers take about 120 bytes: a larger file is read no further
SCIENTIFIC_WORD = re.compile(r"[-+]?\d\.(\d+)[eE][-+]\d{2,3}")  # "-2.755081915890459143e+00": its digits


def read_pose_file(path: str | Path) -> np.ndarray:
    """Read a ``*.pose`` file (six numbers ``x y z rx ry rz``, m and rad) as a 4x4 transform. ``InputError`` for any
    other count, a number that is not finite, a rotation vector of more than a full turn (no rotation needs one:
    degrees read as radians were silently another rotation), or a file cut inside its last number (``_cut_short``: a
    number cut before its exponent is another number)."""
    path = Path(path)
    if path.exists() and not path.is_file():  # a pipe would wait for a writer: never read
        raise InputError(f"the pose file {path} is not a regular file; a .pose file holds six numbers "
                         "x y z rx ry rz (metres, radians)")
    try:
        with path.open("rb") as stream:
            data = stream.read(MAX_POSE_FILE_BYTES + 1)
        text = data.decode("utf-8-sig")  # a byte-order mark: Notepad
        words = text.split()
    except OSError as error:
        raise InputError(f"cannot read the pose file: {file_problem(error, path, 'read')}") from error
    except UnicodeDecodeError as error:
        raise InputError(f"cannot read the pose file {path}: it is not text ({error.reason}). {POSE_FILE_HOLDS}.") \
            from error
    if len(data) > MAX_POSE_FILE_BYTES:
        raise InputError(f"the pose file {path} holds more than {MAX_POSE_FILE_BYTES // 1024} kB, so it is no pose "
                         f"(a log or a point cloud?). {POSE_FILE_HOLDS}.")
    values = _pose_numbers(words, path)
    if _cut_short(words, text):
        raise InputError(f"the pose file {path} ends inside its last number: {quoted(words[-1])} lacks digits or the "
                         "exponent the numbers before it were written with, so the file was cut short (while it was "
                         "copied?) and that number may be another one. Record that pose again")
    if values.shape != (6,):
        raise InputError(f"the pose file {path} must hold exactly six numbers x y z rx ry rz (metres, radians); "
                         f"it holds {values.size}{_count_hint(values.size)}.")
    if not np.all(np.isfinite(values)):
        raise InputError(f"the pose file {path} holds a number that is not finite ({quoted(values.tolist())}); "
                         "record that pose again")
    turn_rad = float(np.linalg.norm(values[3:]))
    if turn_rad > 2.0 * np.pi:
        raise InputError(f"the pose file {path} turns by {turn_rad:.4g} rad (rx ry rz {quoted(values[3:].tolist())}), "
                         "more than a full turn: a .pose file holds UR's rotation vector in radians, and these look "
                         "like degrees (or another robot's angles, such as KUKA's A B C); record the pose as UR "
                         "writes it")
    return from_ur_pose(values)


def _pose_numbers(words: list[str], path: Path) -> np.ndarray:
    """The numbers of a pose file's words; InputError quoting the first that is none (cut short: a file of one long
    word flooded the terminal with it)."""
    values = []
    for word in words:
        try:
            values.append(float(word))
        except ValueError:
            raise InputError(f"cannot read the pose file {path}: {quoted(word)} is no number. {POSE_FILE_HOLDS}.") \
                from None
    return np.array(values, float)


def _cut_short(words: list[str], text: str) -> bool:
    """Whether a pose file written number by number in one scientific format (``%.18e``, as numpy's savetxt writes
    them: the same digits, an exponent) ends inside its last number: the file does not end with white space and that
    number, unlike every one before it, is not written in that format."""
    formats = [SCIENTIFIC_WORD.fullmatch(word) for word in words]
    if len(words) < 2 or text[-1:].isspace() or not all(formats[:-1]):
        return False
    digits = {len(found[1]) for found in formats[:-1] if found is not None}
    last = formats[-1]
    return len(digits) == 1 and (last is None or len(last[1]) not in digits)


def _count_hint(count: int) -> str:
    """What a pose file of ``count`` numbers (not six) may be: cut short, or another robot's convention."""
    if count < 6:
        return " (cut short? record that pose again)"
    if count == 7:
        return (" (a position and a quaternion, as ABB or ROS write a pose? fixwizard reads UR's rotation vector "
                "rx ry rz)")
    return ""


def _natural_key(path: Path) -> tuple[int | str, ...]:
    """Sort key that orders ``pt_2`` before ``pt_10``."""
    return tuple(int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.name))


def pose_files(directory: Path) -> list[Path]:
    """The ``*.pose`` files of a folder (the suffix in any case: ``.POSE`` from a tool that writes upper case) in
    natural name order."""
    return sorted((path for path in directory.iterdir() if path.suffix.lower() == ".pose"), key=_natural_key)


def read_pose_dir(directory: str | Path) -> tuple[list[Path], np.ndarray]:
    """Read every ``*.pose`` file of a folder in natural name order; returns (paths, (N, 4, 4) transforms)."""
    directory = Path(directory)
    if not directory.is_dir():
        raise InputError(f"{directory} is not a folder; give the folder that holds the *.pose files")
    paths = pose_files(directory)
    if not paths:
        raise InputError(f"no *.pose files in {directory}")
    return paths, np.stack([read_pose_file(path) for path in paths])
