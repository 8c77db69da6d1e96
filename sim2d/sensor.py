"""Camera sensor realism (numpy; OpenCV only for JPEG): what a real camera adds to the ideal pinhole image.

One implementation for two users: the simulator applies a :class:`Sensor` to every frame it renders
(``SimConfig.sensor``, ``vtr sim serve --sensor``, the evaluation's sensor conditions), and training draws
random parameters per image and calls the same image operations (training.augment). The runtime never
imports this module.

In the order a camera produces them, each operation on (H, W, 3) uint8 RGB images:

- **motion blur** from the commanded motion: while the shutter is open for ``exposure_s`` the robot turns
  by w * exposure_s (the image slides sideways by focal_px * w * exposure_s pixels) and drives
  v * exposure_s towards what it sees (the image grows about its centre, taken at a nominal 1 m depth);
  the frame is the mean of sub-images along that motion;
- **radial lens distortion** ``k1`` (OpenCV's sign: negative is barrel, straight lines bow outwards), on a
  radius normalised so that the image corners stay where they are (nothing outside the rendered image is
  needed; the centre is magnified by 1 / (1 + k1));
- **exposure and white balance**: slow drifts of the overall gain and of each channel's gain (an
  Ornstein-Uhlenbeck process in log units, correlation time ``drift_time_s``) and a flicker of the gain
  (the beat between mains lighting and the frame rate, ``flicker_hz``);
- **sensor noise**: Gaussian, ``noise`` levels of 255 (1 sigma);
- **JPEG** compression at ``jpeg_quality`` (1-100; 0 = off), as a bridge streaming compressed images does.

Everything random comes from one generator seeded by ``Sensor.reset(seed)``: the same seed and the same
frames give the same images.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

#: Depth (m) at which forward motion's zoom blur is computed (the image has no depth channel).
ZOOM_DEPTH_M = 1.0
#: Most sub-images averaged for motion blur (a blur longer than this many pixels is sampled more coarsely).
MAX_BLUR_SAMPLES = 9


@dataclass(frozen=True)
class SensorConfig:
    """Sensor realism; every field at its default (0) turns its operation off."""

    exposure_s: float = 0.0  # shutter time (s) for motion blur from the commanded (v, w)
    k1: float = 0.0  # radial distortion, negative = barrel (corners fixed)
    gain_drift: float = 0.0  # standard deviation of the exposure gain's slow drift (log units: 0.1 ~ 10%)
    white_balance_drift: float = 0.0  # the same for each channel's gain
    flicker: float = 0.0  # amplitude of the gain's flicker (0.1 = +-10%)
    noise: float = 0.0  # Gaussian sensor noise, levels of 255 (1 sigma)
    jpeg_quality: int = 0  # JPEG quality 1..100; 0 = no compression
    drift_time_s: float = 5.0  # correlation time of the drifts (s)
    flicker_hz: float = 0.7  # frequency of the flicker's beat (Hz)

    def __post_init__(self) -> None:
        limits = {
            "exposure_s": (0.0, 0.5),
            "k1": (-0.5, 0.5),
            "gain_drift": (0.0, 1.0),
            "white_balance_drift": (0.0, 1.0),
            "flicker": (0.0, 0.9),
            "noise": (0.0, 100.0),
            "drift_time_s": (0.01, 1000.0),
            "flicker_hz": (0.0, 100.0),
        }
        for name, (lo, hi) in limits.items():
            value = getattr(self, name)
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            if not (ok and lo <= value <= hi):
                raise ValueError(f"SensorConfig.{name} must be a number in [{lo:g}, {hi:g}], got {value!r}")
        q = self.jpeg_quality
        if not (isinstance(q, int) and not isinstance(q, bool) and 0 <= q <= 100):
            raise ValueError(f"SensorConfig.jpeg_quality must be an integer in 0..100 (0: off), got {q!r}")

    @property
    def active(self) -> bool:
        """Whether any operation is on."""
        return any(
            getattr(self, f)
            for f in ("exposure_s", "k1", "gain_drift", "white_balance_drift", "flicker", "noise")
        ) or bool(self.jpeg_quality)


#: Short names accepted by :func:`parse_sensor` (``vtr sim serve --sensor``), each a SensorConfig field.
SPEC_NAMES = {
    "blur": "exposure_s",
    "k1": "k1",
    "gain_drift": "gain_drift",
    "wb_drift": "white_balance_drift",
    "flicker": "flicker",
    "noise": "noise",
    "jpeg": "jpeg_quality",
    "drift_time": "drift_time_s",
    "flicker_hz": "flicker_hz",
}


def parse_sensor(spec: str) -> SensorConfig:
    """``"blur=0.04,noise=4,jpeg=30,k1=-0.2"`` -> SensorConfig (ValueError, one line, on a bad spec).
    Names: see SPEC_NAMES; blur is the exposure time in seconds."""
    kwargs: dict[str, float | int] = {}
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        name, sep, value = item.partition("=")
        field = SPEC_NAMES.get(name.strip())
        if not sep or field is None:
            raise ValueError(
                f"sensor spec {item!r}: expected NAME=VALUE with NAME in {', '.join(SPEC_NAMES)}"
            )
        try:
            kwargs[field] = int(value) if field == "jpeg_quality" else float(value)
        except ValueError:
            raise ValueError(f"sensor spec {item!r}: {value.strip()!r} is not a number") from None
    return SensorConfig(**kwargs)  # type: ignore[arg-type]


def describe(cfg: SensorConfig) -> str:
    """The spec string of ``cfg`` (its fields that differ from the defaults), as parse_sensor reads it."""
    default = SensorConfig()
    names = {v: k for k, v in SPEC_NAMES.items()}
    return ",".join(
        f"{names[f.name]}={getattr(cfg, f.name):g}"
        for f in fields(cfg)
        if getattr(cfg, f.name) != getattr(default, f.name)
    )


# ------------------------------------------------------------------------------------------ operations
def _sampler(h: int, w: int, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear sampling of an (h, w) image at fractional (rows, cols), clamped to its edges, as (4, N) flat
    pixel indices and (4, N) float32 weights."""
    rows, cols = np.broadcast_arrays(np.asarray(rows, np.float32), np.asarray(cols, np.float32))
    r = np.clip(rows, 0, h - 1).ravel()
    c = np.clip(cols, 0, w - 1).ravel()
    r0 = np.minimum(r.astype(np.int32), max(h - 2, 0))
    c0 = np.minimum(c.astype(np.int32), max(w - 2, 0))
    fr, fc = r - r0, c - c0
    r1, c1 = np.minimum(r0 + 1, h - 1), np.minimum(c0 + 1, w - 1)
    idx = np.stack([r0 * w + c0, r0 * w + c1, r1 * w + c0, r1 * w + c1])
    wts = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc])
    return idx, wts


def _sample(image: np.ndarray, idx: np.ndarray, wts: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """float32 (H', W', 3): ``image`` sampled with _sampler's indices and weights."""
    flat = image.reshape(-1, image.shape[-1]).astype(np.float32)
    acc = np.take(flat, idx[0], axis=0) * wts[0][:, None]
    for k in range(1, 4):
        acc += np.take(flat, idx[k], axis=0) * wts[k][:, None]
    return acc.reshape(*shape, image.shape[-1])


def _to_uint8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def motion_blur(image: np.ndarray, shift_px: float, zoom: float) -> np.ndarray:
    """The mean of the image slid sideways by up to ``shift_px`` pixels (positive: the scene moves right, as
    when the camera turns left) and grown about its centre by up to ``zoom`` (0.02: 2% larger), over the
    exposure. Returns ``image`` itself when the motion is under a tenth of a pixel."""
    h, w = image.shape[:2]
    extent = abs(shift_px) + abs(zoom) * 0.5 * math.hypot(h, w)
    if extent < 0.1:
        return image
    n = int(min(MAX_BLUR_SAMPLES, math.ceil(extent) + 1))
    cy, cx = (h - 1) / 2, (w - 1) / 2
    rows = np.arange(h, dtype=np.float32) - cy
    cols = np.arange(w, dtype=np.float32) - cx
    img = image.astype(np.float32)
    acc = np.zeros(image.shape, np.float32)
    for t in np.linspace(0.0, 1.0, n):
        s = 1.0 + zoom * t
        # a slide and a zoom about the centre are separable: rows first, then columns (linear in each)
        r0, r1, fr = _linear(rows / s + cy, h)
        tmp = img[r0] * (1 - fr)[:, None, None] + img[r1] * fr[:, None, None]
        c0, c1, fc = _linear(cols / s + cx - shift_px * t, w)
        acc += tmp[:, c0] * (1 - fc)[None, :, None] + tmp[:, c1] * fc[None, :, None]
    return _to_uint8(acc / n)


def _linear(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linear interpolation at fractional positions ``x`` along an axis of ``n``, clamped to its ends:
    (lower index, upper index, weight of the upper)."""
    x = np.clip(x, 0, n - 1)
    i0 = np.minimum(x.astype(np.intp), max(n - 2, 0))
    return i0, np.minimum(i0 + 1, n - 1), (x - i0).astype(np.float32)


_DISTORTION_MAPS: dict[tuple[int, int, float], tuple[np.ndarray, np.ndarray]] = {}  # (h, w, k1): sampler


def radial_distortion(image: np.ndarray, k1: float) -> np.ndarray:
    """Radial distortion with coefficient ``k1`` (negative: barrel), radius normalised by the half-diagonal
    so that the corners stay put: the output pixel at radius r shows the pinhole image at
    r * (1 + k1) / (1 + k1 * r^2), which maps [0, 1] onto [0, 1] (monotone for |k1| <= 0.5)."""
    if k1 == 0.0:
        return image
    h, w = image.shape[:2]
    key = (h, w, float(k1))
    if key not in _DISTORTION_MAPS:
        cy, cx = (h - 1) / 2, (w - 1) / 2
        norm = math.hypot(cy, cx) or 1.0
        y = (np.arange(h, dtype=np.float64)[:, None] - cy) / norm
        x = (np.arange(w, dtype=np.float64)[None, :] - cx) / norm
        r2 = x * x + y * y
        scale = (1.0 + k1) / (1.0 + k1 * r2)  # source radius / output radius
        if len(_DISTORTION_MAPS) > 16:
            _DISTORTION_MAPS.clear()
        _DISTORTION_MAPS[key] = _sampler(h, w, y * scale * norm + cy, x * scale * norm + cx)
    return _to_uint8(_sample(image, *_DISTORTION_MAPS[key], (h, w)))


def apply_gains(image: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """Per-channel gains (3,) (exposure times white balance), saturating at 255."""
    g = np.asarray(gains, dtype=np.float32).reshape(1, 1, -1)
    if np.all(g == 1.0):
        return image
    return _to_uint8(image.astype(np.float32) * g)


def add_noise(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of ``sigma`` levels (1 sigma) on every pixel and channel."""
    if sigma <= 0:
        return image
    noise = rng.standard_normal(image.shape, dtype=np.float32) * np.float32(sigma)
    return _to_uint8(image.astype(np.float32) + noise)


def jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    """The image after JPEG compression at ``quality`` (1-100) and decoding (OpenCV)."""
    if not quality:
        return image
    import cv2  # only when JPEG is asked for: the simulator and training run without it otherwise

    ok, buf = cv2.imencode(
        ".jpg", np.ascontiguousarray(image[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    )
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG image")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].copy()


# ------------------------------------------------------------------------------------------ the sensor
class Sensor:
    """A camera's sensor over a run: :meth:`apply` turns each rendered frame into what the camera gives,
    keeping the slow drifts' state between frames."""

    def __init__(self, cfg: SensorConfig, focal_px: float, seed: int = 0) -> None:
        self.cfg, self.focal_px = cfg, float(focal_px)
        self.reset(seed)

    def reset(self, seed: int = 0) -> None:
        """Start again (new generator; the drifts drawn from their stationary spread; the flicker's phase)."""
        self._rng = np.random.default_rng([seed, 7])
        c = self.cfg
        self._log_gain = float(self._rng.standard_normal()) * c.gain_drift
        self._log_wb = self._rng.standard_normal(3) * c.white_balance_drift
        self._phase = float(self._rng.uniform(0.0, 2 * math.pi))
        self._t: float | None = None

    def gains(self, t: float) -> np.ndarray:
        """The per-channel gains at time ``t`` (s), advancing the drifts from the previous frame's time."""
        c = self.cfg
        if self._t is not None and t > self._t:
            a = math.exp(-(t - self._t) / c.drift_time_s)
            b = math.sqrt(1.0 - a * a)
            self._log_gain = a * self._log_gain + b * c.gain_drift * float(self._rng.standard_normal())
            self._log_wb = a * self._log_wb + b * c.white_balance_drift * self._rng.standard_normal(3)
        self._t = t
        flicker = 1.0 + c.flicker * math.sin(2 * math.pi * c.flicker_hz * t + self._phase)
        return np.exp(self._log_gain + self._log_wb) * flicker

    def apply(self, image: np.ndarray, v: float, w: float, t: float) -> np.ndarray:
        """The frame the camera gives at time ``t`` (s) while the robot is commanded (v m/s, w rad/s)."""
        c = self.cfg
        if c.exposure_s:
            image = motion_blur(image, self.focal_px * w * c.exposure_s, v * c.exposure_s / ZOOM_DEPTH_M)
        image = radial_distortion(image, c.k1)
        if c.gain_drift or c.white_balance_drift or c.flicker:
            image = apply_gains(image, self.gains(t))
        image = add_noise(image, c.noise, self._rng)
        return jpeg(image, c.jpeg_quality)
