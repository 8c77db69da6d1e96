"""A camera frame checked once where it enters the runtime, and trusted from then on.

A :class:`Frame` is a uint8 (H, W, 3) RGB image that cannot change (read-only, owned by the frame), plus
what is derived from it at most once: its planar float32 levels (3, H, W), which the matcher, light
matching and the policy's input tensor all start from, and anything a consumer keeps on it with
:meth:`Frame.derived` (a subgoal's network input, its light statistics). Frames are made where images
enter: the client's decoder (:meth:`Frame.decoded`, a payload whose size the decoder checked), the
in-process simulator's robot adapter, and, for a plain array a test or a tool passes to a public call,
:func:`as_frame`, the one conversion. Code that is handed a Frame does not check it again.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

from vtr.runtime.wire_json import BadFrameError

T = TypeVar("T")


class Frame:
    """One checked camera image and what is derived from it (see the module docstring).

    Make one with :func:`as_frame` (any array), :meth:`decoded` (the decoder's own array) or
    :meth:`from_levels` (planar levels a runtime stage computed); the constructor is not for callers."""

    __slots__ = ("_image", "_levels", "_derived")

    def __init__(self, image: np.ndarray | None, levels: np.ndarray | None = None) -> None:
        self._image, self._levels = image, levels
        self._derived: dict[Hashable, Any] = {}

    @classmethod
    def decoded(cls, image: np.ndarray) -> Frame:
        """A frame from a decoder that built ``image`` itself: uint8 (H, W, 3) over a payload whose length it
        checked (``np.frombuffer`` of ``bytes``: read-only). Not checked again."""
        return cls(image)

    @classmethod
    def from_levels(cls, levels: np.ndarray) -> Frame:
        """A frame given by its planar levels: float32 (3, H, W) holding integers 0..255, which the caller
        hands over (made read-only here; the uint8 image is derived only if asked for)."""
        levels.flags.writeable = False
        return cls(None, levels)

    @property
    def image(self) -> np.ndarray:
        """uint8 (H, W, 3), read-only."""
        if self._image is None:
            image = np.ascontiguousarray(self._levels.transpose(1, 2, 0)).astype(np.uint8)
            image.flags.writeable = False
            self._image = image
        return self._image

    @property
    def levels(self) -> np.ndarray:
        """float32 (3, H, W) of the same values, C order, read-only: made on first use, then kept."""
        if self._levels is None:
            self._levels = planar(self._image)
            self._levels.flags.writeable = False
        return self._levels

    @property
    def shape(self) -> tuple[int, int, int]:
        """(H, W, 3), as the image's."""
        if self._image is not None:
            return self._image.shape  # type: ignore[return-value]
        c, h, w = self._levels.shape
        return (h, w, c)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        """``np.asarray(frame)``: the image (read-only), for tools that take arrays."""
        return self.image if dtype is None else self.image.astype(dtype)

    def derived(self, key: Hashable, make: Callable[[Frame], T]) -> T:
        """``make(self)``, made once per frame and ``key`` and kept on the frame (the frame's own data: gone
        with it). The result must not be changed by whoever receives it."""
        try:
            return self._derived[key]
        except KeyError:
            value = self._derived[key] = make(self)
            return value


def planar(image: np.ndarray) -> np.ndarray:
    """uint8 (H, W, 3) -> float32 (3, H, W) of the same values, C order (exact): the strided copy in uint8
    (a quarter of the bytes), then one contiguous conversion (about 20% less than converting while striding)."""
    out = np.empty((3, *image.shape[:2]), np.float32)
    np.copyto(out, np.ascontiguousarray(image.transpose(2, 0, 1)))
    return out


def check_image(image: Any, shape: tuple[int, int] | None = None) -> np.ndarray:
    """``image`` if it is a uint8 (H, W, 3) array ((H, W) = ``shape`` when given), else BadFrameError naming
    what it is instead."""
    dims = getattr(image, "shape", None)
    if not (
        isinstance(image, np.ndarray) and image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    ):
        kind = getattr(image, "dtype", type(image).__name__)
        want = "(H, W, 3)" if shape is None else str((*shape, 3))
        raise BadFrameError(f"image {dims} {kind}, expected a {want} uint8 RGB image")
    if shape is not None and image.shape[:2] != tuple(shape):
        raise BadFrameError(f"image {dims} uint8, expected {(*shape, 3)} uint8")
    return image


def as_frame(image: Frame | np.ndarray, shape: tuple[int, int] | None = None, copy: bool = True) -> Frame:
    """The one conversion of an image to a :class:`Frame`: a Frame is returned as it is (it was checked where
    it was made); an array is checked (:func:`check_image`, with the expected (H, W) ``shape`` when given)
    and copied, so that the frame owns pixels nobody can change (``copy=False``: the caller hands the array
    over, and it is made read-only)."""
    if isinstance(image, Frame):
        return image
    check_image(image, shape)
    if copy:
        image = np.array(image, order="C", copy=True)
    elif not image.flags.c_contiguous:
        image = np.ascontiguousarray(image)
    image.flags.writeable = False
    return Frame(image)


def frames_of(images: np.ndarray) -> list[Frame]:
    """One Frame per image of a (L, H, W, 3) uint8 stack (a route's subgoals), each its own read-only copy."""
    return [as_frame(image) for image in images]
