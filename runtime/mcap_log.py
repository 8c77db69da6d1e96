"""A repeat run as a ROS 2 bag in MCAP storage, for Foxglove and `ros2 bag play` (`vtr repeat --mcap run.mcap`).

Channels (ROS 2 message types, CDR, schemas embedded so any MCAP reader decodes them):

=====================  ==============================  =========================================================
topic                  type                            content
=====================  ==============================  =========================================================
/vtr/camera/image      sensor_msgs/msg/Image (rgb8)    the camera image the decision was taken on
/vtr/subgoal/image     sensor_msgs/msg/Image (rgb8)    the subgoal image steered to
/vtr/cmd_vel           geometry_msgs/msg/TwistStamped  the command applied for dt (linear.x, angular.z)
/vtr/pose              geometry_msgs/msg/PoseStamped   the robot's pose in frame ``map``, only when it is known
/vtr/image_error       std_msgs/msg/Float64            the image error to the subgoal (0..255), to plot
/vtr/step              std_msgs/msg/String             JSON: step, subgoal, image error, e_m, decision, ...
=====================  ==============================  =========================================================

Times: the robot's stamps (simulated seconds for the simulator) are placed after the wall-clock instant the
writer opened, so a run shows a real date and keeps the robot's spacing.

``PATH`` ending in ``.mcap`` is one MCAP file (Foxglove, `ros2 bag play PATH`, rosbags); any other ``PATH`` is a
bag folder with metadata.yaml (format 8) as `ros2 bag record -s mcap` makes it (for Humble, whose rosbag2
predates that format, its maintainers suggest deleting metadata.yaml and `ros2 bag reindex PATH`; not tried here).
The bag is written into a temporary folder beside ``PATH`` and moved into place by :meth:`McapRunWriter.close`,
which first fills in each chunk's CRC-32 (runtime.mcap_walk), so a reader tells a damaged chunk from a good one.

Needs the optional extra ``[ros]`` (the pure-Python ``rosbags``), imported only when a run is written or read: a
robot board that never records runs never needs it. runtime.mcap_read reads a run back (`vtr eval --run`).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime import mcap_walk

TOPICS = {
    "/vtr/camera/image": "sensor_msgs/msg/Image",
    "/vtr/subgoal/image": "sensor_msgs/msg/Image",
    "/vtr/cmd_vel": "geometry_msgs/msg/TwistStamped",
    "/vtr/pose": "geometry_msgs/msg/PoseStamped",
    "/vtr/image_error": "std_msgs/msg/Float64",
    "/vtr/step": "std_msgs/msg/String",
}
_MISSING = "MCAP runs need the package rosbags: pip install 'vtr-mpc[ros]'"
#: Fields of a step copied into the JSON channel when present.
STEP_FIELDS = (
    "step",
    "subgoal",
    "from_subgoal",
    "error",
    "e_m",
    "decision",
    "advanced",
    "jumped_to",
    "v",
    "w",
)


def _rosbags() -> tuple[Any, Any]:
    try:
        from rosbags import rosbag2, typesys
    except ModuleNotFoundError:
        raise ModuleNotFoundError(_MISSING, name="rosbags") from None
    return rosbag2, typesys


def _field(step: Any, name: str, default: Any = None) -> Any:
    """A field of a step record: a mapping's key or an object's attribute."""
    if isinstance(step, Mapping):
        return step.get(name, default)
    return getattr(step, name, default)


class McapRunWriter:
    """Write one run. ``record(step)`` takes any step record with the fields below (mapping or object):

    ``stamp`` (s), ``image`` (H, W, 3) uint8, ``subgoal_image`` or None, ``v``, ``w``, ``pose`` (x, y, yaw) or None,
    ``error``, ``subgoal`` and the optional ``STEP_FIELDS``.
    """

    def __init__(self, path: str | os.PathLike[str], summary_topic: bool = True) -> None:
        rosbag2, typesys = _rosbags()
        self.path = Path(path)
        self.single_file = self.path.suffix == ".mcap"
        self.store = typesys.get_typestore(typesys.Stores.ROS2_HUMBLE)
        self._types = self.store.types
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmp = Path(tempfile.mkdtemp(prefix=f".{self.path.name}.", dir=self.path.parent))
        bag_dir = self._tmp / (self.path.stem if self.single_file else self.path.name)
        self._bag_dir = bag_dir
        try:
            self._writer = rosbag2.Writer(bag_dir, version=8, storage_plugin=rosbag2.StoragePlugin.MCAP)
            self._writer.open()
            self._conns = {
                topic: self._writer.add_connection(topic, t, typestore=self.store)
                for topic, t in TOPICS.items()
            }
        except BaseException:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise
        self._wall0 = time.time()
        self._stamp0: float | None = None
        self.messages = 0
        self._last_ns = 0
        self.closed = False

    # ------------------------------------------------------------------ messages
    def _time(self, stamp: float) -> tuple[int, Any]:
        if self._stamp0 is None:
            self._stamp0 = stamp
        ns = int(round((self._wall0 + stamp - self._stamp0) * 1e9))
        return ns, self._types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

    def _header(self, stamp: Any, frame: str) -> Any:
        return self._types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def _image(self, image: np.ndarray, stamp: Any) -> Any:
        image = np.ascontiguousarray(image, dtype=np.uint8)
        h, w = image.shape[:2]
        return self._types["sensor_msgs/msg/Image"](
            header=self._header(stamp, "camera"),
            height=h,
            width=w,
            encoding="rgb8",
            is_bigendian=0,
            step=3 * w,
            data=image.reshape(-1),
        )

    def _write(self, topic: str, ns: int, msg: Any) -> None:
        self._writer.write(self._conns[topic], ns, self.store.serialize_cdr(msg, TOPICS[topic]))
        self.messages += 1
        self._last_ns = max(self._last_ns, ns)

    def record(self, step: Any) -> None:
        """Write one control step's messages."""
        types = self._types
        ns, stamp = self._time(float(_field(step, "stamp", 0.0)))
        image = _field(step, "image")
        if image is not None:
            self._write("/vtr/camera/image", ns, self._image(image, stamp))
        subgoal_image = _field(step, "subgoal_image")
        if subgoal_image is not None:
            self._write("/vtr/subgoal/image", ns, self._image(subgoal_image, stamp))
        vec = types["geometry_msgs/msg/Vector3"]
        v, w = float(_field(step, "v", 0.0)), float(_field(step, "w", 0.0))
        twist = types["geometry_msgs/msg/Twist"](
            linear=vec(x=v, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=w)
        )
        self._write(
            "/vtr/cmd_vel",
            ns,
            types["geometry_msgs/msg/TwistStamped"](header=self._header(stamp, "base_link"), twist=twist),
        )
        pose = _field(step, "pose")
        if pose is not None and all(math.isfinite(float(p)) for p in pose):
            x, y, yaw = (float(p) for p in pose)
            msg = types["geometry_msgs/msg/PoseStamped"](
                header=self._header(stamp, "map"),
                pose=types["geometry_msgs/msg/Pose"](
                    position=types["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                    orientation=types["geometry_msgs/msg/Quaternion"](
                        x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2)
                    ),
                ),
            )
            self._write("/vtr/pose", ns, msg)
        error = _field(step, "error")
        if error is not None:
            self._write("/vtr/image_error", ns, types["std_msgs/msg/Float64"](data=float(error)))
        info = {k: _field(step, k) for k in STEP_FIELDS if _field(step, k) is not None}
        info["stamp"] = float(_field(step, "stamp", 0.0))
        text = json.dumps(info, default=_plain, allow_nan=False)
        self._write("/vtr/step", ns, types["std_msgs/msg/String"](data=text))

    def record_summary(self, summary: Mapping[str, Any]) -> None:
        """The run's summary as one last JSON message on /vtr/step (``{"summary": {...}}``)."""
        ns = self._last_ns + 1 if self._last_ns else int(round(time.time() * 1e9))
        text = json.dumps({"summary": dict(summary)}, default=_plain)
        self._write("/vtr/step", ns, self._types["std_msgs/msg/String"](data=text))

    # ------------------------------------------------------------------ closing
    def close(self) -> Path:
        """Finish the bag and move it into place (replacing an older one); returns the final path."""
        if self.closed:
            return self.path
        self.closed = True
        try:
            self._writer.close()
            source = self._bag_dir / f"{self._bag_dir.name}.mcap" if self.single_file else self._bag_dir
            for part in [source] if self.single_file else sorted(source.glob("*.mcap")):
                mcap_walk.add_chunk_crcs(part)  # so a reader sees a damaged chunk (rosbags writes none)
            if self.path.is_dir() and not self.single_file:
                shutil.rmtree(self.path)
            os.replace(source, self.path)
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)
        return self.path

    def abort(self) -> None:
        """Drop the bag unwritten (a run that never started): nothing is moved into place."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.close()
        except Exception:  # noqa: BLE001 - the bag is being thrown away
            pass
        shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> McapRunWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _plain(obj: Any) -> Any:
    if hasattr(obj, "tolist"):
        return obj.tolist()
    if hasattr(obj, "name"):  # enums (a controller decision)
        return obj.name
    return str(obj)


def step_fields(rec: Any, route_images: np.ndarray) -> dict[str, Any] | None:
    """A ``runtime.repeater.StepRecord`` as the mapping the run sinks take (:meth:`McapRunWriter.record`,
    ``runtime.foxglove_live``): the terminal record carries its status as the decision; None when the run ended
    before any valid frame (nothing was seen)."""
    if rec.image is None:
        return None
    status = getattr(rec, "status", None)
    action = getattr(rec, "action", None)
    decision = status.value if status is not None else getattr(action, "value", action)
    return {
        "stamp": rec.stamp if rec.stamp is not None else 0.0,
        "image": rec.image,
        "subgoal_image": route_images[min(int(rec.subgoal), len(route_images) - 1)],
        "v": rec.v,
        "w": rec.w,
        "pose": rec.pose,
        "error": rec.error if math.isfinite(rec.error) else None,
        "subgoal": rec.subgoal,
        "from_subgoal": rec.from_subgoal,
        "e_m": rec.e_m,
        "decision": decision,
        "advanced": rec.advanced,
        "jumped_to": rec.jumped_to,
        "step": rec.step,
    }
