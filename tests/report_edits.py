"""Reports edited as a test needs them, consistently: ``report.load`` refuses a pose edited in one of its forms only,
or moved away from the centre its guarantee is measured from."""

import numpy as np
from scipy.spatial.transform import Rotation

from fixwizard import report
from fixwizard.geometry.se3 import make_transform


def with_pose(data: dict, position_m: list[float], rotvec_rad: list[float] | None = None) -> dict:
    """``data`` (a report dict) with its pose at ``position_m`` (and ``rotvec_rad``, else unchanged) in every form,
    and its bounds' centre there too, so that its guarantee still holds about it."""
    rotvec = data["pose"]["rotvec_rad"] if rotvec_rad is None else rotvec_rad
    pose = report.pose_dict(make_transform(Rotation.from_rotvec(np.array(rotvec, float)), np.array(position_m, float)))
    data["pose"] = {**pose, "guaranteed": data["pose"]["guaranteed"]}
    data["bounds"]["center"] = {"position_m": pose["position_m"], "rotvec_rad": pose["rotvec_rad"]}
    return data
