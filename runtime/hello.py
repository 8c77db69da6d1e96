"""What a robot announces in ``hello`` (docs/PROTOCOL.md, "hello"), and whether robot, route and model agree.

:func:`parse_hello` validates a hello reply into a :class:`Hello`; :func:`check_camera` compares the
robot's camera with the camera a route was taught with and the camera a model was trained on, and raises
:class:`CameraMismatchError` with a one-line message naming the first difference; :func:`check_robot_fits`
adds the limits and the control step (:class:`RobotMismatchError`, of which a camera mismatch is one kind).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.protocol import MAX_IMAGE_SIDE, BadFrameError, Limits, Reply, integer, number
from vtr.runtime.scan import ScanSpec, spec_from_dict

#: Cameras whose horizontal fields of view differ by more than this (degrees) see different images.
FOV_TOLERANCE_DEG = 2.0
#: Cameras mounted at heights differing by more than this (metres) see different images.
HEIGHT_TOLERANCE_M = 0.02
#: Clock modes a robot may announce.
MODES = ("lockstep", "realtime")


class RobotMismatchError(ValueError):
    """The robot does not fit the route and the model (camera, limits or control step); the message says how."""


class CameraMismatchError(RobotMismatchError):
    """Robot, route and model disagree about the camera; the message says which and how."""


def camera_from_dict(d: Any, err: type[ValueError] = BadFrameError, where: str = "camera.") -> CameraSpec:
    """Read ``{"width", "height", "fov_deg"?, "height_m"?}``; ``camera_height`` (the simulator's and older
    routes' name) is read as ``height_m``. A field not given is None (unknown)."""
    if not isinstance(d, dict):
        raise err(f"{where.rstrip('.')} must be an object with width and height, got {d!r:.60}")
    width, height = integer(d, "width", err, where), integer(d, "height", err, where)
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise err(f"{where}width/height must be in 1..{MAX_IMAGE_SIDE}, got {width}x{height}")
    fov = number(d, "fov_deg", err, where) if d.get("fov_deg") is not None else None
    if fov is not None and not 0 < fov < 360:
        raise err(f"{where}fov_deg must be in (0, 360), got {fov}")
    key = "height_m" if d.get("height_m") is not None else "camera_height"
    height_m = number(d, key, err, where) if d.get(key) is not None else None
    return CameraSpec(width=width, height=height, fov_deg=fov, height_m=height_m)


@dataclass(frozen=True)
class Hello:
    """A validated hello reply."""

    session: str
    stamp: float
    protocol_version: int
    camera: CameraSpec
    limits: Limits
    #: The robot's control period in seconds (the shortest step it executes faithfully).
    dt: float
    #: "lockstep" (time advances only in steps) or "realtime".
    mode: str
    #: Seconds after which the robot stops by itself when no command arrives (0: never); None: not said.
    cmd_vel_timeout: float | None = None
    #: Robot-clock seconds per wall-clock second in realtime mode (a simulator may run faster).
    realtime_factor: float = 1.0
    robot: str | None = None
    map: str | None = None
    info: dict[str, Any] = field(default_factory=dict)
    #: The range scanner every image reply may carry a reading of (None: camera only).
    scan: ScanSpec | None = None


def parse_hello(reply: Reply) -> Hello:
    """Validate the fields a hello reply must carry; BadFrameError names the first missing or wrong one."""
    h = reply.header
    if reply.cmd != "hello" or not reply.ok or reply.session is None or reply.stamp is None:
        raise BadFrameError("not an ok hello reply")
    version = integer(h, "protocol_version", BadFrameError)
    camera = camera_from_dict(h.get("camera"))
    limits_raw = h.get("limits")
    if not isinstance(limits_raw, dict):
        raise BadFrameError(f"hello field 'limits' must be an object, got {limits_raw!r:.60}")
    limits = Limits(
        *(number(limits_raw, k, BadFrameError, "limits.") for k in ("v_max", "w_max", "max_duration"))
    )
    dt = number(h, "dt", BadFrameError)
    if dt <= 0:
        raise BadFrameError(f"hello field 'dt' must be > 0, got {dt}")
    mode = h.get("mode")
    if mode not in MODES:
        raise BadFrameError(f"hello field 'mode' must be one of {MODES}, got {mode!r:.60}")
    timeout = number(h, "cmd_vel_timeout", BadFrameError) if h.get("cmd_vel_timeout") is not None else None
    if mode == "realtime" and (timeout is None or timeout < 0):
        raise BadFrameError("a realtime robot must announce 'cmd_vel_timeout' (seconds, 0 when it has none)")
    rate = number(h, "realtime_factor", BadFrameError) if h.get("realtime_factor") is not None else 1.0
    if rate <= 0:
        raise BadFrameError(f"hello field 'realtime_factor' must be > 0, got {rate}")
    names = {k: h.get(k) if isinstance(h.get(k), str) else None for k in ("robot", "map")}
    info = h.get("info") if isinstance(h.get("info"), dict) else {}
    scan = spec_from_dict(h["scan"]) if h.get("scan") is not None else None
    return Hello(
        reply.session,
        reply.stamp,
        version,
        camera,
        limits,
        dt,
        mode,
        timeout,
        rate,
        info=info,
        scan=scan,
        **names,
    )


def check_camera(
    robot: CameraSpec, route: CameraSpec | None = None, model: CameraSpec | None = None
) -> list[str]:
    """Raise CameraMismatchError when robot, route and model cameras differ; returns notes on what could not
    be compared (a field one side does not record)."""
    notes: list[str] = []
    for name, other in (("route", route), ("model", model)):
        if other is None:
            notes.append(f"the {name} records no camera; not compared")
            continue
        if (other.width, other.height) != (robot.width, robot.height):
            raise CameraMismatchError(
                f"the robot's camera gives {robot.width}x{robot.height} images but the {name} was made with "
                f"{other.width}x{other.height}"
            )
        for label, a, b, tol, unit in (
            ("field of view", robot.fov_deg, other.fov_deg, FOV_TOLERANCE_DEG, " deg"),
            ("camera height", robot.height_m, other.height_m, HEIGHT_TOLERANCE_M, " m"),
        ):
            if a is None or b is None:
                notes.append(f"{label} of the robot or the {name} unknown; not compared")
            elif abs(a - b) > tol:
                raise CameraMismatchError(
                    f"the robot's {label} is {a:g}{unit} but the {name} was made with {b:g}{unit} "
                    f"(tolerance {tol:g}{unit})"
                )
    return notes


def route_camera(camera: Any) -> CameraSpec | None:
    """The camera a route records in its metadata (None when it records none)."""
    if not isinstance(camera, dict) or "width" not in camera:
        return None
    return camera_from_dict(camera, CameraMismatchError, "route camera.")


def check_robot_fits(hello: Hello, route_cam: dict[str, Any] | None, model: Any) -> list[str]:
    """Refuse (RobotMismatchError, one line) a robot whose camera differs from the route's or the model's
    (``model``: a ModelMeta; then a CameraMismatchError), whose limits are below the model's, or whose steps
    cannot last the model's dt. Returns notes on what could not be compared."""
    notes = check_camera(hello.camera, route_camera(route_cam), model.camera)
    for name, unit in (("v_max", "m/s"), ("w_max", "rad/s")):
        mine, robots = getattr(model, name), getattr(hello.limits, name)
        if mine > robots + 1e-9:
            raise RobotMismatchError(
                f"the model commands up to {name}={mine:g} {unit} but the robot accepts at most {robots:g} {unit}"
            )
    if not hello.dt <= model.dt <= hello.limits.max_duration:
        raise RobotMismatchError(
            f"the model's control step is {model.dt:g} s but the robot runs steps of "
            f"{hello.dt:g}..{hello.limits.max_duration:g} s"
        )
    return notes
