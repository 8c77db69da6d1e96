"""Camera facts from a bag: the horizontal field of view from ``sensor_msgs/CameraInfo`` (`vtr teach --bag`,
`vtr collect --bag`), so a route taught from a bag records its camera and the repeat can check the robot's.

The CameraInfo read is the camera's own: the topic beside the image topic (``<namespace>/camera_info``, the
ROS image_transport convention), else the bag's only CameraInfo topic. Its first message gives
fov = 2 atan(width / (2 fx)) with fx = K[0]; an uncalibrated camera (fx 0, as drivers publish before
calibration) gives none. The mounting height is not in CameraInfo (it is in TF): ``--camera-height`` or unknown.
"""

from __future__ import annotations

import math
from typing import Any

INFO_TYPE = "sensor_msgs/msg/CameraInfo"


def info_connection(bag: Any, image_topic: str) -> Any | None:
    """The CameraInfo connection of the camera on ``image_topic``, or None when the bag has none for it."""
    infos = [c for c in bag.connections if c.msgtype == INFO_TYPE]
    beside = f"{image_topic.rsplit('/', 1)[0]}/camera_info"
    for conn in infos:
        if conn.topic == beside:
            return conn
    return infos[0] if len({c.topic for c in infos}) == 1 else None


def fov_from_info(k: Any, width: int) -> float | None:
    """Horizontal field of view, degrees, of a camera whose intrinsic matrix is ``k`` (row-major 3x3) at
    ``width`` pixels; None when the calibration is missing (fx not a positive number)."""
    try:
        fx = float(k[0])
    except (TypeError, ValueError, IndexError):
        return None
    if not (math.isfinite(fx) and fx > 0 and width > 0):
        return None
    return math.degrees(2 * math.atan(width / (2 * fx)))


def read_camera_info(bag: Any, image_topic: str) -> dict[str, Any] | None:
    """``{"topic", "width", "height", "fov_deg"}`` from the camera's first CameraInfo (``fov_deg`` None when
    uncalibrated), or None when the bag has no CameraInfo for it. A message that does not decode is a
    BagFileError (runtime.bag_reader) naming the file, topic and index."""
    conn = info_connection(bag, image_topic)
    if conn is None:
        return None
    for found, index, _, raw in bag.messages([conn]):
        msg = bag.deserialize(found, index, raw)
        width = int(getattr(msg, "width", 0) or 0)
        k = getattr(msg, "k", getattr(msg, "K", None))
        return {
            "topic": found.topic,
            "width": width,
            "height": int(getattr(msg, "height", 0) or 0),
            "fov_deg": fov_from_info(k, width),
        }
    return None
