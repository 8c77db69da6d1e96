"""The control step as the latency benchmark times it: the runtime's own ``Repeater.step`` on a robot
whose link is a loopback.

``LoopbackRobot`` does what ``runtime.client.SimClient`` does for each call minus the socket: encode the
request (``protocol.encode_request``, with the limits and the session guard) and validate a real encoded
reply (``protocol.decode_reply`` with the expected command, sequence number and shape), the zero
command's reply included. So one timed ``Repeater.step`` is the whole step
the daemon runs (decode, image error, preprocess, inference, postprocess, encode of the command and of
the zero command), without the simulator. Imports no torch, OpenCV or pymunk: the runtime-only memory
probe runs it with those blocked.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from vtr.runtime import protocol
from vtr.runtime.contracts import CONTROL_DT, Observation
from vtr.runtime.frame import Frame
from vtr.runtime.matching import MatchConfig

SESSION = "bench"
#: Subgoals on the benchmark's route. One would do for a controller that looks at one subgoal per step; a
#: route of this length makes one that also scans the subgoals ahead (a lost or stall check) pay for it.
ROUTE_LENGTH = 30


class LoopbackRobot:
    """A ``Robot`` answering every request with the same encoded frame (see the module docstring)."""

    def __init__(self, image: np.ndarray) -> None:
        self.shape = image.shape[:2]
        self._seq = 0
        self._limits = protocol.Limits()
        self._replies = {
            cmd: protocol.encode_image_reply(cmd, 1, SESSION, 1.0, image, pose=None)
            for cmd in ("observe", "step")
        }
        self._replies["stop"] = protocol.encode_ok("stop", 1, SESSION, 1.0)

    def _exchange(self, cmd: str, **fields: Any) -> Observation:
        self._seq += 1
        self._encode(cmd, **fields)
        reply = protocol.decode_reply(
            self._replies[cmd], expect_cmd=cmd, expect_seq=1, expect_shape=self.shape
        )
        assert reply.image is not None and reply.stamp is not None
        return Observation.of_frame(
            Frame.decoded(reply.image), reply.stamp, pose=reply.pose, collided=reply.collided
        )

    def _encode(self, cmd: str, **fields: Any) -> list[bytes]:
        """As SimClient: checked against the robot's limits, guarded by its session."""
        guard = {"session": SESSION} if cmd in protocol.GUARDED_COMMANDS else {}
        return protocol.encode_request(cmd, self._seq, time.time(), self._limits, **guard, **fields)

    def decode(self) -> np.ndarray:
        """Only the reply validation (the ``frame_decode`` stage)."""
        reply = protocol.decode_reply(
            self._replies["step"], expect_cmd="step", expect_seq=1, expect_shape=self.shape
        )
        assert reply.image is not None
        return reply.image

    def encode_command(self, v: float, w: float) -> list[bytes]:
        """Only the command encode (the ``command_encode`` stage)."""
        return self._encode("step", v=v, w=w, duration=CONTROL_DT)

    def observe(self) -> Observation:
        return self._exchange("observe")

    def step(self, v: float, w: float, duration: float) -> Observation:
        return self._exchange("step", v=float(v), w=float(w), duration=float(duration))

    def stop(self) -> None:
        self._seq += 1
        self._encode("stop")
        protocol.decode_reply(self._replies["stop"], expect_cmd="stop", expect_seq=1)


#: The command the sample route is driven with (m/s, rad/s, s): its taught command at every subgoal.
DRIVE = (0.2, 0.1, 0.1)


def sample_route(height: int, width: int, length: int = ROUTE_LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """A current frame and a taught route of ``length`` frames driven from near it (first subgoal first).

    From the simulator when it is installed, else shifted synthetic texture. The route's views change
    from subgoal to subgoal, as on a real route, so the controller uses patch matching (a route of one
    repeated view is "too plain" and makes it fall back to the raw error)."""
    current, route, _ = sample_taught(height, width, length)
    return current, route


def sample_taught(
    height: int, width: int, length: int = ROUTE_LENGTH
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`sample_route`'s current frame and route, and the route's (length, 3) taught poses (x, y, yaw: the
    simulator's, or a straight line along the synthetic texture), each subgoal driven with :data:`DRIVE`."""
    v, w, dt = DRIVE
    try:
        from vtr.sim2d import CameraConfig, Pose, SimConfig, Simulator

        sim = Simulator(SimConfig(camera=CameraConfig(width=width, height=height), noise=0.0))
        sim.reset(seed=0)
        start = sim.pose
        first = sim.reset(pose=Pose(start.x, start.y, start.yaw), seed=0)
        current = sim.step(0.1, 0.1, 0.1)  # near the first subgoal, not on it
        sim.reset(pose=Pose(start.x, start.y, start.yaw), seed=0)
        frames, poses = [first], [(start.x, start.y, start.yaw)]
        for _ in range(length - 1):
            frames.append(sim.step(v, w, dt))
            poses.append((sim.pose.x, sim.pose.y, sim.pose.yaw))
    except (
        Exception
    ):  # simulator missing (the runtime-only memory probe): the timings do not depend on content
        yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
        base = np.stack([xx / width, yy / height, 0.5 + 0.5 * np.sin(xx / 3.0) * np.cos(yy / 5.0)], axis=-1)
        texture = (base * 255).astype(np.uint8)
        frames = [np.roll(texture, 2 * k, axis=1) for k in range(length)]
        current = np.roll(texture, 1, axis=1)
        poses = [(v * dt * k, 0.0, 0.0) for k in range(length)]
    return np.ascontiguousarray(current), np.ascontiguousarray(np.stack(frames)), np.array(poses, np.float64)


def sample_end_view(height: int, width: int, poses: np.ndarray, route: np.ndarray) -> np.ndarray:
    """A view from half a control step of :data:`DRIVE` short of the last of :func:`sample_taught`'s ``poses``
    (the simulator's); the route's last-but-one image where the simulator is missing."""
    v, _, dt = DRIVE
    try:
        from vtr.sim2d import CameraConfig, Pose, SimConfig, Simulator

        sim = Simulator(SimConfig(camera=CameraConfig(width=width, height=height), noise=0.0))
        x, y, yaw = (float(p) for p in poses[-1])
        back = 0.5 * v * dt
        view = sim.reset(pose=Pose(x - back * np.cos(yaw), y - back * np.sin(yaw), yaw), seed=0)
    except Exception:  # simulator missing: the timings do not depend on content
        view = route[-2]
    return np.ascontiguousarray(view)


def progress_afresh(repeater: Any) -> None:
    """Count the follower's no-progress watch afresh before a benchmark step: the view never moves while every
    step drives on, so the watch would end the repeat after its window's taught travel, as it should on a
    robot; counted afresh each step (its check still runs in the step), the benchmark's repeat goes on."""
    progress = getattr(repeater.controller, "progress", None)
    if progress is not None:
        progress.reset()


class BenchStep:
    """``Repeater.step`` on a ``LoopbackRobot`` showing ``current`` while steering to ``route[0]``.

    The controller never reaches the end (the robot's view stays near the first subgoal): every step
    commands, the worst case; everything else is the default controller (the route localiser's window and its
    lost check included), with ``match`` as its image comparison (default: patch matching; ``MatchConfig.paper()`` for the raw error).
    ``route`` is the taught images (from :func:`sample_route`); a single (H, W, 3) image makes a route of
    ``ROUTE_LENGTH`` copies, on which the controller falls back to the raw error (``matching`` says which
    one is in force). The zero command after each step is sent, as the daemon does by default
    (stop-and-go); ``continuous=True`` leaves it out (`vtr repeat --motion continuous`). ``match_light=True``
    wraps the policy in ``LightMatchedPolicy`` as `vtr repeat` does by default. ``poses``: the route's taught
    poses (from :func:`sample_taught`), with :data:`DRIVE` as its taught command everywhere: the step of a
    real route, whose obstruction detector warps the taught floor ahead and whose side estimate registers
    the floor rows on every forward step; without them (all poses zero, no taught motion) neither has any
    floor to judge, and the step leaves both out. ``hold_at``: the route position (subgoal units) the route
    localiser's belief is put back to before each call, so that every step is judged there: in the end's
    zone (``runtime.arrival``), the floor registered along the route as well, as on a real route's last
    steps (with ``current`` from :func:`sample_end_view`).
    """

    name = "runtime.repeater.Repeater.step on a loopback link (protocol decode/encode, no socket)"

    def __init__(
        self,
        model: str | Path,
        threads: int,
        current: np.ndarray,
        route: np.ndarray,
        continuous: bool = False,
        match_light: bool = False,
        match: MatchConfig | None = None,
        poses: np.ndarray | None = None,
        hold_at: float | None = None,
    ) -> None:
        from vtr.runtime.controller import ControllerConfig
        from vtr.runtime.policy import OnnxPolicy
        from vtr.runtime.repeater import RepeatConfig, Repeater
        from vtr.runtime.route import Route

        self.policy = OnnxPolicy(model, threads=threads)
        policy: Any = self.policy
        if match_light:  # as `vtr repeat` does by default (its default profile)
            from vtr.runtime.light import LightMatchedPolicy

            policy = LightMatchedPolicy(self.policy)
        self.robot = LoopbackRobot(current)
        if route.ndim == 3:
            route = np.broadcast_to(route, (ROUTE_LENGTH, *route.shape))
        n = len(route)
        taught = Route(
            images=np.ascontiguousarray(route),
            poses=np.zeros((n, 3)) if poses is None else np.asarray(poses, np.float64),
            commands=np.zeros((n, 2)) if poses is None else np.tile(DRIVE[:2], (n, 1)),
            name="bench",
            dt=self.policy.meta.dt,
        )
        controller = ControllerConfig(
            match=match or MatchConfig(),
            e_m_mode="fixed",
            e_m=1e-3,
            stall_steps=0,
            settle_steps=0,
            continuous=continuous,
        )
        self.repeater = Repeater(
            self.robot, policy, taught, config=RepeatConfig(controller=controller, max_steps=10**12)
        )
        #: The image comparison the controller uses ("raw" also when it fell back from patch matching).
        self.matching = self.repeater.controller.cfg.match.method
        #: Per call, from the Repeater's own stage times (ms): the step's compute (the controller's judgement,
        #: the policy, the command's limits: no link) and its link (the command sent and its reply decoded,
        #: the zero command and its reply).
        self.compute_ms: list[float] = []
        self.link_ms: list[float] = []
        #: Per call: the CPU time this thread spent in the controller's judgement and the policy (ms), which
        #: time the process waited for a core (a busy machine) does not count in.
        self.compute_cpu_ms: list[float] = []
        self._cpu_ns = 0
        self.hold_at = hold_at
        rep = self.repeater
        rep.controller.judge = self._on_cpu(rep.controller.judge)  # type: ignore[method-assign]
        rep.policy = self._on_cpu(rep.policy)

    def _on_cpu(self, call: Any) -> Any:
        """``call`` (a function, or a policy: its ``predict``) adding this thread's CPU time to ``_cpu_ns``."""
        inner = getattr(call, "predict", call)

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.thread_time_ns()
            try:
                return inner(*args, **kwargs)
            finally:
                self._cpu_ns += time.thread_time_ns() - t0

        if inner is call:
            return timed
        return _Timed(call, timed)

    def __call__(self) -> Any:
        self._cpu_ns = 0
        progress_afresh(self.repeater)
        if self.hold_at is not None:  # the view never moves, nor should the belief: judged at the same place
            localiser = self.repeater.controller.localiser
            localiser.start_at(self.hold_at)
            localiser.last = None
        record = self.repeater.step()
        if not record.commanded:  # the identical frame matched the subgoal: cannot happen, say so
            raise RuntimeError(f"the benchmark's repeat ended: {record.status}")
        self.compute_ms.append(record.latency_ms["compute"])
        self.link_ms.append(record.latency_ms["robot"])
        self.compute_cpu_ms.append(self._cpu_ns / 1e6)
        return record


class _Timed:
    """A policy whose ``predict`` is ``timed``; everything else is the policy's."""

    def __init__(self, policy: Any, timed: Any) -> None:
        self._policy, self.predict = policy, timed

    def __getattr__(self, name: str) -> Any:
        return getattr(self._policy, name)
