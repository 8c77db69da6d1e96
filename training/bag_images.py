"""Camera messages from bags as RGB pictures, their size checked before anything is decoded.

``sensor_msgs/Image`` (rgb8, bgr8, mono8, rgba8, bgra8): width and height at most ``MAX_IMAGE_SIDE`` and
the rows (``step``) inside the data. ``CompressedImage``: PNG or JPEG, whose width and height are read
from the header (PNG's IHDR, JPEG's start-of-frame) and checked the same way before OpenCV or Pillow
decodes it, so a small file declaring a huge picture (a decompression bomb) is never expanded.
"""

from __future__ import annotations

import functools
import io
from typing import Any

import numpy as np

from vtr.runtime.contracts import CameraSpec
from vtr.runtime.resample import CameraMapping, plan

#: Largest width or height of a camera image read from a bag, pixels (a 4096x4096 rgb8 image is 48 MiB).
MAX_IMAGE_SIDE = 4096
CHANNELS = {
    "rgb8": (3, False),
    "bgr8": (3, True),
    "rgba8": (4, False),
    "bgra8": (4, True),
    "mono8": (1, False),
}
_PNG = b"\x89PNG\r\n\x1a\n"
#: JPEG start-of-frame markers (baseline, progressive, ...; not DHT C4, JPG C8, DAC CC).
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


class ImageTooLargeError(ValueError):
    """An image over MAX_IMAGE_SIDE: the bag is refused, not the frame skipped."""


class NoDecoderError(ValueError):
    """Neither OpenCV nor Pillow is installed to decode a CompressedImage."""


def compressed_size(data: bytes) -> tuple[int, int]:
    """(width, height) a PNG or JPEG declares in its header; ValueError when it is neither or has none."""
    if data.startswith(_PNG):
        if data[12:16] != b"IHDR" or len(data) < 24:
            raise ValueError("a PNG without its IHDR header")
        return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    if data.startswith(b"\xff\xd8"):
        i = 2
        while i + 9 <= len(data):
            if data[i] != 0xFF:
                break
            marker = data[i + 1]
            if marker == 0xFF:  # fill byte
                i += 1
                continue
            if marker in _SOF:
                return int.from_bytes(data[i + 7 : i + 9], "big"), int.from_bytes(data[i + 5 : i + 7], "big")
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:  # markers without a length
                i += 2
                continue
            i += 2 + int.from_bytes(data[i + 2 : i + 4], "big")
        raise ValueError("a JPEG without a start-of-frame header")
    raise ValueError("neither PNG nor JPEG")


def check_size(width: int, height: int, what: str) -> None:
    if width < 1 or height < 1:
        raise ValueError(f"{what} of {width}x{height} pixels")
    if width > MAX_IMAGE_SIDE or height > MAX_IMAGE_SIDE:
        raise ImageTooLargeError(
            f"{what} of {width}x{height} pixels, more than the {MAX_IMAGE_SIDE}x{MAX_IMAGE_SIDE} cap"
        )


def _decode_compressed(data: bytes, fmt: str) -> np.ndarray:
    try:
        width, height = compressed_size(data)
    except ValueError as exc:
        raise ValueError(f"a {fmt!r} CompressedImage that is {exc}") from None
    check_size(width, height, f"a {fmt!r} CompressedImage")
    try:
        import cv2

        bgr = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if bgr is None:
            raise ValueError(f"a {fmt!r} CompressedImage that does not decode")
        return bgr[:, :, ::-1]
    except ImportError:
        pass
    try:
        from PIL import Image
    except ImportError:
        raise NoDecoderError("CompressedImage needs opencv-python-headless or pillow installed") from None
    try:
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))
    except Exception as exc:
        raise ValueError(f"a {fmt!r} CompressedImage that does not decode") from exc


def decode_image(msg: Any, msgtype: str) -> np.ndarray:
    """A ROS image message as (H, W, 3) uint8 RGB. ValueError naming what cannot be read (the frame is
    skipped); ImageTooLargeError over the cap."""
    if msgtype.endswith("CompressedImage"):
        return _decode_compressed(np.asarray(msg.data, dtype=np.uint8).tobytes(), str(msg.format))
    if msg.encoding not in CHANNELS:
        raise ValueError(f"image encoding {msg.encoding!r} (supported: {', '.join(CHANNELS)})")
    check_size(int(msg.width), int(msg.height), "an image")
    channels, bgr = CHANNELS[msg.encoding]
    data = np.asarray(msg.data, dtype=np.uint8)
    if msg.step < msg.width * channels or data.size < msg.step * msg.height:
        raise ValueError(f"an image whose data ({data.size} bytes) does not fit {msg.height}x{msg.width}")
    rows = data[: msg.step * msg.height].reshape(msg.height, msg.step)[:, : msg.width * channels]
    image = rows.reshape(msg.height, msg.width, channels)
    if channels == 1:
        return np.repeat(image, 3, axis=2)
    image = image[:, :, :3]
    return image[:, :, ::-1] if bgr else image


def square_resize(image: np.ndarray, size: int) -> np.ndarray:
    """Centre-crop to a square, then resize to size x size exactly as the runtime maps a robot's frames
    (runtime/resample.py: area averaging, bilinear upwards), so a route taught from a bag is what a repeat
    on that camera sees."""
    h, w = image.shape[:2]
    return np.ascontiguousarray(_square_mapping(w, h, size)(image))


@functools.lru_cache(maxsize=8)
def _square_mapping(width: int, height: int, size: int) -> CameraMapping:
    return plan(CameraSpec(width, height, None, None), (size, size))
