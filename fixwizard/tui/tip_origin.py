"""Whether a tip calibration was made on the robot connected, in words: a calibration of another robot is right only
if the very same tool, untouched, moved to this one; otherwise its tip is not this tool's and every tap misses."""

from fixwizard.calibration.store import TipCalibration


def other_robot_note(calibration: TipCalibration, robot_name: str) -> str:
    """For choosing ``calibration`` with ``robot_name`` connected: when to use it if another robot made it ("" if
    this one did)."""
    if calibration.robot == robot_name:
        return ""
    return (f"Not calibrated on this robot ({robot_name}): use it only if this very tool, untouched since, is on its "
            "flange; otherwise calibrate the tip anew (a wrong tip makes every tap miss)")


def other_robot_cause(calibration: TipCalibration, robot_name: str) -> str:
    """For taps no pose explains: ``calibration`` was made on another robot than ``robot_name``, a cause no figure
    of the taps can show ("" if this robot made it)."""
    if calibration.robot == robot_name:
        return ""
    return (f"The tip calibration {calibration.name} was made on {calibration.robot or 'an unknown robot'}, not on "
            f"this robot ({robot_name}): unless this very tool is on its flange, untouched since, every tap misses. "
            "Calibrate the tip on this robot and tap again.")
