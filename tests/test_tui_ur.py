"""The wizard on a UR arm, end to end: the real app (Pilot) drives the real ur_rtde client in its link process
against the loopback controller. Sampling opened straight away (as ``--robot HOST --resume`` does) turns freedrive on
once connected; a tap records the contact the controller produced; STOP during a tap stops the arm, records
nothing and leaves freedrive off until re-armed; a link process killed mid-session is explained, the watchdog has
stopped the arm by then, and Reconnect brings the wizard back."""

import asyncio
import os
import signal
import time

import numpy as np
import pytest
from textual.widgets import Button, Static

from fixwizard.robot.ur import URRobot
from fixwizard.tui import keys
from fixwizard.tui.app import FixwizardApp
from fixwizard.tui.widgets.confirm import Confirm
from fixwizard.tui.widgets.errors import ErrorModal
from pilot_wait import dialog_shown, until
from tui_cell import sampling_of, wizard_context
from ur_loopback import TIP_OFFSET_M, flange_above_surface, private_loopback_host

pytestmark = pytest.mark.slow  # a loopback controller, a link process and the wizard: about 20 s
HOST = private_loopback_host()
SIZE = (80, 24)
TAP_KEY, STOP_KEY = keys.TAP.keys, keys.STOP.keys.split(",")[0]


@pytest.fixture
def controller(loopback):
    controller = loopback.start_controller(host=HOST, unlock_delay_s=1.0, base_T_flange=flange_above_surface(0.03))
    yield controller
    controller.close()


@pytest.fixture
def wizard(tmp_path, controller):
    """The wizard's parts with the UR arm at the loopback as its robot."""
    context = wizard_context(tmp_path)
    robot = URRobot(HOST)
    context.with_cell(robot=robot, robot_name=f"UR arm at {HOST}", simulated=False, hands=None)
    yield context
    robot.close()
    context.session.release()


def screen_text(app: FixwizardApp) -> str:
    return "\n".join(str(widget.render()) for widget in app.screen.query(Static))


def arm_stands(controller, for_s: float = 0.3) -> bool:
    before = controller.flange_pose()
    time.sleep(for_s)
    return not controller.program_running() and np.allclose(controller.flange_pose(), before, atol=1e-9)


def test_sampling_on_a_ur_arm_taps_stops_rearms_and_reconnects(wizard, controller):
    async def run():
        app = FixwizardApp(wizard.cell, sampling=wizard.sampling)
        robot = wizard.robot
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: (screen := sampling_of(app)) is not None and screen.is_mounted
                        and not screen.busy and controller.in_freedrive())
            screen = sampling_of(app)
            assert not isinstance(app.screen, ErrorModal), screen_text(app)
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.mode == "freedrive")

            controller.move_by_hand(flange_above_surface(0.008))  # the operator guides the ball above the surface
            await pilot.press(TAP_KEY)
            await until(pilot, lambda: len(wizard.session.taps) == 1 and not screen.busy and controller.in_freedrive())
            np.testing.assert_allclose(wizard.session.taps[0].base_T_tcp, controller.contact_poses()[-1], atol=2e-6)
            assert wizard.session.taps[0].base_T_tcp[2, 3] == pytest.approx(TIP_OFFSET_M, abs=1e-3)  # on the surface

            # 30 mm to the surface at 10 mm/s: seen moving by the app's status poll (every 0.5 s) even under load
            controller.move_by_hand(flange_above_surface(0.03))
            await pilot.press(TAP_KEY)
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.mode == "moving", 10.0)
            await pilot.press(STOP_KEY)
            await until(pilot, lambda: not screen.busy and app.stopped and not controller.program_running(), 10.0)
            await until(pilot, lambda: not isinstance(app.screen, ErrorModal) or bool(app.screen.query("#ok")))
            assert len(wizard.session.taps) == 1  # the stopped tap recorded nothing
            assert arm_stands(controller) and not controller.in_freedrive()
            if isinstance(app.screen, ErrorModal):
                assert "stopped on request" in screen_text(app)
                app.screen.query_one("#ok", Button).press()
                await until(pilot, lambda: app.screen is screen)
            programs = len(controller.programs())
            await pilot.press(TAP_KEY)  # refused while STOPPED: nothing starts
            await pilot.pause(0.3)
            assert arm_stands(controller) and len(controller.programs()) == programs

            await pilot.press(keys.REARM.keys)
            await until(pilot, lambda: dialog_shown(app, Confirm))
            await pilot.press("y")
            await until(pilot, lambda: not app.stopped)
            await until(pilot, lambda: not screen.busy)
            if not controller.in_freedrive():  # re-arming turns freedrive on where a screen guides the arm by hand
                await pilot.press(keys.FREEDRIVE.keys)
            # the controller is in freedrive a moment before f's call returns; till then the tap key is off
            await until(pilot, lambda: controller.in_freedrive() and not screen.busy, 10.0)

            controller.move_by_hand(flange_above_surface(0.03))
            await pilot.press(TAP_KEY)  # 30 mm to the surface at 10 mm/s: the link dies on the way
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.mode == "moving", 10.0)
            os.kill(robot.link_pid, signal.SIGKILL)  # a native crash in ur_rtde
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")),
                        15.0)
            shown_at = controller.flange_pose()  # nothing moves once the error is shown
            assert arm_stands(controller) and np.allclose(controller.flange_pose(), shown_at, atol=1e-9)
            assert "reconnect" in screen_text(app)
            assert sum(isinstance(shown, ErrorModal) for shown in app.screen_stack) == 1
            await until(pilot, lambda: "Nothing recorded is lost: 1 tap is saved" in str(
                screen.query_one("#problem", Static).render()))
            app.screen.query_one("#reconnect", Button).press()
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.connected, 15.0)
            await until(pilot, lambda: app.screen is screen and not screen.busy)
            await until(pilot, lambda: any("freedrive is off, press f" in str(note.message)
                                           for note in app._notifications))
            assert not controller.in_freedrive()  # a fault ended it: nothing starts by itself
            await pilot.press(keys.FREEDRIVE.keys)
            await until(pilot, lambda: controller.in_freedrive() and not screen.busy, 10.0)
            controller.move_by_hand(flange_above_surface(0.006))
            await pilot.press(TAP_KEY)
            await until(pilot, lambda: len(wizard.session.taps) == 2 and not screen.busy, 15.0)
            np.testing.assert_allclose(wizard.session.taps[1].base_T_tcp, controller.contact_poses()[-1], atol=2e-6)

    asyncio.run(run())


def test_a_link_lost_while_the_operator_guides_the_arm_is_announced_with_reconnect(wizard, controller):
    """Nothing asked the robot for anything (freedrive, the operator's hands on the arm) when the link process
    died: the wizard says so by itself, once the watchdog has ended freedrive, and offers Reconnect."""
    async def run():
        app = FixwizardApp(wizard.cell, sampling=wizard.sampling)
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: (screen := sampling_of(app)) is not None and screen.is_mounted
                        and not screen.busy and controller.in_freedrive())
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.connected)
            os.kill(wizard.robot.link_pid, signal.SIGKILL)
            await until(pilot, lambda: dialog_shown(app, ErrorModal) and bool(app.screen.query("#reconnect")),
                        15.0)
            assert not controller.program_running() and not controller.in_freedrive()
            assert "watchdog stopped the arm" in screen_text(app)
            app.screen.query_one("#ok", Button).press()  # not now: the status bar says DISCONNECTED
            await pilot.pause(1.5)
            assert not isinstance(app.screen, ErrorModal)  # said once, not again at every status update
            assert not app.robot_status.connected
    asyncio.run(run())


def test_a_connect_the_controller_refuses_offers_reconnect_which_connects_once_that_is_fixed(wizard, controller):
    """The arm in local control as the wizard starts: the error offered OK alone, and the operator had to try a robot
    key to be offered Reconnect."""
    controller.set_remote_control(False)

    async def run():
        app = FixwizardApp(wizard.cell)  # the start screen: no robot call but the connect's
        async with app.run_test(size=SIZE, notifications=True) as pilot:
            await until(pilot, lambda: dialog_shown(app, ErrorModal), 15.0)
            assert "switch it to remote control" in screen_text(app)
            assert app.screen.query("#reconnect")
            controller.set_remote_control(True)
            app.screen.query_one("#reconnect", Button).press()
            await until(pilot, lambda: app.robot_status is not None and app.robot_status.connected, 15.0)
            assert not isinstance(app.screen, ErrorModal)

    asyncio.run(run())
