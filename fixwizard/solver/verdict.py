"""What a solve may say: unique, ambiguous, undetermined or inconsistent, and why a set is not pinned down.

The rule (``status_of``), for a set that is not empty:

- a mode is *pinned down* when every point of the fixture lies within ``PINNED_FRACTION`` (a quarter) of the
  fixture radius ``r`` of its centre pose, ``max_point_displacement <= r / 4``, and its rotation within
  ``PINNED_ROTATION_RAD`` of the centre's, the turn whose chord at ``r`` is ``r / 4`` (``2 asin(1 / 8)``, 14.4
  degrees). Then any two poses of the mode turn by under 28.8 degrees from each other: a pinned-down mode cannot
  hide two poses related by a rotational symmetry of order 12 or less (nor any turn of 30 degrees or more); the
  position lies within ``r / 4``. The rotation is a condition of its own: a turn moves each point by its distance
  from the axis, so a long fixture (a shaft, a bar) turned about its own axis by any angle moves no point by more
  than its width, which may be well under ``r / 4`` (the displacement alone called such a mode unique with its
  turn free). Poses apart in position at one rotation (a repeated feature) are separate modes already (``modes``).
- ``unique``: one mode, pinned down;
- ``ambiguous``: several modes, each pinned down (distinct poses; ``solve`` says in how many a pose explaining the
  taps was found: one with none may hold no pose, which only finer cells could prove);
- ``undetermined``: some mode is not pinned down: more taps (on other faces), or a larger cell budget where
  the search stopped at cells too coarse to tell. Also a set that looks pinned down but holds no pose found to
  explain every tap within the sample bound (``solve``'s ``unexplained`` check): the cells may hold no pose at
  all, which only finer cells could prove, so its pose is not one a robot may use.

Intervals need enough effective likelihood samples (Kish's ``1 / sum w^2``): below
``MIN_INTERVAL_SAMPLES`` a quantile is decided by a handful of samples, so no interval is given.
"""

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from fixwizard.fixture import Fixture
from fixwizard.geometry.se3 import invert, transform_points
from fixwizard.geometry.so3_grid import chord
from fixwizard.solver.cells import CellSet
from fixwizard.solver.estimates import Bounds

Status = Literal["unique", "ambiguous", "undetermined", "inconsistent"]
STATUSES: tuple[Status, ...] = ("unique", "ambiguous", "undetermined", "inconsistent")
PINNED_FRACTION = 0.25
PINNED_ROTATION_RAD = 2.0 * float(np.arcsin(PINNED_FRACTION / 2.0))  # the turn whose chord at r is PINNED_FRACTION r
MIN_INTERVAL_SAMPLES = 200
# The search stopped at coarse cells when one cell spans more than this fraction of the set's displacement bound.
COARSE_CELL_FRACTION = 0.25
MIN_SPREAD_TAPS = 6  # distinct taps fewer than this rarely pin a pose down
# Taps closer than this fraction of the sample bound are the same point measured twice.
SAME_TAP_FRACTION = 0.5
LINE_FRACTION = 0.05  # taps within this fraction of r of one line (or of one point) pin no rotation about it
SAME_FACING_DEG = 30.0  # tapped faces whose normals lie within this of each other face the same way
AXIS_NAMES = ("+x", "-x", "+y", "-y", "+z", "-z")
MIN_FACE_AREA_SHARE = 0.05  # a direction the fixture has faces towards, worth naming


def is_pinned(bounds: Bounds, fixture_radius_m: float) -> bool:
    """Whether a mode's bounds pin the pose down (see the module doc)."""
    return bool(bounds.max_point_displacement_m <= PINNED_FRACTION * fixture_radius_m
                and bounds.rotation_rad <= PINNED_ROTATION_RAD)


def status_of(mode_bounds: list[Bounds], fixture_radius_m: float) -> Status:
    """The status of a set from its modes' bounds (none: inconsistent)."""
    if not mode_bounds:
        return "inconsistent"
    if not all(is_pinned(bounds, fixture_radius_m) for bounds in mode_bounds):
        return "undetermined"
    return "unique" if len(mode_bounds) == 1 else "ambiguous"


@dataclass(frozen=True)
class Openness:
    """Why a set is not pinned down, in the fixture's terms: ``coarse_cells`` when the search stopped at cells
    that span a large part of the set (a larger budget may tell), the number of distinct taps, whether they lie
    along a line or at one spot, and the CAD-frame directions of faces the fixture has but no tap touched."""

    coarse_cells: bool
    cell_size_m: float
    distinct_taps: int
    taps_in_line: bool
    tapped_facing: list[str]
    untapped_facing: list[str]


def _distinct(base_p_taps: np.ndarray, sample_bound_m: float) -> np.ndarray:
    kept: list[np.ndarray] = []
    for tap in base_p_taps:
        if all(np.linalg.norm(tap - other) > SAME_TAP_FRACTION * sample_bound_m for other in kept):
            kept.append(tap)
    return np.array(kept)


def _facing(normals: np.ndarray) -> list[int]:
    """The axis directions (indices into ``AXIS_NAMES``) nearest each unit normal."""
    axes = np.vstack([np.eye(3), -np.eye(3)])[[0, 3, 1, 4, 2, 5]]
    return [int(index) for index in np.argmax(normals @ axes.T, axis=1)]


def openness(fixture: Fixture, base_p_taps: np.ndarray, sample_bound_m: float, cells: CellSet,
             bounds: Bounds, base_T_cad: np.ndarray) -> Openness:
    """Why the set with ``bounds`` (cells ``cells``, most probable pose ``base_T_cad``) is not pinned down."""
    gamma = float(np.max(cells.rotation_grid.gamma(cells.rotation_level, cells.rotation_ids)))
    cell_size_m = cells.position_bound_m + fixture.radius_m * float(chord(gamma))
    distinct = _distinct(np.asarray(base_p_taps, float), sample_bound_m)
    spread = np.linalg.svd(distinct - distinct.mean(axis=0), compute_uv=False) if len(distinct) > 1 else np.zeros(3)
    spread = spread / np.sqrt(max(len(distinct), 1))
    in_line = len(distinct) < 3 or float(spread[1]) < LINE_FRACTION * fixture.radius_m
    fix_p_taps = transform_points(fixture.fix_T_cad @ invert(base_T_cad), distinct)
    faces = fixture.oracle.distance_interval_m(fix_p_taps, np.zeros(len(fix_p_taps), bool))[2]
    tapped = sorted(set(_facing(fixture.mesh.face_normals[faces])))
    area = np.bincount(_facing(fixture.mesh.face_normals), weights=fixture.mesh.area_faces, minlength=6)
    offered = [index for index in range(6) if area[index] >= MIN_FACE_AREA_SHARE * area.sum()]
    return Openness(cell_size_m >= COARSE_CELL_FRACTION * bounds.max_point_displacement_m, cell_size_m,
                    len(distinct), in_line, [AXIS_NAMES[index] for index in tapped],
                    [AXIS_NAMES[index] for index in offered if index not in tapped])


def undetermined_message(why: Openness, bounds: Bounds, fixture_radius_m: float, max_cells: float) -> str:
    """The operator's message for an undetermined set: how far it is from pinned down, why, and what to do."""
    lines = [f"The taps do not pin the pose down yet: the poses that explain them differ by up to "
             f"{math.ceil(np.degrees(bounds.rotation_rad))} deg and move fixture points by up to "
             f"{math.ceil(bounds.max_point_displacement_m * 1e3)} mm (pinned down means under "
             f"{PINNED_FRACTION * fixture_radius_m * 1e3:.0f} mm, a quarter of the fixture's radius, and turns "
             f"under {np.degrees(PINNED_ROTATION_RAD):.1f} deg)."]
    todo = []
    if why.distinct_taps < MIN_SPREAD_TAPS:
        todo.append(f"only {why.distinct_taps} distinct tap{'s' if why.distinct_taps != 1 else ''}: tap at least "
                    f"{MIN_SPREAD_TAPS}, spread over the fixture")
    elif why.taps_in_line:
        todo.append("the taps lie along one line (or at one spot), which leaves the turn about it free: tap points "
                    "away from that line")
    if why.untapped_facing and len(why.tapped_facing) < 3:
        todo.append(f"every tap touched faces facing {' or '.join(why.tapped_facing)} (CAD frame): also tap faces "
                    f"facing {', '.join(why.untapped_facing)}")
    if why.coarse_cells:
        todo.append(f"the search stopped at cells {why.cell_size_m * 1e3:.0f} mm across at this cell budget "
                    f"({max_cells:.0e}): a larger budget (--max-cells) may narrow the set")
    if not todo:
        todo.append("tap more points on features that tell the remaining poses apart (edges, steps, holes)")
    return lines[0] + " " + "; ".join(item[0].upper() + item[1:] for item in todo) + "."


def probability_text(probability: float) -> str:
    """A mode's probability in whole percent, "under 1 %" or "over 99 %" rather than 0 % or 100 % (it is neither)."""
    return "under 1 %" if probability < 0.01 else "over 99 %" if probability > 0.99 else f"{probability:.0%}"
