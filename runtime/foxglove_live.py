"""`vtr repeat --foxglove [PORT]`: watch a run live in Foxglove (open connection ws://127.0.0.1:PORT).

Serves the run's channels with the Foxglove SDK's WebSocket server, bound to 127.0.0.1 only (nothing leaves the
machine; use an SSH tunnel to watch from elsewhere): ``/vtr/camera/image`` and ``/vtr/subgoal/image``
(foxglove.RawImage, rgb8), ``/vtr/pose`` (foxglove.PoseInFrame in frame ``map``, when the robot knows its pose)
and ``/vtr/step`` (JSON: step, subgoal, image error, e_m, decision, v, w). The recorded counterpart, with ROS 2
message types, is runtime/mcap_log.py.

Needs the optional extra ``[foxglove]`` (foxglove-sdk, a compiled wheel): never part of the robot-board install.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

HOST = "127.0.0.1"
_MISSING = "the live view needs the package foxglove-sdk: pip install 'vtr-mpc[foxglove]'"


class FoxgloveLive:
    """A Foxglove WebSocket server on 127.0.0.1:``port`` (0 picks a free port) fed by :meth:`record`."""

    def __init__(self, port: int = 8765, context: Any = None) -> None:
        try:
            import foxglove
            from foxglove import channels, messages
        except ModuleNotFoundError:
            raise ModuleNotFoundError(_MISSING, name="foxglove") from None
        self._m = messages
        self.context = context if context is not None else foxglove.Context()
        try:
            self.server = foxglove.start_server(name="vtr repeat", host=HOST, port=port, context=self.context)
        except RuntimeError as exc:  # the SDK's FoxgloveError: a port in use, or one not ours to bind
            why = str(exc).removeprefix("FoxgloveError: ").strip() or "the server did not start"
            raise OSError(
                f"--foxglove {port}: cannot serve the live view on {HOST}:{port} ({why}); "
                "pick a free port, or 0 for any"
            ) from None
        self.port = int(self.server.port)
        ctx = self.context
        self._camera = channels.RawImageChannel("/vtr/camera/image", context=ctx)
        self._subgoal = channels.RawImageChannel("/vtr/subgoal/image", context=ctx)
        self._pose = channels.PoseInFrameChannel("/vtr/pose", context=ctx)
        self._step = foxglove.Channel("/vtr/step", context=ctx)

    def _image(self, image: np.ndarray, stamp: Any) -> Any:
        image = np.ascontiguousarray(image, dtype=np.uint8)
        h, w = image.shape[:2]
        return self._m.RawImage(
            timestamp=stamp,
            frame_id="camera",
            width=w,
            height=h,
            encoding="rgb8",
            step=3 * w,
            data=image.tobytes(),
        )

    def record(self, step: Mapping[str, Any]) -> None:
        """Publish one step (the mapping of runtime.mcap_log.step_fields)."""
        m = self._m
        t = float(step.get("stamp") or 0.0)
        stamp = m.Timestamp(int(t), int(round((t - int(t)) * 1e9)) % 10**9)
        if step.get("image") is not None:
            self._camera.log(self._image(step["image"], stamp))
        if step.get("subgoal_image") is not None:
            self._subgoal.log(self._image(step["subgoal_image"], stamp))
        pose = step.get("pose")
        if pose is not None and all(math.isfinite(float(p)) for p in pose):
            x, y, yaw = (float(p) for p in pose)
            orientation = m.Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
            self._pose.log(
                m.PoseInFrame(
                    timestamp=stamp,
                    frame_id="map",
                    pose=m.Pose(position=m.Vector3(x=x, y=y, z=0.0), orientation=orientation),
                )
            )
        skip = ("image", "subgoal_image", "pose")
        self._step.log({k: v for k, v in step.items() if k not in skip and v is not None})

    def close(self) -> None:
        self.server.stop()
