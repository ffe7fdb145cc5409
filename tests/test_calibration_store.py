"""The stored tip calibration (schema fixwizard.tip/1): atomic round trip, clear errors, the shipped example."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from fixwizard.calibration.calibrate import calibrate_tip
from fixwizard.calibration.errors import CalibrationFileError
from fixwizard.calibration.residuals import ResidualStats
from fixwizard.calibration.store import TipCalibration, load_calibration, save_calibration
from fixwizard.calibration.taps import PoseSeries
from fixwizard.errors import InputError
from test_calibration_helpers import synthetic_steps

EXAMPLE = Path(__file__).resolve().parents[1] / "calibrations" / "example_matlab_logo.yaml"


@pytest.fixture(scope="module")
def calibration() -> TipCalibration:
    return calibrate_tip(**synthetic_steps(), ball_diameter_m=0.003, name="bench", robot="UR5e 20235500001")


def numbers(value) -> np.ndarray:
    """The numbers of a field: an array, a float, residual statistics or excluded taps."""
    if isinstance(value, ResidualStats):
        return np.array([value.rms_m, value.max_m])
    if isinstance(value, tuple):
        return np.array([(tap.index, tap.residual_m, tap.threshold_m) for tap in value]).reshape(-1, 3)
    return np.asarray(value, dtype=float)


def assert_same(loaded: TipCalibration, original: TipCalibration) -> None:
    for name, value in vars(original).items():
        if isinstance(value, str | None):
            assert getattr(loaded, name) == value
        elif name == "steps":
            assert loaded.steps.keys() == value.keys()
            for step, series in value.items():
                np.testing.assert_allclose(loaded.steps[step].base_T_tcp, series.base_T_tcp, atol=1e-15)
                assert loaded.steps[step].files == series.files
                assert [tap.file for tap in loaded.steps[step].excluded] == [tap.file for tap in series.excluded]
                np.testing.assert_allclose(numbers(loaded.steps[step].excluded), numbers(series.excluded), rtol=1e-12)
        else:
            np.testing.assert_allclose(numbers(getattr(loaded, name)), numbers(value), rtol=1e-12, atol=1e-15)


def test_a_saved_calibration_loads_back_unchanged(calibration, tmp_path):
    path = save_calibration(calibration, tmp_path / "calibrations" / "bench.yaml")
    assert_same(load_calibration(path), calibration)
    assert [file.name for file in path.parent.iterdir()] == ["bench.yaml"]


def test_saving_replaces_an_existing_file(calibration, tmp_path):
    path = tmp_path / "bench.yaml"
    path.write_text("old")
    save_calibration(calibration, path)
    assert load_calibration(path).name == "bench"


def test_excluded_taps_survive_the_round_trip(tmp_path):
    steps = synthetic_steps()
    tilted = steps["tilted"].base_T_tcp.copy()
    tilted[4, :3, 3] += 0.01
    steps["tilted"] = PoseSeries(tilted, tuple(f"t{index}.pose" for index in range(len(tilted))))
    with_outlier = calibrate_tip(**steps, ball_diameter_m=0.003)
    loaded = load_calibration(save_calibration(with_outlier, tmp_path / "outlier.yaml"))
    assert [(tap.index, tap.file) for tap in loaded.steps["tilted"].excluded] == [(4, "t4.pose")]
    assert_same(loaded, with_outlier)


def damage(document: dict, change: str) -> dict:
    if change == "wrong schema":
        document["schema"] = "fixwizard.report/1"
    elif change == "missing tip":
        del document["tcp_p_tip_m"]
    elif change == "tip of two numbers":
        document["tcp_p_tip_m"] = [0.0, 0.05]
    elif change == "infinite bound":
        document["sample_bound_m"] = float("inf")
    elif change == "text for a number":
        document["fit"]["fine_tip"]["rms_mm"] = "small"
    elif change == "pose of five numbers":
        document["steps"]["tilted"]["base_T_tcp_ur_m_rad"][3] = [0.1, 0.2, 0.3, 0.0, 0.0]
    elif change == "missing step":
        del document["steps"]["pivot"]
    return document


@pytest.mark.parametrize("change, message", [
    ("wrong schema", "is not a tip calibration: expected 'schema: fixwizard.tip/1', found 'fixwizard.report/1'"),
    ("missing tip", "'tcp_p_tip_m' is missing"),
    ("tip of two numbers", "'tcp_p_tip_m' must be 3, not of shape (2,)"),
    ("infinite bound", "'sample_bound_m' holds numbers that are not finite"),
    ("text for a number", "'fit.fine_tip.rms_mm' must hold numbers"),
    ("pose of five numbers", "'steps.tilted.base_T_tcp_ur_m_rad' must hold numbers"),
    ("missing step", "'steps.pivot' is missing"),
])
def test_a_damaged_file_is_refused_with_what_is_wrong(calibration, tmp_path, change, message):
    path = save_calibration(calibration, tmp_path / "bench.yaml")
    path.write_text(yaml.safe_dump(damage(yaml.safe_load(path.read_text()), change)))
    with pytest.raises(CalibrationFileError) as caught:
        load_calibration(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)


@pytest.mark.parametrize("text", ["tcp_p_tip_m: [0, 0, {", "- just\n- a list\n", ""])
def test_a_file_that_is_not_a_calibration_is_refused(tmp_path, text):
    path = tmp_path / "other.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match="tip calibration"):
        load_calibration(path)


def test_a_missing_file_is_refused(tmp_path):
    with pytest.raises(CalibrationFileError, match="cannot read the tip calibration"):
        load_calibration(tmp_path / "absent.yaml")


def test_the_shipped_example_loads_and_recomputes_from_its_own_raw_poses():
    example = load_calibration(EXAMPLE)
    assert example.tcp_p_tip_m.shape == (3,)
    assert example.ball_diameter_m == 0.003
    assert example.sample_bound_m == pytest.approx(0.8e-3)
    assert example.tip_residuals.max_m <= 0.35e-3
    recomputed = calibrate_tip(**example.steps, ball_diameter_m=example.ball_diameter_m)
    np.testing.assert_allclose(recomputed.tcp_p_tip_m, example.tcp_p_tip_m, atol=1e-12)
    np.testing.assert_allclose(recomputed.base_T_table, example.base_T_table, atol=1e-12)
