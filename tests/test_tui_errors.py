"""The error modal offers the recoveries the robot can do: reconnect after a lost link, and unlock a protective
stop on a UR arm (its dashboard) as its message promises, on the simulated cell as the pendant would."""

import asyncio

from textual.app import App

from fixwizard.calibration.errors import CalibrationError, CalibrationFileError
from fixwizard.errors import InputError
from fixwizard.robot.base import ConnectionLost, ProtectiveStop
from fixwizard.robot.ur_errors import LinkLost, URProtectiveStop
from fixwizard.tui.widgets.errors import ErrorModal, error_message, error_title
from pilot_wait import until


def buttons_of(error: Exception, simulated: bool, can_unlock: bool) -> dict[str, str]:
    """Button id -> label of the modal for ``error``."""
    async def run() -> dict[str, str]:
        app = App()
        async with app.run_test() as pilot:
            app.push_screen(ErrorModal(error, simulated, can_unlock))
            await until(pilot, lambda: isinstance(app.screen, ErrorModal) and app.screen.query("#ok"))
            return {button.id: str(button.label) for button in app.screen.query("Button")}
    return asyncio.run(run())


def test_a_ur_protective_stop_offers_the_unlock_its_message_promises():
    error = URProtectiveStop(" during the tap")
    assert "with Unlock in fixwizard" in str(error)
    assert buttons_of(error, simulated=False, can_unlock=True) == {"ok": "OK", "unlock": "Unlock (cell checked)"}


def test_no_unlock_without_a_robot_that_can_and_the_simulated_one_says_so():
    assert "unlock" not in buttons_of(ProtectiveStop(), simulated=False, can_unlock=False)
    assert buttons_of(ProtectiveStop(), simulated=True, can_unlock=False)["unlock"].startswith("SIMULATED")


def test_a_lost_link_offers_reconnect_and_shows_what_was_kept():
    error = LinkLost("the link to the robot is down during the tap: the controller closed the RTDE connection")
    error.add_note("The contact was saved as tap 4.")
    assert set(buttons_of(error, simulated=False, can_unlock=True)) == {"ok", "reconnect"}
    assert isinstance(error, ConnectionLost)
    assert error_message(error).endswith("RTDE connection. The contact was saved as tap 4.")


def test_a_message_is_a_sentence_but_a_path_it_starts_with_stays_as_typed():
    """Linux tells Mymesh.stl from mymesh.stl: a capital the operator did not type would point at another file."""
    assert error_message(InputError("mymesh.stl is the fixture mesh; choose another path")) == \
        "mymesh.stl is the fixture mesh; choose another path"
    assert error_message(InputError("sessions/a.jsonl is open elsewhere")).startswith("sessions/a.jsonl ")
    assert error_message(InputError("the disk is full")) == "The disk is full"


def test_a_tip_calibration_that_cannot_go_on_is_not_called_a_file_problem():
    """The automatic taps refused with the ball 528 mm from the table corner were headed "File or input problem"."""
    assert error_title(CalibrationError("the ball is 528 mm away from the table corner")) == "Tip calibration problem"
    assert error_title(CalibrationFileError("the tip calibration t.yaml is damaged")) == "File or input problem"
