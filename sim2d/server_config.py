"""How the simulator server listens, what it accepts and how its clock runs (``vtr sim serve``)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vtr.runtime import protocol
from vtr.runtime.address import check_endpoint
from vtr.runtime.protocol import Limits


@dataclass
class ServerConfig:
    """How the simulator server listens and what it accepts."""

    #: ZeroMQ endpoint to bind; ``tcp://127.0.0.1:*`` picks a free port (see ``SimServer.endpoint``).
    bind: str = "tcp://127.0.0.1:5555"
    #: sim2d.SimConfig for the simulator ``serve`` builds; None means SimConfig() defaults.
    sim: Any = None
    #: Requests larger than this (all frames together) get an error reply.
    max_message_bytes: int = protocol.MAX_MESSAGE_BYTES
    #: Hard cap handed to ZeroMQ (ZMQ_MAXMSGSIZE): a peer sending more is disconnected without a reply.
    hard_max_message_bytes: int = protocol.MAX_MESSAGE_BYTES
    #: Linear speed limit in m/s; faster step requests are rejected (the paper's robot: 0.5).
    v_max: float = protocol.V_MAX
    #: Angular speed limit in rad/s (the paper's robot: 1.0).
    w_max: float = protocol.W_MAX
    #: Longest simulated duration one step request may ask for, in seconds.
    max_step_duration: float = protocol.MAX_DURATION
    #: How often the loop wakes up to check for shutdown, in milliseconds.
    poll_ms: int = 100
    #: "lockstep": time advances only in step requests; "realtime": time follows the wall clock.
    mode: str = "lockstep"
    #: "realtime" only: simulated seconds per wall-clock second.
    realtime_factor: float = 1.0
    #: "realtime" only: seconds without a new step after which the robot is brought to zero (0: never).
    cmd_vel_timeout: float = 0.5
    #: Announce the simulator's range scanner and send a scan with every image (False: a camera-only robot).
    scan: bool = True
    #: Report the executed twist (the one the robot is driving with) in every image reply, announced in hello.
    twist: bool = True
    #: A RouteScript the robot drives by itself, as its own joystick would (sim2d/joystick.py; realtime only).
    drive_script: Any = None

    def __post_init__(self) -> None:
        check_endpoint(self.bind, bind=True)
        if self.max_message_bytes < 1024:
            raise ValueError(f"max_message_bytes must be >= 1024, got {self.max_message_bytes}")
        if self.hard_max_message_bytes < self.max_message_bytes:
            raise ValueError(
                f"hard_max_message_bytes={self.hard_max_message_bytes} must be >= "
                f"max_message_bytes={self.max_message_bytes}"
            )
        for name in ("v_max", "w_max", "max_step_duration"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if self.poll_ms < 1:
            raise ValueError(f"poll_ms must be >= 1, got {self.poll_ms}")
        if self.mode not in ("lockstep", "realtime"):
            raise ValueError(f"mode must be 'lockstep' or 'realtime', got {self.mode!r}")
        if not (math.isfinite(self.realtime_factor) and self.realtime_factor > 0):
            raise ValueError(f"realtime_factor must be a positive number, got {self.realtime_factor!r}")
        if self.drive_script is not None and self.mode != "realtime":
            raise ValueError(
                "a drive script needs --mode realtime: in lockstep nothing moves between requests"
            )
        if not (math.isfinite(self.cmd_vel_timeout) and self.cmd_vel_timeout >= 0):
            raise ValueError(
                f"cmd_vel_timeout must be >= 0 seconds (0 disables), got {self.cmd_vel_timeout!r}"
            )

    @property
    def limits(self) -> Limits:
        return Limits(v_max=self.v_max, w_max=self.w_max, max_duration=self.max_step_duration)
