"""Property tests of `vtr collect/teach --bag`'s reader (training/bag_read.py) beside the wire's fuzzing: a
ROS 2 MCAP bag, a ROS 2 sqlite3 bag and a bz2-compressed ROS 1 bag, cut, overwritten or grown anywhere, read
into a drive or raise BagError with one line; nothing else escapes. Small budgets (CI has 2 cores)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from bag_fixtures import T0, write_drive_bag
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.typesys import Stores, get_typestore

from vtr.training.bag_read import BagError, read_bag

FAST = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
edits = st.lists(
    st.tuples(
        st.sampled_from(["overwrite", "insert", "cut"]),
        st.floats(min_value=0.0, max_value=1.0),
        st.binary(min_size=1, max_size=48),
    ),
    min_size=1,
    max_size=4,
)


@pytest.fixture(scope="module")
def bags(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The unchanged bags, written once: a ROS 2 bag folder of each storage and a ROS 1 .bag file."""
    root = tmp_path_factory.mktemp("bags")
    for storage in ("mcap", "sqlite3"):
        write_drive_bag(root / storage, storage=storage, seconds=1.0, odom=True)
    store = get_typestore(Stores.ROS1_NOETIC)
    types, vec = store.types, store.types["geometry_msgs/msg/Vector3"]
    writer = Ros1Writer(root / "drive.bag")
    writer.set_compression(Ros1Writer.CompressionFormat.BZ2)
    with writer:
        image = writer.add_connection("/camera/image", "sensor_msgs/msg/Image", typestore=store)
        cmd = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=store)
        for k in range(10):
            t = T0 + k * 10**8
            stamp = types["builtin_interfaces/msg/Time"](sec=t // 10**9, nanosec=t % 10**9)
            msg = types["sensor_msgs/msg/Image"](
                header=types["std_msgs/msg/Header"](seq=k, stamp=stamp, frame_id="c"),
                height=4,
                width=4,
                encoding="rgb8",
                is_bigendian=0,
                step=12,
                data=np.full(48, k, np.uint8),
            )
            writer.write(image, t, store.serialize_ros1(msg, "sensor_msgs/msg/Image"))
            twist = types["geometry_msgs/msg/Twist"](
                linear=vec(x=0.2, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.1)
            )
            writer.write(cmd, t, store.serialize_ros1(twist, "geometry_msgs/msg/Twist"))
    return root


def _mutate(data: bytes, changes: list[tuple[str, float, bytes]]) -> bytes:
    out = bytearray(data)
    for kind, where, junk in changes:
        at = int(where * len(out))
        if kind == "overwrite":
            out[at : at + len(junk)] = junk
        elif kind == "insert":
            out[at:at] = junk
        else:
            del out[at:]
    return bytes(out)


def _read(path: Path) -> None:
    try:
        drive = read_bag(
            [path], "/camera/image", "/cmd_vel", "/odom" if path.is_dir() else None, image_size=4
        )
    except BagError as exc:
        assert str(exc) and "\n" not in str(exc), str(exc)
        return
    assert drive.images.shape[1:] == (4, 4, 3) and len(drive.commands) == len(drive)
    assert all("\n" not in w for w in drive.warnings)


@FAST
@given(st.sampled_from(["mcap", "sqlite3", "ros1"]), edits)
def test_a_damaged_bag_reads_or_says_why(
    bags: Path, kind: str, changes: list[tuple[str, float, bytes]]
) -> None:
    with tempfile.TemporaryDirectory() as folder:
        if kind == "ros1":
            path = Path(folder) / "drive.bag"
            path.write_bytes(_mutate((bags / "drive.bag").read_bytes(), changes))
        else:
            path = Path(shutil.copytree(bags / kind, Path(folder) / kind))
            storage = next(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
            storage.write_bytes(_mutate(storage.read_bytes(), changes))
        _read(path)


def test_the_unchanged_bags_read_cleanly(bags: Path) -> None:
    for path in (bags / "mcap", bags / "sqlite3", bags / "drive.bag"):
        drive = read_bag([path], "/camera/image", "/cmd_vel", image_size=4)
        assert len(drive) == 10 and drive.skipped == {} and drive.warnings == []
