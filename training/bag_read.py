"""A teleoperated drive from ROS 1 / ROS 2 bags (sqlite3 or MCAP), resampled to the control step dt.

Used by `vtr collect --bag` (a training dataset) and `vtr teach --bag` (a route). Needs the optional extra
``[ros]`` (the pure-Python ``rosbags``), imported only here and only when a bag is read; ROS itself is not needed.

Messages understood: camera ``sensor_msgs/Image`` (rgb8, bgr8, mono8, rgba8, bgra8) or ``CompressedImage``
(decoded with OpenCV or Pillow, whichever is installed); command ``geometry_msgs/Twist`` or ``TwistStamped``
(v = linear.x, w = angular.z, REP-103); optional pose ``nav_msgs/Odometry`` or ``geometry_msgs/PoseStamped``.

Times: a message's own ``header.stamp`` (when it was captured or sent) where it has one, else the time the bag
received it (``Twist`` has no header). A topic whose stamps are zero, or lie more than ``CLOCK_TOLERANCE_S`` from
its receive times (a device clock, not the ROS clock the other topics use), is timed by its receive times;
``source["stamps"]`` says which clock each topic used. Resampling: frames lie on a grid of step
dt from the first moment both a camera frame and a command exist. Frame k takes the camera frame nearest to its
time if it lies within dt/2 and was not used by frame k-1, and the command active at its time (the last one
received; older than ``cmd_timeout`` means the robot's controller has stopped it, so zero, as ros2_controllers'
``cmd_vel_timeout`` does). A frame without a camera frame, before the first command, with a command beyond the
limits or a picture that does not decode is skipped, with the reason counted; a skipped frame splits the drive
into segments (a training pair never spans a gap). Images are centre-cropped to a square and resized.

Bad files (runtime.bag_reader, training/bag_images.py): sizes are checked before anything is decompressed or
decoded (a chunk, a message, an image over its cap refuses the bag); a message that does not decode as its
type is a BagError naming the file, topic and message index; a damaged file is read as far as it goes, its
damage in ``BagDrive.warnings``.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime import protocol
from vtr.runtime.bag_caps import BagFileError
from vtr.runtime.bag_reader import GuardedBag, shown
from vtr.training.bag_camera import read_camera_info
from vtr.training.bag_images import ImageTooLargeError, NoDecoderError, decode_image, square_resize

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
COMMAND_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped")
#: Largest median gap between a topic's header stamps and its receive times that still counts as one clock, s.
CLOCK_TOLERANCE_S = 1.0


class BagError(ValueError):
    """A bag that cannot be used: missing topics, wrong message types, nothing usable; the message says which."""


def import_rosbags() -> Any:
    """rosbags' type system, or a one-line error naming the extra to install."""
    try:
        from rosbags import typesys
    except ModuleNotFoundError:
        raise BagError("reading ROS bags needs the package rosbags: pip install 'vtr-mpc[ros]'") from None
    return typesys


@dataclass
class BagDrive:
    """A drive resampled to dt. Frame k: ``images[k]``, the command active at its time, the pose (NaN if unknown)."""

    images: np.ndarray  # (T, S, S, 3) uint8
    commands: np.ndarray  # (T, 2) float64 (v, w)
    poses: np.ndarray  # (T, 3) float64, NaN without odometry
    segments: np.ndarray  # (T,) int: runs of consecutive frames (no gap inside)
    dt: float
    skipped: dict[str, int] = field(default_factory=dict)  # reason -> frames
    source: dict[str, Any] = field(
        default_factory=dict
    )  # bag paths, topics, types, message counts, camera size
    warnings: list[str] = field(default_factory=list)  # damage found while reading (read as far as it goes)

    def __len__(self) -> int:
        return int(self.images.shape[0])

    def camera(self, fov_deg: float | None = None, height_m: float | None = None) -> dict[str, Any]:
        """The camera of the resampled images (docs/PROTOCOL.md's hello camera): the square crop narrows the
        horizontal field of view of a wide camera, so the native one is converted. The native field of view is
        ``fov_deg`` (--camera-fov) when given, else the bag's CameraInfo's (training/bag_camera.py); ``fov_from``
        says which, and a field known from neither is listed in ``unknown`` (`vtr repeat` refuses a route whose
        field of view is unknown)."""
        size = int(self.images.shape[2]) if len(self) else 0
        native = self.source.get("camera") or {}
        info = self.source.get("camera_info") or {}
        source = "--camera-fov" if fov_deg is not None else f"sensor_msgs/CameraInfo on {info.get('topic')}"
        fov_deg = fov_deg if fov_deg is not None else info.get("fov_deg")
        fov = None
        if fov_deg is not None and native:
            ratio = min(native["width"], native["height"]) / native["width"]
            fov = math.degrees(2 * math.atan(math.tan(math.radians(fov_deg) / 2) * ratio))
        camera = {"width": size, "height": size, "fov_deg": fov, "height_m": height_m, "native": native}
        camera["fov_from"] = source if fov is not None else "unknown"
        unknown = [k for k in ("fov_deg", "height_m") if camera[k] is None]
        return {**camera, "unknown": unknown} if unknown else camera

    def report(self) -> str:
        lines = [
            f"{self.source.get('images', 0)} camera frames and {self.source.get('commands', 0)} commands over "
            f"{self.source.get('seconds', 0.0):.1f} s -> {len(self)} frames at dt {self.dt} s in "
            f"{len(np.unique(self.segments)) if len(self) else 0} segments"
        ]
        stamps = self.source.get("stamps") or {}
        if stamps:
            lines.append("  times: " + "; ".join(f"{topic} {clock}" for topic, clock in stamps.items()))
        lines += [
            f"  skipped {n} frames: {reason}"
            for reason, n in sorted(self.skipped.items(), key=lambda x: -x[1])
        ]
        return "\n".join(lines)


def _connections(bag: GuardedBag, topic: str | None, types: tuple[str, ...], role: str) -> list[Any]:
    if topic is None:
        return []
    found = [c for c in bag.connections if c.topic == topic]
    if not found:
        known = sorted({f"{shown(c.topic)} ({shown(c.msgtype)})" for c in bag.connections})
        listed = ", ".join(known[:12]) + (f" and {len(known) - 12} more" if len(known) > 12 else "")
        raise BagError(f"{bag.name()}: no topic {topic!r} for the {role}; topics: {listed or 'none'}")
    wrong = [c.msgtype for c in found if c.msgtype not in types]
    if wrong:
        raise BagError(
            f"{bag.name()}: {role} topic {topic!r} carries {shown(wrong[0])}; expected one of {', '.join(types)}"
        )
    return found


def _yaw(q: Any) -> float:
    return math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def read_bag(
    paths: list[str | Path],
    image_topic: str,
    cmd_topic: str,
    odom_topic: str | None = None,
    dt: float = 0.1,
    image_size: int = 128,
    cmd_timeout: float = 0.5,
    limits: protocol.Limits | None = None,
) -> BagDrive:
    """Read one drive from ``paths`` (bag folders or .mcap/.db3/.bag files read as one); see the module docstring."""
    if not (dt > 0 and image_size > 0 and cmd_timeout > 0):
        raise BagError(f"dt, image_size and cmd_timeout must be > 0, got {dt}, {image_size}, {cmd_timeout}")
    limits = limits or protocol.Limits()  # the model's limits: commands beyond them make no training pairs
    typesys = import_rosbags()
    store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
    try:
        with GuardedBag(paths, typestore=store) as bag:
            image_conns = _connections(bag, image_topic, IMAGE_TYPES, "camera")
            cmd_conns = _connections(bag, cmd_topic, COMMAND_TYPES, "command")
            pose_conns = _connections(bag, odom_topic, POSE_TYPES, "pose")
            times, cmds, poses = _first_pass(
                bag, image_conns + cmd_conns + pose_conns, image_topic, cmd_topic
            )
            if not times["image"] or not times["cmd"]:
                raise BagError(
                    f"the bag has {len(times['image'])} camera frames and {len(times['cmd'])} commands: "
                    "nothing to use" + "".join(f"; {w}" for w in bag.warnings)
                )
            clocks = {topic: _message_times(pairs) for topic, pairs in times.items()}
            image_t, image_order = _sorted(clocks["image"][0])
            cmd_t, cmd_order = _sorted(clocks["cmd"][0])
            pose_t, pose_order = _sorted(clocks["pose"][0])
            plan, skipped = _plan(image_t, cmd_t, np.array(cmds)[cmd_order], dt, cmd_timeout, limits)
            plan = {
                k: (t, int(image_order[j]), c) for k, (t, j, c) in plan.items()
            }  # j: the message's position
            images, native = _decode_planned(bag, image_conns, plan, image_size, skipped)
            camera_info = read_camera_info(bag, image_topic)
            warnings = list(bag.warnings)
    except BagFileError as exc:
        raise BagError(str(exc)) from None
    keep = [k for k in sorted(plan) if k in images]
    seg = np.cumsum([1] + [int(b - a != 1) for a, b in zip(keep, keep[1:], strict=False)]) - 1 if keep else []
    frame_t = np.array([plan[k][0] for k in keep])
    return BagDrive(
        images=np.stack([images[k] for k in keep])
        if keep
        else np.zeros((0, image_size, image_size, 3), np.uint8),
        commands=np.array([plan[k][2] for k in keep], np.float64).reshape(-1, 2),
        poses=_poses_at(frame_t, pose_t, np.array(poses).reshape(-1, 3)[pose_order], dt),
        segments=np.asarray(seg, np.int64),
        dt=dt,
        skipped=dict(skipped),
        source={
            "bags": [str(p) for p in paths],
            "topics": {"image": image_topic, "cmd": cmd_topic, "odom": odom_topic},
            "types": {"image": image_conns[0].msgtype, "cmd": cmd_conns[0].msgtype},
            "images": len(image_t),
            "commands": len(cmd_t),
            "seconds": round(max(image_t[-1], cmd_t[-1]) - min(image_t[0], cmd_t[0]), 3),
            "stamps": {topic: clock for topic, (_, clock) in clocks.items() if times[topic]},
            "camera": {"width": native[1], "height": native[0]} if native else {},
            "camera_info": camera_info,
        },
        warnings=warnings,
    )


def _message_times(pairs: list[tuple[float, float | None]]) -> tuple[np.ndarray, str]:
    """One topic's message times, s, and which clock they are: the header stamps when every message has a
    non-zero one on the receive clock (within CLOCK_TOLERANCE_S), else the receive times."""
    received = np.array([r for r, _ in pairs], np.float64)
    if not pairs or any(h is None for _, h in pairs):
        return received, "receive (no header)"
    stamped = np.array([h for _, h in pairs], np.float64)
    if not np.all(stamped > 0):
        return received, "receive (zero header stamps)"
    offset = statistics.median((received - stamped).tolist())
    if abs(offset) > CLOCK_TOLERANCE_S:
        return received, f"receive (header stamps {offset:+.1f} s off the receive clock)"
    return stamped, "header"


def _sorted(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Times in increasing order and the message positions they came from (header stamps may arrive out of
    order)."""
    order = np.argsort(t, kind="stable")
    return t[order], order


def _plan(
    image_t: np.ndarray,
    cmd_t: np.ndarray,
    cmds: np.ndarray,
    dt: float,
    cmd_timeout: float,
    limits: protocol.Limits,
) -> tuple[dict[int, tuple[float, int, tuple[float, float]]], Counter]:
    """Grid frame k -> (time, camera frame index, command); reasons for the frames left out."""
    skipped: Counter = Counter()
    start = max(image_t[0], cmd_t[0])
    skipped["camera frames before the first command"] = int(np.sum(image_t < cmd_t[0] - dt / 2))
    plan: dict[int, tuple[float, int, tuple[float, float]]] = {}
    last_image = -1
    for k in range(int(math.floor((image_t[-1] - start) / dt + 0.5)) + 1):
        t = start + k * dt
        j = int(np.searchsorted(image_t, t))
        j = min((i for i in (j - 1, j) if 0 <= i < len(image_t)), key=lambda i: abs(image_t[i] - t))
        if abs(image_t[j] - t) > dt / 2 or j == last_image:
            skipped["no camera frame within dt/2 of the frame time (camera slower than 1/dt, or a gap)"] += 1
            continue
        i = int(np.searchsorted(cmd_t, t, side="right")) - 1
        v, w = cmds[i] if t - cmd_t[i] <= cmd_timeout else (0.0, 0.0)
        if not (math.isfinite(v) and math.isfinite(w)):
            skipped["non-finite command"] += 1
            continue
        if abs(v) > limits.v_max or abs(w) > limits.w_max:
            skipped[
                f"command beyond the limits (|v| <= {limits.v_max} m/s, |w| <= {limits.w_max} rad/s)"
            ] += 1
            continue
        last_image = j
        plan[k] = (t, j, (float(v), float(w)))
    return plan, Counter({r: n for r, n in skipped.items() if n})


def _first_pass(
    bag: GuardedBag, conns: list[Any], image_topic: str, cmd_topic: str
) -> tuple[dict[str, list[tuple[float, float | None]]], list[tuple[float, float]], list[tuple[float, ...]]]:
    """Every message's (receive time, header stamp or None) by role, the commands and the poses."""
    times: dict[str, list[tuple[float, float | None]]] = {"image": [], "cmd": [], "pose": []}
    cmds, poses = [], []
    for conn, i, stamp, raw in bag.messages(conns):
        msg = bag.deserialize(conn, i, raw)
        header = getattr(msg, "header", None)
        pair = (
            stamp * 1e-9,
            header.stamp.sec + header.stamp.nanosec * 1e-9 if header is not None else None,
        )
        if conn.topic == image_topic:
            times["image"].append(pair)
        elif conn.topic == cmd_topic:
            twist = msg.twist if conn.msgtype.endswith("TwistStamped") else msg
            times["cmd"].append(pair)
            cmds.append((float(twist.linear.x), float(twist.angular.z)))
        else:
            pose = msg.pose.pose if conn.msgtype.endswith("Odometry") else msg.pose
            xyt = (float(pose.position.x), float(pose.position.y), _yaw(pose.orientation))
            times["pose"].append(pair)
            poses.append(xyt if all(math.isfinite(p) for p in xyt) else (math.nan,) * 3)
    return times, cmds, poses


def _decode_planned(
    bag: GuardedBag, conns: list[Any], plan: dict, size: int, skipped: Counter
) -> tuple[dict[int, np.ndarray], tuple[int, int] | None]:
    """Second pass over the camera topic: decode only the frames the plan uses. A picture that does not decode
    is skipped (counted); one over the size cap refuses the bag."""
    wanted = {j: k for k, (_, j, _) in plan.items()}
    images: dict[int, np.ndarray] = {}
    native = None
    for conn, j, _, raw in bag.messages(conns):
        if j not in wanted:
            continue
        try:
            image = decode_image(bag.deserialize(conn, j, raw), conn.msgtype)
        except (ImageTooLargeError, NoDecoderError) as exc:
            raise BagError(
                f"{bag.where(conn, j)} is {exc}" if isinstance(exc, ImageTooLargeError) else str(exc)
            ) from None
        except ValueError as exc:
            skipped[f"camera frame not usable: {exc}"] += 1
            continue
        native = native or image.shape[:2]
        images[wanted[j]] = square_resize(image, size)
    return images, native


def _poses_at(frame_t: np.ndarray, pose_t: np.ndarray, poses: np.ndarray, dt: float) -> np.ndarray:
    """The pose nearest each frame time within dt, NaN elsewhere."""
    out = np.full((len(frame_t), 3), np.nan)
    if len(pose_t) == 0 or len(frame_t) == 0:
        return out
    j = (
        np.clip(np.searchsorted(pose_t, frame_t), 1, len(pose_t) - 1)
        if len(pose_t) > 1
        else np.zeros(len(frame_t), int)
    )
    if len(pose_t) > 1:
        j = np.where(np.abs(pose_t[j - 1] - frame_t) < np.abs(pose_t[j] - frame_t), j - 1, j)
    near = np.abs(pose_t[j] - frame_t) <= dt
    out[near] = poses[j[near]]
    return out


def add_arguments(parser: Any, what: str) -> None:
    """The bag options shared by `vtr collect --bag` and `vtr teach --bag`."""
    group = parser.add_argument_group(f"from a ROS 1/2 bag (--bag, needs pip install 'vtr-mpc[ros]'): {what}")
    group.add_argument(
        "--bag",
        action="append",
        default=None,
        metavar="PATH",
        help="bag folder or file (repeat to join several)",
    )
    group.add_argument("--image-topic", default=None, help="sensor_msgs/Image or CompressedImage topic")
    group.add_argument("--cmd-topic", default=None, help="geometry_msgs/Twist or TwistStamped topic")
    group.add_argument("--odom-topic", default=None, help="optional nav_msgs/Odometry or PoseStamped topic")
    group.add_argument(
        "--cmd-timeout",
        type=float,
        default=0.5,
        help="a command older than this counts as zero, s (default 0.5)",
    )
    group.add_argument(
        "--camera-fov",
        type=float,
        default=None,
        help="the camera's horizontal field of view, deg (default: from the bag's sensor_msgs/CameraInfo; "
        "without one it is stored as unknown, which `vtr repeat` refuses)",
    )
    group.add_argument(
        "--camera-height",
        type=float,
        default=None,
        help="the camera's height above the floor, m (default: unknown, not compared)",
    )


def read_bag_args(args: Any, dt: float, image_size: int) -> BagDrive:
    """read_bag from parsed `--bag ...` options; BagError when a topic option is missing."""
    if not args.image_topic or not args.cmd_topic:
        raise BagError("--bag needs --image-topic and --cmd-topic")
    return read_bag(
        args.bag, args.image_topic, args.cmd_topic, args.odom_topic, dt, image_size, args.cmd_timeout
    )
