"""Size caps for ROS bags and MCAP files, and decompression that stops at them.

rosbags (the reader behind `vtr eval --run` and `vtr collect/teach --bag`) decompresses a chunk whole and
compares its size with the declared one afterwards, so a 13 KB file could take gigabytes. While a bag is
read through runtime.bag_reader, :func:`bounded_decompression` swaps rosbags' decompressors for ones that
refuse a chunk declaring more than ``MAX_CHUNK_BYTES`` and stop where the output passes its declared size:

- an MCAP chunk (zstd, lz4): at its declared uncompressed size, itself at most ``MAX_CHUNK_BYTES``;
- a ROS 1 chunk (bz2, lz4): at ``MAX_CHUNK_BYTES``;
- a ROS 2 bag compressed per message (zstd): at ``MAX_MESSAGE_BYTES`` a message;
- a ROS 2 bag compressed per file (zstd, decompressed to a temporary file by rosbags): at
  ``FILE_EXPANSION`` times the file's size (at least ``MAX_CHUNK_BYTES``).

Stdlib only at import; the compression modules (rosbags' own dependencies) load when a bag is read.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

MIB = 2**20
#: Decompressed size of one chunk, bytes: a chunk holds one 4096x4096 rgb8 image (48 MiB) with room to spare.
MAX_CHUNK_BYTES = 64 * MIB
#: One message, bytes (after any per-message decompression).
MAX_MESSAGE_BYTES = 64 * MIB
#: Chunks whose times overlap are decompressed together (rosbags merges them by time): their total, bytes.
MAX_LIVE_BYTES = 2 * MAX_CHUNK_BYTES
#: A zstd-compressed bag file may expand this many times (rosbags writes it to a temporary file).
FILE_EXPANSION = 100


class BagFileError(ValueError):
    """A bag or MCAP file that cannot be read within the caps or at all; one line naming the file."""


class CapError(BagFileError):
    """Decompressed data past a cap or past its declared size (the reader adds the file's name)."""


def mib(n: int) -> str:
    """A size for a message: MiB from 1 MiB up, else bytes."""
    return f"{n / MIB:.1f} MiB" if n >= MIB else f"{n} bytes"


def _zstd() -> Any:
    try:
        from compression import zstd  # Python 3.14
    except ImportError:
        from backports import zstd
    return zstd


def inflate(new: Callable[[], Any], data: bytes, limit: int, too_big: str) -> bytes:
    """Every frame of ``data`` through decompressor objects made by ``new`` (zstd, lz4.frame and bz2 share
    their ``decompress(data, max_length)``/``eof``/``unused_data`` interface); CapError(``too_big``) past
    ``limit`` bytes, ValueError for data that ends inside a frame."""
    parts: list[bytes] = []
    total = 0
    while data:
        d = new()
        piece = d.decompress(data, max_length=limit + 1 - total)
        while piece:
            parts.append(piece)
            total += len(piece)
            if total > limit or d.eof or d.needs_input:
                break
            piece = d.decompress(b"", max_length=limit + 1 - total)
        if total > limit:
            raise CapError(f"{too_big}; refusing to decompress it")
        if not d.eof:
            raise ValueError("compressed data that ends inside a frame")
        data = d.unused_data
    return parts[0] if len(parts) == 1 else b"".join(parts)


def _mcap_chunk(new: Callable[[], Any]) -> Callable[[bytes, int], bytes]:
    def decompress(data: bytes, size: int) -> bytes:
        if size > MAX_CHUNK_BYTES:
            raise CapError(
                f"a chunk declares {mib(size)} uncompressed, more than the {mib(MAX_CHUNK_BYTES)} cap; "
                "refusing to decompress it"
            )
        return inflate(new, data, size, f"a chunk expands past the {mib(size)} it declares")

    return decompress


def _capped(new: Callable[[], Any], limit: int, what: str) -> Callable[[bytes], bytes]:
    return lambda data: inflate(new, data, limit, f"{what} expands past the {mib(limit)} cap")


class _CappedStream:
    """A zstd file reader that raises CapError past ``limit`` bytes (rosbags copies it to a temporary file)."""

    def __init__(self, inner: Any, limit: int) -> None:
        self.inner, self.limit, self.total = inner, limit, 0

    def read(self, size: int = -1) -> bytes:
        """Up to ``size`` bytes (all when negative), read a MiB at a time; CapError past the limit."""
        parts: list[bytes] = []
        left = size if size >= 0 else self.limit + 1
        while left > 0:
            data = self.inner.read(min(left, MIB))
            if not data:
                break
            self.total += len(data)
            if self.total > self.limit:
                raise CapError(
                    f"a zstd-compressed bag file expands past {mib(self.limit)} ({FILE_EXPANSION}x its size)"
                )
            parts.append(data)
            left -= len(data)
        return b"".join(parts)

    def __enter__(self) -> _CappedStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.inner.close()


class _BoundedZstd:
    """Stands in for the zstd module in rosbags' ROS 2 reader: per-message and per-file decompression capped."""

    def __init__(self, real: Any) -> None:
        self.real = real

    def decompress(self, data: bytes) -> bytes:
        too_big = f"a zstd-compressed message expands past the {mib(MAX_MESSAGE_BYTES)} cap"
        return inflate(self.real.ZstdDecompressor, data, MAX_MESSAGE_BYTES, too_big)

    def open(self, fileobj: Any, mode: str = "rb") -> _CappedStream:
        limit = max(FILE_EXPANSION * os.fstat(fileobj.fileno()).st_size, MAX_CHUNK_BYTES)
        return _CappedStream(self.real.open(fileobj, mode), limit)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.real, name)


_depth = 0


@contextmanager
def bounded_decompression() -> Iterator[None]:
    """rosbags' decompressors replaced by the capped ones above while the block runs (nesting allowed)."""
    global _depth
    import bz2

    import lz4.frame
    from rosbags.rosbag1 import reader as ros1
    from rosbags.rosbag2 import reader as ros2
    from rosbags.rosbag2 import storage_mcap

    zstd = _zstd()
    saved = dict(storage_mcap.DECOMPRESSORS), dict(ros1.decompressors), ros2.zstd
    if _depth == 0:
        storage_mcap.DECOMPRESSORS.update(
            zstd=_mcap_chunk(zstd.ZstdDecompressor), lz4=_mcap_chunk(lz4.frame.LZ4FrameDecompressor)
        )
        ros1.decompressors.update(
            bz2=_capped(bz2.BZ2Decompressor, MAX_CHUNK_BYTES, "a bz2 chunk"),
            lz4=_capped(lz4.frame.LZ4FrameDecompressor, MAX_CHUNK_BYTES, "an lz4 chunk"),
        )
        ros2.zstd = _BoundedZstd(zstd)
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0:
            storage_mcap.DECOMPRESSORS.clear()
            storage_mcap.DECOMPRESSORS.update(saved[0])
            ros1.decompressors.clear()
            ros1.decompressors.update(saved[1])
            ros2.zstd = saved[2]
