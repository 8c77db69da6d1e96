"""What a robot announces in ``hello`` (docs/PROTOCOL.md, "hello"), and whether robot, route and model agree.

:func:`read_hello` reads every field of a hello reply on its own (a field that is wrong takes a fallback and
its problem is listed, so `vtr check-robot` reports them all); :func:`parse_hello` is the strict form, raising
on the first problem. Fields hello gained within protocol version 1 after its first text (``ADDED_FIELDS``) are
optional with documented defaults, and :func:`accept_hello` is the one check `vtr teach` and `vtr repeat` apply:
the defaults filled in, a warning naming what the robot should add. :func:`check_camera` compares the robot's
camera with the camera a route was taught with and the camera a model was trained on, and raises
:class:`CameraMismatchError` with a one-line message naming the first difference. A camera need not be the
model's size: :func:`fit_robot` plans how its frames become the model's input (runtime.resample: centre crop,
narrowed to the widest field of view the model saw, resampled), compares the camera the model then sees, and
adds the limits and the control step (:class:`RobotMismatchError`, of which a camera mismatch is one kind).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, TypeVar

from vtr.runtime.contracts import CAMERA, CameraSpec
from vtr.runtime.model_meta import FINE_TUNE_HINT
from vtr.runtime.protocol import MAX_IMAGE_SIDE, VERSION, BadFrameError, Limits, Reply, integer, number
from vtr.runtime.resample import CameraMapping, plan
from vtr.runtime.scan import ScanSpec, spec_from_dict

#: Cameras whose horizontal fields of view differ by more than this (degrees) see different images.
FOV_TOLERANCE_DEG = 2.0
#: Cameras mounted at heights differing by more than this (metres) see different images.
HEIGHT_TOLERANCE_M = 0.02
#: What to do when the robot's camera does not fit the route's or the model's (a refusal's last words).
_FIX = {"route": "teach the route again with this camera", "model": FINE_TUNE_HINT}
#: Clock modes a robot may announce.
MODES = ("lockstep", "realtime")
#: Fields hello gained within version 1 after its first text, each optional, and what leaving it out means
#: (docs/PROTOCOL.md, "Versioning": a field added to version 1 is optional, a breaking change bumps it).
ADDED_FIELDS = {
    "dt": "the route's control step (the robot is taken to execute it faithfully)",
    "mode": "not said: the clock checks of a realtime robot are skipped",
    "cmd_vel_timeout": "not said (a realtime robot must announce it)",
    "realtime_factor": "1",
    "scan": "no range scanner: camera-only safety",
    "twist": "no executed twist in replies: `vtr teach --follow` goes by the pose",
}
#: Of those, the ones every robot should announce: a warning names them when left out.
SHOULD_ANNOUNCE = ("dt", "mode")
#: What an executed-twist report may say it is (hello's ``twist.source``): measured by the wheels, or the
#: command the base is executing (whoever sent it).
TWIST_SOURCES = ("measured", "commanded")
#: Older names still read, each with the name to use instead; a hello using one gets a warning.
DEPRECATED = {"camera.camera_height": "camera.height_m"}

T = TypeVar("T")


class RobotMismatchError(ValueError):
    """The robot does not fit the route and the model (camera, limits or control step); the message says how."""


class CameraMismatchError(RobotMismatchError):
    """Robot, route and model disagree about the camera; the message says which and how."""


def current_camera_names(camera: dict[str, Any]) -> dict[str, Any]:
    """A camera object with its deprecated keys (``DEPRECATED``) under their current names, where the current
    one is not given, the rest as given: what a route records and what is read, whichever way the robot described
    its camera (a hello, the simulator's info, an older route)."""
    out = dict(camera)
    for old, new in DEPRECATED.items():
        before, after = old.split(".", 1)[1], new.split(".", 1)[1]
        if before in out:
            value = out.pop(before)
            if out.get(after) is None:
                out[after] = value
    return out


def camera_from_dict(d: Any, err: type[ValueError] = BadFrameError, where: str = "camera.") -> CameraSpec:
    """Read ``{"width", "height", "fov_deg"?, "height_m"?}``; ``camera_height`` (deprecated: the simulator's
    and older routes' name) is read as ``height_m``. A field not given is None (unknown)."""
    if not isinstance(d, dict):
        raise err(f"{where.rstrip('.')} must be an object with width and height, got {d!r:.60}")
    d = current_camera_names(d)
    width, height = integer(d, "width", err, where), integer(d, "height", err, where)
    if not (0 < width <= MAX_IMAGE_SIDE and 0 < height <= MAX_IMAGE_SIDE):
        raise err(f"{where}width/height must be in 1..{MAX_IMAGE_SIDE}, got {width}x{height}")
    fov = number(d, "fov_deg", err, where) if d.get("fov_deg") is not None else None
    if fov is not None and not 0 < fov < 360:
        raise err(f"{where}fov_deg must be in (0, 360), got {fov}")
    height_m = number(d, "height_m", err, where) if d.get("height_m") is not None else None
    return CameraSpec(width=width, height=height, fov_deg=fov, height_m=height_m)


@dataclass(frozen=True)
class Hello:
    """A validated hello reply."""

    session: str
    stamp: float
    protocol_version: int
    camera: CameraSpec
    limits: Limits
    #: The robot's control period in seconds (the shortest step it executes faithfully); None: not announced
    #: (a bridge older than the field; :func:`accept_hello` puts the route's in).
    dt: float | None
    #: "lockstep" (time advances only in steps) or "realtime"; None: not announced.
    mode: str | None
    #: Seconds after which the robot stops by itself when no command arrives (0: never); None: not said.
    cmd_vel_timeout: float | None = None
    #: Robot-clock seconds per wall-clock second in realtime mode (a simulator may run faster).
    realtime_factor: float = 1.0
    robot: str | None = None
    map: str | None = None
    info: dict[str, Any] = field(default_factory=dict)
    #: The range scanner every image reply may carry a reading of (None: camera only).
    scan: ScanSpec | None = None
    #: Where the executed twist every image reply carries comes from (``TWIST_SOURCES``); None: not reported.
    twist: str | None = None
    #: Deprecated names the robot used (keys of ``DEPRECATED``).
    deprecated: tuple[str, ...] = ()

    @property
    def missing(self) -> list[str]:
        """The fields every robot should announce that this one did not (``SHOULD_ANNOUNCE``)."""
        return [k for k in SHOULD_ANNOUNCE if getattr(self, k) is None]


def _limits(h: dict[str, Any]) -> Limits:
    raw = h.get("limits")
    if not isinstance(raw, dict):
        raise BadFrameError(f"hello field 'limits' must be an object, got {raw!r:.60}")
    values = [number(raw, k, BadFrameError, "limits.") for k in ("v_max", "w_max", "max_duration")]
    try:
        return Limits(*values)
    except ValueError as exc:  # a negative or zero bound
        raise BadFrameError(f"hello field 'limits': {exc}") from None


def _optional(h: dict[str, Any], key: str) -> float | None:
    return number(h, key, BadFrameError) if h.get(key) is not None else None


def _positive(h: dict[str, Any], key: str) -> float | None:
    value = _optional(h, key)
    if value is not None and value <= 0:
        raise BadFrameError(f"hello field {key!r} must be > 0, got {value}")
    return value


def _mode(h: dict[str, Any]) -> str | None:
    mode = h.get("mode")
    if mode is not None and mode not in MODES:
        raise BadFrameError(f"hello field 'mode' must be one of {MODES}, got {mode!r:.60}")
    return mode


def _twist(h: dict[str, Any]) -> str | None:
    raw = h.get("twist")
    if raw is None:
        return None
    source = raw.get("source") if isinstance(raw, dict) else None
    if source not in TWIST_SOURCES:
        raise BadFrameError(f"hello field 'twist' must be an object with 'source' one of {TWIST_SOURCES}")
    return source


def _version(h: dict[str, Any]) -> int:
    version = integer(h, "protocol_version", BadFrameError)
    if version != VERSION:
        raise BadFrameError(
            f"the robot speaks protocol_version {version}; this runtime needs version {VERSION}"
        )
    return version


def read_hello(reply: Reply) -> tuple[Hello, dict[str, str]]:
    """Every field of a hello reply read on its own: the Hello (a wrong field takes its fallback: the shipped
    camera, the paper's limits, not announced) and each problem by field name. BadFrameError when the reply is
    no ok hello at all."""
    h = reply.header
    if reply.cmd != "hello" or not reply.ok or reply.session is None or reply.stamp is None:
        raise BadFrameError("not an ok hello reply")
    problems: dict[str, str] = {}

    def read(name: str, parse: Callable[[], T], fallback: T) -> T:
        try:
            return parse()
        except BadFrameError as exc:
            problems[name] = str(exc)
            return fallback

    version = read("protocol_version", lambda: _version(h), VERSION)
    camera = read("camera", lambda: camera_from_dict(h.get("camera")), CAMERA)
    limits = read("limits", lambda: _limits(h), Limits())
    dt = read("dt", lambda: _positive(h, "dt"), None)
    mode = read("mode", lambda: _mode(h), None)
    timeout = read("cmd_vel_timeout", lambda: _optional(h, "cmd_vel_timeout"), None)
    if mode == "realtime" and (timeout is None or timeout < 0):
        problems.setdefault(
            "cmd_vel_timeout",
            "a realtime robot must announce 'cmd_vel_timeout' (seconds, 0 when it has none)",
        )
    rate = read("realtime_factor", lambda: _positive(h, "realtime_factor"), None) or 1.0
    scan = read("scan", lambda: spec_from_dict(h["scan"]) if h.get("scan") is not None else None, None)
    twist = read("twist", lambda: _twist(h), None)
    cam = h.get("camera") if isinstance(h.get("camera"), dict) else {}
    deprecated = ("camera.camera_height",) if "camera_height" in cam and "height_m" not in cam else ()
    names = {k: h.get(k) if isinstance(h.get(k), str) else None for k in ("robot", "map")}
    info = h.get("info") if isinstance(h.get("info"), dict) else {}
    hello = Hello(
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
        twist=twist,
        deprecated=deprecated,
        **names,
    )
    return hello, problems


def parse_hello(reply: Reply) -> Hello:
    """Validate the fields a hello reply must carry; BadFrameError names the first missing or wrong one."""
    hello, problems = read_hello(reply)
    if problems:
        raise BadFrameError(next(iter(problems.values())))
    return hello


def hello_warnings(hello: Hello, dt: float | None = None) -> list[str]:
    """What the robot should add or rename (fields left out get their defaults, ``dt`` the route's)."""
    warnings = []
    if hello.missing:
        names = " and ".join(f"'{k}'" for k in hello.missing)
        route_dt = f" {dt:g} s" if dt is not None else ""
        assumed = f"; until then dt is taken as the route's{route_dt}" if hello.dt is None else ""
        warnings.append(
            f"the robot's hello does not announce {names}, which protocol version 1 gained after its first "
            f"text: add {'them' if len(hello.missing) > 1 else 'it'} (docs/PROTOCOL.md, 'hello'){assumed}"
        )
    for old in hello.deprecated:
        warnings.append(f"the robot's hello says '{old}', a deprecated name: say '{DEPRECATED[old]}'")
    return warnings


def accept_hello(hello: Hello, dt: float) -> tuple[Hello, list[str]]:
    """The one check `vtr teach` and `vtr repeat` apply to a parsed hello: the fields version 1 gained after its
    first text take their defaults (``dt``: the route's control step) and the warnings say what to add."""
    return replace(hello, dt=hello.dt if hello.dt is not None else dt), hello_warnings(hello, dt)


def check_camera(
    robot: CameraSpec, route: CameraSpec | None = None, model: CameraSpec | None = None, via: str = ""
) -> list[str]:
    """Raise CameraMismatchError when robot, route and model cameras differ; returns notes on what could not
    be compared (a field one side does not record). ``robot`` is the camera the model sees (after the mapping
    ``via`` describes, runtime.resample)."""
    return _compare(robot, "route", route, via) + _compare(robot, "model", model, via)


def _compare(robot: CameraSpec, name: str, other: CameraSpec | None, via: str = "") -> list[str]:
    """check_camera for one of route and model."""
    if other is None:
        return [f"the {name} records no camera; not compared"]
    _check_size(robot, name, other.width, other.height)
    notes = []
    for label, a, b, tol, unit in (
        ("field of view", robot.fov_deg, other.fov_deg, FOV_TOLERANCE_DEG, " deg"),
        ("camera height", robot.height_m, other.height_m, HEIGHT_TOLERANCE_M, " m"),
    ):
        if a is None or b is None:
            notes.append(f"{label} of the robot or the {name} unknown; not compared")
        elif abs(a - b) > tol:
            raise CameraMismatchError(
                f"the robot's {label} is {a:.4g}{unit}{via} but the {name} was made with {b:.4g}{unit} "
                f"(tolerance {tol:g}{unit}); {_FIX[name]}"
            )
    return notes


def _check_size(robot: CameraSpec, name: str, width: int, height: int) -> None:
    if (width, height) != (robot.width, robot.height):
        raise CameraMismatchError(
            f"the robot's camera gives {robot.width}x{robot.height} images but the {name} was made with "
            f"{width}x{height}"
        )


def require_known_fov(camera: Any, where: str) -> None:
    """Refuse (CameraMismatchError, one line with the fix) a route that records its camera's field of view as
    unknown (``"unknown": ["fov_deg", ...]``: taught from a bag without CameraInfo): the camera check that
    protects a repeat could not run."""
    if isinstance(camera, dict) and "fov_deg" in (camera.get("unknown") or ()):
        raise CameraMismatchError(
            f"{where}: the route's camera field of view is unknown (taught from a bag without "
            "sensor_msgs/CameraInfo), so the robot's camera cannot be checked; re-teach it with --camera-fov DEG"
        )


def route_camera(camera: Any) -> CameraSpec | None:
    """The camera a route records in its metadata (None when it records none)."""
    if not isinstance(camera, dict) or "width" not in camera:
        return None
    return camera_from_dict(camera, CameraMismatchError, "route camera.")


def check_camera_range(robot: CameraSpec, model: Any, via: str = "") -> list[str]:
    """A model with a camera range (``model.camera_range``, runtime.model_meta: trained across it, or measured
    to work in it) takes a robot whose field of view and height lie inside that range (widened by the
    tolerances above); outside it, or with an image size it was not made for, CameraMismatchError in one line
    naming the range and the fine-tune command."""
    rng = model.camera_range
    _check_size(robot, "model", model.image_width, model.image_height)
    notes = []
    for label, value, (lo, hi), tol, unit in (
        ("field of view", robot.fov_deg, rng.fov_deg, FOV_TOLERANCE_DEG, " deg"),
        ("camera height", robot.height_m, rng.height_m, HEIGHT_TOLERANCE_M, " m"),
    ):
        if value is None:
            notes.append(f"{label} of the robot unknown; not compared with the model's range ({rng})")
        elif not lo - tol <= value <= hi + tol:
            raise CameraMismatchError(
                f"the robot's {label} is {value:.4g}{unit}{via}, outside the cameras the model takes ({rng}); "
                f"{FINE_TUNE_HINT}"
            )
    return notes


def widest_fov(model: Any) -> float | None:
    """The widest horizontal field of view (deg) the model was trained on: its range's, else its camera's."""
    rng = getattr(model, "camera_range", None)
    return rng.fov_deg[1] if rng is not None else model.camera_fov_deg


def fit_camera(robot: CameraSpec, model: Any) -> CameraMapping:
    """How the robot's frames become the model's input (runtime.resample): the centre crop of the model's
    aspect, narrowed to the model's widest field of view when the camera is wider (beyond the tolerance), then
    resampled to the model's size. `vtr teach` and `vtr repeat` both map by it."""
    return plan(robot, (model.image_height, model.image_width), widest_fov(model), FOV_TOLERANCE_DEG)


def fit_model(robot: CameraSpec, model: Any) -> tuple[CameraMapping, list[str]]:
    """The mapping of the robot's camera to the model's input (:func:`fit_camera`) and the check that the
    camera the model then sees is one it was trained on (its range, check_camera_range, or its one camera
    within the tolerances); CameraMismatchError in one line naming the numbers and the fine-tune command."""
    mapping = fit_camera(robot, model)
    seen, via = mapping.camera(robot.height_m), _via(mapping)
    if getattr(model, "camera_range", None) is not None:
        return mapping, check_camera_range(seen, model, via)
    return mapping, _compare(seen, "model", model.camera, via)


def _via(mapping: CameraMapping) -> str:
    return "" if mapping.identity else f" (its {mapping.describe(seen=False)})"


def fit_robot(hello: Hello, route_cam: dict[str, Any] | None, model: Any) -> tuple[CameraMapping, list[str]]:
    """Refuse (RobotMismatchError, one line) a robot whose camera, as the model sees it through
    :func:`fit_camera`, differs from the route's or is not the model's (:func:`fit_model`; ``model``: a
    ModelMeta), whose limits are below the model's, or whose steps cannot last the model's dt. Returns the
    mapping and notes on what could not be compared."""
    mapping, notes = fit_model(hello.camera, model)
    seen = mapping.camera(hello.camera.height_m)
    notes = _compare(seen, "route", route_camera(route_cam), _via(mapping)) + notes
    for name, unit in (("v_max", "m/s"), ("w_max", "rad/s")):
        mine, robots = getattr(model, name), getattr(hello.limits, name)
        if mine > robots + 1e-9:
            raise RobotMismatchError(
                f"the model commands up to {name}={mine:g} {unit} but the robot accepts at most {robots:g} {unit}"
            )
    dt = hello.dt if hello.dt is not None else model.dt  # not announced: taken to fit (accept_hello warns)
    if not dt <= model.dt <= hello.limits.max_duration:
        raise RobotMismatchError(
            f"the model's control step is {model.dt:g} s but the robot runs steps of "
            f"{dt:g}..{hello.limits.max_duration:g} s"
        )
    return mapping, notes


def mapping_notes(mapping: CameraMapping) -> list[str]:
    """The start-up line of a camera that is not the model's input: how its frames are mapped, and that the
    crop narrows a camera wider than the model saw."""
    if mapping.identity:
        return []
    return [mapping.narrowing() or f"the camera's frames are resampled for the model: {mapping.describe()}"]
