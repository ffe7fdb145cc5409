"""The bundled demo: an L-shaped bracket mesh (mm) shipped inside the package, simulated taps on it at a
hidden pose, and the simulated cell that holds it. This is what ``fixwizard`` runs when nothing else
is chosen; everything it produces is marked SIMULATED by the callers."""

from pathlib import Path

from fixwizard.fixture import Fixture, load_fixture
from fixwizard.robot.sim import SimulatedCell

DATA_DIR = Path(__file__).resolve().parent / "data"
DEMO_MESH = DATA_DIR / "demo_bracket.stl"
DEMO_MESH_UNITS = "mm"
DEMO_TAPS = DATA_DIR / "demo_bracket_taps.yaml"
DISC_MESH = DATA_DIR / "demo_disc.stl"  # a second bundled fixture (mm), made by tools/make_demo_disc.py


def demo_fixture() -> Fixture:
    """The bundled bracket (160 x 90 x 60 mm, no symmetry) in metres."""
    return load_fixture(DEMO_MESH, DEMO_MESH_UNITS)


def disc_fixture() -> Fixture:
    """The bundled round plate with a flat and a notch (90 x 78 x 25 mm, no symmetry) in metres."""
    return load_fixture(DISC_MESH, DEMO_MESH_UNITS)


def demo_cell(seed: int = 0) -> SimulatedCell:
    """A simulated cell with the bundled bracket at a random resting pose drawn from ``seed``."""
    return SimulatedCell.with_fixture(demo_fixture(), seed=seed)
