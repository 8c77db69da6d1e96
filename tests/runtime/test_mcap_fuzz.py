"""Property tests of the MCAP readers, beside the wire's (test_protocol_fuzz.py): whatever bytes a run or bag
holds (cut, overwritten, grown), reading returns or raises BagFileError, one line; nothing else escapes.

Budgets are small (CI has 2 cores); tests/test_crafted_files.py holds the named cases and the memory bound.
"""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from vtr.runtime.bag_caps import BagFileError
from vtr.runtime.bag_reader import GuardedBag
from vtr.runtime.mcap_log import McapRunWriter
from vtr.runtime.mcap_read import read_run

FAST = settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.too_slow])
STORE = get_typestore(Stores.ROS2_HUMBLE)


@functools.cache
def _run_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.mcap"
        with McapRunWriter(path) as writer:
            for k in range(6):
                image = np.full((4, 4, 3), k, np.uint8)
                writer.record({"stamp": 0.1 * k, "image": image, "v": 0.1, "w": 0.0, "pose": (0.1 * k, 0, 0)})
            writer.record_summary({"status": "finished", "subgoals_reached": 3, "steps": 6})
        return path.read_bytes()


@functools.cache
def _zstd_bag_bytes() -> bytes:
    """An MCAP bag whose chunks are zstd-compressed (the run writer's are not)."""
    vec = STORE.types["geometry_msgs/msg/Vector3"]
    twist = STORE.types["geometry_msgs/msg/Twist"](
        linear=vec(x=0.2, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.1)
    )
    with tempfile.TemporaryDirectory() as folder:
        writer = Writer(Path(folder) / "bag", version=9, storage_plugin=StoragePlugin.MCAP)
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        with writer:
            conn = writer.add_connection("/cmd_vel", "geometry_msgs/msg/Twist", typestore=STORE)
            for k in range(20):
                writer.write(conn, k * 10**8, STORE.serialize_cdr(twist, "geometry_msgs/msg/Twist"))
        return (Path(folder) / "bag" / "bag.mcap").read_bytes()


edits = st.lists(
    st.tuples(
        st.sampled_from(["overwrite", "insert", "cut"]),
        st.floats(min_value=0.0, max_value=1.0),
        st.binary(min_size=1, max_size=48),
    ),
    min_size=1,
    max_size=4,
)


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


def _one_line(exc: BaseException) -> None:
    text = str(exc)
    assert "\n" not in text and text, text


@FAST
@given(edits)
# found by CI (session 7): a damaged schema of the right name decodes to a Pose without its fields
@example(changes=[("overwrite", 0.8818199568298812, b"0")])
@example(changes=[("overwrite", 0.87890625, b"0")])
def test_a_damaged_run_reads_or_says_why_in_one_line(changes: list[tuple[str, float, bytes]]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.mcap"
        path.write_bytes(_mutate(_run_bytes(), changes))
        try:
            run = read_run(path)
        except BagFileError as exc:
            _one_line(exc)
            return
        assert run.commands.shape[1] == 2 and len(run.poses) == len(run.commands)
        assert all("\n" not in w for w in run.warnings)


@FAST
@given(edits)
def test_a_damaged_compressed_bag_reads_or_says_why_in_one_line(
    changes: list[tuple[str, float, bytes]],
) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bag.mcap"
        path.write_bytes(_mutate(_zstd_bag_bytes(), changes))
        try:
            with GuardedBag([path], typestore=STORE) as bag:
                for conn, i, _, raw in bag.messages(bag.connections):
                    bag.deserialize(conn, i, raw)
        except BagFileError as exc:
            _one_line(exc)


def test_the_unchanged_files_read_cleanly() -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.mcap"
        path.write_bytes(_run_bytes())
        run = read_run(path)
        assert len(run.commands) == 6 and run.warnings == [] and run.summary["steps"] == 6
        path.write_bytes(_zstd_bag_bytes())
        with GuardedBag([path], typestore=STORE) as bag:
            assert sum(1 for _ in bag.messages(bag.connections)) == 20 and bag.warnings == []


@pytest.mark.parametrize("size", [0, 8, 9, 40])
def test_a_file_cut_anywhere_near_its_start_is_one_line(tmp_path: Path, size: int) -> None:
    path = tmp_path / "run.mcap"
    path.write_bytes(_run_bytes()[:size])
    with pytest.raises(BagFileError) as info:
        read_run(path)
    _one_line(info.value)
