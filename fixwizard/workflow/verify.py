"""Is the fixture still where the report says? A few new taps tested against the report's guaranteed set.

The report's guaranteed set is every pose that explains the report's own taps (``inputs.points_m``, with its ball
and sample bound), and it lies within the report's bounds about ``bounds.center``. So a pose of that set that
explains the new taps is a pose of the bounds region that explains the report's taps and the new ones together:
``verify`` searches the region (``solver.verify_search``) with both. No cell survives: no pose the report allows
explains the new taps, so the fixture has moved (or the new taps are off): a proof, exit 2. Some cells survive:
the taps are consistent with the report, exit 0. One sample bound serves all taps in the search, the larger of
the report's (plus the 0.1 um its taps were rounded to) and the new taps' one: a larger bound keeps more poses,
so an empty set stays a proof. When the new taps were measured with another ball than the report's, the report's
taps cannot join the search (one ball radius for all); then only the new taps are tested against the bounds
region, a weaker test that the verdict says it is.

Consistent taps prove no move, but they may see some moves poorly (``missable_move``): to first order, the true
pose explains every new tap within the sample bound, which puts each fixture point within a figure of the report's
pose to use (inf along a move that changes no tap's distance: fewer than six taps, faces all facing one way). A
unique report's verdict says "Keep using the report's pose" only where that figure is no larger than the report's
own guarantee for the pose (``pose.guaranteed.max_point_displacement_m``); otherwise it gives the figure, names the
move seen least (a slide along, or a turn about an axis along, a base direction) and a point whose tap would see it.

How far off the taps are: each new tap's distance from the surface at the report's pose, and, for a moved
fixture, the sample bound up to which no pose explains the taps (proved) and one with which some pose does.

``fixwizard verify REPORT POINTS`` prints the verdict; the wizard's "Check a calibrated fixture" runs the same
on taps it records, after suggesting 7 spread over the fixture and the directions its faces face
(``suggest_check_points``): six or more are needed to see every move.
"""

import argparse
import datetime as dt
import hashlib
import math
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fixwizard import report
from fixwizard.errors import InputError, MeshError, file_problem
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.geometry.se3 import transform_points
from fixwizard.points import holds_taps, load_points
from fixwizard.solver.solve import MAX_BALL_DIAMETER_M, check_reach, check_sample_bound
from fixwizard.solver.verify_search import (
    AllowedRegion,
    BoundBracket,
    RegionSearch,
    search_region,
    smallest_sample_bound,
)
from fixwizard.synthetic import touching_ball_contacts
from fixwizard.units import parse_length_m
from fixwizard.workflow.live import tap_surface_distances_m
from fixwizard.workflow.missable_move import MissableMove, missable_move

EXIT_CONSISTENT, EXIT_BAD_INPUT, EXIT_MOVED = 0, 1, 2
MAX_TAPS = 200
SUGGESTED_TAPS = (6, 8)  # six ways to move: fewer taps always leave a move they cannot see
REPORT_TAPS_ROUNDING_M = 1e-7  # the report writes its taps to 0.1 um: their error grows by at most this
SAME_BALL_M = 1e-9
REACHABLE_NORMAL_Z = -0.2  # a face the tool reaches from above or the side points at least this much up (base frame)
SUGGESTION_CANDIDATES = 400
SUPPORT_CLEARANCE_M = 0.002  # a suggested ball stays this far above the fixture's lowest point, where it rests
UP_FACING_NORMAL_Z = 0.7  # on a fixture too thin for that clearance, suggestions are on faces within 45 deg of up
RIGID_MOTIONS = 6  # the ways a rigid body moves: three slides, three turns
SAME_AXIS_DEG = 10.0  # a direction within this of a base axis is named by it ("x"), others by their components


def fixture_of(loaded: report.Report, mesh: str | Path | None = None) -> Fixture:
    """The report's mesh (or ``mesh``, its copy elsewhere), loaded in the report's units and checked to be the
    very file the report was made from (its sha256); InputError saying what to do otherwise."""
    path = Path(mesh) if mesh is not None else loaded.mesh
    if not path.is_file():
        where = "you gave" if mesh is not None else f"named by the report {loaded.path}"
        state = "is missing" if not path.exists() else "is a folder or a special file, not a mesh file"
        raise InputError(f"the mesh {path} {where} {state}: put it back, or give where it is now with --mesh PATH")
    try:
        sha256 = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError as error:
        raise InputError(f"cannot read the report's mesh: {file_problem(error, path, 'read')}") from error
    _check_same_mesh(sha256, path, loaded)  # before loading: a changed mesh is said to be one, not what it lacks
    try:
        fixture = load_fixture(path, loaded.mesh_units)
    except MeshError as error:
        raise InputError(f"the report's mesh cannot be used: {error}") from error
    _check_same_mesh(fixture.sha256, path, loaded)  # the bytes loaded: the file may have been saved again since
    return fixture


def _check_same_mesh(sha256: str, path: Path, loaded: report.Report) -> None:
    """InputError with the fix where ``sha256`` (of the mesh at ``path``) is not that of the report's mesh."""
    if sha256 != loaded.mesh_sha256:
        raise InputError(f"the mesh {path} is not the one the report {loaded.path} was made with (its content "
                         "changed: sha256 differs): put the original mesh back, or calibrate the fixture again with "
                         "this one")


def region_of(loaded: report.Report) -> AllowedRegion:
    """The poses the report's bounds allow; InputError for a report without them (inconsistent)."""
    if (loaded.center_base_T_cad is None or loaded.position_bound_m is None
            or loaded.rotation_bound_deg is None):
        raise InputError(f"the report {loaded.path} is {loaded.status}: it has no pose to check taps against; "
                         "calibrate the fixture again")
    return AllowedRegion(loaded.center_base_T_cad, loaded.position_bound_m, math.radians(loaded.rotation_bound_deg))


def _checked_taps(base_p_taps: np.ndarray) -> np.ndarray:
    taps = np.asarray(base_p_taps, float)
    if taps.ndim != 2 or taps.shape[1] != 3 or len(taps) == 0:
        raise InputError("give at least one tap as [x, y, z] in metres (6-8 spread over the fixture are best)")
    if len(taps) > MAX_TAPS:
        raise InputError(f"{len(taps)} taps are far more than a check needs: give 6-8 spread over the fixture")
    bad = np.flatnonzero(~np.all(np.isfinite(taps), axis=1))
    if len(bad):
        raise InputError(f"tap {bad[0] + 1} has a coordinate that is not a finite number; fix or remove it")
    check_reach(taps)  # millimetres taken for metres would be called a moved fixture
    return taps


def _report_taps(loaded: report.Report) -> np.ndarray:
    """The report's own taps (N, 3, m); InputError for damaged ones."""
    try:
        taps = np.array(loaded.data["inputs"].get("points_m") or [], float).reshape(-1, 3)
    except (TypeError, ValueError):
        raise InputError(f"{loaded.path}: inputs.points_m must list the taps as [x, y, z] in metres") from None
    if not np.all(np.isfinite(taps)):
        raise InputError(f"{loaded.path}: inputs.points_m holds numbers that are not finite")
    return taps


@dataclass(frozen=True)
class CheckPoint:
    """A suggested tap: the ball centre touching the surface (base frame, m) at the report's pose, the outward
    normal there (base frame) and where it is, in words."""

    base_p_ball_m: np.ndarray
    base_n: np.ndarray
    where: str


@dataclass(frozen=True)
class VerifyResult:
    """The verdict on new taps (N, 3, base frame, m). ``distances_m``: each new tap's distance from the surface at
    the report's pose (positive: short of it); ``with_report_taps``: the report's own taps were searched too (the
    full test); ``bracket``: for a moved fixture, how large a sample bound some pose needs (None otherwise);
    ``sample_bound_m`` and ``ball_diameter_m``: what the new taps were tested with."""

    report: report.Report
    base_p_taps: np.ndarray
    search: RegionSearch
    distances_m: np.ndarray
    with_report_taps: bool
    sample_bound_m: float
    ball_diameter_m: float
    bracket: BoundBracket | None
    missable: MissableMove | None  # consistent taps of a unique report: how far they let the fixture be from its pose
    seeing_point: CheckPoint | None  # where a further tap would see the move ``missable`` says is seen least
    given_sample_bound_m: float  # the new taps' bound as given; ``sample_bound_m`` is larger with the report's taps

    @property
    def moved(self) -> bool:
        return self.search.moved


def verify(loaded: report.Report, fixture: Fixture, base_p_taps: np.ndarray, ball_diameter_m: float | None = None,
           sample_bound_m: float | None = None, cancel: threading.Event | None = None) -> VerifyResult:
    """Test new taps against the report (see the module doc); the ball and the sample bound of the new taps default
    to the report's. Raises ``SearchCancelled`` when ``cancel`` is set meanwhile."""
    taps = _checked_taps(base_p_taps)
    ball_m = loaded.ball_diameter_m if ball_diameter_m is None else ball_diameter_m
    bound_m = given_m = loaded.sample_bound_m if sample_bound_m is None else sample_bound_m
    if not (math.isfinite(ball_m) and 0.0 <= ball_m <= MAX_BALL_DIAMETER_M):
        raise InputError(f"a {ball_m * 1e3:g} mm tip ball is implausible; give the diameter with its unit, e.g. "
                         "--ball-diameter 3mm")
    check_sample_bound(bound_m)
    region = region_of(loaded)
    report_taps = _report_taps(loaded)
    with_report_taps = abs(ball_m - loaded.ball_diameter_m) <= SAME_BALL_M and len(report_taps) > 0
    if with_report_taps:
        searched = np.vstack([report_taps, taps])
        bound_m = max(bound_m, loaded.sample_bound_m + REPORT_TAPS_ROUNDING_M)
    else:
        searched = taps
    found = search_region(fixture, region, searched, ball_m, bound_m, cancel=cancel)
    bracket = smallest_sample_bound(fixture, region, searched, ball_m, bound_m, cancel) if found.moved else None
    assert loaded.base_T_cad is not None  # region_of refused a report without a pose
    distances = tap_surface_distances_m(fixture, taps, ball_m, loaded.base_T_cad)
    missable, seeing = None, None
    to_use = loaded.pose_to_use()
    if not found.moved and loaded.status == "unique" and len(taps) >= SUGGESTED_TAPS[0] and to_use is not None:
        missable = missable_move(fixture, to_use[0], taps, ball_m, bound_m)
        seeing = seeing_point(fixture, to_use[0], ball_m, missable)
    return VerifyResult(loaded, taps, found, distances, with_report_taps, bound_m, ball_m, bracket, missable, seeing,
                        given_m)


def _direction_words(base_u: np.ndarray) -> str:
    """A base-frame direction: the axis it lies along (within ``SAME_AXIS_DEG``, "x", either sense), else its unit
    components ("(0.71, 0.71, 0.00)")."""
    unit = base_u / np.linalg.norm(base_u)
    axis = int(np.argmax(np.abs(unit)))
    if abs(unit[axis]) >= math.cos(math.radians(SAME_AXIS_DEG)):
        return "xyz"[axis]
    unit = unit if unit[axis] > 0 else -unit
    return "(" + ", ".join(f"{value:.2f}" for value in unit) + ")"


def move_words(missable: MissableMove) -> str:
    """The move ``missable`` says is seen least, in words: a slide along a base direction, or a turn about an axis
    along one through a point (base frame, mm): the screw axis of the move, through ``c + w x v / |w|^2``."""
    base_v, base_w = missable.base_m_move[:3], missable.base_m_move[3:] / missable.radius_m
    if not missable.mostly_turn:
        return f"a slide along {_direction_words(base_v)} of the base frame"
    base_p_axis = missable.base_p_centre + np.cross(base_w, base_v) / float(base_w @ base_w)
    return (f"a turn about an axis along {_direction_words(base_w)} of the base frame through x "
            f"{base_p_axis[0] * 1e3:.0f}, y {base_p_axis[1] * 1e3:.0f}, z {base_p_axis[2] * 1e3:.0f} mm")


def seeing_point(fixture: Fixture, base_T_cad: np.ndarray, ball_diameter_m: float,
                 missable: MissableMove) -> CheckPoint:
    """Where to tap to see the move ``missable`` says is seen least: among the points ``suggest_check_points`` picks
    from, the one whose distance from the surface that move changes most (``|n . (v + w x (p - c))|``)."""
    base_p, base_n = _reachable_contacts(fixture, base_T_cad, ball_diameter_m)
    base_v, base_w = missable.base_m_move[:3], missable.base_m_move[3:] / missable.radius_m
    moved = base_v + np.cross(base_w, base_p - missable.base_p_centre)
    best = int(np.argmax(np.abs(np.sum(base_n * moved, axis=1))))
    return _check_point(base_p[best], base_n[best])


def verdict_lines(result: VerifyResult) -> list[str]:
    """The verdict in words, mm and s: moved (a proof) or consistent, with what to do next; how far the taps are
    off, what was tested."""
    count = len(result.base_p_taps)
    taps = f"{count} tap{'s' if count != 1 else ''}"
    distances_mm = np.abs(result.distances_m) * 1e3
    worst = int(np.argmax(distances_mm))
    lines = []
    if result.moved:
        lines.append(f"MOVED: no pose the report allows explains the {taps} (this is a proof): the fixture has moved "
                     "since the report, or the taps are off (another fixture, the wrong tip). Calibrate it again.")
    elif result.report.status != "unique":  # whatever the taps, its pose is none to keep using
        lines.append(f"consistent with the report: poses the report allows explain the {taps}. The report is "
                     f"{result.report.status}, so its pose is none a robot program may use: tap more points and solve "
                     "again for a unique pose.")
    elif count < SUGGESTED_TAPS[0]:
        lines.append(f"consistent with the report: poses the report allows explain the {taps}, too few to see a small "
                     f"move: tap {SUGGESTED_TAPS[0]}-{SUGGESTED_TAPS[1]} points spread over the fixture, then check "
                     "again.")
    else:
        lines.append(_unique_consistent_line(result, taps))
    raised = (f" (the report's: one bound serves its taps and the new ones; {result.given_sample_bound_m * 1e3:.2f} mm "
              "was given)" if result.sample_bound_m > result.given_sample_bound_m + 2 * REPORT_TAPS_ROUNDING_M else "")
    lines.append(f"At the report's pose the taps lie up to {distances_mm[worst]:.2f} mm off the surface (tap "
                 f"{worst + 1}; RMS {float(np.sqrt(np.mean(distances_mm**2))):.2f} mm); sample bound "
                 f"{result.sample_bound_m * 1e3:.2f} mm{raised}.")
    bracket = result.bracket
    explained_m = None if bracket is None else bracket.explained_m
    if bracket is not None and explained_m is None:
        lines.append(f"Not even a {bracket.ruled_out_m * 1e3:.0f} mm sample bound lets a pose the report allows "
                     "explain them.")
    elif bracket is not None and explained_m is not None:
        lines.append(f"Up to a sample bound of {bracket.ruled_out_m * 1e3:.2f} mm no allowed pose explains them "
                     f"(proved); with {explained_m * 1e3:.2f} mm some pose does.")
    search = result.search
    if result.with_report_taps:
        tested = "with the report's own taps"
    elif len(_report_taps(result.report)) == 0:
        tested = "against the report's bounds only (the report lists no taps of its own: a weaker test)"
    else:
        tested = ("against the report's bounds only (the new ball differs from the report's, so its taps could not "
                  "join: a weaker test)")
    lines.append(f"Tested {tested}, to within {search.slack_m * 1e3:.2f} mm, in {search.elapsed_s:.1f} s.")
    return lines


def _unique_consistent_line(result: VerifyResult, taps: str) -> str:
    """The verdict on taps consistent with a unique report: "Keep using the report's pose" only where, to first
    order, they put every fixture point within the report's own guarantee of its pose (``missable_move``); else how
    far they let it be, the move they see least and where a tap would see it."""
    missable, seeing, to_use = result.missable, result.seeing_point, result.report.pose_to_use()
    assert missable is not None and seeing is not None and to_use is not None  # verify gives them for a unique report
    allowed_m, point_m = to_use[1].max_point_displacement_m, missable.point_m
    said = f"consistent with the report: poses the report allows explain the {taps}"
    tap_there = f"tap {seeing.where}, which would see it, and check again"
    if point_m is None:
        return (f"{said}, but to first order no pose near the report's fits them within the sample bound (taps at "
                "edges, where the surface bends, or errors at the bound), so how far they let the fixture be from the "
                "report's pose cannot be told. Before using the report's pose, tap points in the middle of faces and "
                "check again.")
    if point_m >= missable.radius_m:  # beyond first order: a move the size of the fixture, or one never seen
        unseen = ("changes no tap's distance (to first order), so a move of any size that way would not show"
                  if math.isinf(point_m) else "changes the taps' distances so little (to first order) that a move "
                  "that way would not show before it moved the fixture by as much as its own radius")
        return (f"{said}, but they cannot see every move: {move_words(missable)} {unseen}. Use the report's pose only "
                f"if the fixture cannot have moved so, or {tap_there} ({RIGID_MOTIONS} or more taps on faces facing "
                "different ways see every move).")
    assert missable.slide_m is not None and missable.turn_rad is not None
    within = (f"to first order (small moves) they put every point of the fixture within "
              f"{report.rounded_up_text(point_m * 1e3, 2)} mm of the report's pose")
    guaranteed = f"the {report.rounded_up_text(allowed_m * 1e3, 2)} mm the report guarantees"
    if point_m <= allowed_m:
        return f"{said}, and {within}, no more than {guaranteed}. Keep using the report's pose."
    size = (f"{math.degrees(missable.turn_rad):.2f} deg" if missable.mostly_turn
            else f"{missable.slide_m * 1e3:.2f} mm")
    return (f"{said}, but {within} only, more than {guaranteed}; they see {move_words(missable)} least (up to {size} "
            "would not show), so the report's pose may be off by up to "
            f"{report.rounded_up_text(point_m * 1e3, 2)} mm: {tap_there}.")


def report_lines(loaded: report.Report, now_age_s: float) -> list[str]:
    """What report is checked: fixture, status, age (or how far in the future it is dated: a wrong clock) and
    SIMULATED."""
    simulated = "SIMULATED " if loaded.simulated else ""
    region = region_of(loaded)
    return [(f"{simulated}report {loaded.path} of '{loaded.name}': {loaded.status}, {age_words(now_age_s)}, "
             f"guaranteed set within {report.rounded_up_text(region.position_m * 1e3, 2)} mm and "
             f"{report.rounded_up_text(math.degrees(region.rotation_rad), 2)} deg of its centre (bounds.center)")]


def age_words(now_age_s: float) -> str:
    """A report's age (s) in words: "3.2 h old", or how far in the future it is dated (a wrong clock)."""
    if now_age_s < -report.FUTURE_TOLERANCE_S:
        return f"dated {age_text(-now_age_s)} in the future (check the clocks of the PCs)"
    return f"{age_text(max(now_age_s, 0.0))} old"


def age_text(age_s: float) -> str:
    """An age in the largest unit that keeps it readable: s, min, h or days."""
    for unit, seconds in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if abs(age_s) >= seconds:
            return f"{age_s / seconds:.1f} {unit}"
    return f"{age_s:.0f} s"


def _facing(base_n: np.ndarray) -> str:
    if base_n[2] >= 0.9:
        return "a face pointing up"
    axis = int(np.argmax(np.abs(base_n[:2])))
    return f"a face pointing {'+-'[int(base_n[axis] < 0)]}{'xy'[axis]}{' and up' if base_n[2] > 0.3 else ''}"


def suggest_check_points(fixture: Fixture, base_T_cad: np.ndarray, ball_diameter_m: float,
                         count: int = SUGGESTED_TAPS[1] - 1) -> list[CheckPoint]:
    """``count`` points to tap for a check at the report's pose, on faces the tool reaches (not facing down), spread
    over the fixture and over the directions its faces point in, so that a move in any direction shows: farthest
    points in position and normal (scaled by the fixture's radius) among random surface points (the same points
    for the same inputs). The ball of each stays ``SUPPORT_CLEARANCE_M`` above the fixture's lowest point (base z):
    the foot of a side face is where the table or the clamp is. On a fixture too thin for that (a sheet), the balls
    are on faces pointing up (``UP_FACING_NORMAL_Z``), never at its edge."""
    base_p, base_n = _reachable_contacts(fixture, base_T_cad, ball_diameter_m)
    features = np.hstack([base_p, fixture.radius_m * base_n])
    chosen = [int(np.argmax(base_n[:, 2]))]
    while len(chosen) < min(count, len(base_p)):
        distance = np.min(np.linalg.norm(features[:, None] - features[chosen][None], axis=2), axis=1)
        chosen.append(int(np.argmax(distance)))
    return [_check_point(base_p[index], base_n[index]) for index in chosen]


def _reachable_contacts(fixture: Fixture, base_T_cad: np.ndarray,
                        ball_diameter_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Candidate taps (ball centres (K, 3) and outward normals (K, 3), base frame) at the report's pose, on faces the
    tool reaches and clear of where the fixture rests (see ``suggest_check_points``)."""
    base_R_cad = base_T_cad[:3, :3]
    radius_m = ball_diameter_m / 2.0
    reachable = (fixture.mesh.face_normals @ base_R_cad.T)[:, 2] >= REACHABLE_NORMAL_Z
    mask = reachable if np.any(reachable) else None
    cad_p_balls, cad_n = touching_ball_contacts(fixture.mesh, SUGGESTION_CANDIDATES, radius_m,
                                                np.random.default_rng(0), mask)
    base_p = transform_points(base_T_cad, cad_p_balls)
    base_n = cad_n @ base_R_cad.T
    support_z_m = float(np.min(transform_points(base_T_cad, fixture.mesh.vertices)[:, 2]))
    clear = base_p[:, 2] - radius_m >= support_z_m + SUPPORT_CLEARANCE_M
    if not np.any(clear):
        clear = base_n[:, 2] >= UP_FACING_NORMAL_Z
    if np.any(clear):
        base_p, base_n = base_p[clear], base_n[clear]
    return base_p, base_n


def _check_point(base_p_ball: np.ndarray, base_n: np.ndarray) -> CheckPoint:
    return CheckPoint(base_p_ball, base_n, f"{_facing(base_n)} at x {base_p_ball[0] * 1e3:.0f}, y "
                                           f"{base_p_ball[1] * 1e3:.0f}, z {base_p_ball[2] * 1e3:.0f} mm")


def _report_argument(args: argparse.Namespace) -> report.Report:
    """The report given as REPORT; InputError saying the arguments seem swapped when it is none and REPORT holds taps
    or POINTS is a report."""
    try:
        return report.load(args.report)
    except InputError as error:
        if holds_taps(args.report):
            raise InputError(f"{args.report} is a points file (the taps), not a fixwizard report: the arguments seem "
                             f"swapped; give the report first: fixwizard verify REPORT POINTS") from error
        if report.is_report_file(args.points):
            raise InputError(f"{args.report} is not a fixwizard report, and {args.points}, given as POINTS, is one: "
                             "the arguments seem swapped; give the report first: fixwizard verify REPORT POINTS") \
                from error
        raise


def verify_command(args: argparse.Namespace) -> int:
    """``fixwizard verify``: exit 0 when the taps are consistent with the report, 2 when the fixture has moved."""
    loaded = _report_argument(args)
    region_of(loaded)  # refuse an inconsistent report before loading the mesh
    taps = _checked_taps(load_points(args.points))
    fixture = fixture_of(loaded, args.mesh)
    age_s = (dt.datetime.now(dt.UTC) - loaded.created).total_seconds()
    print("\n".join(report_lines(loaded, age_s)))
    result = verify(loaded, fixture, taps, parse_length_m(args.ball_diameter) if args.ball_diameter else None,
                    parse_length_m(args.sample_bound) if args.sample_bound else None)
    print("\n".join(verdict_lines(result)))
    sys.stdout.flush()
    return EXIT_MOVED if result.moved else EXIT_CONSISTENT

