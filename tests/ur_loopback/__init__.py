"""A loopback Universal Robots controller for testing ``fixwizard.robot.ur`` against the real ur_rtde client:
it runs in a child process and listens on a loopback address (the tests choose one of their own) at the
controller's fixed ports."""

import os
import random
import time

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard.geometry.se3 import make_transform
from ur_loopback.controller import LoopbackController
from ur_loopback.process import LoopbackProcess

__all__ = ["TIP_OFFSET_M", "LoopbackController", "LoopbackProcess", "flange_above_surface", "private_loopback_host"]

TIP_OFFSET_M = 0.1  # the loopback's ball tip on the flange z axis


def flange_above_surface(hover_m: float) -> np.ndarray:
    """Flange pose with the tool pointing straight down and the tip ``hover_m`` above the surface (z = 0)."""
    return make_transform(Rotation.from_euler("x", np.pi), [0.4, -0.1, TIP_OFFSET_M + hover_m])


def private_loopback_host() -> str:
    """A loopback address of this test run's own (every 127.x.y.z is the loopback on Linux): the controller's fixed
    ports there clash with no other program or parallel run holding them on 127.0.0.1; ``UR_LOOPBACK_HOST`` chooses
    it instead (e.g. 127.0.0.1 where only that one is the loopback)."""
    if chosen := os.environ.get("UR_LOOPBACK_HOST"):
        return chosen
    rng = random.Random(os.getpid() ^ time.time_ns())
    return f"127.{rng.randint(1, 254)}.{rng.randint(1, 254)}.{rng.randint(1, 254)}"
