"""A camera of any size seen through the model's input: planned once at start, applied where frames enter.

The robot's frame is centre-cropped to the model's aspect ratio, and further when its field of view is wider
than the model may see, then area-resampled to the model's size (a box filter; bilinear where the crop has
fewer pixels than the model's input). Square pixels and a centred principal point are assumed, so a centred
crop of ``c`` of the ``W`` columns keeps the optical axis and sees ``2 atan(tan(fov / 2) * c / W)`` degrees
(:func:`cropped_fov`). The crop may end between pixels (a fraction of a pixel is weighted by its area), so the
effective field of view is exactly the one planned. :func:`plan` decides the crop; :class:`CameraMapping`
applies it with taps precomputed per axis (a frame costs a weighted sum of a few gathered rows, then of a few
columns); a crop of whole pixels by an integer factor is an exact block mean in integers, and a camera that is
already the model's input passes through untouched. `vtr teach` and `vtr repeat` map with the same plan
(runtime.hello.fit_camera), so a route stores what the model sees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.frame import Frame


def cropped_fov(fov_deg: float, fraction: float) -> float:
    """Horizontal field of view (deg) of a centred crop keeping ``fraction`` of a camera's columns."""
    return math.degrees(2.0 * math.atan(math.tan(math.radians(fov_deg) / 2.0) * fraction))


def _taps(n_src: int, start: float, length: float, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """(idx, weights), each (n_out, T): output i = sum_t weights[i, t] * source[idx[i, t]] along one axis, for
    the source interval [start, start + length) (pixel j covers [j, j + 1)) resampled to n_out pixels."""
    scale = length / n_out
    i = np.arange(n_out, dtype=np.float64)
    if scale >= 1.0:  # box filter: each output pixel averages the source area it covers
        lo, hi = start + i * scale, start + (i + 1) * scale
        first = np.floor(lo).astype(np.int64)
        taps = int(math.ceil(scale)) + 1
        idx = first[:, None] + np.arange(taps)[None, :]
        overlap = np.minimum(hi[:, None], idx + 1.0) - np.maximum(lo[:, None], idx)
        weights = np.clip(overlap, 0.0, None) / scale
    else:  # bilinear between the two source pixel centres around each output centre, kept inside the crop
        centre = start + (i + 0.5) * scale - 0.5
        first_px, last_px = max(0, math.floor(start)), min(n_src, math.ceil(start + length)) - 1
        centre = np.clip(centre, first_px, last_px)
        j0 = np.minimum(np.floor(centre).astype(np.int64), max(first_px, last_px - 1))
        frac = centre - j0
        idx = np.stack([j0, j0 + 1], axis=1)
        weights = np.stack([1.0 - frac, frac], axis=1)
    idx = np.clip(idx, 0, n_src - 1)
    return idx, weights.astype(np.float32)


@dataclass(frozen=True)
class CameraMapping:
    """How frames of a ``source`` (H, W) camera become ``size`` (H, W) model input: the crop (x, y, width,
    height, in source pixels, possibly fractional), the camera's field of view and the one seen through the
    crop (None: unknown), and whether the crop was narrowed below the model's aspect to keep the field of view
    within ``widest_deg``."""

    source: tuple[int, int]
    size: tuple[int, int]
    crop: tuple[float, float, float, float]
    fov_deg: float | None = None
    seen_fov_deg: float | None = None
    narrowed: bool = False
    widest_deg: float | None = None
    _plan: tuple = field(default=(), init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        (src_h, src_w), (out_h, out_w) = self.source, self.size
        x, y, cw, ch = self.crop
        if self.identity:
            kind: tuple = ("identity",)
        elif all(float(v).is_integer() for v in self.crop) and cw % out_w == 0 and ch == cw // out_w * out_h:
            kind = ("block", int(x), int(y), int(cw // out_w))
        else:
            iy, wy = _taps(src_h, y, ch, out_h)
            ix, wx = _taps(src_w, x, cw, out_w)
            c0, c1 = int(ix.min()), int(ix.max()) + 1  # only the columns the crop reads are gathered
            per_tap = (
                iy.T.copy(),
                wy.T[:, :, None, None].copy(),
                (ix - c0).T.copy(),
                wx.T[:, None, :, None].copy(),
            )
            shapes = [(out_h, c1 - c0, 3)] * 2 + [(out_h, out_w, 3)] * 2
            buffers = tuple(np.empty(shape, np.float32) for shape in shapes)  # one mapping serves one client
            kind = ("taps", *per_tap, c0, c1, buffers)
        object.__setattr__(self, "_plan", kind)

    @property
    def identity(self) -> bool:
        """The camera is the model's input: frames pass through untouched."""
        return self.source == self.size and self.crop == (0.0, 0.0, float(self.size[1]), float(self.size[0]))

    def camera(self, height_m: float | None) -> CameraSpec:
        """The camera the model sees through this mapping (its size, the cropped field of view)."""
        return CameraSpec(self.size[1], self.size[0], self.seen_fov_deg, height_m)

    def describe(self, seen: bool = True) -> str:
        """One line: camera size, crop, model size, and the field of view seen (``seen``)."""
        (src_h, src_w), (out_h, out_w) = self.source, self.size
        x, y, cw, ch = self.crop
        fov = "" if self.fov_deg is None else f" of {self.fov_deg:.4g} deg"
        fov_seen = "" if self.seen_fov_deg is None or not seen else f", fov {self.seen_fov_deg:.4g} deg"
        crop = "all of it" if (cw, ch) == (src_w, src_h) else f"the centre {cw:.4g}x{ch:.4g}"
        return f"camera {src_w}x{src_h}{fov}: {crop} -> {out_w}x{out_h}{fov_seen}"

    def narrowing(self) -> str | None:
        """The start-up line saying the crop narrows a camera wider than the model sees, or None."""
        if not self.narrowed:
            return None
        return (
            f"the camera is wider than the model sees ({self.widest_deg:.4g} deg): its frames are cropped "
            f"further ({self.describe()})"
        )

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """uint8 (H, W, 3) of the source size -> uint8 (h, w, 3) of the model's (the same array when identity)."""
        kind = self._plan[0]
        if kind == "identity":
            return image
        out_h, out_w = self.size
        if kind == "block":
            _, x, y, k = self._plan
            crop = image[y : y + k * out_h, x : x + k * out_w].reshape(out_h, k, k * out_w, 3)
            n = k * k
            wide = np.uint16 if 2 * 255 * n + n < 2**16 else np.uint32
            rows = crop[:, 0].astype(wide)  # sums of k whole rows first (contiguous), then of k columns
            for dy in range(1, k):
                rows += crop[:, dy]
            rows = rows.reshape(out_h, out_w, k, 3)
            total = rows[:, :, 0].copy()
            for dx in range(1, k):
                total += rows[:, :, dx]
            return ((2 * total + n) // (2 * n)).astype(np.uint8)  # the mean, rounded half up: exact
        _, iy, wy, ix, wx, c0, c1, (acc, part, out, cols) = self._plan
        rows = image[:, c0:c1]
        # into buffers made once: a fresh float array per tap would cost more in page faults than the sums
        np.multiply(rows[iy[0]], wy[0], out=acc)  # (out_h, columns, 3): a weighted gathered row per tap
        for t in range(1, len(iy)):
            acc += np.multiply(rows[iy[t]], wy[t], out=part)
        np.multiply(np.take(acc, ix[0], axis=1, out=cols), wx[0], out=out)  # (out_h, out_w, 3)
        for t in range(1, len(ix)):
            out += np.multiply(np.take(acc, ix[t], axis=1, out=cols), wx[t], out=cols)
        return np.clip(np.floor(out + 0.5), 0, 255).astype(np.uint8)

    def frame(self, image: np.ndarray) -> Frame:
        """The decoder's image (read-only, its size checked there) as the model-size Frame; built here, so
        not checked again."""
        if self._plan[0] == "identity":
            return Frame.decoded(image)
        out = self(image)
        out.flags.writeable = False
        return Frame.decoded(out)


def plan(
    camera: CameraSpec,
    size: tuple[int, int],
    widest_deg: float | None = None,
    tolerance_deg: float = 0.0,
) -> CameraMapping:
    """The mapping of ``camera``'s frames to ``size`` (H, W): the widest centred crop of the model's aspect,
    narrowed to ``widest_deg`` when the camera's field of view (when known) would exceed it by more than
    ``tolerance_deg``. A camera narrower than the model wants is not widened (the caller's check refuses it)."""
    src_w, src_h = camera.width, camera.height
    out_h, out_w = size
    aspect = out_w / out_h
    cw = min(float(src_w), src_h * aspect)
    if cw == src_h * aspect:
        cw = float(round(cw, 9))  # whole pixels stay whole (no 119.99999 from the division)
    fov = camera.fov_deg
    seen = None if fov is None else cropped_fov(fov, cw / src_w)
    narrowed = False
    if seen is not None and widest_deg is not None and seen > widest_deg + tolerance_deg:
        cw = src_w * math.tan(math.radians(widest_deg) / 2) / math.tan(math.radians(fov) / 2)
        seen, narrowed = cropped_fov(fov, cw / src_w), True
    ch = cw / aspect
    if cw < 1.0 or ch < 1.0:
        raise ValueError(f"a {src_w}x{src_h} camera leaves a crop of {cw:.2g}x{ch:.2g} pixels for the model")
    crop = ((src_w - cw) / 2.0, (src_h - ch) / 2.0, cw, ch)
    return CameraMapping((src_h, src_w), (out_h, out_w), crop, fov, seen, narrowed, widest_deg)
