"""An MCAP file's records walked by their headers before rosbags reads it: caps checked, a cut-off file found.

Nothing is decompressed: each record is an opcode and a length (the MCAP spec), and a chunk's header declares
its uncompressed size, so a chunk over ``MAX_CHUNK_BYTES`` or a message record over ``MAX_MESSAGE_BYTES`` is
refused before any byte of it is read. A file whose data section stops part way (a recording that did not
finish, a copy cut short) or whose summary does not read is :func:`repaired` into a temporary copy: the
complete records, a Data End and a footer without a summary, which rosbags then scans in order.
"""

from __future__ import annotations

import os
import shutil
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

from vtr.runtime.bag_caps import MAX_CHUNK_BYTES, MAX_MESSAGE_BYTES, BagFileError, mib

MAGIC = b"\x89MCAP0\r\n"
OP_FOOTER, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x02, 0x05, 0x06, 0x0F
_FOOTER_LENGTH = 20  # summary start, summary offset start (u64 each), summary crc (u32)
#: What a file that is not an MCAP looks like, by its first bytes (for the one-line error).
_LOOKS_LIKE = {
    b"\x89PNG": "a PNG image",
    b"\xff\xd8\xff": "a JPEG image",
    b"{": "JSON (a `vtr repeat --log` file?)",
    b"#ROSBAG": "a ROS 1 bag",
    b"SQLite format": "an SQLite database (a ROS 2 .db3 bag?)",
    b"PK\x03\x04": "a zip archive (an .npz?)",
}


@dataclass(frozen=True)
class Walk:
    """Where the complete records of the data section end, and why the file needs repair (None: it does not)."""

    path: Path
    size: int
    good_end: int
    damage: str | None


def describe(head: bytes) -> str:
    """What a file starting with ``head`` looks like."""
    if not head:
        return "it is empty"
    for magic, what in _LOOKS_LIKE.items():
        if head.startswith(magic):
            return f"it is {what}"
    return "it does not start with the MCAP magic bytes"


def walk(path: str | os.PathLike[str]) -> Walk:
    """Walk ``path``'s data section; BagFileError when it is not an MCAP file or a record exceeds a cap."""
    path = Path(path)
    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        head = f.read(16)
        if not head.startswith(MAGIC):
            raise BagFileError(f"{path}: not an MCAP file ({describe(head)})")
        pos = len(MAGIC)
        while True:
            f.seek(pos)
            header = f.read(9)
            if len(header) < 9:
                return Walk(path, size, pos, f"it ends at byte {size} without its summary (cut off?)")
            op, length = header[0], int.from_bytes(header[1:], "little")
            end = pos + 9 + length
            if end > size:
                return Walk(
                    path, size, pos, f"the record at byte {pos} runs past its end at byte {size} (cut off?)"
                )
            if op == OP_CHUNK and length >= 24:
                declared = int.from_bytes(f.read(24)[16:24], "little")
                if declared > MAX_CHUNK_BYTES:
                    raise BagFileError(
                        f"{path}: the chunk at byte {pos} declares {mib(declared)} uncompressed, more than the "
                        f"{mib(MAX_CHUNK_BYTES)} cap; refusing to decompress it"
                    )
            elif op == OP_MESSAGE and length > MAX_MESSAGE_BYTES:
                raise BagFileError(
                    f"{path}: the message at byte {pos} takes {mib(length)}, more than the "
                    f"{mib(MAX_MESSAGE_BYTES)} cap"
                )
            elif op in (OP_DATA_END, OP_FOOTER):
                return Walk(
                    path, size, pos, None if _ends_well(f, size) else "its summary or footer is damaged"
                )
            pos = end


def _ends_well(f, size: int) -> bool:
    """A footer record and the closing magic at the end of the file."""
    tail = 9 + _FOOTER_LENGTH + len(MAGIC)
    if size < tail:
        return False
    f.seek(size - tail)
    data = f.read(tail)
    return data[0] == OP_FOOTER and data[1:9] == struct.pack("<Q", _FOOTER_LENGTH) and data.endswith(MAGIC)


def repaired(found: Walk, out: Path) -> Path:
    """A copy of ``found.path`` at ``out`` holding its complete data records, then a Data End and a footer with
    no summary (rosbags reads such a file by scanning it); returns ``out``."""
    with open(found.path, "rb") as src, open(out, "wb") as dst:
        left = found.good_end
        while left > 0:
            block = src.read(min(left, 2**20))
            if not block:
                break
            dst.write(block)
            left -= len(block)
        dst.write(bytes([OP_DATA_END]) + struct.pack("<QI", 4, 0))
        dst.write(bytes([OP_FOOTER]) + struct.pack("<QQQI", _FOOTER_LENGTH, 0, 0, 0) + MAGIC)
    return out


def copy_folder(folder: Path, repairs: dict[Path, Walk], dest: Path) -> Path:
    """A bag folder's copy in ``dest``: repaired copies of the damaged MCAP files, links to everything else."""
    out = dest / folder.name
    out.mkdir()
    for item in folder.iterdir():
        if item in repairs:
            repaired(repairs[item], out / item.name)
        elif item.is_file():
            try:
                os.symlink(item.resolve(), out / item.name)
            except OSError:
                shutil.copy2(item, out / item.name)
    return out


def add_chunk_crcs(path: str | os.PathLike[str]) -> int:
    """Fill in the CRC-32 of every uncompressed chunk that has none (rosbags' writer leaves it 0), in place, so
    a reader sees when a chunk's bytes were damaged; returns how many were filled."""
    filled = 0
    with open(path, "r+b") as f:
        size = os.fstat(f.fileno()).st_size
        pos = len(MAGIC)
        while pos + 9 <= size:
            f.seek(pos)
            op, length = struct.unpack("<BQ", f.read(9))
            if op in (OP_DATA_END, OP_FOOTER):
                break
            if op == OP_CHUNK:
                crc, name_len = struct.unpack("<II", f.read(32)[24:32])
                compression = f.read(name_len)
                (records,) = struct.unpack("<Q", f.read(8))
                if crc == 0 and compression == b"":
                    crc, left = 0, records
                    while left > 0:
                        block = f.read(min(left, 2**20))
                        crc, left = zlib.crc32(block, crc), left - len(block)
                    f.seek(pos + 9 + 24)
                    f.write(struct.pack("<I", crc))
                    filled += 1
            pos += 9 + length
    return filled
