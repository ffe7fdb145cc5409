"""Whether the taps say the tip calibration's ball diameter is wrong, in the operator's words.

A wrong ball diameter leaves every tap off the surface by the same amount (the radius error), so no pose
explains the taps. The solver's diagnosis (``solver.diagnose``) fits the ball together with the pose; when a
ball of another size explains all taps at the same sample bound and that is its most likely cause, the taps
are fine and the calibration is not: the screens say so instead of blaming a tap.
"""

from dataclasses import dataclass

from fixwizard.solver.solve import Solution


@dataclass(frozen=True)
class BallMismatch:
    """The ball diameter (m) the taps fit and the one (m) the tip calibration says."""

    fitted_diameter_m: float
    calibrated_diameter_m: float

    def sentence(self) -> str:
        """What it means and what to do, for the operator."""
        return (f"The taps fit a ball of about {self.fitted_diameter_m * 1e3:.1f} mm, the tip calibration says "
                f"{self.calibrated_diameter_m * 1e3:.1f} mm: check the ball (measure it) and calibrate the tip again "
                "with its diameter. The taps themselves are probably fine.")


def ball_mismatch(solution: Solution) -> BallMismatch | None:
    """The mismatch when ``solution`` is inconsistent and its diagnosis names the ball diameter first, else None."""
    diagnosis = solution.diagnosis
    if solution.status != "inconsistent" or diagnosis is None or diagnosis.ball_diameter_m is None:
        return None
    if not diagnosis.causes or diagnosis.causes[0].code != "ball_diameter":
        return None
    return BallMismatch(diagnosis.ball_diameter_m, 2.0 * solution.problem.ball_radius_m)
