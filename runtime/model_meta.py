"""Constants that travel inside the ONNX file as metadata, written by export/ and checked by the runtime."""

from __future__ import annotations

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
OPTIONAL_FIELDS = ("camera_fov_deg", "camera_height_m")
OUTPUT_VELOCITIES = "velocities"  # (B, 2, N): row 0 = v (m/s), row 1 = w (rad/s)


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

    @property
    def camera(self) -> CameraSpec:
        """The camera this model expects: its input size, and the field of view and height it was trained on."""
        return CameraSpec(self.image_width, self.image_height, self.camera_fov_deg, self.camera_height_m)

    def __post_init__(self) -> None:
        if self.image_height <= 0 or self.image_width <= 0:
            raise ValueError(f"image size must be positive, got {self.image_height}x{self.image_width}")
        if self.horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {self.horizon}")
        check_preprocessing(self.preprocessing)
        if not (self.v_max > 0 and self.w_max > 0 and self.dt > 0):
            raise ValueError(f"v_max, w_max and dt must be positive: {self}")

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
