"""A deliberately broken robot bridge for the conformance checker's tests.

It wraps the real simulator server's request handling (sim2d SimServer over a sim2d Simulator) behind a ROUTER
socket, so that it can also *not* answer a request, and breaks the protocol in one named way (``FAULTS``).
"""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import numpy as np
import zmq

from vtr.sim2d.server import ServerConfig, SimServer

FAULTS = (
    "no_limits",  # hello announces no limits
    "no_camera",  # hello announces no camera
    "wrong_size",  # images are 64x64 while hello announces 128x128
    "bare_errors",  # error replies are the literal {"ok": false, "error": ...}
    "bare_stop",  # the stop reply is the literal {"ok": true}
    "accepts_over_limit",  # announces 0.5 / 1.0 / 10 s but accepts anything
    "zero_step_moves",  # a zero step turns the robot
    "frozen_camera",  # the image never changes
    "clockwise",  # pose yaw grows clockwise
    "stamp_back",  # step replies go back in time
    "silent_on_bad",  # a bad request gets no reply at all
    "slow",  # every observe takes 40 ms
    "ignores_session",  # executes a step meant for another session
    "no_watchdog",  # realtime, announces cmd_vel_timeout 0.5 s but keeps driving
    "scan_short",  # announces a scanner, sends one beam fewer
    "scan_missing",  # announces a scanner, sends no scan
    "scan_unannounced",  # sends scans without announcing a scanner
    "twist_missing",  # announces its executed twist, sends none
    "twist_backwards",  # reports w with the wrong sign
    "twist_unannounced",  # sends twists without announcing them
    "old_hello",  # hello as the protocol's first text had it: no dt, no mode, camera.camera_height
    "hello_two_wrong",  # hello announces no limits and mode "turbo"
)


def _header(frames: list[bytes]) -> dict[str, Any]:
    return json.loads(frames[0])


def _frames(header: dict[str, Any], rest: list[bytes]) -> list[bytes]:
    return [json.dumps(header).encode(), *rest]


class FaultyRobot:
    """Serve a sim2d Simulator with one fault; a context manager giving ``endpoint``."""

    def __init__(self, simulator: Any, fault: str | None) -> None:
        if fault is not None and fault not in FAULTS:
            raise ValueError(f"unknown fault {fault!r}")
        self.fault = fault
        loose = fault == "accepts_over_limit"
        realtime = fault == "no_watchdog"
        cfg = ServerConfig(
            bind="tcp://127.0.0.1:*",
            mode="realtime" if realtime else "lockstep",
            cmd_vel_timeout=0.0 if realtime else 0.5,
            v_max=50.0 if loose else 0.5,
            w_max=100.0 if loose else 1.0,
            max_step_duration=1000.0 if loose else 10.0,
        )
        self.server = SimServer(simulator, cfg)
        self.first_image: list[bytes] | None = None
        self.endpoint = ""
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._serve, daemon=True)

    def __enter__(self) -> FaultyRobot:
        self._thread.start()
        self._ready.wait(5)
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)

    def _request(self, frames: list[bytes]) -> list[bytes]:
        if self.fault == "ignores_session":
            try:
                header = _header(frames)
            except ValueError:
                return frames
            if isinstance(header, dict) and header.pop("session", None) is not None:
                return _frames(header, [])
        if self.fault == "zero_step_moves":
            try:
                header = _header(frames)
            except ValueError:
                return frames  # malformed: the server answers it
            if (
                isinstance(header, dict)
                and header.get("cmd") == "step"
                and header.get("v") == 0
                and header.get("w") == 0
            ):
                header["w"] = 0.5
                return _frames(header, [])
        return frames

    def _reply(self, frames: list[bytes]) -> list[bytes] | None:
        header, rest, fault = _header(frames), frames[1:], self.fault
        if not header["ok"]:
            if fault == "silent_on_bad":
                return None
            if fault == "bare_errors":
                return _frames({"ok": False, "error": header["error"]}, [])
            return frames
        cmd = header["cmd"]
        if cmd == "hello" and fault in ("no_limits", "accepts_over_limit"):
            header.pop("limits")
            if fault == "accepts_over_limit":
                header["limits"] = {"v_max": 0.5, "w_max": 1.0, "max_duration": 10.0}
        if cmd == "hello" and fault == "no_watchdog":
            header["cmd_vel_timeout"] = 0.5
        if cmd == "hello" and fault == "no_camera":
            header.pop("camera")
            header.pop("info")
        if cmd == "hello" and fault == "scan_unannounced":
            header.pop("scan")
        if cmd == "hello" and fault == "old_hello":
            for key in ("dt", "mode", "cmd_vel_timeout", "realtime_factor", "scan", "twist"):
                header.pop(key, None)
            header["camera"]["camera_height"] = header["camera"].pop("height_m")
        if cmd == "hello" and fault == "hello_two_wrong":
            header.pop("limits")
            header["mode"] = "turbo"
        if cmd == "hello" and fault == "twist_unannounced":
            header.pop("twist")
        if rest and "twist" in header and fault == "twist_missing":
            header.pop("twist")
        if rest and "twist" in header and fault == "twist_backwards":
            header["twist"]["w"] = -header["twist"]["w"]
        if rest and "scan" in header and fault == "scan_short":
            header["scan"]["ranges"] = header["scan"]["ranges"][:-1]
        if rest and "scan" in header and fault == "scan_missing":
            header.pop("scan")
        if cmd == "stop" and fault == "bare_stop":
            return _frames({"ok": True}, [])
        if rest and fault == "wrong_size":
            image = np.frombuffer(rest[0], np.uint8).reshape(header["height"], header["width"], 3)
            header.update(height=64, width=64)
            rest = [np.ascontiguousarray(image[:64, :64]).tobytes()]
        if rest and fault == "frozen_camera":
            self.first_image = self.first_image or rest
            rest = self.first_image
        if header.get("pose") and fault == "clockwise":
            header["pose"]["yaw"] = -header["pose"]["yaw"]
        if cmd == "step" and fault == "stamp_back":
            header["stamp"] = 100.0 - header["stamp"]
        return _frames(header, rest)

    def _serve(self) -> None:
        ctx = zmq.Context()
        sock = ctx.socket(zmq.ROUTER)
        sock.setsockopt(zmq.LINGER, 0)
        sock.bind("tcp://127.0.0.1:*")
        self.endpoint = sock.getsockopt_string(zmq.LAST_ENDPOINT)
        self._ready.set()
        try:
            while not self._stop.is_set():
                if not sock.poll(50):
                    continue
                identity, empty, *frames = sock.recv_multipart()
                reply = self._reply(self.server.handle(self._request(frames)))
                if (
                    self.fault == "slow"
                    and reply is not None
                    and b'"cmd":"observe"' in reply[0].replace(b" ", b"")
                ):
                    time.sleep(0.04)
                if reply is not None:
                    sock.send_multipart([identity, empty, *reply])
        finally:
            sock.close(linger=0)
            ctx.term()
