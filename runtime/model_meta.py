"""Constants that travel inside the ONNX file as metadata, written by export/ and checked by the runtime."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

from vtr.runtime.contracts import CAMERA, CONTROL_DT, V_MAX, W_MAX, CameraSpec
from vtr.runtime.preprocess import PREPROCESSING, check_preprocessing

#: Metadata key prefix in the ONNX file's metadata_props.
PREFIX = "vtr."
#: Bump when the model's input/output contract changes.
FORMAT_VERSION = 1
INPUT_CURRENT = "current"
INPUT_SUBGOAL = "subgoal"
#: Metadata a model may lack (older exports); read as None.
OPTIONAL_FIELDS = (
    "camera_fov_deg",
    "camera_height_m",
    "camera_fov_min_deg",
    "camera_fov_max_deg",
    "camera_height_min_m",
    "camera_height_max_m",
)
#: What a robot whose camera the model was not trained for runs first (training/README.md, fine-tuning).
FINE_TUNE_HINT = (
    "collect data with this camera and fine-tune: vtr collect ... then vtr train velocitynet "
    "--init models/velocitynet.pt --viewnet models/viewnet.pt --data DATA --out DIR"
)
OUTPUT_VELOCITIES = "velocities"  # (B, 2, N): row 0 = v (m/s), row 1 = w (rad/s)


@dataclass(frozen=True)
class CameraRange:
    """Fields of view (deg) and heights (m) of the robot cameras a model takes, each (min, max): the range its
    training data spans (export/provenance.camera_of), or one it was measured to work in on held-out routes
    (`vtr export --camera-range`; the shipped model's, models/training-summary.json)."""

    fov_deg: tuple[float, float]
    height_m: tuple[float, float]

    def __str__(self) -> str:
        (f0, f1), (h0, h1) = self.fov_deg, self.height_m
        return f"fov {f0:g}-{f1:g} deg, height {h0:g}-{h1:g} m"

    def props(self) -> dict[str, float]:
        """The ModelMeta fields that record this range."""
        return {
            "camera_fov_min_deg": self.fov_deg[0],
            "camera_fov_max_deg": self.fov_deg[1],
            "camera_height_min_m": self.height_m[0],
            "camera_height_max_m": self.height_m[1],
        }

    @classmethod
    def parse(cls, text: str) -> CameraRange:
        """``FOV0-FOV1,H0-H1`` (deg, m: ``65-120,0.2-0.45``); ValueError in one line naming the text."""
        parts = [part.split("-") for part in text.split(",")]
        try:
            if len(parts) != 2 or any(len(part) != 2 for part in parts):
                raise ValueError
            (f0, f1), (h0, h1) = ((float(a), float(b)) for a, b in parts)
        except ValueError:
            raise ValueError(
                f"camera range {text!r} is not FOV0-FOV1,H0-H1 (deg, m), e.g. 65-120,0.2-0.45"
            ) from None
        if not (0 < f0 <= f1 < 180 and 0 < h0 <= h1 and math.isfinite(h1)):
            raise ValueError(
                f"camera range {text!r}: needs 0 < fov min <= max < 180 deg and 0 < height min <= max m"
            )
        return cls((f0, f1), (h0, h1))

    @classmethod
    def of(cls, cameras: list[tuple[float, float]]) -> CameraRange:
        """The range spanned by (fov deg, height m) pairs (the episodes of a dataset)."""
        fovs, heights = [c[0] for c in cameras], [c[1] for c in cameras]
        return cls((min(fovs), max(fovs)), (min(heights), max(heights)))


@dataclass(frozen=True)
class ModelMeta:
    """The model's constants. Every field is stored as a string under ``vtr.<field>``."""

    image_height: int = CAMERA.height
    image_width: int = CAMERA.width
    horizon: int = 2  # N velocity steps predicted per call
    v_max: float = V_MAX  # m/s, |v| <= v_max by the tanh head
    w_max: float = W_MAX  # rad/s
    dt: float = CONTROL_DT  # s each predicted command is meant to be applied for
    preprocessing: str = PREPROCESSING
    format_version: int = FORMAT_VERSION
    #: The camera the training images came from (None: not recorded, as in models exported before it was).
    camera_fov_deg: float | None = CAMERA.fov_deg  # degrees, horizontal
    camera_height_m: float | None = CAMERA.height_m  # metres above the floor
    #: The range of robot cameras the model takes (CameraRange): the training images', for a model trained
    #: across cameras, or one measured on held-out routes (None: the camera above only, within the 2 deg /
    #: 2 cm rule of runtime.hello).
    camera_fov_min_deg: float | None = None
    camera_fov_max_deg: float | None = None
    camera_height_min_m: float | None = None
    camera_height_max_m: float | None = None

    @property
    def camera(self) -> CameraSpec:
        """The camera this model expects: its input size, and the field of view and height it was trained on."""
        return CameraSpec(self.image_width, self.image_height, self.camera_fov_deg, self.camera_height_m)

    @property
    def camera_range(self) -> CameraRange | None:
        """The robot cameras the model takes (None: its one camera only, or exported before ranges were
        recorded)."""
        bounds = (
            self.camera_fov_min_deg,
            self.camera_fov_max_deg,
            self.camera_height_min_m,
            self.camera_height_max_m,
        )
        if any(b is None for b in bounds):
            return None
        return CameraRange((float(bounds[0]), float(bounds[1])), (float(bounds[2]), float(bounds[3])))  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        if self.image_height <= 0 or self.image_width <= 0:
            raise ValueError(f"image size must be positive, got {self.image_height}x{self.image_width}")
        if self.horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {self.horizon}")
        check_preprocessing(self.preprocessing)
        if not (self.v_max > 0 and self.w_max > 0 and self.dt > 0):
            raise ValueError(f"v_max, w_max and dt must be positive: {self}")
        bounds = (
            self.camera_fov_min_deg,
            self.camera_fov_max_deg,
            self.camera_height_min_m,
            self.camera_height_max_m,
        )
        if any(b is not None for b in bounds):
            if any(b is None for b in bounds):
                raise ValueError(
                    "a camera range needs all four of camera_fov_min/max_deg, camera_height_min/max_m"
                )
            fmin, fmax, hmin, hmax = (float(b) for b in bounds)  # type: ignore[arg-type]
            if not (0 < fmin <= fmax < 180 and 0 < hmin <= hmax):
                raise ValueError(f"bad camera range: fov {fmin:g}..{fmax:g} deg, height {hmin:g}..{hmax:g} m")

    def to_props(self) -> dict[str, str]:
        return {PREFIX + k: str(v) for k, v in asdict(self).items() if v is not None}

    @classmethod
    def from_props(cls, props: dict[str, str]) -> ModelMeta:
        """Parse ONNX metadata; raises ValueError naming any missing or malformed key. Keys of no field are
        ignored (``vtr.e_m_default``, which models exported before it was dropped carry; the provenance)."""
        kwargs = {}
        for name, field in cls.__dataclass_fields__.items():
            key = PREFIX + name
            if key not in props and name in OPTIONAL_FIELDS:
                kwargs[name] = None
                continue
            if key not in props:
                raise ValueError(f"model metadata lacks {key!r}; was it exported with `vtr export`?")
            typ = (
                float
                if name in OPTIONAL_FIELDS
                else (
                    field.type
                    if isinstance(field.type, type)
                    else {"int": int, "float": float, "str": str}[field.type]
                )
            )
            try:
                kwargs[name] = typ(props[key])
            except ValueError as err:
                raise ValueError(
                    f"model metadata {key}={props[key]!r} is not a valid {typ.__name__}"
                ) from err
        meta = cls(**kwargs)
        if meta.format_version != FORMAT_VERSION:
            raise ValueError(
                f"model format version {meta.format_version}, this runtime reads {FORMAT_VERSION}"
            )
        return meta
