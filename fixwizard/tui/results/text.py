"""The results screen's text: the pose in mm and degrees with its UR literal, the guaranteed bounds and
intervals, warnings, the candidate poses of an ambiguous result with what to tap next, and the cause of an
inconsistent one (a wrong ball diameter, or a suspect tap); the solver's own figures are in ``workflow.details``."""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import format_ur_pose, rotation_angle_rad
from fixwizard.report import robot_pose_text, rounded_up_text
from fixwizard.solver.estimates import Bounds
from fixwizard.solver.solve import Mode, Solution
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.ball_check import ball_mismatch

HEADLINES = {"unique": "UNIQUE: one pose of the fixture explains the {taps} taps.",
             "ambiguous": "AMBIGUOUS: the {taps} taps leave {modes} distinct poses.",
             "undetermined": "UNDETERMINED: the {taps} taps do not pin the pose down.",
             "inconsistent": "INCONSISTENT: no pose of the fixture explains all {taps} taps."}

SAID_BY_SUSPECT_LINES = ("inconsistent", "suspect_tap", "ball_diameter", "sample_bound", "mesh_or_units")


UNEXPLAINED_HEADLINE = "UNDETERMINED: no pose was found that explains all {taps} taps within the sample bound."


def headline(solution: Solution, tap_count: int) -> str:
    unexplained = "unexplained" in [warning.code for warning in solution.warnings]
    return (UNEXPLAINED_HEADLINE if unexplained else HEADLINES[solution.status]).format(taps=tap_count,
                                                                                       modes=len(solution.modes))


def pose_lines(base_T_cad: np.ndarray, status: str) -> list[str]:
    """Position (mm), turn (rotation vector in deg, as the UR pendant shows it) and the UR pose literal (only for a
    unique result: ``report.robot_pose_text``)."""
    x, y, z = base_T_cad[:3, 3] * 1e3
    rx, ry, rz = np.degrees(Rotation.from_matrix(base_T_cad[:3, :3]).as_rotvec())
    return [f"  position  x {x:.2f}  y {y:.2f}  z {z:.2f} mm",
            f"  turn      rx {rx:.2f}  ry {ry:.2f}  rz {rz:.2f} deg (as the UR pendant shows it)",
            f"  UR pose   {robot_pose_text(status, format_ur_pose(base_T_cad))}"]


def bounds_text(bounds: Bounds) -> str:
    return (f"CAD origin within {rounded_up_text(bounds.position_m * 1e3, 2)} mm, rotation within "
            f"{rounded_up_text(np.degrees(bounds.rotation_rad), 2)} deg")


def summary_lines(solution: Solution) -> list[str]:
    """The expected pose, its guaranteed bounds and the 95/99 % intervals (unique or ambiguous)."""
    base_T_cad, bounds = solution.base_T_cad, solution.bounds
    assert base_T_cad is not None and bounds is not None, "a unique or ambiguous solution has a pose and bounds"
    lines = ["Fixture pose (CAD frame in the robot base frame, most probable):",
             *pose_lines(base_T_cad, solution.status),
             "Guaranteed: the true pose lies within these of the centre pose",
             f"  centre    {format_ur_pose(bounds.base_T_cad_center)}",
             f"  {bounds_text(bounds)}",
             f"  any point of the fixture within {rounded_up_text(bounds.max_point_displacement_m * 1e3, 2)} mm"]
    if solution.intervals:
        lines.append("Likely: " + "; ".join(
            f"{interval.level:.0%} within {interval.position_m * 1e3:.2f} mm, "
            f"{np.degrees(interval.rotation_rad):.2f} deg" for interval in solution.intervals))
    return lines


def mode_line(number: int, mode: Mode) -> str:
    x, y, z = mode.base_T_cad[:3, 3] * 1e3
    angle = np.degrees(rotation_angle_rad(mode.base_T_cad[:3, :3]))
    return (f"  {number}. {mode.probability:6.1%}  x {round(x)} y {round(y)} z {round(z)} mm, turned {round(angle)} "
            f"deg; within {rounded_up_text(mode.bounds.position_m * 1e3, 1)} mm, "
            f"{rounded_up_text(np.degrees(mode.bounds.rotation_rad), 1)} deg")


def modes_lines(solution: Solution, advice: TapAdvice | None) -> list[str]:
    """The candidate poses, most probable first, and one sentence on where to tap to tell the first two apart."""
    lines = ["Candidate poses that fit the taps (probability, pose, guaranteed bounds):",
             *(mode_line(number, mode) for number, mode in enumerate(solution.modes, start=1))]
    if advice is not None:
        lines.append(f"Next: {advice.sentence()} Then press r to tap it and solve again.")
    return lines


def suspect_lines(solution: Solution) -> list[str]:
    """What to do about an inconsistent result: a wrong ball diameter said plainly when the diagnosis finds one,
    else its causes, most likely first; and how to drop the suspect tap."""
    diagnosis = solution.diagnosis
    causes = [] if diagnosis is None else [f"  {number}. {cause.message}"
                                           for number, cause in enumerate(diagnosis.causes, start=1)]
    lines = ["Why, most likely cause first:", *causes] if causes else [
        "Check the mesh and its units, the tip calibration and the sample bound."]
    suspect = solution.suspect_tap
    mismatch = ball_mismatch(solution)
    if mismatch is not None:
        lines = [mismatch.sentence(), "Less likely causes:", *causes[1:]]
        if suspect is not None:
            lines.append(f"Dropping tap {suspect.index + 1} (d) would not fix a wrong ball: drop it only if you saw it "
                         "miss the fixture.")
        lines.append("Press r to go back to sampling.")
        return lines
    if suspect is not None:
        lines.append(f"Press d to drop tap {suspect.index + 1} (the journal keeps it, marked dropped; u on the "
                     "sampling screen takes the drop back), then solve again.")
    else:
        lines.append("Press r to go back to sampling.")
    return lines


def warning_lines(solution: Solution) -> list[str]:
    """The solver's warnings, except those ``suspect_lines`` already says in other words ("none" only when the
    solution has no warning at all, as the report then has none)."""
    warnings = [warning for warning in solution.warnings if warning.code not in SAID_BY_SUSPECT_LINES]
    if not warnings:
        return [] if solution.warnings else ["Warnings: none."]
    return ["Warnings:", *(f"  - {warning.message}" for warning in warnings)]
