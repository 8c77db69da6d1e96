"""Small crafted files for the bad-file tests: MCAP records written by hand (the spec's opcode + length + body),
decompression bombs that are a few KB on disk (repeated zstd frames, a deflate stream of repeated full-flush
segments), runs and bags with one bad message.

A bomb is real: decompressed, it is the size it declares (zeros), so a reader that expands it shows it.
"""

from __future__ import annotations

import io
import shutil
import struct
import zlib
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from vtr.runtime.mcap_log import McapRunWriter

STORE = get_typestore(Stores.ROS2_HUMBLE)
BAG_TOPICS = {"/camera/image": "sensor_msgs/msg/Image", "/cmd_vel": "geometry_msgs/msg/Twist"}
MAGIC = b"\x89MCAP0\r\n"
T0 = 1_700_000_000 * 10**9


def _s(text: str | bytes) -> bytes:
    data = text.encode() if isinstance(text, str) else text
    return struct.pack("<I", len(data)) + data


def record(op: int, body: bytes) -> bytes:
    return bytes([op]) + struct.pack("<Q", len(body)) + body


def schema(sid: int, msgtype: str) -> bytes:
    text = STORE.generate_msgdef(msgtype, ros_version=2)[0]
    return record(0x03, struct.pack("<H", sid) + _s(msgtype) + _s("ros2msg") + _s(text))


def channel(cid: int, sid: int, topic: str) -> bytes:
    return record(0x04, struct.pack("<HH", cid, sid) + _s(topic) + _s("cdr") + struct.pack("<I", 0))


def message(cid: int, t_ns: int, data: bytes) -> bytes:
    return record(0x05, struct.pack("<HIQQ", cid, 0, t_ns, t_ns) + data)


def chunk(compressed: bytes, declared: int, compression: str = "zstd") -> bytes:
    head = struct.pack("<QQQI", T0, T0 + 10**9, declared, 0) + _s(compression)
    return record(0x06, head + struct.pack("<Q", len(compressed)) + compressed)


def mcap(*records: bytes) -> bytes:
    """A file: magic, a ros2 header, the records, Data End, a footer without a summary, magic."""
    end = record(0x0F, struct.pack("<I", 0)) + record(0x02, struct.pack("<QQI", 0, 0, 0)) + MAGIC
    return MAGIC + record(0x01, _s("ros2") + _s("crafted")) + b"".join(records) + end


def _zstd():
    try:
        from compression import zstd
    except ImportError:
        from backports import zstd
    return zstd


def zstd_zeros(n: int) -> bytes:
    """A zstd stream of ``n`` zero bytes, a few bytes a MiB: one small frame repeated (decoders read frames in
    a row), then one for the rest."""
    zstd = _zstd()
    full, rest = divmod(n, 2**20)
    return zstd.compress(bytes(2**20)) * full + (zstd.compress(bytes(rest)) if rest else b"")


def image_bomb_chunk(side: int, channel_id: int, declared: int | None = None) -> bytes:
    """A zstd chunk holding one honest ``side`` x ``side`` rgb8 Image message of zeros (a few KB compressed);
    it declares its true size unless ``declared`` makes it lie."""
    msg = STORE.types["sensor_msgs/msg/Image"](
        header=STORE.types["std_msgs/msg/Header"](
            stamp=STORE.types["builtin_interfaces/msg/Time"](sec=T0 // 10**9, nanosec=0), frame_id="cam"
        ),
        height=side,
        width=side,
        encoding="rgb8",
        is_bigendian=0,
        step=3 * side,
        data=np.zeros(0, np.uint8),
    )
    cdr = bytes(STORE.serialize_cdr(msg, "sensor_msgs/msg/Image"))[:-4]  # all but the empty data's length
    pixels = 3 * side * side
    body = struct.pack("<HIQQ", channel_id, 0, T0, T0) + cdr + struct.pack("<I", pixels)
    head = bytes([0x05]) + struct.pack("<Q", len(body) + pixels) + body
    size = len(head) + pixels
    return chunk(_zstd().compress(head) + zstd_zeros(pixels), size if declared is None else declared)


def png_bomb(side: int) -> bytes:
    """A PNG of ``side`` x ``side`` black rgb8 pixels, a few hundred KB: the deflate stream is one full-flush
    segment of zeros repeated (each segment starts afresh, so repeating it is valid)."""
    row = 1 + 3 * side  # filter byte + pixels
    rows_per_block = max(1, 2**20 // row)
    blocks, rest = divmod(side, rows_per_block)
    z = zlib.compressobj(9)
    head = z.compress(bytes(row * rows_per_block)) + z.flush(zlib.Z_FULL_FLUSH)
    segment = z.compress(bytes(row * rows_per_block)) + z.flush(zlib.Z_FULL_FLUSH)
    last = z.compress(bytes(row * rest)) + z.flush(zlib.Z_FINISH)
    total = row * side
    adler = struct.pack(">I", ((total % 65521) << 16) | 1)  # adler32 of zeros: a = 1, b = length
    idat = head + segment * (blocks - 1) + last[:-4] + adler

    def png_chunk(kind: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    ihdr = struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", idat) + png_chunk(b"IEND", b"")
    )


def twist(v: float = 0.2, w: float = 0.1) -> bytes:
    vec = STORE.types["geometry_msgs/msg/Vector3"]
    msg = STORE.types["geometry_msgs/msg/Twist"](
        linear=vec(x=v, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=w)
    )
    return bytes(STORE.serialize_cdr(msg, "geometry_msgs/msg/Twist"))


def compressed_image(data: bytes, t_ns: int) -> bytes:
    header = STORE.types["std_msgs/msg/Header"](
        stamp=STORE.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9),
        frame_id="c",
    )
    msg = STORE.types["sensor_msgs/msg/CompressedImage"](
        header=header, format="png", data=np.frombuffer(data, np.uint8)
    )
    return bytes(STORE.serialize_cdr(msg, "sensor_msgs/msg/CompressedImage"))


def raw_bag(path: Path, topics: dict[str, str], messages: list[tuple[str, int, bytes]]) -> Path:
    """A ROS 2 MCAP bag folder written by rosbags with the given raw (already CDR) messages."""
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {t: writer.add_connection(t, msgtype, typestore=STORE) for t, msgtype in topics.items()}
        for topic, t_ns, raw in messages:
            writer.write(conns[topic], t_ns, raw)
    return path


def _deflate_zeros(prefix: bytes, n: int) -> tuple[bytes, int]:
    """Raw deflate of ``prefix`` + ``n`` zero bytes, a few KB: full-flush segments of 1 MiB of zeros repeat
    byte for byte (each starts afresh); returns the stream and the CRC-32 of what it inflates to."""
    z = zlib.compressobj(9, zlib.DEFLATED, -15)
    out = [z.compress(prefix) + z.flush(zlib.Z_FULL_FLUSH)]
    full, rest = divmod(n, 2**20)
    segment = z.compress(bytes(2**20)) + z.flush(zlib.Z_FULL_FLUSH)
    out.append(segment * full)
    out.append(z.compress(bytes(rest)) + z.flush(zlib.Z_FINISH))
    crc = zlib.crc32(prefix)
    block = bytes(2**20)
    for _ in range(full):
        crc = zlib.crc32(block, crc)
    return b"".join(out), zlib.crc32(bytes(rest), crc)


def zip_bomb(path: Path, members: dict[str, bytes | tuple[bytes, int]]) -> Path:
    """A zip of ``members``: bytes stored as they are, (prefix, n) deflated as ``prefix`` + n zeros."""
    local, central = bytearray(), bytearray()
    for name, content in members.items():
        if isinstance(content, tuple):
            data, crc = _deflate_zeros(*content)
            method, size = 8, len(content[0]) + content[1]
        else:
            data, crc, method, size = content, zlib.crc32(content), 0, len(content)
        raw = name.encode()
        fields = struct.pack("<HHHHHIII", 20, 0, method, 0, 0x21, crc, len(data), size)
        central += b"PK\x01\x02" + struct.pack("<H", 20) + fields
        central += struct.pack("<HHHHHII", len(raw), 0, 0, 0, 0, 0, len(local)) + raw
        local += b"PK\x03\x04" + fields + struct.pack("<HH", len(raw), 0) + raw + data
    n = len(members)
    end = b"PK\x05\x06" + struct.pack("<HHHHIIH", 0, 0, n, n, len(central), len(local), 0)
    path.write_bytes(bytes(local) + bytes(central) + end)
    return path


def run_steps(path: Path, steps: int = 9, side: int = 8, extra: list[str] | None = None) -> Path:
    with McapRunWriter(path) as writer:
        for k in range(steps):
            image = np.full((side, side, 3), k, np.uint8)
            writer.record(
                {
                    "stamp": 0.1 * k,
                    "image": image,
                    "subgoal_image": image,
                    "v": 0.25,
                    "w": 0.0,
                    "pose": (0.025 * k, 0.0, 0.0),
                    "error": 5.0,
                    "subgoal": k // 2,
                }
            )
        for text in extra or []:
            writer._write("/vtr/step", writer._last_ns + 1, STORE.types["std_msgs/msg/String"](data=text))
        writer.record_summary({"status": "finished", "subgoals_reached": 5, "steps": steps})
    return path


def pose_of_another_type(path: Path) -> Path:
    string = STORE.types["std_msgs/msg/String"](data="x")
    raw = bytes(STORE.serialize_cdr(string, "std_msgs/msg/String"))
    folder = raw_bag(path.with_suffix(""), {"/vtr/pose": "std_msgs/msg/String"}, [("/vtr/pose", T0, raw)])
    shutil.move(folder / f"{folder.name}.mcap", path)
    shutil.rmtree(folder)
    return path


def cut(source: Path, path: Path, keep: float) -> Path:
    data = source.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    return path


def corrupt_middle(source: Path, path: Path) -> Path:
    data = bytearray(source.read_bytes())
    mid = len(data) // 2
    data[mid - 2048 : mid + 2048] = np.random.default_rng(4).integers(0, 256, 4096, dtype=np.uint8).tobytes()
    path.write_bytes(bytes(data))
    return path


def bag_with(path: Path, bad: str) -> Path:
    """A 10-frame bag whose frame or command 2..4 is bad: a cut image, random bytes, a non-UTF-8 encoding."""
    messages = []
    for k in range(10):
        t = T0 + k * 10**8
        image = STORE.types["sensor_msgs/msg/Image"](
            header=STORE.types["std_msgs/msg/Header"](
                stamp=STORE.types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9),
                frame_id="c",
            ),
            height=4,
            width=4,
            encoding="rgb8",
            is_bigendian=0,
            step=12,
            data=np.zeros(48, np.uint8),
        )
        raw_image = bytes(STORE.serialize_cdr(image, "sensor_msgs/msg/Image"))
        raw_cmd = twist()
        if bad == "cut image" and k == 3:
            raw_image = raw_image[: len(raw_image) // 2]
        if bad == "random twist" and k == 4:
            raw_cmd = np.random.default_rng(k).integers(0, 256, 16, dtype=np.uint8).tobytes()
        if bad == "encoding" and k == 2:
            raw_image = raw_image.replace(b"rgb8", b"\xff\xfe\x80\x81")
        messages += [("/camera/image", t, raw_image), ("/cmd_vel", t, raw_cmd)]
    return raw_bag(path, BAG_TOPICS, messages)


def npy_header(shape: tuple[int, ...], dtype: str) -> bytes:
    from numpy.lib import format as npy_format

    out = io.BytesIO()
    npy_format.write_array_header_1_0(out, {"descr": dtype, "fortran_order": False, "shape": shape})
    return out.getvalue()


def checkpoint_bomb(path: Path, small: Path) -> Path:
    """A torch checkpoint whose tensor's storage is a 100 MB member deflated to a few KB (``small``: the
    checkpoint it came from)."""
    import zipfile

    import torch

    torch.save({"kind": "velocitynet", "w": torch.zeros(4)}, small)
    with zipfile.ZipFile(small) as z:
        members = {i.filename: z.read(i) for i in z.infolist()}
    name = next(n for n in members if n.endswith("data/0"))
    members[name] = (b"", 100 * 2**20)
    return zip_bomb(path, members)
