"""Robot cells: the ``Robot`` protocol, its results and errors, and a simulated cell."""

from fixwizard.robot.base import (
                                  ConnectionLost,
                                  EmergencyStop,
                                  MotionStopped,
                                  MoveBlocked,
                                  NoContact,
                                  NotInRemoteControl,
                                  ProtectiveStop,
                                  Robot,
                                  RobotError,
                                  RobotStatus,
                                  TapResult,
)

__all__ = ["ConnectionLost", "EmergencyStop", "MotionStopped", "MoveBlocked",
           "NoContact", "NotInRemoteControl", "ProtectiveStop",
           "Robot", "RobotError", "RobotStatus", "TapResult"]
