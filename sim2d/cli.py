"""`vtr sim`: the simulator from the command line.

vtr sim snapshot --out house.png [--x X --y Y --yaw YAW] [--start NAME]
vtr sim serve --bind tcp://127.0.0.1:5555 [--noise 0.05] [--no-scan] [--fov 70 --camera-height 0.45] [--sensor SPEC]
vtr sim route --house random:SEED --seed K --out route.json   (a generated route to `vtr teach`)
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

from vtr.runtime.address import check_endpoint
from vtr.runtime.cliargs import add_config_arguments, config_from_args, opt
from vtr.runtime.commands import Command
from vtr.runtime.contracts import CAMERA


@dataclass(frozen=True)
class SnapshotConfig:
    """What `vtr sim snapshot` draws."""

    out: str = opt("house.png", "output picture (PNG)")
    house: str = opt("house", "map name in sim2d/maps, a path, or random:SEED (a procedural house)")
    x: float | None = opt(None, "robot x in metres (default: the start pose's)")
    y: float | None = opt(None, "robot y in metres (default: the start pose's)")
    yaw: float | None = opt(
        None, "robot yaw in radians, counter-clockwise from +x (default: the start pose's)"
    )
    start: str | None = opt(None, "name of a start pose of the map (e.g. kitchen) instead of the first one")
    brightness: float = opt(1.0, "camera brightness multiplier")
    changes: tuple[str, ...] = ()  # appearance changes (sim2d.appearance); the CLI's repeatable --change

    def __post_init__(self) -> None:
        if not self.out:
            raise ValueError("--out must be a file path, got an empty string")
        if Path(self.out).suffix.lower() != ".png":
            raise ValueError(f"--out {self.out!r}: the snapshot is written as PNG; give a .png file name")
        for name in ("x", "y", "yaw"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"--{name} must be finite, got {value!r}")


def run_snapshot(cfg: SnapshotConfig) -> int:
    from vtr.sim2d.config import CameraConfig, Pose, SimConfig
    from vtr.sim2d.simulator import Simulator
    from vtr.sim2d.snapshot import snapshot

    sim = Simulator(
        SimConfig(house=cfg.house, changes=cfg.changes, camera=CameraConfig(brightness=cfg.brightness))
    )
    base = sim.house.start_poses[0]
    if cfg.start is not None:
        if cfg.start not in sim.house.start_names:
            print(
                f"vtr sim snapshot: unknown start {cfg.start!r}; known: {', '.join(sim.house.start_names)}",
                file=sys.stderr,
            )
            return 2
        base = sim.house.start_poses[sim.house.start_names.index(cfg.start)]
    pose = Pose(
        base.x if cfg.x is None else cfg.x,
        base.y if cfg.y is None else cfg.y,
        base.yaw if cfg.yaw is None else cfg.yaw,
    )
    try:
        path = snapshot(sim, cfg.out, pose)
    except ValueError as err:
        print(f"vtr sim snapshot: {err}", file=sys.stderr)
        return 2
    room = sim.house.room_at(pose.x, pose.y)
    print(f"wrote {path} (robot at x={pose.x:.2f} y={pose.y:.2f} yaw={pose.yaw:.2f} in {room})")
    return 0


@dataclass(frozen=True)
class RouteGenConfig:
    """What `vtr sim route` generates (sim2d.route_gen)."""

    out: str = opt("route.json", "where to write the ROUTE.json")
    house: str = opt("house", "map name in sim2d/maps, a path, or random:SEED (a procedural house)")
    seed: int = opt(0, "route seed: another seed, another route in the same house")

    def __post_init__(self) -> None:
        if not self.out.endswith(".json"):
            raise ValueError(f"--out {self.out!r}: give a .json file name")
        if self.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {self.seed}")


def run_route(cfg: RouteGenConfig) -> int:
    import json

    from vtr.runtime.atomic import write_text_atomic
    from vtr.sim2d.route_gen import generate_route, route_json

    try:
        script = generate_route(cfg.house, cfg.seed)
    except RuntimeError as err:
        print(f"vtr sim route: {err}", file=sys.stderr)
        return 1
    write_text_atomic(cfg.out, json.dumps(route_json(script), indent=2) + "\n")
    moved = sum(abs(s.v) * s.duration for s in script.segments)
    print(
        f"wrote {cfg.out}: {len(script.segments)} segments, {script.duration:.1f} s, {moved:.2f} m in {cfg.house}"
    )
    return 0


def run_serve(
    bind: str,
    noise: float,
    house: str,
    brightness: float,
    mode: str = "lockstep",
    cmd_vel_timeout: float = 0.5,
    changes: tuple[str, ...] = (),
    scan: bool = True,
    drive_script: str | None = None,
    twist: bool = True,
    camera: dict[str, float | int] | None = None,
    sensor: str = "",
) -> int:
    """``camera``: CameraConfig fields besides brightness (fov_deg, camera_height, width, height);
    ``sensor``: a sim2d.sensor spec (blur=0.04,noise=4,...), empty for the ideal camera."""
    from vtr.runtime.route_script import load_route_script
    from vtr.sim2d.config import CameraConfig, SimConfig
    from vtr.sim2d.sensor import parse_sensor

    try:
        from vtr.sim2d.server import BindError, ServerConfig, serve
    except ImportError as err:
        print(
            f"vtr sim serve: the simulator server (sim2d/server.py) is not available: {err}", file=sys.stderr
        )
        return 3
    check_endpoint(bind, bind=True)
    sim_cfg = SimConfig(
        house=house,
        noise=noise,
        changes=changes,
        camera=CameraConfig(brightness=brightness, **(camera or {})),  # type: ignore[arg-type]
        sensor=parse_sensor(sensor) if sensor else None,
    )
    script = None if drive_script is None else load_route_script(drive_script)
    cfg = ServerConfig(
        bind=bind,
        sim=sim_cfg,
        mode=mode,
        cmd_vel_timeout=cmd_vel_timeout,
        scan=scan,
        drive_script=script,
        twist=twist,
    )
    try:
        return int(serve(cfg) or 0)
    except BindError as err:  # the port is taken, or the interface does not exist
        print(f"vtr sim serve: {err}; choose another --bind", file=sys.stderr)
        return 2


_CHANGE_HELP = (
    "appearance change KIND:TARGET=VALUE, repeatable (sim2d/appearance.py), e.g. retexture:wall=3, "
    "move:sofa=0.3, light:level=0.6, light:dark=w,0.5, obstacle:2.0,3.0=0.4, floor:kitchen=5 (default: none)"
)


def add_snapshot_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, SnapshotConfig)
    parser.add_argument("--change", action="append", default=[], metavar="SPEC", help=_CHANGE_HELP)


def add_serve_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--bind",
        default="tcp://127.0.0.1:5555",
        help="ZeroMQ endpoint to bind (default: tcp://127.0.0.1:5555)",
    )
    parser.add_argument(
        "--noise",
        type=float,
        default=0.0,
        help="actuation noise level (SimConfig.noise), 0 = off (default: 0)",
    )
    parser.add_argument(
        "--house",
        default="house",
        help="map name in sim2d/maps, a path, or random:SEED (a procedural house) (default: house)",
    )
    parser.add_argument("--change", action="append", default=[], metavar="SPEC", help=_CHANGE_HELP)
    parser.add_argument(
        "--brightness", type=float, default=1.0, help="camera brightness multiplier (default: 1.0)"
    )
    parser.add_argument(
        "--fov",
        type=float,
        default=CAMERA.fov_deg,
        help="camera horizontal field of view, degrees (default: 90)",
    )
    parser.add_argument(
        "--camera-height",
        type=float,
        default=CAMERA.height_m,
        help="camera height above the floor, metres (default: 0.3)",
    )
    parser.add_argument(
        "--size",
        default=f"{CAMERA.width}x{CAMERA.height}",
        metavar="WxH",
        help="image size in pixels, rendered at that resolution (default: 128x128)",
    )
    parser.add_argument(
        "--sensor",
        default="",
        metavar="SPEC",
        help="camera sensor realism (sim2d/sensor.py), e.g. blur=0.04,noise=6,flicker=0.15,gain_drift=0.1,"
        "wb_drift=0.05,jpeg=30,k1=-0.2; blur is the exposure time in s (default: none, the ideal camera)",
    )
    parser.add_argument(
        "--mode",
        choices=("lockstep", "realtime"),
        default="lockstep",
        help="lockstep: time advances only in step requests (deterministic); realtime: follows the wall clock "
        "(default: lockstep)",
    )
    parser.add_argument(
        "--cmd-vel-timeout",
        type=float,
        default=0.5,
        help="realtime: stop the robot when no step arrived for this many seconds; 0 disables (default: 0.5)",
    )
    parser.add_argument(
        "--no-scan",
        dest="scan",
        action="store_false",
        help="serve a camera-only robot: no range scanner in hello, no scan in the replies (default: a 181-beam "
        "270 deg scanner, 5 m, sim2d/rangefinder.py)",
    )
    parser.add_argument(
        "--no-twist",
        dest="twist",
        action="store_false",
        help="report no executed twist in the replies (default: the commanded twist, docs/PROTOCOL.md)",
    )
    parser.add_argument(
        "--drive-script",
        default=None,
        metavar="ROUTE_JSON",
        help="realtime: the robot drives this ROUTE.json by itself, from its start pose, as its own joystick "
        "would, starting at the first observe (try `vtr teach --follow` with it) (default: none)",
    )


def add_route_arguments(parser: argparse.ArgumentParser) -> None:
    add_config_arguments(parser, RouteGenConfig)


def run_snapshot_cli(args: argparse.Namespace) -> int:
    return run_snapshot(config_from_args(SnapshotConfig, args, changes=tuple(args.change)))


def run_serve_cli(args: argparse.Namespace) -> int:
    return run_serve(
        args.bind,
        args.noise,
        args.house,
        args.brightness,
        args.mode,
        args.cmd_vel_timeout,
        tuple(args.change),
        args.scan,
        args.drive_script,
        args.twist,
        {"fov_deg": args.fov, "camera_height": args.camera_height, **_size(args.size)},
        args.sensor,
    )


def _size(spec: str) -> dict[str, int]:
    """``"WxH"`` -> {"width": W, "height": H} (ValueError, one line, otherwise)."""
    try:
        w, h = (int(v) for v in spec.lower().split("x"))
    except ValueError:
        raise ValueError(f"--size {spec!r}: expected WIDTHxHEIGHT in pixels, e.g. 160x120") from None
    return {"width": w, "height": h}


def run_route_cli(args: argparse.Namespace) -> int:
    return run_route(config_from_args(RouteGenConfig, args))


# `vtr sim SUBCOMMAND`: bad configuration values or a bad map file are a ValueError, one line, exit 2
COMMANDS = {
    "snapshot": Command(
        __name__,
        "write a top-down picture of the house beside the robot's camera image",
        "sim",
        "add_snapshot_arguments",
        "run_snapshot_cli",
    ),
    "serve": Command(
        __name__,
        "serve the simulator over ZeroMQ (runtime/protocol.py)",
        "sim",
        "add_serve_arguments",
        "run_serve_cli",
    ),
    "route": Command(
        __name__,
        "generate a taught route for a house (ROUTE.json for `vtr teach`)",
        "sim",
        "add_route_arguments",
        "run_route_cli",
    ),
}
