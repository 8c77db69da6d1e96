"""Small ROS 2 bags written with rosbags, in the layout `ros2 bag record -s mcap` makes (a folder with
metadata.yaml and the storage file), for the bag tests.

The drive: the robot moves forward at v = 0.2 m/s (0.45 m/s between 1.0 and 1.5 s) and turns at w = 0.1 rad/s;
camera frame k is a 24x32 picture with red = k, green = 100, blue = 200 (so a channel swap shows), odometry
x = integral of v.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

STORE = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000 * 10**9  # ns


def _stamp(t_ns: int) -> object:
    return STORE.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def _header(t_ns: int, frame: str) -> object:
    return STORE.types["std_msgs/msg/Header"](stamp=_stamp(t_ns), frame_id=frame)


def speed(t: float, fast: float = 0.45) -> float:
    return fast if 1.0 <= t < 1.5 else 0.2


def picture(k: int) -> np.ndarray:
    image = np.zeros((24, 32, 3), np.uint8)
    image[..., 0], image[..., 1], image[..., 2] = k % 256, 100, 200
    return image


def image_message(k: int, t_ns: int, kind: str) -> tuple[str, object]:
    types, rgb = STORE.types, picture(k)
    if kind == "compressed":
        import cv2

        ok, png = cv2.imencode(".png", rgb[:, :, ::-1])
        assert ok
        msg = types["sensor_msgs/msg/CompressedImage"](
            header=_header(t_ns, "cam"), format="png", data=png.ravel()
        )
        return "sensor_msgs/msg/CompressedImage", msg
    data = {"rgb8": rgb, "bgr8": rgb[:, :, ::-1], "mono8": rgb[:, :, :1]}[kind]
    channels = data.shape[2]
    padded = np.zeros((24, 32 * channels + 4), np.uint8)  # rows padded to `step`, as some drivers do
    padded[:, : 32 * channels] = data.reshape(24, -1)
    msg = types["sensor_msgs/msg/Image"](
        header=_header(t_ns, "cam"),
        height=24,
        width=32,
        encoding=kind,
        is_bigendian=0,
        step=32 * channels + 4,
        data=padded.ravel(),
    )
    return "sensor_msgs/msg/Image", msg


def camera_info(fx: float) -> object:
    """The CameraInfo of the 32x24 camera with focal length ``fx`` pixels (0: uncalibrated)."""
    types = STORE.types
    k = np.array([fx, 0.0, 16.0, 0.0, fx, 12.0, 0.0, 0.0, 1.0])
    roi = types["sensor_msgs/msg/RegionOfInterest"](
        x_offset=0, y_offset=0, height=0, width=0, do_rectify=False
    )
    return types["sensor_msgs/msg/CameraInfo"](
        header=_header(T0, "cam"),
        height=24,
        width=32,
        distortion_model="plumb_bob",
        d=np.zeros(5),
        k=k,
        r=np.eye(3).ravel(),
        p=np.zeros(12),
        binning_x=0,
        binning_y=0,
        roi=roi,
    )


def write_drive_bag(
    path: Path,
    *,
    image_kind: str = "rgb8",
    stamped: bool = False,
    odom: bool = True,
    camera_hz: float = 10.0,
    cmd_hz: float = 20.0,
    seconds: float = 3.0,
    camera_gap: tuple[float, float] | None = None,
    cmd_silence: tuple[float, float] | None = None,
    fast: float = 0.45,
    storage: str = "mcap",
    camera_latency: float = 0.0,
    camera_clock: float = 0.0,
    camera_info_fx: float | None = None,
) -> Path:
    """Write the drive to the bag folder ``path``; returns it. Camera frames reach the bag ``camera_latency``
    seconds after their header stamp; ``camera_clock`` shifts the camera's header stamps (a device clock).
    ``camera_info_fx``: also a sensor_msgs/CameraInfo on /camera/camera_info with that focal length (pixels)."""
    types = STORE.types
    vec = types["geometry_msgs/msg/Vector3"]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    events: list[tuple[int, str, object, str]] = []
    for k in range(int(seconds * camera_hz)):
        t = k / camera_hz
        if camera_gap and camera_gap[0] <= t < camera_gap[1]:
            continue
        captured = T0 + round(t * 1e9) + 3_000_000  # 3 ms after the tick
        msgtype, msg = image_message(k, captured + round(camera_clock * 1e9), image_kind)
        events.append((captured + round(camera_latency * 1e9), "/camera/image", msg, msgtype))
    for k in range(int(seconds * cmd_hz)):
        t = k / cmd_hz
        if cmd_silence and cmd_silence[0] <= t < cmd_silence[1]:
            continue
        twist = types["geometry_msgs/msg/Twist"](
            linear=vec(x=speed(t, fast), y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.1)
        )
        t_ns = T0 + round(t * 1e9)
        if stamped:
            msg, msgtype = (
                types["geometry_msgs/msg/TwistStamped"](header=_header(t_ns, "base_link"), twist=twist),
                "geometry_msgs/msg/TwistStamped",
            )
        else:
            msg, msgtype = twist, "geometry_msgs/msg/Twist"
        events.append((t_ns, "/cmd_vel", msg, msgtype))
    if odom:
        x = 0.0
        for k in range(int(seconds * 50)):
            t = k / 50
            pose = types["geometry_msgs/msg/Pose"](
                position=types["geometry_msgs/msg/Point"](x=x, y=0.0, z=0.0),
                orientation=types["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=np.sin(0.05 * t), w=np.cos(0.05 * t)
                ),
            )
            cov = np.zeros(36)
            msg = types["nav_msgs/msg/Odometry"](
                header=_header(T0 + round(t * 1e9), "odom"),
                child_frame_id="base_link",
                pose=types["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov),
                twist=types["geometry_msgs/msg/TwistWithCovariance"](
                    twist=types["geometry_msgs/msg/Twist"](
                        linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                    ),
                    covariance=cov,
                ),
            )
            events.append((T0 + round(t * 1e9), "/odom", msg, "nav_msgs/msg/Odometry"))
            x += speed(t, fast) / 50
    if camera_info_fx is not None:
        events.append((T0, "/camera/camera_info", camera_info(camera_info_fx), "sensor_msgs/msg/CameraInfo"))
    events.sort(key=lambda e: e[0])
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for t_ns, topic, msg, msgtype in events:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=STORE)
            writer.write(conns[topic], t_ns, STORE.serialize_cdr(msg, msgtype))
    return path
