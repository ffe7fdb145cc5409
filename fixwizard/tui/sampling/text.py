"""The sampling screen's sentences: the live check in plain words (its figures in ``live_details``, on demand),
and a robot problem with the next step."""

from pathlib import Path

import numpy as np

from fixwizard.report import rounded_up_text
from fixwizard.solver.solve import MIN_TAPS
from fixwizard.solver.verdict import probability_text
from fixwizard.tui.start.choices import FixtureChoice
from fixwizard.workflow.advice import TapAdvice
from fixwizard.workflow.hover import CLEARANCE_M, HoverPlan
from fixwizard.workflow.identify import MeshVerdict, ranked
from fixwizard.workflow.live import LiveView


def bounds_text(check: LiveView) -> str:
    bounds = check.bounds
    assert bounds is not None, "only a check that kept poses has bounds"
    return (f"origin within {rounded_up_text(bounds.position_m * 1e3, 1)} mm, rotation within "
            f"{rounded_up_text(np.degrees(bounds.rotation_rad), 1)} deg, any point within "
            f"{rounded_up_text(bounds.max_point_displacement_m * 1e3, 1)} mm")


def live_text(check: LiveView | None, tap_count: int, progress: str | None, first_cause: str = "") -> str:
    """What the latest quick solve says about the taps; ``progress``: what the running check is doing, in words
    (None when none is on its way): of newer taps, or looking closer at these (going deeper, tightening);
    ``first_cause``: said first when no pose explains the taps (a tip calibration made on another robot)."""
    if tap_count < MIN_TAPS:
        return (f"Live check: starts at {MIN_TAPS} taps ({MIN_TAPS - tap_count} to go). 10-20 taps over several "
                "faces give tight bounds.")
    if check is None:
        return f"Checking {tap_count} taps: {progress or 'starting'}..."
    doing = ""
    if progress and check.tap_count != tap_count:
        doing = f" (checking {tap_count}: {progress}...)"
    elif progress:
        doing = f" (looking closer: {progress}...)"
    head = f"Live check of {check.tap_count} taps{doing}: "
    first = f"{first_cause} " if first_cause else ""
    if check.ball_mismatch is not None:
        return head + f"NO POSE FITS these taps with this ball. {first}{check.ball_mismatch.sentence()}"
    if check.verdict == "inconsistent":
        cause = check.cause or "check the mesh, its units and the tip calibration."
        return head + f"INCONSISTENT, no pose explains the taps. {first}Most likely: {cause}"
    if check.verdict == "undetermined" and check.cause is not None:
        return (head + f"NO POSE FOUND that explains every tap within the sample bound. {first}Check the tip "
                f"calibration's bound and the ball diameter. Guaranteed so far: {bounds_text(check)}.")
    if check.verdict == "undetermined":
        return (head + "the pose is not pinned down yet; keep tapping, on other faces too. Guaranteed so far: "
                f"{bounds_text(check)}.")
    if check.verdict == "ambiguous":
        top = check.modes[0]
        return (head + f"AMBIGUOUS so far, the taps leave {len(check.modes)} candidate poses (most likely "
                f"{probability_text(top.probability)}); tap features that tell them apart. Guaranteed now: "
                f"{bounds_text(check)}.")
    tightness = "as tight as the full solve's" if check.refined else "tightening them..."
    return head + f"unique so far. Guaranteed now: {bounds_text(check)}; {tightness}"


def live_details(check: LiveView | None) -> str:
    """The live check's technical figures, for the details dialog (those of the results' Details view)."""
    if check is None:
        return f"No live check yet: it starts at {MIN_TAPS} taps."
    refinement = "the full solve's" if check.refined else "a quick"
    return "\n".join([f"{check.tap_count} taps; bounds from {refinement} hull refinement.",
                      *check.details])


NO_SAFE_HOVER = ("The possible poses still differ too much for the robot to go there on its own: guide the ball "
                 "above the point by hand, then press t.")


def guide_text(advice: TapAdvice, plan: HoverPlan | None) -> str:
    """The suggested next tap (marked * in the top view) and how to get there."""
    how = "Press g to go above it." if plan is not None else NO_SAFE_HOVER
    return f"Next (* in the view): {advice.sentence()} {how}"


def hover_question(plan: HoverPlan, simulated: bool) -> str:
    """What the robot will do when the operator confirms the move to the suggested point."""
    advice = plan.advice
    x, y, z = advice.base_p_point_m * 1e3
    return (f"{'SIMULATED: ' if simulated else ''}The robot will rise to {CLEARANCE_M * 1e3:.0f} mm above the "
            f"fixture, move across, turn the tool towards {advice.face} and stop {plan.hover_m * 1e3:.0f} mm above "
            f"the point near x {round(x)}, y {round(y)}, z {round(z)} mm. Keep hands and objects clear of the arm. "
            "Press y to move, n to cancel.")


def identify_text(choices: list[FixtureChoice], verdicts: list[MeshVerdict], chosen: Path) -> str:
    """Which of the offered fixtures the taps fit, best fit first, one line each, then what to do."""
    lines, fitting, open_ones = [], [], []
    chosen_fits = False
    label_of = {verdict.mesh: choice.label for choice, verdict in zip(choices, verdicts, strict=True)}
    for verdict in ranked(verdicts):
        is_chosen = verdict.mesh.resolve() == chosen.resolve()
        mark = " (the chosen one)" if is_chosen else ""
        detail = {"unreadable": f": {verdict.message}",
                  "fits": f": taps {verdict.rms_mm:.2f} mm off (RMS)" if verdict.rms_mm is not None else ""}
        lines.append(f"{verdict.verdict:11}  {label_of[verdict.mesh]}{mark}{detail.get(verdict.verdict, '')}")
        if verdict.verdict == "fits":
            fitting.append(label_of[verdict.mesh])
            chosen_fits = chosen_fits or is_chosen
        if verdict.verdict == "not decided":
            open_ones.append(label_of[verdict.mesh])
    if open_ones:
        lines.append(f"Not decided yet for {', '.join(open_ones)}: the taps neither rule them out nor pin a pose "
                     "down; tap more points, spread over the fixture.")
    if not fitting and not open_ones:
        lines.append("No fixture fits these taps: check the mesh units, the tip calibration and the sample bound.")
    elif len(fitting) > 1:
        lines.append(f"{len(fitting)} fixtures fit these taps: tap features that differ between them.")
    elif fitting and chosen_fits and not open_ones:
        lines.append("Only the chosen fixture fits these taps (a fixture is ruled out when no pose of it explains "
                     "them).")
    elif fitting and not chosen_fits:
        lines.append(f"The taps do not fit the chosen fixture; they fit {fitting[0]}. Leave (Esc), choose it on the "
                     "start screen and tap again.")
    return "\n".join(lines)


def robot_problem_text(message: str, tap_count: int, session_path: Path) -> str:
    """A robot or file problem and the promise that the recorded taps are kept."""
    sentence = message if message.endswith((".", "!", "?")) else f"{message}."
    return (f"{sentence}\nNothing recorded is lost: {tap_count} tap{'s are' if tap_count != 1 else ' is'} saved in "
            f"{session_path}.")
