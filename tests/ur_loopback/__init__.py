"""A loopback Universal Robots controller for testing ``fixwizard.robot.ur`` against the real ur_rtde client:
it runs in a child process and listens on a loopback address (the tests choose one of their own) at the
controller's fixed ports."""

from ur_loopback.controller import LoopbackController
from ur_loopback.process import LoopbackProcess

__all__ = ["LoopbackController", "LoopbackProcess"]
