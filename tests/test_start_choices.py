"""What the start screen lists, read from the cell's folders without waiting on anything: a named pipe among the
tip calibrations is left out (reading it waited for a writer, and the start screen never opened)."""

import os
import shutil
import threading
from pathlib import Path

from fixwizard.tui.start.choices import calibration_choices

EXAMPLE_CALIBRATION = Path(__file__).resolve().parents[1] / "calibrations" / "example_matlab_logo.yaml"


def test_a_pipe_among_the_tip_calibrations_is_left_out(tmp_path):
    shutil.copy(EXAMPLE_CALIBRATION, tmp_path / "logo.yaml")
    os.mkfifo(tmp_path / "pipe.yaml")
    listed = []
    reader = threading.Thread(target=lambda: listed.append(calibration_choices(tmp_path)), daemon=True)
    reader.start()
    reader.join(timeout=10)
    if reader.is_alive():  # let the stuck reader go before failing
        with open(tmp_path / "pipe.yaml", "w"):
            pass
    assert listed, "the list waited on the pipe"
    assert [choice.path.name for choice in listed[0]] == ["logo.yaml"]
