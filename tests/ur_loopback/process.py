"""Run ``LoopbackController``s in a child process and drive them through proxies with the same methods
(ur_rtde's constructors hold the GIL while they wait for the controller, so it cannot share the test's
process). The child ends with the test process, so a killed test run does not keep the ports."""

import multiprocessing
import os
import threading
import time
from multiprocessing.managers import BaseManager

from ur_loopback.controller import LoopbackController


class _ControllerManager(BaseManager):
    pass


_ControllerManager.register("LoopbackController", LoopbackController)


def _exit_with_parent(parent_pid: int) -> None:
    """In the child: exit as soon as the process that started it is gone."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(0.2)
        os._exit(0)

    threading.Thread(target=watch, name="loopback-parent-watch", daemon=True).start()


class LoopbackProcess:
    """The child process; ``start_controller`` makes and starts a controller there and returns its proxy."""

    def __init__(self) -> None:
        self._manager = _ControllerManager(ctx=multiprocessing.get_context("spawn"))
        self._manager.start(_exit_with_parent, (os.getpid(),))

    def start_controller(self, **options) -> LoopbackController:
        """A started controller (``options`` as ``LoopbackController`` takes them); ``close`` it when done."""
        controller = self._manager.LoopbackController(**options)
        controller.start()
        return controller

    def close(self) -> None:
        self._manager.shutdown()
