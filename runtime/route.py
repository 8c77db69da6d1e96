"""The taught visual trajectory: subgoal images with their poses and commands, in a versioned ``.npz``.

Arrays (L = number of subgoals):

- ``images``   (L, H, W, 3) uint8 RGB, at the model's resolution.
- ``poses``    (L, 3) float64 (x, y, yaw); NaN where the robot did not know its pose.
- ``commands`` (L, 2) float64 (v, w): the command applied in the control step right after subgoal i was
  recorded (zeros for the last subgoal).
- ``clearance`` (L,) float64, optional: the free distance (m) the teach's range scan showed ahead of each
  subgoal in the taught driving direction (inf: nothing in range, NaN: no scan there); absent when the
  teaching robot had no range sensor.
- ``meta``     a 0-d unicode array holding a JSON object: ``format_version``, ``camera`` (dict),
  ``spacing`` (the subgoal spacing rule, see runtime.teach), ``map``, ``dt`` (s), ``created`` (ISO 8601
  UTC), ``name``.

The file is written uncompressed (a route is a few MB; a compressed one would expand more than the loader's
cap) to a temporary name in the same folder and ``os.replace``d into place. ``load`` first checks the
archive's size caps (runtime.npz_guard: at most 4x the file size, no pickles), then reads with
``allow_pickle=False`` and validates every array.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vtr.runtime.atomic import atomic_path
from vtr.runtime.contracts import CONTROL_DT
from vtr.runtime.kinematics import unicycle
from vtr.runtime.npz_guard import MAX_EXPANSION, NpzTooLargeError, check_npz
from vtr.runtime.paths import require_file

ROUTE_FORMAT_VERSION = 1


class RouteError(ValueError):
    """A route file or object that is malformed; the message says what is wrong."""


def _utc_now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


@dataclass
class Route:
    """A visual trajectory of L subgoals (see the module docstring for the arrays)."""

    images: np.ndarray
    poses: np.ndarray
    commands: np.ndarray
    name: str = "route"
    camera: dict[str, Any] = field(default_factory=dict)
    spacing: dict[str, Any] = field(default_factory=dict)
    map: str | None = None
    dt: float = CONTROL_DT
    created: str = field(default_factory=_utc_now)
    format_version: int = ROUTE_FORMAT_VERSION
    clearance: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.images = np.asarray(self.images)
        self.poses = np.asarray(self.poses, dtype=np.float64)
        self.commands = np.asarray(self.commands, dtype=np.float64)
        if self.clearance is not None:
            self.clearance = np.asarray(self.clearance, dtype=np.float64)
        self.validate()

    def __len__(self) -> int:
        return int(self.images.shape[0])

    @property
    def steps_between(self) -> int | None:
        """Control steps from one subgoal to the next where the teach spaced them by steps, else None."""
        every = self.spacing.get("every") if self.spacing.get("rule") == "steps" else None
        return every if isinstance(every, int) and every >= 1 else None

    def travel_poses(self) -> np.ndarray | None:
        """Poses to measure the taught travel between subgoals by (the progress gate's input).

        The taught poses where the robot reported them all. Where it did not (a bridge without odometry, a
        bag without ``--odom-topic``) and subgoals are a fixed number of control steps apart (spacing
        "steps"), the path the taught commands drive from the first subgoal, each held for its gap (the
        route keeps one command per subgoal, so a gap whose commands changed is approximated). None when
        neither is known (spacing by distance or by image change without poses)."""
        if np.isfinite(self.poses).all():
            return self.poses
        every = self.steps_between
        if every is None:
            return None
        dt = float(self.spacing.get("dt", self.dt)) * every
        out = np.zeros((len(self), 3))
        for i in range(1, len(self)):
            out[i] = unicycle(*out[i - 1], *self.commands[i - 1], dt)
        return out

    @property
    def image_shape(self) -> tuple[int, int]:
        return (int(self.images.shape[1]), int(self.images.shape[2]))

    def validate(self) -> None:
        """Raise RouteError naming the first thing that is wrong."""
        im = self.images
        if im.dtype != np.uint8 or im.ndim != 4 or im.shape[-1] != 3:
            raise RouteError(f"route images must be (L, H, W, 3) uint8, got {im.shape} {im.dtype}")
        n = im.shape[0]
        if n < 1:
            raise RouteError("route has no subgoal images")
        if self.poses.shape != (n, 3):
            raise RouteError(f"route poses must be ({n}, 3), got {self.poses.shape}")
        if self.commands.shape != (n, 2):
            raise RouteError(f"route commands must be ({n}, 2), got {self.commands.shape}")
        if not np.all(np.isfinite(self.commands)):
            raise RouteError("route commands contain NaN or inf")
        if np.any(np.isinf(self.poses)):
            raise RouteError("route poses contain inf (unknown poses are NaN)")
        if self.clearance is not None and (self.clearance.shape != (n,) or bool(np.any(self.clearance < 0))):
            raise RouteError(f"route clearance must be ({n},) metres >= 0, got shape {self.clearance.shape}")
        if not (isinstance(self.dt, int | float) and np.isfinite(self.dt) and self.dt > 0):
            raise RouteError(f"route dt must be a positive number of seconds, got {self.dt!r}")
        if self.format_version != ROUTE_FORMAT_VERSION:
            raise RouteError(
                f"route format version {self.format_version}, this runtime reads version {ROUTE_FORMAT_VERSION}"
            )

    def meta_dict(self) -> dict[str, Any]:
        return {
            "format_version": self.format_version,
            "name": self.name,
            "camera": self.camera,
            "spacing": self.spacing,
            "map": self.map,
            "dt": self.dt,
            "created": self.created,
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write atomically: a temporary file in the same folder, then os.replace."""
        self.validate()
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            np.savez(
                f,
                images=self.images,
                poses=self.poses,
                commands=self.commands,
                meta=np.array(json.dumps(self.meta_dict())),
                **({} if self.clearance is None else {"clearance": self.clearance}),
            )
            f.flush()
            os.fsync(f.fileno())

    @classmethod
    def load(cls, path: str | os.PathLike[str], max_expansion: float = MAX_EXPANSION) -> Route:
        """Read and validate a route file; RouteError says what is wrong with it.

        A file whose arrays would take more than ``max_expansion`` times its size is refused unread.
        """
        path = require_file(path, "route file")
        try:
            check_npz(path, max_expansion)
        except NpzTooLargeError as exc:
            raise RouteError(str(exc)) from None
        try:
            with np.load(path, allow_pickle=False) as data:
                missing = {"images", "poses", "commands", "meta"} - set(data.files)
                if missing:
                    raise RouteError(f"{path}: not a route file, missing arrays {sorted(missing)}")
                images, poses, commands = data["images"], data["poses"], data["commands"]
                clearance = data["clearance"] if "clearance" in data.files else None
                meta_raw = data["meta"]
        except RouteError:
            raise
        except FileNotFoundError:
            raise
        except Exception as exc:
            # numpy's own text for a random file suggests allow_pickle, which must never be the fix here
            why = "not a NumPy .npz archive" if "pickle" in str(exc) else str(exc)
            raise RouteError(
                f"{path}: cannot read as a route .npz ({why}); pass a route written by `vtr teach`"
            ) from exc
        try:
            meta = json.loads(str(meta_raw.item()))
        except (ValueError, TypeError) as exc:
            raise RouteError(f"{path}: route metadata is not JSON: {exc}") from exc
        if not isinstance(meta, dict):
            raise RouteError(f"{path}: route metadata must be a JSON object")
        version = meta.get("format_version")
        if version != ROUTE_FORMAT_VERSION:
            raise RouteError(
                f"{path}: route format version {version!r}, this runtime reads {ROUTE_FORMAT_VERSION}"
            )
        try:
            return cls(
                images=images,
                poses=poses,
                commands=commands,
                name=str(meta.get("name", "route")),
                camera=dict(meta.get("camera") or {}),
                spacing=dict(meta.get("spacing") or {}),
                map=meta.get("map"),
                dt=meta.get("dt", CONTROL_DT),
                created=str(meta.get("created", "")),
                format_version=version,
                clearance=clearance,
            )
        except RouteError as exc:
            raise RouteError(f"{path}: {exc}") from None
