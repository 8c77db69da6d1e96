"""An in-process simulator as a ``runtime.robot.Robot``: the evaluation's fast path (no sockets)."""

from __future__ import annotations

from typing import Any

from vtr.runtime.contracts import Observation, Pose, Simulator
from vtr.runtime.frame import as_frame


def _pose_tuple(pose: Any) -> tuple[float, float, float]:
    return (float(pose.x), float(pose.y), float(pose.yaw))


class LocalRobot:
    """Adapt a ``sim2d.Simulator`` (reset/step/observe/pose/time/collided) to the Robot protocol.

    The simulator is lockstep, so ``stop`` only records the zero command: no simulated time passes
    between steps. ``commands`` keeps every (v, w, duration) applied, zero commands included.
    ``scan`` True puts the simulator's range scan on every observation (``Simulator.scan``, as
    ``vtr sim serve`` sends it); False (the default) is a camera-only robot.
    """

    def __init__(self, simulator: Simulator, scan: bool = False) -> None:
        self.sim = simulator
        self.scan = bool(scan)
        self.commands: list[tuple[float, float, float]] = []
        #: The last observation handed out (evaluation scores with its true pose).
        self.last: Observation | None = None

    def _obs(self, image: Any) -> Observation:
        # the frame is made here, where the image enters (a fresh render, handed over: not copied)
        self.last = Observation.of_frame(
            as_frame(image, copy=False),
            float(self.sim.time),
            pose=_pose_tuple(self.sim.pose),
            collided=bool(self.sim.collided),
            scan=self.sim.scan() if self.scan else None,  # type: ignore[attr-defined]
        )
        return self.last

    def reset(self, pose: tuple[float, float, float] | None = None, seed: int | None = None) -> Observation:
        return self._obs(self.sim.reset(pose=None if pose is None else Pose(*pose), seed=seed))

    def observe(self) -> Observation:
        return self._obs(self.sim.observe())

    def step(self, v: float, w: float, duration: float) -> Observation:
        self.commands.append((float(v), float(w), float(duration)))
        return self._obs(self.sim.step(float(v), float(w), float(duration)))

    def stop(self) -> None:
        self.commands.append((0.0, 0.0, 0.0))
