"""Bags and MCAP files read within caps (runtime.bag_caps, runtime.mcap_walk, runtime.bag_reader): every
decompressor rosbags uses stops at its cap, a cut-off file is read up to the cut, chunks rosbags would hold
together are capped, a run's chunks carry CRCs so damage shows."""

from __future__ import annotations

import bz2
import struct
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from vtr.runtime import bag_caps, bag_reader, mcap_walk
from vtr.runtime.bag_caps import CapError, bounded_decompression
from vtr.runtime.bag_reader import GuardedBag
from vtr.runtime.mcap_log import McapRunWriter
from vtr.runtime.mcap_read import read_run

STORE = get_typestore(Stores.ROS2_HUMBLE)
BIG = bytes(bag_caps.MAX_CHUNK_BYTES + 2**20)  # one MiB past the cap, zeros: compresses to a few KB


def _zstd():
    try:
        from compression import zstd
    except ImportError:
        from backports import zstd
    return zstd


@pytest.fixture(scope="module")
def bombs() -> dict[str, bytes]:
    return {"zstd": _zstd().compress(BIG), "lz4": lz4.frame.compress(BIG), "bz2": bz2.compress(BIG)}


def test_every_decompressor_rosbags_uses_stops_at_its_cap(bombs: dict[str, bytes]) -> None:
    from rosbags.rosbag1 import reader as ros1
    from rosbags.rosbag2 import reader as ros2
    from rosbags.rosbag2 import storage_mcap

    original = storage_mcap.DECOMPRESSORS["zstd"], ros1.decompressors["bz2"], ros2.zstd
    with bounded_decompression():
        for kind in ("zstd", "lz4"):
            with pytest.raises(CapError, match="declares 65.0 MiB uncompressed, more than the 64.0 MiB cap"):
                storage_mcap.DECOMPRESSORS[kind](bombs[kind], len(BIG))
            with pytest.raises(CapError, match="expands past the 1000 bytes it declares"):
                storage_mcap.DECOMPRESSORS[kind](bombs[kind], 1000)
        for kind in ("bz2", "lz4"):
            with pytest.raises(CapError, match="expands past the 64.0 MiB cap"):
                ros1.decompressors[kind](bombs[kind])
        with pytest.raises(CapError, match="zstd-compressed message expands past"):
            ros2.zstd.decompress(bombs["zstd"])
        small = _zstd().compress(b"abc" * 1000)
        assert storage_mcap.DECOMPRESSORS["zstd"](small, 3000) == b"abc" * 1000  # honest data passes
        assert ros2.zstd.decompress(small + small) == b"abc" * 2000  # frames in a row, as zstd reads them
    assert (storage_mcap.DECOMPRESSORS["zstd"], ros1.decompressors["bz2"], ros2.zstd) == original


def test_a_zstd_compressed_bag_file_is_capped_at_its_expansion(
    tmp_path: Path, bombs: dict[str, bytes]
) -> None:
    from rosbags.rosbag2 import reader as ros2

    path = tmp_path / "bag.mcap.zstd"
    path.write_bytes(bombs["zstd"])
    with bounded_decompression(), open(path, "rb") as f, ros2.zstd.open(f, "rb") as stream:
        with pytest.raises(CapError, match=r"100x its size"):
            while stream.read(2**20):
                pass


def test_cut_data_is_damage_not_a_cap() -> None:
    with pytest.raises(ValueError, match="ends inside a frame") as info:
        bag_caps.inflate(_zstd().ZstdDecompressor, _zstd().compress(bytes(10**6))[:-8], 10**6, "x")
    assert not isinstance(info.value, CapError)


def _run(path: Path, steps: int, side: int = 96) -> Path:
    with McapRunWriter(path) as writer:
        for k in range(steps):
            image = np.full((side, side, 3), k, np.uint8)
            step = {"stamp": 0.1 * k, "image": image, "subgoal_image": image, "v": 0.1, "w": 0.0}
            writer.record({**step, "pose": (0.01 * k, 0, 0)})
    return path


def test_a_run_cut_off_is_read_up_to_the_cut_with_a_warning(tmp_path: Path) -> None:
    path = _run(tmp_path / "run.mcap", 30)  # two chunks: the first ends inside step 18
    data = path.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: int(len(data) * 0.9)])
    run = read_run(tmp_path / "cut.mcap")
    assert len(run.commands) == 18 and len(run.warnings) == 1
    assert "cut.mcap is damaged" in run.warnings[0] and "cut off" in run.warnings[0]
    assert not list(tmp_path.glob("vtr-bag-*"))  # the repaired copy was temporary


def test_a_damaged_chunk_stops_reading_with_a_warning_thanks_to_its_crc(tmp_path: Path) -> None:
    path = _run(tmp_path / "run.mcap", 45)  # three chunks
    found = mcap_walk.walk(path)
    assert found.damage is None
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one bit in an image's pixels, in the second chunk
    path.write_bytes(bytes(data))
    run = read_run(path)
    assert len(run.commands) == 18 and "checksum" in run.warnings[0]


def test_a_summary_that_does_not_read_falls_back_to_the_data_section(tmp_path: Path) -> None:
    path = _run(tmp_path / "run.mcap", 5, side=8)
    data = bytearray(path.read_bytes())
    end = mcap_walk.walk(path).good_end  # the Data End record: the summary follows it
    data[end + 9 : len(data) - 37] = bytes([0x03]) * (len(data) - 37 - end - 9)  # garbage records
    path.write_bytes(bytes(data))
    run = read_run(path)
    assert len(run.commands) == 5 and "index does not read" in run.warnings[0]


def test_a_run_named_otherwise_is_still_read(tmp_path: Path) -> None:
    path = _run(tmp_path / "run.mcap", 3, side=8)
    path.rename(tmp_path / "run.dat")
    assert len(read_run(tmp_path / "run.dat").commands) == 3


def _overlapping_chunks(path: Path) -> Path:
    """Two chunks of ~1.1 MiB whose times overlap (messages written out of time order)."""
    image = STORE.types["sensor_msgs/msg/Image"]
    header = STORE.types["std_msgs/msg/Header"](
        stamp=STORE.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""
    )
    msg = image(
        header=header,
        height=1,
        width=200_000,
        encoding="mono8",
        is_bigendian=0,
        step=200_000,
        data=np.zeros(200_000, np.uint8),
    )
    raw = bytes(STORE.serialize_cdr(msg, "sensor_msgs/msg/Image"))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/i", "sensor_msgs/msg/Image", typestore=STORE)
        for t in [*range(0, 12, 2), *range(1, 12, 2)]:  # chunk 1: even seconds, chunk 2: odd ones
            writer.write(conn, t * 10**9, raw)
    return path


def test_chunks_rosbags_would_decompress_together_are_capped(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = _overlapping_chunks(tmp_path / "bag")
    with GuardedBag([path]) as bag:  # 2.3 MiB at once is within the real cap
        assert sum(1 for _ in bag.messages(bag.connections)) == 12
    monkeypatch.setattr(bag_reader, "MAX_LIVE_BYTES", 2 * 2**20)
    with pytest.raises(bag_caps.BagFileError, match=r"chunks overlapping in time would take 2\.\d MiB"):
        GuardedBag([path]).__enter__()


def test_a_written_run_carries_a_crc_in_every_chunk(tmp_path: Path) -> None:
    path = _run(tmp_path / "run.mcap", 30)
    crcs = []
    with open(path, "rb") as f:
        data = f.read()
    pos = 8
    while data[pos] not in (mcap_walk.OP_DATA_END, mcap_walk.OP_FOOTER):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == mcap_walk.OP_CHUNK:
            crcs.append(struct.unpack_from("<I", data, pos + 9 + 24)[0])
        pos += 9 + length
    assert len(crcs) == 2 and all(crcs)


@pytest.mark.parametrize("mode", ["FILE", "MESSAGE", "STORAGE"])
def test_honest_compressed_bags_read_through_the_caps(tmp_path: Path, mode: str) -> None:
    from rosbags.rosbag2 import CompressionFormat, CompressionMode

    vec = STORE.types["geometry_msgs/msg/Vector3"]
    twist = STORE.types["geometry_msgs/msg/Twist"](
        linear=vec(x=0.2, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.1)
    )
    writer = Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode[mode], CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=STORE)
        for k in range(30):
            writer.write(conn, k * 10**8, STORE.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
    with GuardedBag([tmp_path / "bag"], typestore=STORE) as bag:
        got = [bag.deserialize(c, i, raw).linear.x for c, i, _, raw in bag.messages(bag.connections)]
    assert got == [0.2] * 30 and bag.warnings == []
